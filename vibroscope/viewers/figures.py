"""Matplotlib figures of the analysis results: PSD, FRF (Bode + coherence), mode shapes, FDD
singular values, and a one-call writer of the summary PNGs.

matplotlib is imported inside the functions (the Agg backend is chosen when there is no
display), so importing this module costs nothing.
"""

from __future__ import annotations

import os
import sys
from functools import partial
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from vibroscope.signals import true_runs
from vibroscope.viewers._common import (distinct_labels, mode_label, nearest_frequencies, pyplot, real_shape,
                                       sensor_geometry, short_label)

__all__ = ["OwnsWorkerPool", "plot_spectrum", "plot_frf", "plot_mode_shapes", "plot_singular_values", "plot_signals",
           "plot_stabilization", "plot_frf_synthesis", "plot_mode_set_comparison", "plot_mode_shapes_3d",
           "summary_figures", "figure_jobs", "PendingFigures", "DrawnFigure", "quiet_worker", "server_pool", "in_figure_order", "FIGURE_ORDER", "preload",
           "plot_ods"]

#: resolution of the written PNGs (dots per inch)
DPI = 110
#: zlib level of the written PNGs (lossless at any level)
PNG_LEVEL = 6
_MAX_LEGEND = 12


def preload() -> None:
    """Import what drawing and writing a figure needs (pyplot, with Agg when there is no display,
    and PIL), so that the first figure does not wait for it; run in a background thread while an
    analysis computes (:func:`vibroscope.commands._outputs.preload_outputs`)."""
    pyplot()
    import PIL.Image  # noqa: F401


def _legend_if(ax, **kw) -> None:
    """``ax.legend(**kw)`` when something on `ax` has a label (no empty legend, no warning)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kw)


def _legend(ax, n: int) -> None:
    if n == 0:
        return
    if n > _MAX_LEGEND:
        ax.legend(fontsize=6, ncol=3, loc="best", title=f"{n} channels", title_fontsize=7)
    else:
        ax.legend(fontsize=7 if n > 4 else 8, ncol=2 if n > 6 else 1, loc="best")


def _spectrum_ylabel(spectrum, db: bool) -> str:
    u = set(spectrum.units)
    unit = u.pop() if len(u) == 1 else ""
    what = {"density": "PSD", "spectrum": "power spectrum", "amplitude": "amplitude"}.get(spectrum.scaling, "value")
    if db:
        return f"{what} [dB re 1 {unit}]" if unit else f"{what} [dB re 1 unit, see legend]"
    return f"{what} [{unit}]" if unit else f"{what} [units in legend]"


def plot_spectrum(spectrum, ax=None, *, db: bool = False, channels: Sequence[str | int] | None = None):
    """Plot spectra of several channels against frequency.

    Parameters
    ----------
    spectrum : Spectrum
        ``frequencies`` (Hz), ``values`` (n_channels, n_freqs), ``channels``, ``units``, ``scaling``.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on; a new figure is made when None.
    db : bool, optional
        Plot ``10 log10`` of a power quantity (``20 log10`` of an amplitude spectrum) on a linear
        axis instead of the values on a logarithmic axis.
    channels : sequence of str or int, optional
        Channels to plot (names or indices); all when None.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        plt = pyplot()
        _, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    idx = range(len(spectrum.channels)) if channels is None else [
        c if isinstance(c, (int, np.integer)) else spectrum.channels.index(c) for c in channels]
    f = np.asarray(spectrum.frequencies)
    fac = 20.0 if spectrum.scaling == "amplitude" else 10.0
    n = 0
    for i in idx:
        v = np.asarray(spectrum.values[i], dtype=float)
        label = short_label(spectrum.channels[i])
        if len(set(spectrum.units)) > 1 and spectrum.units[i]:
            label += f" [{spectrum.units[i]}]"
        if db:
            with np.errstate(divide="ignore"):
                ax.plot(f, fac * np.log10(v), lw=1, label=label)
        else:
            pos = v > 0
            ax.semilogy(f[pos], v[pos], lw=1, label=label)
        n += 1
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel(_spectrum_ylabel(spectrum, db))
    st = spectrum.settings or {}
    bits = [f"Δf = {spectrum.df:.3g} Hz"] if f.size > 1 else []
    if st.get("nperseg"):
        bits.append(f"nperseg = {st['nperseg']}")
    if st.get("n_averages"):
        bits.append(f"{st['n_averages']} averages")
    if st.get("window"):
        bits.append(f"window = {st['window']}")
    title = {"density": "Power spectral density", "spectrum": "Power spectrum",
             "amplitude": "Amplitude spectrum"}.get(spectrum.scaling, "Spectrum")
    ax.set_title(title + (f" ({', '.join(bits)})" if bits else ""), fontsize=10)
    if f.size:
        ax.set_xlim(f[0], f[-1])
    ax.grid(True, which="major", alpha=0.4)
    ax.grid(True, which="minor", alpha=0.12)
    _legend(ax, n)
    return ax


def plot_frf(frf, *, output: str | int = 0, input: str | int = 0, fig=None):
    """Bode-style plot of one FRF with its coherence.

    Three stacked axes share the frequency axis: magnitude in dB re 1 unit of `H`, phase in
    degrees, coherence γ².

    Parameters
    ----------
    frf : FRF
        ``frequencies`` (Hz), ``H[f, output, input]``, ``coherence[f, output]``, ``inputs``,
        ``outputs``, ``estimator``, ``kind``, ``units``.
    output, input : str or int, optional
        Which response and which excitation (names or indices).
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.

    Returns
    -------
    matplotlib.figure.Figure
    """
    o = output if isinstance(output, (int, np.integer)) else frf.outputs.index(output)
    i = input if isinstance(input, (int, np.integer)) else frf.inputs.index(input)
    if fig is None:
        plt = pyplot()
        fig = plt.figure(figsize=(8, 7), layout="constrained")
    else:
        fig.clf()
    axm, axp, axc = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [2.2, 1.3, 1]})
    f = np.asarray(frf.frequencies)
    h = np.asarray(frf.H)[:, o, i]
    with np.errstate(divide="ignore"):
        mag = 20 * np.log10(np.abs(h))
    unit = frf.units or "unit"
    axm.plot(f, mag, lw=1.1, color="C0", label=f"{frf.estimator}")
    axm.set_ylabel(f"|H| [dB re 1 {unit}]")
    _legend_if(axm, fontsize=8, loc="best")
    axp.plot(f, np.degrees(np.angle(h)), lw=1.0, color="C1")
    axp.set_ylabel("phase [deg]")
    axp.set_ylim(-185, 185)
    axp.set_yticks([-180, -90, 0, 90, 180])
    coh = np.asarray(frf.coherence)
    if coh.ndim == 2 and coh.shape[1] > o:
        axc.plot(f, coh[:, o], lw=1.0, color="C2")
    axc.set_ylabel("coherence γ² [-]")
    axc.set_ylim(-0.02, 1.05)
    axc.set_xlabel("frequency [Hz]")
    for a in (axm, axp, axc):
        a.grid(True, alpha=0.4)
    if f.size:
        axc.set_xlim(f[0], f[-1])
    kind = f" {frf.kind}" if frf.kind else ""
    axm.set_title(f"FRF{kind} ({frf.estimator}): {short_label(frf.outputs[o], 34)} / {short_label(frf.inputs[i], 34)}",
                  fontsize=10)
    return fig


def plot_mode_shapes(modal, coords: Mapping[str, Any] | None = None, *, fig=None, true_modes=None):
    """One panel per mode: the real (in-phase) mode shape at the measurement points.

    With `coords`, the amplitude along each sensor's measuring direction is drawn against the
    coordinate in which the points spread most (vertically when that is the height z, as for
    a tower); without, against the point index along a line with the point names as ticks.

    Parameters
    ----------
    modal : ModalModel
        Anything with ``natural_frequencies`` (Hz), ``damping_ratios``, ``shapes`` (complex,
        (n_modes, n_points)), ``points`` and ``method``.
    coords : mapping, optional
        ``point -> {"xyz": (x, y, z), "direction": ...}`` or ``point -> (x, y, z[, direction])``
        (see :func:`vibroscope.viewers._common.sensor_geometry`).
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.
    true_modes : ModalModel, optional
        Reference modes (e.g. a model's); the nearest in frequency is named in each title, and
        its shape is drawn dashed when it has the same points.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fn = np.asarray(modal.natural_frequencies, dtype=float)
    zeta = np.asarray(modal.damping_ratios, dtype=float)
    shapes = np.atleast_2d(np.asarray(modal.shapes, dtype=complex))
    points = list(modal.points)
    n_modes = fn.size
    pos, dirs, from_coords = sensor_geometry(points, coords)
    xcoord, vertical, coord_label = _shape_axis(pos, from_coords, len(points))
    order = np.argsort(xcoord, kind="stable")
    groups = _direction_groups(dirs) if from_coords else [("", np.arange(len(points)))]
    fig, axes = _mode_axes(fig, n_modes, vertical)
    tm_idx, same_points = None, False
    if true_modes is not None:
        tm_idx = nearest_frequencies(fn, np.asarray(true_modes.natural_frequencies, dtype=float))
        same_points = list(getattr(true_modes, "points", [])) == points
    for r, ax in enumerate(axes):
        if r >= n_modes:
            ax.set_visible(False)
            continue
        phi = real_shape(shapes[r])
        ref = None
        if tm_idx is not None and tm_idx[r] >= 0 and same_points:
            ref = _reference_shape(np.asarray(true_modes.shapes)[tm_idx[r]], phi)
        _draw_shape(ax, shapes[r], phi, ref, xcoord, order, groups, vertical)
        _label_shape_axes(ax, points, xcoord, order, vertical, coord_label, from_coords)
        title = f"Mode {r + 1}: {mode_label(fn[r], zeta[r])}"
        if tm_idx is not None and tm_idx[r] >= 0:
            ft = float(np.asarray(true_modes.natural_frequencies)[tm_idx[r]])
            title += f"\ntrue {ft:.4g} Hz ({100 * (fn[r] - ft) / ft:+.2f} %)"
        ax.set_title(title, fontsize=9)
        ax.grid(True, alpha=0.4)
        if r == 0:
            _legend_if(ax, fontsize=7, loc="best")
    fig.suptitle(f"Mode shapes ({getattr(modal, 'method', '')}, {len(points)} points)", fontsize=11)
    return fig


def _shape_axis(pos: np.ndarray, from_coords: bool, n_points: int) -> tuple[np.ndarray, bool, str]:
    """(coordinate of each point along the structure, drawn vertically?, its axis label): the
    coordinate in which the points spread most (vertical when it is the height z), else the
    point index."""
    if from_coords and n_points > 1:
        axis = int(np.argmax(np.ptp(pos, axis=0)))
        return pos[:, axis], axis == 2, f"{'xyz'[axis]} [m]"
    return np.arange(n_points, dtype=float), False, "measurement point"


_AXIS_NAMES = {(1.0, 0.0, 0.0): "along x", (0.0, 1.0, 0.0): "along y", (0.0, 0.0, 1.0): "along z"}


def _direction_groups(dirs: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """(name, point indices) per measuring direction, e.g. the two horizontal axes of a tower:
    one line each."""
    keys = [tuple(np.round(d, 3)) for d in dirs]
    groups = []
    for key in dict.fromkeys(keys):
        members = np.array([k for k, kk in enumerate(keys) if kk == key])
        groups.append((_AXIS_NAMES.get(tuple(float(v) for v in key), f"along {key}"), members))
    return groups


def _mode_axes(fig, n_modes: int, vertical: bool):
    """(figure, axes): one axes per mode on a grid (narrow, tall panels for a vertical
    structure), in `fig` (cleared) or a new figure."""
    ncols = min(max(n_modes, 1), 5 if vertical else 3)
    nrows = int(np.ceil(max(n_modes, 1) / ncols))
    if fig is None:
        plt = pyplot()
        w = 2.6 * ncols + 0.8 if vertical else 4.0 * ncols + 0.6
        h = 4.2 * nrows + 0.6 if vertical else 2.9 * nrows + 0.7
        fig = plt.figure(figsize=(min(w, 16), min(h, 14)), layout="constrained")
    else:
        fig.clf()
    return fig, np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False).ravel())


def _reference_shape(shape: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """A reference mode's real shape scaled to 1 and signed like `phi`."""
    ref = real_shape(shape)
    ref = ref / (np.max(np.abs(ref)) or 1.0)
    return -ref if np.dot(ref, phi) < 0 else ref


def _draw_shape(ax, shape, phi, ref, xcoord, order, groups, vertical: bool) -> None:
    """Per measuring direction: the real shape `phi`, the modulus ``|φ|`` and the reference `ref`."""
    mod = np.abs(shape) / (np.max(np.abs(shape)) or 1.0)
    (ax.axvline if vertical else ax.axhline)(0, color="0.5", lw=0.8)
    for g, (gname, members) in enumerate(groups):
        sel = order[np.isin(order, members)]  # this direction's points along the structure
        x, y = xcoord[sel], phi[sel]
        col = f"C{g % 10}" if len(groups) > 1 else "C0"
        lab = f"{gname} (real part)" if len(groups) > 1 else "identified (real part)"
        lines = [(y, "o-", dict(color=col, lw=1.4, ms=4, label=lab)),
                 (mod[sel], ":", dict(color=col, lw=0.9, alpha=0.6, label="|φ|" if g == 0 else None))]
        if ref is not None:
            lines.append((ref[sel], "s--", dict(color="C3" if len(groups) == 1 else col, lw=1.0, ms=3,
                                                alpha=0.8, label="true" if g == 0 else None)))
        for vals, fmt, kw in lines:
            if vertical:
                ax.plot(vals, x, fmt, **kw)
            else:
                ax.plot(x, vals, fmt, **kw)


def _label_shape_axes(ax, points, xcoord, order, vertical: bool, coord_label: str, from_coords: bool) -> None:
    """Amplitude and coordinate labels and limits; a few points along a line named as ticks."""
    if vertical:
        ax.set_xlabel("amplitude [-]")
        ax.set_ylabel(coord_label)
        ax.set_xlim(-1.15, 1.15)
        return
    ax.set_ylabel("amplitude [-]")
    ax.set_ylim(-1.15, 1.15)
    ax.set_xlabel(coord_label)
    xs = xcoord[order]
    if len(points) <= 12 and np.all(np.diff(xs) > 0):
        short = distinct_labels(points)
        ax.set_xticks(xs, [short[k] for k in order], rotation=30 if len(points) > 5 else 0,
                      ha="right" if len(points) > 5 else "center", fontsize=7)
        if from_coords:
            ax.set_xlabel(coord_label + " (sensor names as ticks)")


def plot_singular_values(frequencies, S, modes=None, *, ax=None, n_sv: int = 3, true_frequencies=None):
    """FDD singular value spectra in dB with the picked modes marked.

    Parameters
    ----------
    frequencies : array_like, shape (n_freqs,)
        Hz.
    S : array_like, shape (n_freqs, n_sv_total) or (n_freqs,)
        Singular values of the cross-spectral matrix per frequency, descending (unit²/Hz).
    modes : ModalModel or array_like, optional
        Picked modes (anything with ``natural_frequencies``) or their frequencies in Hz; each
        is marked on the first singular value.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on; a new figure when None.
    n_sv : int, optional
        How many singular values to draw.
    true_frequencies : array_like, optional
        Reference natural frequencies in Hz, drawn as dotted vertical lines.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        plt = pyplot()
        _, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    f = np.asarray(frequencies, dtype=float)
    S = np.asarray(S, dtype=float)
    if S.ndim == 1:
        S = S[:, None]
    with np.errstate(divide="ignore"):
        sdb = 10 * np.log10(S)
    for k in range(min(n_sv, S.shape[1])):
        ax.plot(f, sdb[:, k], lw=1.2 if k == 0 else 0.8, alpha=1.0 if k == 0 else 0.7, label=f"$s_{k + 1}$")
    if true_frequencies is not None:
        for j, ft in enumerate(np.atleast_1d(np.asarray(true_frequencies, dtype=float))):
            ax.axvline(ft, color="0.4", ls=":", lw=1.0, label="true modes" if j == 0 else None)
    if modes is not None:
        fm = np.atleast_1d(np.asarray(getattr(modes, "natural_frequencies", modes), dtype=float))
        ok = np.isfinite(fm)
        y = np.interp(fm[ok], f, sdb[:, 0])
        ax.plot(fm[ok], y, "v", color="C3", ms=8, label="picked modes")
        span = (f[-1] - f[0]) if f.size > 1 else 1.0
        pts = sorted(zip(fm[ok], y))
        clusters: list[list[tuple[float, float]]] = []
        for fi, yi in pts:  # modes closer than 5 % of the span share a column of stacked labels
            if clusters and fi - clusters[-1][-1][0] < 0.05 * span:
                clusters[-1].append((fi, yi))
            else:
                clusters.append([(fi, yi)])
        from matplotlib.transforms import offset_copy

        for cl in clusters:
            base = max(yi for _, yi in cl)
            for k, (fi, yi) in enumerate(cl):
                tr = offset_copy(ax.transData, fig=ax.figure, x=0, y=8 + 10 * k, units="points")
                ax.annotate(f"{fi:.4g} Hz", (fi, yi), xytext=(fi, base), textcoords=tr, ha="center",
                            fontsize=7, color="C3",
                            arrowprops=dict(arrowstyle="-", color="C3", lw=0.5, alpha=0.5, shrinkA=0, shrinkB=4))
    finite = sdb[:, : min(n_sv, S.shape[1])][np.isfinite(sdb[:, : min(n_sv, S.shape[1])])]
    if finite.size:
        lo, hi = float(finite.min()), float(finite.max())
        pad = 0.06 * (hi - lo or 1.0)
        ax.set_ylim(lo - pad, hi + 4 * pad)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("singular value [dB re 1 unit²/Hz]")
    ax.set_title("Frequency domain decomposition: singular values of the CSD matrix", fontsize=10)
    if f.size:
        ax.set_xlim(f[0], f[-1])
    ax.grid(True, alpha=0.4)
    _legend_if(ax, fontsize=8, loc="best")
    return ax


def plot_signals(signals, *, fig=None, max_channels: int = 6, max_points: int = 1600):
    """Time series of the first channels, one panel each, min/max-decimated for size.

    Missing samples (NaN, ±Inf: logging gaps, lost chunks, masked faults) are never bridged: the
    trace breaks there and each gap is shaded (``axvspan``, labelled "gap (no data)"; gaps closer
    than 1/300 of the record merge into one span). The title counts the gaps of the channel that
    has the most, and says when they merged into fewer shaded spans.

    Parameters
    ----------
    signals : Signals
        ``data`` (n_channels, n_samples), ``fs`` (Hz), ``channels``, ``units``, ``t0`` (s).
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.
    max_channels : int, optional
        At most this many channels are drawn (the title says how many there are).
    max_points : int, optional
        Longer records are drawn as their per-bin minimum and maximum envelope (over the present
        samples; a bin with none is a break).

    Returns
    -------
    matplotlib.figure.Figure
    """
    n = min(signals.n_channels, max_channels)
    if fig is None:
        plt = pyplot()
        fig = plt.figure(figsize=(8, 1.5 + 1.35 * n), layout="constrained")
    else:
        fig.clf()
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True, squeeze=False).ravel())
    t = np.arange(signals.n_samples) / signals.fs
    n_gaps = n_shaded = 0
    for k, ax in enumerate(axes):
        x = np.asarray(signals.data[k], dtype=float)
        finite = np.isfinite(x)
        if not finite.all():
            x = np.where(finite, x, np.nan)
        if x.size > max_points:
            nb = max_points // 2
            edges = np.linspace(0, x.size, nb + 1).astype(int)
            with np.errstate(invalid="ignore"):
                lo = np.fmin.reduceat(x, edges[:-1])
                hi = np.fmax.reduceat(x, edges[:-1])
            tb = t[edges[:-1]]
            ax.fill_between(tb, lo, hi, color=f"C{k % 10}", lw=0)
        else:
            ax.plot(t, x, lw=0.8, color=f"C{k % 10}")
        spans = gap_spans(finite, signals.fs, min_width=signals.duration / 300)  # visible when short
        for j, (a, b) in enumerate(spans):
            ax.axvspan(a, b, color="0.5", alpha=0.35, lw=0, label="gap (no data)" if j == 0 else None)
        if spans:
            n_gaps = max(n_gaps, int(np.count_nonzero(np.diff(finite.astype(np.int8)) == -1)) + int(not finite[0]))
            n_shaded = max(n_shaded, len(spans))
            _legend_if(ax, loc="upper right", fontsize=7)
        u = signals.units[k]
        ax.set_ylabel(f"[{u}]" if u else "[-]", fontsize=8)
        ax.set_title(short_label(signals.channels[k], 60), fontsize=8, loc="left")
        ax.grid(True, alpha=0.4)
    t0 = f"{signals.t0:.3f}" if abs(signals.t0) >= 1e6 else f"{signals.t0:g}"
    axes[-1].set_xlabel(f"time since t0 = {t0} s [s]")
    more = f" (first {n} of {signals.n_channels})" if signals.n_channels > n else ""
    gaps = f"; {n_gaps} gaps without data, shaded" if n_gaps else ""
    if n_gaps > n_shaded:
        gaps += f" (merged into {n_shaded} span{'s' if n_shaded > 1 else ''} at this scale)"
    fig.suptitle(f"Time series, fs = {signals.fs:g} Hz{more}{gaps}", fontsize=10)
    return fig


def gap_spans(present: np.ndarray, fs: float, *, min_width: float = 0.0, max_spans: int = 200) -> list:
    """Time spans ``(start_s, stop_s)`` of the runs of missing samples, for drawing.

    A gap starts at its first missing sample and ends at the next present one (``stop / fs``).
    Spans closer than `min_width` (s) are merged, each is widened to at least `min_width` so that
    it shows, and at most `max_spans` are returned (the closest merged first).

    Parameters
    ----------
    present : ndarray of bool, shape (n_samples,)
        True where the sample is present (finite).
    fs : float
        Sampling frequency in Hz.
    min_width : float, optional
        Narrowest span drawn, in s; default 0.
    max_spans : int, optional
        Most spans returned; default 200.

    Returns
    -------
    list of (float, float)
        In s from the first sample.
    """
    a, b = true_runs(~np.asarray(present, bool))
    a, b = a / fs, b / fs
    if a.size == 0:
        return []
    spans = [[a[0], b[0]]]
    for s0, s1 in zip(a[1:], b[1:]):
        if s0 - spans[-1][1] < min_width:
            spans[-1][1] = s1
        else:
            spans.append([s0, s1])
    while len(spans) > max_spans:
        gaps = np.diff([s[0] for s in spans])  # merge the closest neighbours
        j = int(np.argmin(gaps))
        spans[j][1] = spans[j + 1][1]
        del spans[j + 1]
    return [(float(s0), float(max(s1, s0 + min_width))) for s0, s1 in spans]


def plot_stabilization(stabilization, sv=None, modes=None, *, ax=None):
    """Stabilization diagram: poles (frequency vs model order), coloured by stability.

    Parameters
    ----------
    stabilization : Stabilization
        From :func:`vibroscope.modal.ssi_cov` or :func:`vibroscope.modal.lscf` (``order``,
        ``frequency``, ``stable`` 0–3).
    sv : tuple (frequencies, S) or (frequencies, S, label), optional
        First singular value of the CSD (or the FRFs' summed power, with its label) drawn behind
        the poles (dB, right axis), as is customary.
    modes : ModalModel, optional
        Selected modes, marked by vertical lines.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib Axes
        The axes of the poles.

    References
    ----------
    .. [1] B. Peeters and G. De Roeck, "Reference-based stochastic subspace identification for
       output-only modal analysis", Mech. Syst. Signal Process. 13(6), 855–878, 1999.
    """
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(9, 5), layout="constrained")
    st = stabilization
    styles = {0: ("new pole", "x", "0.6"), 1: ("stable f", ".", "tab:orange"),
              2: ("stable f, ζ", "+", "tab:blue"), 3: ("stable f, ζ, MAC", "o", "tab:green")}
    for code, (label, marker, color) in styles.items():
        m = st.stable == code
        if m.any():
            ax.scatter(st.frequency[m], st.order[m], marker=marker, s=14 if marker != "o" else 10,
                       color=color, label=label, linewidths=0.8)
    if sv is not None:
        f, S = sv[0], sv[1]
        ax2 = ax.twinx()
        ax2.plot(f, 10 * np.log10(np.maximum(S[:, 0], np.finfo(float).tiny)), color="0.3", lw=0.8)
        ax2.set_ylabel(sv[2] if len(sv) > 2 else "first singular value [dB]")
        fmax = max(float(np.max(st.frequency)) if st.frequency.size else f[-1], 1e-9)
        ax.set_xlim(0, min(f[-1], 1.05 * fmax))
    if modes is not None:
        for fn in np.atleast_1d(modes.natural_frequencies):
            ax.axvline(fn, color="tab:red", lw=0.6, ls="--")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("model order")
    from vibroscope.modal.methods import MODAL_METHODS

    m = MODAL_METHODS.get(st.settings.get("method", "ssi_cov"), MODAL_METHODS["ssi_cov"])
    order = f"{st.settings.get('n_lags', '?')} block rows" if m.order == "block rows" else m.order
    ax.set_title(f"Stabilization diagram ({m.display}, {order})")
    _legend_if(ax, loc="upper left", fontsize=8, framealpha=0.9)
    ax.grid(alpha=0.3)
    return ax


def plot_frf_synthesis(frf, synthesized, modal=None, *, max_outputs: int = 4, input: int = 0, fig=None):
    """Measured FRFs with the modal model's synthesized FRFs overlaid, and their error.

    Parameters
    ----------
    frf : FRF
        Measured ``H[f, output, input]``.
    synthesized : FRF
        The model's FRFs on the same axis (e.g. :meth:`vibroscope.modal.lsfd.LSFDResult.synthesize`).
    modal : ModalModel, optional
        Its natural frequencies are marked.
    max_outputs : int, optional
        Outputs drawn (the first ones); default 4.
    input : int, optional
        Input column; default 0.
    fig : matplotlib Figure, optional

    Returns
    -------
    matplotlib Figure
        Per output: magnitude (dB, measured and synthesized) and phase; a bottom panel with the
        relative error ``|H − Ĥ| / |H|`` (dB) of every output, and the overall error in the title.
    """
    plt = pyplot()
    n = min(max_outputs, len(frf.outputs))
    if fig is None:
        fig = plt.figure(figsize=(10, 2.2 * n + 2.2), layout="constrained")
    axes = fig.subplots(n + 1, 2, squeeze=False, gridspec_kw={"width_ratios": [2, 1]})
    f = frf.frequencies
    Hs = np.asarray(synthesized.H)
    fs_ = synthesized.frequencies
    band = (f >= fs_.min()) & (f <= fs_.max())
    tot_num = tot_den = 0.0
    err_ax = axes[n, 0]
    for o in range(len(frf.outputs)):
        h = frf.H[band, o, input]
        hs = np.interp(f[band], fs_, Hs[:, o, input].real) + 1j * np.interp(f[band], fs_, Hs[:, o, input].imag)
        ok = np.isfinite(h)
        tot_num += float(np.sum(np.abs(h[ok] - hs[ok]) ** 2))
        tot_den += float(np.sum(np.abs(h[ok]) ** 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            e = 20 * np.log10(np.abs(h - hs) / np.abs(h))
        if o < 8:
            err_ax.plot(f[band], e, lw=0.7, label=short_label(frf.outputs[o], 20))
        if o >= n:
            continue
        ax, axp = axes[o]
        with np.errstate(divide="ignore"):
            ax.plot(f, 20 * np.log10(np.abs(frf.H[:, o, input])), color="0.35", lw=0.9, label="measured")
            ax.plot(fs_, 20 * np.log10(np.abs(Hs[:, o, input])), color="tab:red", lw=1.0, ls="--", label="synthesized")
        axp.plot(f, np.degrees(np.angle(frf.H[:, o, input])), color="0.35", lw=0.8)
        axp.plot(fs_, np.degrees(np.angle(Hs[:, o, input])), color="tab:red", lw=0.9, ls="--")
        ax.set_ylabel(f"|H| [dB re 1 {frf.units or 'unit'}]", fontsize=8)
        ax.set_title(f"{short_label(frf.outputs[o])} / {short_label(frf.inputs[input], 24)}", fontsize=9)
        axp.set_ylabel("phase [deg]", fontsize=8)
        axp.set_ylim(-185, 185)
        if modal is not None:
            for fn in np.atleast_1d(modal.natural_frequencies):
                ax.axvline(fn, color="tab:green", lw=0.5, ls=":")
        for a in (ax, axp):
            a.grid(alpha=0.3)
            a.set_xlim(fs_.min(), fs_.max())
        if o == 0:
            _legend_if(ax, fontsize=8, loc="best")
    err_ax.set_xlabel("frequency [Hz]")
    err_ax.set_ylabel("|H − Ĥ| / |H| [dB]")
    err_ax.set_xlim(fs_.min(), fs_.max())
    err_ax.grid(alpha=0.3)
    if len(frf.outputs) > 1:
        _legend_if(err_ax, fontsize=7, ncol=2, loc="upper right")
    axes[n, 1].axis("off")
    rel = np.sqrt(tot_num / tot_den) if tot_den > 0 else np.nan
    axes[n, 1].text(0.05, 0.5, f"overall relative error\n‖H − Ĥ‖ / ‖H‖ = {100 * rel:.2f} %\n"
                              f"over {fs_.min():.4g}–{fs_.max():.4g} Hz", fontsize=10, va="center")
    fig.suptitle("Measured vs synthesized FRFs (LSFD modal model)", fontsize=11)
    return fig


def plot_mode_shapes_3d(modal, coords: Mapping[str, Any], *, fig=None, max_modes: int = 12, amplitude: float = 0.15):
    """One 3-D panel per mode: the geometry's measured nodes, undeformed and displaced by the shape.

    Points at one position (a triaxial node: ``12+X``, ``12+Y``, ``12+Z``) form one node whose
    displacement is the sum of each point's real shape value along its measuring direction.

    Parameters
    ----------
    modal : ModalModel
        Natural frequencies (Hz), damping ratios, complex shapes ``(n_modes, n_points)``, points.
    coords : mapping
        ``point -> {"xyz": (x, y, z), "direction": (dx, dy, dz)}`` in m
        (:meth:`vibroscope.io.coords.SensorCoords.as_mapping`).
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.
    max_modes : int, optional
        Panels drawn at most (the first modes); default 12.
    amplitude : float, optional
        Largest node displacement drawn, as a share of the geometry's largest extent (default 0.15).

    Returns
    -------
    matplotlib.figure.Figure
        Grey: undeformed nodes; coloured: displaced nodes, joined to their rest position, the
        colour the signed displacement along the mode's main direction of motion (red +, blue −).
    """
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    fn = np.asarray(modal.natural_frequencies, dtype=float)
    zeta = np.asarray(modal.damping_ratios, dtype=float)
    shapes = np.atleast_2d(np.asarray(modal.shapes, dtype=complex))
    pos, dirs, _ = sensor_geometry(list(modal.points), coords)
    node_pos, member = np.unique(np.round(pos, 9), axis=0, return_inverse=True)
    member = np.asarray(member).reshape(-1)
    extent = float(np.max(np.ptp(node_pos, axis=0))) if len(node_pos) > 1 else 1.0
    extent = extent if extent > 0 else 1.0
    n = min(fn.size, max_modes)
    cols = min(n, 4) or 1
    rows = max(1, -(-n // cols))
    if fig is None:
        fig = plt.figure(figsize=(3.6 * cols, 3.4 * rows), layout="constrained")
    else:
        fig.clear()
    lo, hi = node_pos.min(axis=0) - amplitude * extent, node_pos.max(axis=0) + amplitude * extent
    for r in range(n):
        ax = fig.add_subplot(rows, cols, r + 1, projection="3d")
        phi = real_shape(shapes[r])
        disp = np.zeros_like(node_pos)
        np.add.at(disp, member, phi[:, None] * dirs)
        mag = np.linalg.norm(disp, axis=1)
        top = float(mag.max()) if mag.size and mag.max() > 0 else 1.0
        moved = node_pos + amplitude * extent * disp / top
        ax.scatter(*node_pos.T, color="0.7", s=8, depthshade=False)
        for a, b in zip(node_pos, moved):
            ax.plot(*np.c_[a, b], color="0.6", lw=0.6)
        axis = int(np.argmax(np.sum(disp ** 2, axis=0)))  # the mode's main direction of motion
        ax.scatter(*moved.T, c=disp[:, axis] / top, cmap="coolwarm", vmin=-1, vmax=1, s=22, depthshade=False,
                   edgecolors="0.3", linewidths=0.3)
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
        ax.set_box_aspect(np.maximum(hi - lo, 0.05 * extent))
        ax.set_xlabel("x [m]", fontsize=7, labelpad=-8)
        ax.set_ylabel("y [m]", fontsize=7, labelpad=-8)
        ax.set_zlabel("z [m]", fontsize=7, labelpad=-8)
        ax.tick_params(labelsize=6, pad=-2)
        for a in (ax.xaxis, ax.yaxis, ax.zaxis):
            a.set_major_locator(MaxNLocator(3))
        ax.view_init(elev=28, azim=-60)
        ax.set_title(f"Mode {r + 1}: {mode_label(fn[r], zeta[r])}\nmoves mostly along {'xyz'[axis]}", fontsize=8)
    more = f"; first {n} of {fn.size} modes" if fn.size > n else ""
    fig.suptitle(f"Mode shapes on the geometry ({getattr(modal, 'method', '')}, {len(node_pos)} nodes, "
                 f"{len(modal.points)} points{more}); grey: at rest; red +, blue −", fontsize=10)
    return fig


def plot_mode_set_comparison(comparison, *, fig=None):
    """Two mode sets compared: the MAC matrix (pairs framed) and each pair's frequency difference.

    Parameters
    ----------
    comparison : ModeSetComparison
        From :func:`vibroscope.modal.compare.compare_mode_sets`.
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.

    Returns
    -------
    matplotlib.figure.Figure
        Left: ``MAC[i, j]`` of mode i of A (rows) and mode j of B (columns), 0 white to 1 dark,
        the values written in the cells (up to 16 × 16 modes), pairs framed in red. Right: the
        relative frequency difference ``(f_B − f_A) / f_A`` of each pair in %, its MAC beside.

    References
    ----------
    .. [1] R. J. Allemang, "The Modal Assurance Criterion -- twenty years of use and abuse",
       Sound and Vibration 37(8), 14–23, 2003.
    """
    from matplotlib.patches import Rectangle

    plt = pyplot()
    c = comparison
    M = np.nan_to_num(np.asarray(c.mac, float))
    na, nb = M.shape
    if fig is None:
        fig = plt.figure(figsize=(min(15.0, 7.5 + 0.35 * max(na, nb)), min(11.0, 4.0 + 0.33 * max(na, nb))),
                         layout="constrained")
    else:
        fig.clear()
    ax, ax2 = fig.subplots(1, 2, width_ratios=[1.25, 1])
    im = ax.imshow(M, cmap="Greys", vmin=0, vmax=1, aspect="auto", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="MAC", shrink=0.8)
    ax.set_yticks(range(na), [f"{i + 1}: {f:.4g} Hz" for i, f in enumerate(c.frequencies_a)], fontsize=7)
    ax.set_xticks(range(nb), [f"{j + 1}: {f:.4g} Hz" for j, f in enumerate(c.frequencies_b)], fontsize=7,
                  rotation=60, ha="right")
    ax.set_ylabel(f"A: {short_label(c.labels[0], 40)}")
    ax.set_xlabel(f"B: {short_label(c.labels[1], 40)}")
    if max(na, nb) <= 16:
        for i in range(na):
            for j in range(nb):
                ax.text(j, i, f"{M[i, j]:.2f}", ha="center", va="center", fontsize=7,
                        color="white" if M[i, j] > 0.6 else "black")
    for i, j in c.pairs:
        ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="tab:red", lw=1.8))
    ax.set_title(f"MAC on {len(c.points)} common points (matched by {c.matched_by}); pairs framed", fontsize=9)
    if len(c.pairs):
        y = np.arange(len(c.pairs))
        d = 100 * np.asarray(c.frequency_difference)
        ax2.barh(y, d, color=np.where(np.asarray(c.mac_pairs) >= 0.9, "tab:green", "tab:orange"))
        ax2.set_yticks(y, [f"A{i + 1} {c.frequencies_a[i]:.4g} / B{j + 1} {c.frequencies_b[j]:.4g} Hz"
                           for i, j in c.pairs], fontsize=7)
        ax2.invert_yaxis()
        span = max(float(np.max(np.abs(d))), 1e-3)
        for k, (dv, m) in enumerate(zip(d, c.mac_pairs)):
            ax2.text(max(dv, 0.0) + 0.04 * span, k, f"{dv:+.2f} %  MAC {m:.2f}", va="center", ha="left", fontsize=7)
        ax2.set_xlim(-1.15 * span, 2.3 * span)
    else:
        ax2.text(0.5, 0.5, "no pair (MAC and frequency limits)", ha="center", va="center", transform=ax2.transAxes)
    ax2.axvline(0, color="0.3", lw=0.8)
    ax2.set_xlabel("(f_B − f_A) / f_A [%]")
    ax2.grid(axis="x", alpha=0.3)
    un = [f"A{i + 1} {c.frequencies_a[i]:.4g}" for i in c.unpaired_a] + \
         [f"B{j + 1} {c.frequencies_b[j]:.4g}" for j in c.unpaired_b]
    ax2.set_title(f"{len(c.pairs)} pairs (green: MAC ≥ 0.9, orange: below)\nunpaired (Hz): "
                  f"{', '.join(un[:6]) + (' …' if len(un) > 6 else '') or 'none'}", fontsize=8)
    fig.suptitle("Mode sets compared: A (rows) vs B (columns)", fontsize=11)
    return fig


def save_figure(fig, path: Path) -> Path:
    """Write `fig` as a PNG at :data:`DPI`, palette-quantised (256 colours) to stay small.

    The figure is drawn once on its Agg canvas at :data:`DPI` (:meth:`Figure.savefig` draws a
    figure with a layout engine twice, the first time only to place it: the same pixels for 25 %
    more time here) and its RGBA pixels are encoded once, as the quantised PNG (not encoded by
    matplotlib, decoded and encoded again), at zlib level :data:`PNG_LEVEL` (the pixels of level 9
    with ``optimize``, in a seventh of the time, the file ~10 % larger). The PNG's ``Software``
    text is :data:`vibroscope.provenance.GENERATOR`: the mark by which a later run knows the file
    as its own output (and may replace it). A figure on another canvas than Agg's is drawn by
    :meth:`Figure.savefig`.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure; closed once written.
    path : Path or file-like
        The PNG file to write (or a binary file object, e.g. :class:`io.BytesIO`).

    Returns
    -------
    Path or file-like
        `path`.
    """
    import io

    from vibroscope.provenance import GENERATOR

    try:
        from PIL import Image
        from PIL.PngImagePlugin import PngInfo
    except ImportError:  # pragma: no cover - pillow comes with matplotlib
        fig.savefig(path, dpi=DPI, format="png", metadata={"Software": GENERATOR})
        pyplot().close(fig)
        return path
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = fig.canvas
    if type(canvas) is FigureCanvasAgg:  # noqa: E721 - a subclass (a GUI canvas) may draw otherwise
        dpi = fig.dpi
        fig.dpi = DPI  # as savefig(dpi=DPI) does, restored below
        try:
            canvas.draw()
            rgba = canvas.buffer_rgba()  # (h, w, 4) of the figure at DPI
            im = Image.frombuffer("RGBA", (rgba.shape[1], rgba.shape[0]), rgba, "raw", "RGBA", 0, 1)
            im = im.convert("RGB")  # a copy: the canvas may go
        finally:
            fig.dpi = dpi
            pyplot().close(fig)
    else:
        buf = io.BytesIO()
        fig.savefig(buf, dpi=DPI, format="png")
        pyplot().close(fig)
        buf.seek(0)
        with Image.open(buf) as png:
            im = png.convert("RGB")
    info = PngInfo()
    info.add_text("Software", GENERATOR)
    with im:
        im.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE) \
            .save(path, format="PNG", compress_level=PNG_LEVEL, pnginfo=info)
    return path


#: the figure jobs of the running :class:`PendingFigures`, read by the forked workers (inherited
#: with the parent's memory: nothing is pickled but an index and the path written)
_JOBS: list = []


def _render(k: int) -> str:
    """Worker: draw and save job `k` of :data:`_JOBS`; returns the path written."""
    return _render_job(_JOBS[k])


def _render_job(job) -> str:
    """Worker: draw and save one ``(draw, path)`` job; returns the path written."""
    draw, path = job
    fig = draw()
    return str(save_figure(getattr(fig, "figure", fig), path))


def quiet_worker() -> None:
    """Start a worker process: Ctrl-C is the parent's to handle (it terminates the workers), not a traceback
    each; SIGTERM (``Pool.terminate``) ends a worker at once, whatever handler the parent had
    installed when it forked (a Python handler that raises or holds the signal would leave the
    worker waiting on the pool's queue, and the parent's join waiting for ever)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def server_pool(server, processes: int):
    """A ``multiprocessing`` pool of `processes` workers forked from a drawing server
    (:mod:`vibroscope.viewers.drawing_server`), each started with :func:`quiet_worker`.

    Ctrl-C is held back while the pool starts its workers
    (:func:`vibroscope.viewers._common.sigint_held`); one that came meanwhile terminates the new
    pool here and is then raised, so no worker is left without an owner (one would hold the
    server's lifeline, and neither would ever end). The caller terminates the pool it gets.

    Parameters
    ----------
    server : multiprocessing context
        :func:`vibroscope.viewers.drawing_server.context`.
    processes : int
        Number of workers.

    Returns
    -------
    multiprocessing.pool.Pool
    """
    from vibroscope.viewers._common import sigint_held

    started = []
    try:
        with sigint_held():
            started.append(server.Pool(processes, initializer=quiet_worker))
    except BaseException:
        for p in started:
            p.terminate()
            p.join()
        raise
    return started[0]


def _workers() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


class OwnsWorkerPool:
    """A ``multiprocessing`` pool held in ``self._pool`` (None when there is none), stopped by
    :meth:`close` or on leaving a ``with`` block."""

    _pool = None

    def close(self) -> None:
        """Stop the workers (those still running are terminated; nothing of theirs is kept)."""
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class DrawnFigure:
    """A figure drawn elsewhere (:class:`vibroscope.viewers.ahead.TimeSeriesAhead`): a job of
    :class:`PendingFigures` whose PNG bytes are waited for and written as they are.

    Parameters
    ----------
    png : callable
        ``png()`` returns the PNG file's bytes (waiting for them if need be).
    """

    def __init__(self, png):
        self.png = png

    def write(self, path: Path) -> Path:
        """Write the PNG bytes to `path`.

        Parameters
        ----------
        path : Path
            The PNG file to write.

        Returns
        -------
        Path
            `path`.
        """
        Path(path).write_bytes(self.png())
        return Path(path)


class PendingFigures(OwnsWorkerPool):
    """Figures being drawn and saved in worker processes while the caller does other work.

    Each job is drawn and written by one of up to `workers` processes forked from this one (they
    inherit the data: nothing is copied or pickled, and matplotlib is imported in the workers, in
    parallel); :meth:`wait` returns the paths. Where ``fork`` is not available (not Linux), or with
    one job or ``workers=1``, the jobs run in this process in :meth:`wait`. Fork them before
    starting threads that hold locks the figures need (the rerun recording): the workers only
    draw with matplotlib and write PNGs.

    Parameters
    ----------
    jobs : sequence of (callable, Path)
        ``draw()`` returns a matplotlib Figure (or an Axes of one), written to the path by
        :func:`save_figure` (PNG at :data:`DPI`, palette-quantised); a :class:`DrawnFigure`
        in place of `draw` is written by :meth:`wait`, in this process.
    workers : int, optional
        Worker processes; default the CPU cores this process may use, at most one per job.
    server : multiprocessing context, optional
        The context of a running drawing server
        (:func:`vibroscope.viewers.drawing_server.context`): the workers are forked from it, with
        matplotlib already loaded there, and the jobs are pickled to them (so each ``draw`` must
        pickle: a module-level function or a ``functools.partial`` of one, as
        :func:`figure_jobs` makes them); this process then never imports matplotlib, even for
        one job. Default None: forked from this process as above.
    """

    def __init__(self, jobs, *, workers: int | None = None, server=None):
        global _JOBS
        jobs = list(jobs)
        self._paths = [p for _, p in jobs]
        self._drawn = [(d, p) for d, p in jobs if isinstance(d, DrawnFigure)]
        self._jobs = [(d, p) for d, p in jobs if not isinstance(d, DrawnFigure)]
        self._pool = self._result = None
        n = min(len(self._jobs), workers or _workers())
        if server is not None and n >= 1:
            self._pool = server_pool(server, n)
            try:  # the slowest first (listed first by the caller), one job at a time to whichever is free
                self._result = self._pool.map_async(_render_job, self._jobs, chunksize=1)
            except BaseException:
                self.close()
                raise
        elif n > 1 and sys.platform.startswith("linux") and not _JOBS:
            import multiprocessing

            import PIL.Image  # noqa: F401 - imported once, here, not in each worker

            pyplot()
            _JOBS = self._jobs
            try:
                self._pool = multiprocessing.get_context("fork").Pool(n, initializer=quiet_worker)
                # the slowest first (listed first by the caller), one job at a time to whichever is free
                self._result = self._pool.map_async(_render, range(len(self._jobs)), chunksize=1)
            finally:
                _JOBS = []  # the workers hold their copy; the parent's reference is not needed

    def wait(self) -> list[Path]:
        """The paths written, in the order of the jobs, once all are written.

        Returns
        -------
        list of Path

        Raises
        ------
        Exception
            The first error of a job, as raised in its worker.
        """
        if self._pool is None:
            done = [save_figure(getattr(f, "figure", f), p) for f, p in ((d(), p) for d, p in self._jobs)]
        else:
            try:
                done = [Path(p) for p in self._result.get()]
            finally:
                self.close()
        done += [d.write(p) for d, p in self._drawn]
        rank = {str(p): k for k, p in enumerate(self._paths)}
        return sorted(done, key=lambda p: rank.get(str(p), len(rank)))



def figure_jobs(out_dir: str | Path, *, signals=None, psd=None, frf=None, modal=None, sv=None,
                coords: Mapping[str, Any] | None = None, true_modes=None, stabilization=None,
                synthesized=None, kinematics=None, ahead=None) -> list:
    """The summary figures of an analysis as ``(draw, path)`` jobs, the slowest first.

    Parameters are those of :func:`summary_figures`.

    Parameters
    ----------
    out_dir : str or Path
        Folder to write into (created if missing).
    signals, psd, frf, modal, sv, coords, true_modes, stabilization, synthesized
        See :func:`summary_figures`.
    kinematics : tuple of Signals, optional
        ``(acceleration, velocity, displacement)``: writes ``kinematics.png``
        (:func:`vibroscope.viewers.acquisition.plot_kinematics` with these integrals).
    ahead : TimeSeriesAhead, optional
        Time-series figures already being drawn for `signals`
        (:meth:`vibroscope.viewers.ahead.TimeSeriesAhead.drawn`): their jobs are
        :class:`DrawnFigure` objects, and `kinematics` is not needed for ``kinematics.png``.

    Returns
    -------
    list of (callable, Path)
        For :class:`PendingFigures`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jobs = []
    drawn = ahead.drawn(signals) if ahead is not None else {}
    if "kinematics" in drawn:
        jobs.append((drawn["kinematics"], out / "kinematics.png"))
    elif kinematics is not None:
        from vibroscope.viewers.acquisition import plot_kinematics

        acc, vel, disp = kinematics
        jobs.append((partial(plot_kinematics, acc, integrals=(vel, disp)), out / "kinematics.png"))
    if sv is not None and len(sv) == 2:
        ft = None if true_modes is None else true_modes.natural_frequencies
        jobs.append((partial(plot_singular_values, sv[0], sv[1], modal, true_frequencies=ft), out / "singular_values.png"))
    if "signals" in drawn:
        jobs.append((drawn["signals"], out / "signals.png"))
    elif signals is not None:
        jobs.append((partial(plot_signals, signals), out / "signals.png"))
    if synthesized is not None and frf is not None:
        jobs.append((partial(plot_frf_synthesis, frf, synthesized, modal), out / "frf_synthesis.png"))
    if frf is not None:
        jobs.append((partial(plot_frf, frf), out / "frf.png"))
    if modal is not None and len(np.atleast_1d(modal.natural_frequencies)):
        jobs.append((partial(plot_mode_shapes, modal, coords, true_modes=true_modes), out / "modes.png"))
    if stabilization is not None:
        jobs.append((partial(plot_stabilization, stabilization, sv, modal), out / "stabilization.png"))
    if psd is not None:
        jobs.append((partial(plot_spectrum, psd), out / "psd.png"))
    return jobs


#: the order in which :func:`summary_figures` lists the figures it wrote
FIGURE_ORDER = ("signals", "psd", "frf", "modes", "singular_values", "stabilization", "frf_synthesis", "kinematics")


def in_figure_order(paths) -> list[Path]:
    """`paths` sorted as :data:`FIGURE_ORDER` (others last, in their order).

    Parameters
    ----------
    paths : iterable of Path

    Returns
    -------
    list of Path
    """
    rank = {name: k for k, name in enumerate(FIGURE_ORDER)}
    return sorted((Path(p) for p in paths), key=lambda p: rank.get(p.stem, len(rank)))


def summary_figures(out_dir: str | Path, *, signals=None, psd=None, frf=None, modal=None, sv=None,
                    coords: Mapping[str, Any] | None = None, true_modes=None,
                    stabilization=None, synthesized=None, workers: int | None = None) -> list[Path]:
    """Write the summary PNGs of an analysis, those whose inputs are given, drawn in parallel
    (:class:`PendingFigures`).

    Parameters
    ----------
    out_dir : str or Path
        Folder to write into (created if missing).
    signals : Signals, optional
        Writes ``signals.png`` (time series of the first channels).
    psd : Spectrum, optional
        Writes ``psd.png``.
    frf : FRF, optional
        Writes ``frf.png`` (first output and input).
    modal : ModalModel, optional
        Writes ``modes.png``; its frequencies are marked in ``singular_values.png``.
    sv : tuple (frequencies, S), optional
        FDD singular values, ``S`` of shape (n_freqs, n); writes ``singular_values.png``.
    coords : mapping, optional
        Sensor coordinates for the mode shapes (see :func:`plot_mode_shapes`).
    true_modes : ModalModel, optional
        Reference modes, marked in the mode and singular value figures.
    stabilization : Stabilization, optional
        SSI-COV or LSCF poles; writes ``stabilization.png``.
    synthesized : FRF, optional
        The modal model's FRFs; with `frf` writes ``frf_synthesis.png`` (:func:`plot_frf_synthesis`).
    workers : int, optional
        Processes drawing the figures; default the CPU cores available (1: in this process).

    Returns
    -------
    list of Path
        The files written, in the order above.
    """
    jobs = figure_jobs(out_dir, signals=signals, psd=psd, frf=frf, modal=modal, sv=sv, coords=coords,
                       true_modes=true_modes, stabilization=stabilization, synthesized=synthesized)
    with PendingFigures(jobs, workers=workers) as pending:
        return in_figure_order(pending.wait())


def plot_ods(ods_result, coords: Mapping[str, Any] | None = None, *, fig=None, true_modes=None):
    """Draw an operating deflection shape like a mode shape.

    Wraps it with :func:`ods_as_modal_model` and draws it with
    :func:`vibroscope.viewers.figures.plot_mode_shapes` (in-phase part relative to the
    reference point, and the modulus dotted), titled as an ODS.

    Parameters
    ----------
    ods_result : OperatingShape
        From :func:`vibroscope.spectral.integration.ods`.
    coords : mapping, optional
        Sensor positions and directions (see :func:`vibroscope.viewers._common.sensor_geometry`);
        points on a line when None.
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.
    true_modes : ModalModel, optional
        Reference modes; the one nearest in frequency is named and drawn dashed.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from vibroscope.modal import ods_as_modal_model

    o = ods_result
    if fig is None:
        fig = pyplot().figure(figsize=(6.4, 4.0), layout="constrained")
    fig = plot_mode_shapes(ods_as_modal_model(o), coords, fig=fig, true_modes=true_modes)
    ax = fig.axes[0]
    old = ax.get_title().split("\n")[1:]
    src = {"frf": f"FRF (input {short_label(str(o.input), 24)})", "csd": "CSD (output-only)"}.get(o.source, o.source)
    asked = "" if f"{o.requested_frequency:.4g}" == f"{o.frequency:.4g}" else f", nearest line to {o.requested_frequency:.4g} Hz"
    ref = distinct_labels(o.points)[o.points.index(o.reference)] if o.reference in o.points else o.reference
    title = f"ODS at {o.frequency:.4g} Hz{asked}\nfrom {src}, phase reference {ref}"
    ax.set_title("\n".join([title, *old]), fontsize=9)
    for line in ax.get_lines():
        if line.get_label() == "identified (real part)":
            line.set_label("in phase with the reference")
        elif line.get_label() == "|φ|":
            line.set_label("modulus")
    ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"Operating deflection shape ({len(o.points)} points)", fontsize=11)
    return fig
