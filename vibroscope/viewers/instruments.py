"""Matplotlib figures (and a rerun recording) of the founding paper's virtual instruments.

The numbers come from :mod:`vibroscope.instruments` (the paper's scenarios from
:mod:`vibroscope.instruments.scenarios`); this module only draws them.
matplotlib is imported inside the functions (:func:`vibroscope.viewers.figures.pyplot`
chooses Agg when there is no display), rerun inside :func:`log_sweep`.

- result plots: :func:`plot_bode`, :func:`plot_nyquist`, :func:`plot_step`,
  :func:`plot_hydraulic_comparison`, :func:`plot_mr_loops` (what the results' ``.plot()`` call);
- the paper's figures as PNGs: :func:`figure_pneumatic` (figs. 2-3), :func:`figure_hydraulic`
  (P vs PD2), :func:`figure_block_schema` (fig. 7), :func:`figure_mr_hysteresis`;
- the comparative sweep: :func:`figure_sweep` (PNG) and :func:`log_sweep` (``.rrd``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroscope.viewers.figures import pyplot, save_figure

__all__ = [
    "plot_bode",
    "plot_nyquist",
    "plot_step",
    "plot_hydraulic_comparison",
    "plot_mr_loops",
    "figure_pneumatic",
    "figure_hydraulic",
    "figure_block_schema",
    "figure_mr_hysteresis",
    "figure_sweep",
    "log_sweep",
]


# --------------------------------------------------------------------------- result plots


def plot_bode(result, axes=None, label: str | None = None, **kwargs):
    """Magnitude (dB) and phase (deg) of a :class:`~vibroscope.instruments.lti.BodeResult` on
    log frequency axes; returns the two axes.

    Parameters
    ----------
    result : BodeResult
        Its ``frequencies``, ``magnitude_db`` and ``phase_deg`` are drawn.
    axes : sequence of 2 matplotlib.axes.Axes, optional
        Magnitude and phase axes; default a new figure (shared x).
    label : str, optional
        Legend label of the curves.
    **kwargs
        Passed to ``Axes.semilogx``.

    Returns
    -------
    (Axes, Axes)
    """
    if axes is None:
        _, axes = pyplot().subplots(2, 1, sharex=True, figsize=(6, 5))
    a1, a2 = axes
    a1.semilogx(result.frequencies, result.magnitude_db, label=label, **kwargs)
    a2.semilogx(result.frequencies, result.phase_deg, label=label, **kwargs)
    a1.set_ylabel("magnitude [dB]")
    a2.set_ylabel("phase [deg]")
    a2.set_xlabel("frequency [Hz]")
    for a in axes:
        a.grid(True, which="both", alpha=0.3)
    return axes


def plot_nyquist(result, ax=None, label: str | None = None, mirror: bool = True, **kwargs):
    """Re/Im locus of a :class:`~vibroscope.instruments.lti.NyquistResult` (with its mirror
    image for negative frequencies, dashed) and the critical point -1; returns the axes.

    Parameters
    ----------
    result : NyquistResult
        Its complex ``response`` is drawn.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on; default a new figure.
    label : str, optional
        Legend label of the locus.
    mirror : bool, optional
        Also draw the mirror image ``conj(response)``, dashed; default True.
    **kwargs
        Passed to ``Axes.plot`` for the locus.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        _, ax = pyplot().subplots(figsize=(5, 5))
    (line,) = ax.plot(result.response.real, result.response.imag, label=label, **kwargs)
    if mirror:
        ax.plot(result.response.real, -result.response.imag, "--", color=line.get_color(), lw=0.8)
    ax.plot([-1], [0], "r+", ms=10)
    ax.set_xlabel("Re G")
    ax.set_ylabel("Im G")
    ax.grid(True, alpha=0.3)
    return ax


def plot_step(result, ax=None, label: str | None = None, **kwargs):
    """A :class:`~vibroscope.instruments.lti.StepResult` versus time; returns the axes.

    Parameters
    ----------
    result : StepResult
        Its ``response`` is drawn against ``time_s`` (s).
    ax : matplotlib.axes.Axes, optional
        Axes to draw on; default a new figure.
    label : str, optional
        Legend label of the curve.
    **kwargs
        Passed to ``Axes.plot``.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        _, ax = pyplot().subplots(figsize=(6, 3.5))
    ax.plot(result.time_s, result.response, label=label, **kwargs)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("response")
    ax.grid(True, alpha=0.3)
    return ax


def plot_hydraulic_comparison(comparison, axes=None):
    """Step responses and piston velocities of the P and PD2 loops of a
    :class:`~vibroscope.instruments.hydraulic.HydraulicComparison`; returns the two axes.

    Parameters
    ----------
    comparison : HydraulicComparison
        Its ``step_p`` and ``step_pd2`` step responses are drawn (time in ms).
    axes : sequence of 2 matplotlib.axes.Axes, optional
        Position and velocity axes; default a new figure.

    Returns
    -------
    (Axes, Axes)
    """
    from vibroscope.instruments.hydraulic import step_velocity

    if axes is None:
        _, axes = pyplot().subplots(1, 2, figsize=(11, 4))
    for r, lab in ((comparison.step_p, "P"), (comparison.step_pd2, "PD2")):
        axes[0].plot(r.time_s * 1e3, r.response, label=f"{lab}: settling {r.settling_time_s * 1e3:.0f} ms")
        axes[1].plot(r.time_s * 1e3, step_velocity(r), label=lab)
    axes[0].set_ylabel("position x/r [-]")
    axes[1].set_ylabel("velocity per unit step [1/s]")
    axes[0].set_title("unit step of position reference")
    axes[1].set_title("piston velocity (acceleration phase)")
    for a in axes:
        a.set_xlabel("time [ms]")
        a.grid(True, alpha=0.3)
        a.legend()
    return axes


def plot_mr_loops(result, axes=None, label: str | None = None, last_s: float | None = None, **kwargs):
    """Force-displacement and force-velocity loops (mm, mm/s, kN) of a
    :class:`~vibroscope.instruments.mr_damper.MRDamperResult`, the last `last_s` seconds
    (all by default); returns the two axes.

    Parameters
    ----------
    result : MRDamperResult
        Its ``x`` (m), ``xdot`` (m/s) and ``force`` (N) are drawn in mm, mm/s and kN.
    axes : sequence of 2 matplotlib.axes.Axes, optional
        Force-displacement and force-velocity axes; default a new figure.
    label : str, optional
        Legend label of the loops.
    last_s : float, optional
        Only the samples with ``time_s >= time_s[-1] - last_s``; default all.
    **kwargs
        Passed to ``Axes.plot``.

    Returns
    -------
    (Axes, Axes)
    """
    if axes is None:
        _, axes = pyplot().subplots(1, 2, figsize=(10, 4))
    m = slice(None) if last_s is None else result.time_s >= result.time_s[-1] - last_s
    axes[0].plot(result.x[m] * 1e3, result.force[m] * 1e-3, label=label, **kwargs)
    axes[1].plot(result.xdot[m] * 1e3, result.force[m] * 1e-3, label=label, **kwargs)
    axes[0].set_xlabel("displacement x [mm]")
    axes[1].set_xlabel("velocity x' [mm/s]")
    for a in axes:
        a.set_ylabel("force f [kN]")
        a.grid(True, alpha=0.3)
    return axes


def _finish(fig, ax_flat, title: str, path) -> Path:
    for a in ax_flat:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, Path(path))


# --------------------------------------------------------------------------- the paper's figures


def figure_pneumatic(path, areas_cm2=(60.0, 70.0, 80.0), flow: float = 50e-6, **params) -> Path:
    """Paper figures 2 and 3: displacement, velocity, acceleration step responses and
    Bode / Nyquist of the pneumatic motor for several piston areas.

    Parameters
    ----------
    path : str or path-like
        PNG file written.
    areas_cm2 : sequence of float
        Piston areas in cm^2 (converted to m^2).
    flow : float
        Step of air flow Q in m^3/s (default 50 cm^3/s, mid of the paper's 20-100 cm^3/s).
    **params
        Other :func:`vibroscope.instruments.pneumatic.pneumatic_motor` parameters (SI).

    Returns
    -------
    Path
        The PNG written.
    """
    from vibroscope.instruments.scenarios import PNEUMATIC_OUTPUTS, pneumatic_scenario

    sc = pneumatic_scenario(areas_cm2, flow, **params)
    scales = {"displacement": (1e3, "mm"), "velocity": (1e3, "mm/s"), "acceleration": (1e3, "mm/s²")}
    fig, ax = pyplot().subplots(2, 3, figsize=(13, 7))
    for a_cm2, steps, b, ny in zip(sc.areas_cm2, sc.steps, sc.bode, sc.nyquist):
        lab = f"A = {a_cm2:g} cm²"
        for k, out in enumerate(PNEUMATIC_OUTPUTS):
            scale, unit = scales[out]
            r = steps[out]
            ax[0, k].plot(r.time_s, r.response * scale, label=lab)
            ax[0, k].set_ylabel(f"{out} [{unit}]")
            ax[0, k].set_title(f"{out} for a {flow * 1e6:g} cm³/s flow step")
        ax[1, 0].semilogx(b.frequencies, b.magnitude_db, label=lab)
        ax[1, 1].semilogx(b.frequencies, b.phase_deg, label=lab)
        ax[1, 2].plot(ny.response.real * 1e-2, ny.response.imag * 1e-2, label=lab)
    for a in ax[0]:
        a.set_xlabel("time [s]")
    ax[1, 0].set_title("Bode magnitude z/Q")
    ax[1, 0].set_ylabel("|z/Q| [dB re 1 s/m²]")
    ax[1, 1].set_title("Bode phase z/Q")
    ax[1, 1].set_ylabel("phase [deg]")
    for a in ax[1, :2]:
        a.set_xlabel("frequency [Hz]")
    ax[1, 2].set_title("Nyquist of velocity/flow ż/Q")
    ax[1, 2].set_xlabel("Re ż/Q [10² m⁻²]")
    ax[1, 2].set_ylabel("Im ż/Q [10² m⁻²]")
    ax[1, 2].set_aspect("equal", adjustable="datalim")
    return _finish(fig, ax.flat, "Linear pneumatic motor (Olaru & Olaru 2011, eq. 3) — effect of piston area A", path)


def figure_hydraulic(path) -> Path:
    """Step and velocity responses of P versus PD2 position control, both tunings of
    :func:`vibroscope.instruments.hydraulic.hydraulic_comparison`.

    Parameters
    ----------
    path : str or path-like
        PNG file written.

    Returns
    -------
    Path
        The PNG written.
    """
    from vibroscope.instruments.scenarios import hydraulic_scenario

    fig, axes = pyplot().subplots(2, 2, figsize=(11, 7))
    for row, (tuning, c) in zip(axes, hydraulic_scenario(("itae", "same-gain")).items()):
        plot_hydraulic_comparison(c, row)
        row[0].set_title(f"position step, tuning '{tuning}'")
    fig.suptitle(f"Linear hydraulic motor (Merritt 1967), ω_h = {c.omega_h / 2 / np.pi:.0f} Hz: P vs PD2")
    fig.tight_layout()
    return save_figure(fig, Path(path))


def figure_block_schema(path, load_step: float = -0.5, t_load: float = 15.0, t_end: float = 40.0) -> Path:
    """Indicial responses at every point (open / closed loop, with / without load) and Bode
    of each component, as the paper's figure 7 instrument.

    Parameters
    ----------
    path : str or path-like
        PNG file written.
    load_step : float
        Height of the load disturbance step at the plant input (same unit as the reference).
    t_load : float
        Time of the load step, s.
    t_end : float
        Simulated time, s.

    Returns
    -------
    Path
        The PNG written.
    """
    from vibroscope.instruments.scenarios import block_schema_scenario

    sc = block_schema_scenario(load_step, t_load, t_end)
    t, reference, load = sc.time_s, sc.reference, sc.load
    fig, ax = pyplot().subplots(2, 2, figsize=(12, 8))
    names = {"e": "error e", "u": "regulator out u", "c": "correction out c", "y": "plant out y", "r": "reference r"}
    for point, lab in names.items():
        (ln,) = ax[0, 0].plot(t, reference[point], label=lab)
        if point in ("e", "y", "u"):
            ax[0, 1].plot(t, reference[point] + load[point], color=ln.get_color(),
                          label=f"{lab} (load {load_step:g} at {t_load:g} s)")
    ax[0, 1].plot(t, reference["y"], "k:", lw=1, label="plant out y, no load")
    for point in ("u", "c", "y"):
        ax[1, 0].plot(t, sc.open_loop[point].response, label=names[point])
    f = sc.frequencies
    for name, b in sc.block_bode.items():
        ax[1, 1].semilogx(f, b.magnitude_db, label=name)
    ax[1, 1].semilogx(f, sc.closed_loop_bode.magnitude_db, "k--", label="closed loop y/r")
    ax[0, 0].set_title("closed loop: unit reference step, every point")
    ax[0, 1].set_title("closed loop with a load step at the plant input")
    ax[1, 0].set_title("open loop (no feedback): unit reference step")
    ax[1, 0].set_ylim(-0.5, 15)
    ax[1, 1].set_title("Bode magnitude of each component")
    for a in (ax[0, 0], ax[0, 1], ax[1, 0]):
        a.set_xlabel("time [s]")
        a.set_ylabel("signal [unit of r]")
    ax[1, 1].set_xlabel("frequency [Hz]")
    ax[1, 1].set_ylabel("magnitude [dB]")
    return _finish(fig, ax.flat, "Block schema: PI H_R = 0.9(9.9s+1)/(3s), correction H_c = 1/(0.7s+1), "
                                 "plant PT2 (ω_n = 5 rad/s, ζ = 0.7)", path)


def figure_mr_hysteresis(
    path,
    currents=(0.0, 0.5, 1.0, 1.5, 2.0),
    amplitude: float = 0.015,
    frequency: float = 2.5,
    params=None,
) -> Path:
    """Force-displacement and force-velocity loops of the MR damper for several currents
    (:func:`vibroscope.instruments.mr_damper.sine_test`).

    Parameters
    ----------
    path : str or path-like
        PNG file written.
    currents : sequence of float
        Coil currents, A.
    amplitude : float
        Sinusoidal displacement amplitude, m (Spencer's test: 1.5 cm).
    frequency : float
        Excitation frequency, Hz (Spencer's test: 2.5 Hz).
    params : MRDamperParams, optional
        Damper; Spencer et al. (1997) by default.

    Returns
    -------
    Path
        The PNG written.
    """
    from vibroscope.instruments.mr_damper import sine_test

    results = sine_test(currents, amplitude, frequency, params=params)
    period = 1.0 / frequency
    fig, axes = pyplot().subplots(1, 3, figsize=(14, 4.3))
    for i, r in zip(currents, results):
        plot_mr_loops(r, axes[:2], label=f"i = {i:g} A", last_s=period)
        axes[2].plot(r.time_s, r.force * 1e-3, label=f"i = {i:g} A")
    axes[0].set_title(f"force-displacement ({amplitude * 1e3:g} mm, {frequency:g} Hz)")
    axes[1].set_title("force-velocity")
    axes[2].set_title("force history")
    axes[2].set_xlabel("time [s]")
    axes[2].set_ylabel("force f [kN]")
    axes[2].grid(True, alpha=0.3)
    axes[2].legend(fontsize=8, loc="upper right", framealpha=0.9)
    fig.suptitle("MR damper, Spencer et al. (1997) model; loop energy per cycle: "
                 + ", ".join(f"{r.loop_energy(period):.0f} J" for r in results))
    fig.tight_layout()
    return save_figure(fig, Path(path))


# --------------------------------------------------------------------------- comparative sweep


def figure_sweep(result, path, title: str = "") -> Path:
    """Step responses and Bode of every case of a
    :class:`~vibroscope.instruments.sweeps.SweepResult`, overlaid.

    Parameters
    ----------
    result : SweepResult
        The sweep.
    path : str or path-like
        PNG file written.
    title : str
        Figure title.

    Returns
    -------
    Path
        The PNG written.
    """
    fig = pyplot().figure(figsize=(12, 5.5))
    ax_t = fig.add_subplot(1, 2, 1)
    ax_m = fig.add_subplot(2, 2, 2)
    ax_p = fig.add_subplot(2, 2, 4, sharex=ax_m)
    for s, b, lab in zip(result.steps, result.bodes, result.labels):
        ax_t.plot(s.time_s, s.response, label=lab)
        ax_m.semilogx(b.frequencies, b.magnitude_db, label=lab)
        ax_p.semilogx(b.frequencies, b.phase_deg, label=lab)
    what, unit = result.model.quantity, result.model.unit
    ax_t.set_title(f"step response: {what}")
    ax_t.set_xlabel("time [s]")
    ax_t.set_ylabel(f"{what} [{unit}]" if unit else what)
    ax_m.set_title("Bode")
    ax_m.set_ylabel("magnitude [dB]")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("frequency [Hz]")
    for a in (ax_t, ax_m, ax_p):
        a.grid(True, which="both", alpha=0.3)
    ax_t.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, Path(path))


def log_sweep(result, path, tag: str) -> Path | None:
    """Save the step responses and Bode magnitudes of a sweep as a rerun ``.rrd`` recording.

    Parameters
    ----------
    result : SweepResult
        The sweep.
    path : str or path-like
        The ``.rrd`` file.
    tag : str
        Recording name suffix (``vibroscope-compare-<tag>``).

    Returns
    -------
    Path or None
        The file written, or None when rerun-sdk is not installed.
    """
    try:
        import rerun as rr
    except ImportError:
        return None
    rec = rr.RecordingStream(f"vibroscope-compare-{tag}")
    for k, (lab, s, b) in enumerate(zip(result.labels, result.steps, result.bodes)):
        ent = f"case_{k + 1}"
        rec.log(f"step/{ent}", rr.SeriesLines(names=lab), static=True)
        rec.send_columns(f"step/{ent}", indexes=[rr.TimeColumn("time", duration=np.asarray(s.time_s))],
                         columns=rr.Scalars.columns(scalars=np.asarray(s.response)))
        rec.log(f"bode_db/{ent}", rr.SeriesLines(names=lab), static=True)
        rec.send_columns(f"bode_db/{ent}", indexes=[rr.TimeColumn("frequency_bin",
                                                                  sequence=np.arange(b.frequencies.size))],
                         columns=rr.Scalars.columns(scalars=np.asarray(b.magnitude_db)))
    rec.save(str(path))
    return Path(path)
