"""The founding paper's acquisition instrument, as figures: acceleration, velocity and
displacement against time, and the operating deflection shape (the relative movement of the
robot's bodies) at a resonance, drawn and animated like a mode.

matplotlib and rerun are imported inside the functions (through
:func:`vibroscope.viewers._common.pyplot` and :func:`vibroscope.viewers.rerun_view.log_analysis`),
so importing this module costs nothing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal, Mapping

import numpy as np

from vibroscope.modal import ods_as_modal_model
from vibroscope.signals import true_runs
from vibroscope.spectral.integration import OperatingShape, integrate, velocity_and_displacement
from vibroscope.viewers._common import distinct_labels, pyplot

__all__ = ["plot_kinematics", "ods_as_modal_model", "log_ods"]

_PREFIX = {0: "", -3: "m", -6: "µ", -9: "n"}
_PRETTY = {"m/s^2": "m/s²", "m/s2": "m/s²", "m s^-2": "m/s²", "m/s²": "m/s²", "m/s": "m/s", "m": "m"}


def _display_unit(unit: str, peak: float) -> tuple[float, str]:
    """(factor, unit label) that brings `peak` of an SI length-based `unit` to 1–1000 (mm, µm, nm)."""
    u = _PRETTY.get(unit.strip())
    if u is None:
        return 1.0, unit or "-"
    if not np.isfinite(peak) or peak <= 0 or peak >= 1.0:
        return 1.0, u
    e = int(np.clip(3 * np.floor(np.log10(peak) / 3), -9, 0))
    return 10.0 ** -e, _PREFIX[e] + u


def _trace(ax, t: np.ndarray, x: np.ndarray, color: str, max_points: int) -> None:
    """A line, or its per-bin min/max envelope when longer than `max_points` (as plot_signals)."""
    if x.size > max_points:
        nb = max_points // 2
        edges = np.linspace(0, x.size, nb + 1).astype(int)
        with np.errstate(invalid="ignore"):  # over the present samples; an all-missing bin breaks
            lo = np.fmin.reduceat(x, edges[:-1])
            hi = np.fmax.reduceat(x, edges[:-1])
        ax.fill_between(t[edges[:-1]], lo, hi, color=color, lw=0, step="post")
    else:
        ax.plot(t, x, lw=0.8, color=color)


def plot_kinematics(acc_signals, *, f_cut: float | None = None,
                    method: Literal["frequency", "highpass"] = "frequency", max_channels: int = 3,
                    fig=None, max_points: int = 3000, integrals=None):
    """Acceleration, velocity and displacement against time, one column per channel.

    Velocity and displacement come from :func:`vibroscope.spectral.integration.integrate`
    (drift-free, high-passed at `f_cut`). Each row shares its y axis across the channels, in
    the SI unit with the prefix that suits the largest value (m/s², mm/s, µm, ...). The first
    and last ``1 / f_cut`` s, where the integrals depend on the unknown signal outside the
    record, are shaded; with gaps (NaN), those of every stretch between gaps (each integrated
    on its own), and the gaps are red. Peak and RMS are over the samples present.

    Parameters
    ----------
    acc_signals : Signals
        Accelerations, ``data`` shape (n_channels, n_samples), in m/s², ``fs`` in Hz.
    f_cut : float, optional
        High-pass cut-off in Hz of the integrations; default
        :func:`vibroscope.spectral.integration.default_f_cut`.
    method : {'frequency', 'highpass'}, optional
        Integration method (see :func:`~vibroscope.spectral.integration.integrate`).
    max_channels : int, optional
        At most this many channels (the first ones) are drawn; the title says how many there are.
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.
    max_points : int, optional
        Longer records are drawn as their per-bin minimum/maximum envelope.
    integrals : tuple of Signals, optional
        ``(velocity, displacement)`` of `acc_signals`, already integrated
        (``integrate(acc_signals, order=1)``, ``order=2``; `f_cut` and `method` are then theirs):
        not computed again.

    Returns
    -------
    matplotlib.figure.Figure
        3 × n axes (rows: acceleration, velocity, displacement).

    Raises
    ------
    ValueError
        If `max_channels` < 1, or from :func:`~vibroscope.spectral.integration.integrate`.
    """
    if max_channels < 1:
        raise ValueError(f"{max_channels=} must be at least 1")
    nc = min(acc_signals.n_channels, int(max_channels))
    acc = acc_signals.select(range(nc))
    if integrals is not None:
        vel, disp = (s.select(range(nc)) for s in integrals)
        method = vel.meta["integration"].get("method", method)
    else:
        vel, disp = velocity_and_displacement(acc, f_cut=f_cut, method=method)
    fc = vel.meta["integration"]["f_cut_hz"]
    if fig is None:
        plt = pyplot()
        fig = plt.figure(figsize=(min(3.9 * nc + 1.3, 16), 7.2), layout="constrained")
    else:
        fig.clf()
    axes = fig.subplots(3, nc, sharex=True, sharey="row", squeeze=False)
    t = np.arange(acc.n_samples) / acc.fs
    T = acc.duration
    names = distinct_labels(acc.channels, 30)
    rows = [("acceleration", acc), ("velocity", vel), ("displacement", disp)]
    edge = 1.0 / fc
    for r, (what, sig) in enumerate(rows):
        data = np.asarray(sig.data)
        # one prefix per row (shared y axis); units may differ per channel only if unknown
        units = set(sig.units)
        unit = units.pop() if len(units) == 1 else ""
        top = np.abs(data[np.isfinite(data)])
        fac, ulabel = _display_unit(unit, float(top.max()) if top.size else 0.0)
        for c in range(nc):
            ax = axes[r, c]
            x = data[c] * fac
            _trace(ax, t, x, f"C{r}", max_points)
            # every stretch between gaps is integrated as a record of its own: edge zones at both of its
            # ends; the gaps themselves (missing, never bridged) in red
            a_s, b_s = true_runs(np.isfinite(np.asarray(acc.data[c])))
            for k, (a, b) in enumerate(zip(a_s[:200] / acc.fs, b_s[:200] / acc.fs)):
                if 2 * edge < 0.5 * (b - a):
                    for lo, hi in ((a, a + edge), (b - edge, b)):
                        ax.axvspan(lo, hi, color="0.85", lw=0, zorder=0)
                if k and a > b_s[k - 1] / acc.fs:
                    ax.axvspan(b_s[k - 1] / acc.fs, a, color="tab:red", alpha=0.25, lw=0, zorder=0)
            fin = x[np.isfinite(x)]
            rms = float(np.sqrt(np.mean(fin ** 2))) if fin.size else float("nan")
            peak = float(np.max(np.abs(fin))) if fin.size else float("nan")
            ax.text(0.01, 0.97, f"peak {peak:.3g}, rms {rms:.3g} {ulabel}", transform=ax.transAxes,
                    ha="left", va="top", fontsize=7, bbox=dict(fc="white", ec="none", alpha=0.75, pad=1.5))
            ax.grid(True, alpha=0.4)
            if c == 0:
                ax.set_ylabel(f"{what} [{ulabel}]", fontsize=9)
            if r == 0:
                ax.set_title(names[c], fontsize=9)
            if r == 2:
                ax.set_xlabel("time [s]")
        axes[r, 0].set_xlim(0.0, T)
    from matplotlib.ticker import MaxNLocator

    axes[-1, 0].xaxis.set_major_locator(MaxNLocator(nbins=5 if nc > 1 else 8))
    more = f"; first {nc} of {acc_signals.n_channels} channels" if acc_signals.n_channels > nc else ""
    import textwrap

    width = int(fig.get_figwidth() * 14)  # characters of 9.5 pt text across the figure
    lines = [f"Acceleration, velocity, displacement (integrated by the {method} method, high-pass f_cut = {fc:.3g} Hz, "
             f"zero-phase Butterworth 4, −6 dB)",
             "(shaded: 1/f_cut edge zones" + ("; red: missing, each stretch between gaps integrated apart"
                                              if not np.isfinite(acc.data).all() else "") + f"{more})"]
    fig.suptitle("\n".join(w for line in lines for w in textwrap.wrap(line, width)), fontsize=9.5)
    return fig


def log_ods(ods_result: OperatingShape, coords: Mapping[str, Any] | None = None, *,
            rrd_path: str | Path | None = None, spawn: bool = False, signals=None,
            recording_name: str | None = None) -> Path | None:
    """Log an operating deflection shape to a rerun recording, animated like a mode.

    Calls :func:`vibroscope.viewers.rerun_view.log_analysis` with ``modal=ods_as_modal_model(...)``:
    the points move along their measuring directions over one cycle on the ``animation``
    timeline, entity ``/modes/mode_1_<f>Hz``.

    Parameters
    ----------
    ods_result : OperatingShape
        From :func:`vibroscope.spectral.integration.ods`.
    coords : mapping, optional
        Sensor positions and directions; points on a line when None.
    rrd_path : str or Path, optional
        Write the recording to this ``.rrd`` file.
    spawn : bool, optional
        Open a rerun viewer and stream to it.
    signals : Signals, optional
        Time series logged alongside (e.g. the accelerations it came from).
    recording_name : str, optional
        Default ``"ODS at <f> Hz"``.

    Returns
    -------
    Path or None
        `rrd_path` once written, None when only spawned.

    Raises
    ------
    ValueError
        If neither `rrd_path` nor `spawn` is given.
    """
    from vibroscope.viewers.rerun_view import log_analysis

    name = recording_name or f"ODS at {ods_result.frequency:.4g} Hz"
    return log_analysis(signals=signals, modal=ods_as_modal_model(ods_result), coords=coords, rrd_path=rrd_path,
                        spawn=spawn, recording_name=name)
