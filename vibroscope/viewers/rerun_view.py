"""Log an analysis to one rerun recording (``.rrd`` file and/or a spawned viewer), and read a
recording back.

rerun is imported inside the functions: importing this module never imports it.

Timelines
---------
``time`` (duration)
    The time series, in s since the first sample (``Signals.t0`` is written in the ``about``
    document). Stored by rerun as int64 ns. A channel longer than :data:`MAX_POINTS` (100 000)
    samples is logged for display as its min/max envelope (:func:`envelope_indices`: the
    smallest and largest sample of each of 50 000 consecutive bins, at their true times), so a
    1e7-sample analysis stays small and every peak stays visible; the spectra keep the full
    resolution of the record.
``frequency_mHz`` (sequence)
    Spectra, FRF and coherence. rerun 0.41's :class:`~rerun.blueprint.TimeSeriesView` plots
    against a timeline only (no free x axis, no log axes), and timelines hold integers
    (sequences) or times; a sequence whose index is the frequency in **millihertz**
    (``round(1000 f)``) keeps the axis a plain linear frequency axis whose numbers read
    directly as mHz (1000 = 1 Hz), without the time formatting (s, min) a duration timeline
    would put on frequencies taken as seconds. When the resolution is finer than 1 mHz
    (rounded bins would collide) the timeline is ``frequency_uHz`` (µHz) instead. Power
    quantities are logged in dB (``10 log10``), since the view has no logarithmic y axis.
``animation`` (sequence)
    Mode shape animation frames, `frames` per cycle of every mode.

The viewer shows one timeline at a time: each tab of the blueprint names the timeline its views
need; the time panel starts on ``animation`` (playing, looped) when there are modes, else on
``time``.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from vibroscope.signals import true_runs
from vibroscope.viewers._common import mode_label, sensor_geometry

__all__ = ["log_analysis", "open_in_viewer", "show_recording", "flush_recording", "viewer_executable", "VIEWER_PORT", "read_rrd", "channel_entity", "mode_entity", "frequency_index",
           "mode_frames", "node_frames", "envelope_indices", "MAX_POINTS", "preload"]

#: animation frames per cycle of a mode
FRAMES = 40

#: the port a spawned rerun viewer listens on (rerun's default)
VIEWER_PORT = 9876

#: most points logged per time-series channel: longer channels are logged as their min/max
#: envelope (:func:`envelope_indices`), 50 000 bins of two true samples each
MAX_POINTS = 100_000


def _esc(part: str) -> str:
    import rerun as rr

    return rr.escape_entity_path_part(part)


def channel_entity(prefix: str, channel: str) -> str:
    """Entity path of a channel under `prefix`: its message path split on ``/``, each part escaped.

    Parameters
    ----------
    prefix : str
        E.g. ``"signals"``, ``"psd"``, ``"frf/magnitude_db"``.
    channel : str
        Channel name, e.g. ``"/imu/wrist.linear_acceleration.z"``.

    Returns
    -------
    str
        E.g. ``"/signals/imu/wrist.linear_acceleration.z"`` (as rerun writes it back).
    """
    parts = [p for p in str(channel).split("/") if p] or ["_"]
    return "/" + "/".join([*(p for p in prefix.split("/") if p), *(_esc(p) for p in parts)])


def mode_entity(r: int, f: float) -> str:
    """Entity path of mode `r` (0-based) at `f` Hz: ``/modes/mode_1_2.82Hz``.

    Parameters
    ----------
    r : int
        Mode index from 0 (the path numbers modes from 1).
    f : float
        Natural frequency in Hz (3 significant digits in the path).

    Returns
    -------
    str
    """
    return "/modes/" + _esc(f"mode_{r + 1}_{f:.3g}Hz")


def frequency_index(frequencies: np.ndarray) -> tuple[str, np.ndarray]:
    """The frequency timeline used for spectra: its name and integer index values.

    Parameters
    ----------
    frequencies : array_like, shape (n_freqs,)
        Hz, ascending.

    Returns
    -------
    name : str
        ``"frequency_mHz"``, or ``"frequency_uHz"`` when mHz rounding would merge bins.
    index : ndarray of int64
        ``round(1000 f)`` (or ``round(1e6 f)``).
    """
    f = np.asarray(frequencies, dtype=float)
    idx = np.round(f * 1e3).astype(np.int64)
    if f.size > 1 and np.any(np.diff(idx) <= 0):
        return "frequency_uHz", np.round(f * 1e6).astype(np.int64)
    return "frequency_mHz", idx


def mode_frames(shape: np.ndarray, positions: np.ndarray, directions: np.ndarray, scale: float,
                frames: int = FRAMES) -> np.ndarray:
    """Displaced point positions over one cycle of a mode.

    ``x_k = positions + scale · Re(φ̂ · exp(j 2π k / frames)) · directions`` for
    ``k = 0 … frames − 1``, with ``φ̂ = φ / max|φ|``.

    Parameters
    ----------
    shape : array_like, complex, shape (n_points,)
    positions, directions : ndarray, shape (n_points, 3)
    scale : float
        Largest displacement in m.
    frames : int, optional

    Returns
    -------
    ndarray, shape (frames, n_points, 3)
    """
    phi = np.asarray(shape, dtype=complex)
    m = np.max(np.abs(phi)) if phi.size else 0.0
    phi = phi / m if m > 0 else phi
    ph = np.exp(2j * np.pi * np.arange(frames) / frames)
    amp = np.real(phi[None, :] * ph[:, None])  # (frames, n_points)
    return positions[None, :, :] + scale * amp[:, :, None] * directions[None, :, :]


def decibels(v: np.ndarray, fac: float = 10.0) -> np.ndarray:
    """``fac · log10(v)``: 10 for a power (PSD), 20 for an amplitude (|H|); NaN where ``v <= 0``.

    Parameters
    ----------
    v : array_like
        Non-negative values.
    fac : float, optional
        10 (default) or 20.

    Returns
    -------
    ndarray of float, shape of `v`
    """
    v = np.asarray(v, dtype=float)
    out = np.full(v.shape, np.nan)
    pos = v > 0
    out[pos] = fac * np.log10(v[pos])
    return out


def _mode_table(modal) -> str:
    fn = np.asarray(modal.natural_frequencies, dtype=float)
    z = np.asarray(modal.damping_ratios, dtype=float)
    extra = getattr(modal, "extra", {}) or {}
    mpc = extra.get("mpc")
    lines = [f"# Modes ({getattr(modal, 'method', '')})", "",
             f"{len(modal.points)} points: " + ", ".join(f"`{p}`" for p in modal.points), "",
             "| # | f [Hz] | ζ [%] |" + (" MPC |" if mpc is not None else ""),
             "|---|---|---|" + ("---|" if mpc is not None else "")]
    for r in range(fn.size):
        zs = f"{100 * z[r]:.3f}" if np.isfinite(z[r]) else "n/a"
        row = f"| {r + 1} | {fn[r]:.4f} | {zs} |"
        if mpc is not None:
            row += f" {float(np.asarray(mpc)[r]):.3f} |"
        lines.append(row)
    return "\n".join(lines)


def preload() -> None:
    """Import rerun and what its first recording needs, so that :func:`log_analysis` does not wait
    for it; run in a background thread while an analysis computes
    (:func:`vibroscope.commands._outputs.preload_outputs`). pyarrow imports pandas (when
    installed) on the first array it builds from a list, as the blueprint does: that import is
    done here too."""
    import pyarrow as pa
    import rerun  # noqa: F401
    import rerun.blueprint  # noqa: F401

    pa.array([0], type=pa.int8())


def whole_time_axis(rrb, timeline: str, start: dict, end: dict):
    """Axis showing [start, end] of `timeline` and every datum of it (not a window at the cursor)."""
    axis = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.absolute(**start),
                                                 end=rrb.TimeRangeBoundary.absolute(**end)))
    ranges = rrb.VisibleTimeRange(timeline, start=rrb.TimeRangeBoundary.infinite(),
                                  end=rrb.TimeRangeBoundary.infinite())
    return dict(axis_x=axis, time_ranges=ranges)


def _eye(rrb, positions: np.ndarray):
    """A camera that frames the whole structure from the side, slightly above, z up."""
    pos = np.asarray(positions, dtype=float).reshape(-1, 3)
    target = pos.mean(axis=0) if pos.size else np.zeros(3)
    ptp = np.ptp(pos, axis=0) if len(pos) > 1 else np.ones(3)
    ext = float(ptp.max()) or 1.0
    tall = int(np.argmax(ptp)) == 2  # a tower: narrow tall views; else a beam or chain: wide views
    d = np.array([1.0, -1.0, 0.3]) if tall else np.array([0.1, -1.0, 0.35])
    eye = target + (1.6 if tall else 0.8) * ext * d / np.linalg.norm(d)
    return rrb.EyeControls3D(position=eye.tolist(), look_target=target.tolist(), eye_up=[0.0, 0.0, 1.0])


def _build_blueprint(*, signals, spec_entities, frf_present, csd_present, modal, ftl, f_range=None,
                     positions=None, stabilization_present=False, kinematics=None):
    import rerun.blueprint as rrb

    tabs = []
    active = None
    fx = {} if f_range is None else whole_time_axis(rrb, ftl, dict(seq=int(f_range[0])), dict(seq=int(f_range[1])))
    # resonances sit low in the band: keep the legends out of their way
    legend = rrb.PlotLegend(corner=rrb.Corner2D.RightTop)
    if signals is not None:
        tx = whole_time_axis(rrb, "time", dict(seconds=0.0), dict(seconds=float(signals.duration)))
        views = [rrb.TimeSeriesView(origin=channel_entity("signals", c), name=f"{c} [{u or '-'}]", **tx)
                 for c, u in zip(signals.channels, signals.units)]
        tabs.append(rrb.Grid(*views, grid_columns=1 if len(views) <= 4 else 2,
                             name="Time series (timeline: time)"))
    if kinematics is not None:
        vel, disp = kinematics
        tx = whole_time_axis(rrb, "time", dict(seconds=0.0), dict(seconds=float(vel.duration)))
        fc = vel.meta.get("integration", {}).get("f_cut_hz")
        cut = f", high-pass {fc:.3g} Hz" if fc else ""
        tabs.append(rrb.Vertical(
            rrb.TimeSeriesView(origin="/velocity", name=f"velocity [{vel.units[0] or '-'}] (integrated{cut})",
                               plot_legend=legend, **tx),
            rrb.TimeSeriesView(origin="/displacement", name=f"displacement [{disp.units[0] or '-'}] (integrated{cut})",
                               plot_legend=legend, **tx),
            name="Velocity & displacement (timeline: time)"))
    if spec_entities:
        views = [rrb.TimeSeriesView(origin="/psd", name=f"PSD [dB re 1 unit²/Hz] vs frequency ({ftl})",
                                    plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop,
                                                               visible=len(signals.channels) <= 8 if signals
                                                               else True), **fx)]
        if csd_present:
            views.append(rrb.TimeSeriesView(origin="/csd/singular_values",
                                            name=f"CSD singular values (FDD) [dB] vs frequency ({ftl})",
                                            plot_legend=legend, **fx))
        tabs.append(rrb.Vertical(*views, name=f"Spectra (timeline: {ftl})"))
    if frf_present:
        tabs.append(rrb.Vertical(
            rrb.TimeSeriesView(origin="/frf/magnitude_db", name=f"FRF magnitude [dB] vs frequency ({ftl})",
                               plot_legend=legend, **fx),
            rrb.TimeSeriesView(origin="/frf/phase_deg", name=f"FRF phase [deg] vs frequency ({ftl})",
                               axis_y=rrb.ScalarAxis(range=(-180.0, 180.0)), plot_legend=legend, **fx),
            rrb.TimeSeriesView(origin="/frf/coherence", name=f"coherence γ² [-] vs frequency ({ftl})",
                               axis_y=rrb.ScalarAxis(range=(0.0, 1.05)), plot_legend=legend, **fx),
            row_shares=[2, 1.3, 1], name=f"FRF (timeline: {ftl})"))
    if stabilization_present:
        tabs.append(rrb.TimeSeriesView(origin="/stabilization", name=f"Stabilization diagram: model order vs "
                                       f"frequency ({ftl}); green = stable in f, ζ and MAC",
                                       plot_legend=rrb.PlotLegend(visible=False), **fx))
    if modal is not None and len(np.atleast_1d(modal.natural_frequencies)):
        fn = np.asarray(modal.natural_frequencies, dtype=float)
        z = np.asarray(modal.damping_ratios, dtype=float)
        eye = _eye(rrb, positions) if positions is not None else None
        views3d = [rrb.Spatial3DView(origin=mode_entity(r, fn[r]), line_grid=rrb.LineGrid3D(visible=False),
                                     eye_controls=eye,
                                     name=f"{r + 1}: {fn[r]:.4g} Hz, " + (f"{100 * z[r]:.2f} %" if np.isfinite(z[r])
                                                                         else "ζ n/a"))
                   for r in range(fn.size)]
        # tall views side by side for a tower (extent along z), wide views stacked for a beam or chain
        tall = positions is not None and len(positions) > 1 and int(np.argmax(np.ptp(positions, axis=0))) == 2
        tabs.append(rrb.Horizontal(
            rrb.Grid(*views3d, grid_columns=min(8, len(views3d)) if tall else 1),
            rrb.TextDocumentView(origin="/modes/table", name="Mode table"),
            column_shares=[3, 1], name="Mode shapes (timeline: animation)"))
        active = len(tabs) - 1
    tabs.append(rrb.TextDocumentView(origin="/about", name="About this recording"))
    if active is not None:
        panel = rrb.TimePanel(timeline="animation", play_state="playing", loop_mode="all", fps=20.0)
    elif signals is not None:
        panel = rrb.TimePanel(timeline="time")
    else:
        panel = rrb.TimePanel(timeline=ftl)
        active = 0
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=active or 0), panel, collapse_panels=False)


def log_analysis(*, signals=None, psd=None, csd=None, frf=None, modal=None,
                 coords: Mapping[str, Any] | None = None, rrd_path: str | Path | None = None,
                 spawn: bool = False, application_id: str = "vibroscope",
                 recording_name: str | None = None, frames: int = FRAMES,
                 recording_id: str | None = None, stabilization=None, synthesized=None,
                 kinematics=None, max_points: int | None = MAX_POINTS, singular_values=None) -> Path | None:
    """Log the results of one analysis to one rerun recording, with a blueprint.

    Entities (channel names are split on ``/`` into entity path parts):

    - ``/signals/<channel>``: the samples, one ``send_columns`` per channel on the ``time``
      timeline (duration, s since the first sample), :class:`rerun.Scalars` (float64, exact);
      beyond `max_points` samples, the min/max envelope (true samples at their true times,
      :func:`envelope_indices`).
    - ``/psd/<channel>``: ``10 log10`` of the PSD on the frequency timeline (see the module
      docstring: ``frequency_mHz``, index ``round(1000 f)``); NaN where the PSD is 0.
    - ``/csd/singular_values/s1..s3``: ``10 log10`` of the first singular values of `csd`.
    - ``/frf/{magnitude_db,phase_deg,coherence}/<output>`` (``.../in<k>/<output>`` with several
      inputs): ``20 log10 |H|``, phase in degrees, γ².
    - ``/modes/mode_<r>_<f>Hz``: :class:`rerun.Points3D` of the sensors displaced along their
      measuring directions over the ``animation`` timeline (`frames` per cycle, see
      :func:`mode_frames`; the largest displacement is 15 % of the structure's size) and a
      :class:`rerun.LineStrips3D` joining the deformed locations (:func:`node_frames`); the
      undeformed sensors and structure under ``.../undeformed`` (static, grey);
      ``/modes/table``: a markdown :class:`rerun.TextDocument` of the modes.
    - ``/stabilization/<class>/order_<n>``: the poles of a stabilization diagram as points (their
      model order) on the frequency timeline, one series per order and stability class
      (new, stable f, stable f+ζ, stable f+ζ+MAC).
    - ``/frf/magnitude_db/synthesized/<output>``, ``/frf/phase_deg/synthesized/<output>``: the
      modal model's synthesized FRFs beside the measured ones.
    - ``/about``: what the timelines mean and the settings.

    Parameters
    ----------
    signals : Signals, optional
    psd : Spectrum, optional
        When None and `csd` is given, the diagonal of `csd` is logged.
    csd : CrossSpectralMatrix, optional
    frf : FRF, optional
    modal : ModalModel, optional
        Anything with ``natural_frequencies`` (Hz), ``damping_ratios``, ``shapes``
        (complex, (n_modes, n_points)), ``points``, ``method``.
    coords : mapping, optional
        Sensor positions and directions (see
        :func:`vibroscope.viewers._common.sensor_geometry`); points on a line when None.
    rrd_path : str or Path, optional
        Write the recording (and its blueprint) to this ``.rrd`` file.
    spawn : bool, optional
        Once the recording is complete, open it in the rerun viewer (:func:`open_in_viewer`: the
        program rerun-sdk installs; a viewer already running takes it); without `rrd_path` the
        file is written to a folder of its own in the system's temporary folder for the viewer.
        When no viewer can open (no display, no program), a one-line warning says why. A
        command writing `rrd_path` under a temporary name calls :func:`open_in_viewer` itself
        once the file has its final name.
    application_id : str, optional
    recording_name : str, optional
        Shown in the viewer as the recording's name.
    frames : int, optional
        Animation frames per mode cycle.
    recording_id : str, optional
        Fixed recording id (a random one when None).
    stabilization : Stabilization, optional
        Poles of SSI-COV or LSCF (``order``, ``frequency`` Hz, ``stable`` 0–3).
    synthesized : FRF, optional
        The modal model's FRFs (logged beside `frf`).
    kinematics : (Signals, Signals), optional
        Velocity and displacement integrated from the accelerations
        (:func:`vibroscope.spectral.integration.integrate`), logged under ``/velocity/<channel>``
        and ``/displacement/<channel>`` on the ``time`` timeline, in a tab of their own.
    max_points : int or None, optional
        Most points logged per time-series channel (default :data:`MAX_POINTS`, 100 000): a
        longer channel is logged as its min/max envelope over ``max_points // 2`` bins; None logs
        every sample.
    singular_values : SingularValues, optional
        The singular values of `csd` already computed (:func:`vibroscope.modal.fdd.singular_values`,
        ``Analysis.singular_values``), logged instead of computing them again; used only when its
        frequencies are those of `csd`.

    Returns
    -------
    Path or None
        `rrd_path` once written and closed, None when only shown in a viewer.

    Raises
    ------
    ValueError
        If neither `rrd_path` nor `spawn` is given.

    Notes
    -----
    Frequency axis: rerun 0.41 plots scalars only against a timeline, and a timeline holds
    integers (sequence) or times (duration/timestamp). Spectra therefore go on the sequence
    timeline ``frequency_mHz`` whose index is ``round(1000 f)``: a linear frequency axis whose
    numbers read as millihertz (``frequency_uHz`` when bins are finer than 1 mHz). A duration
    timeline in "seconds = Hz" was not used because the viewer labels durations as times
    (seconds, minutes), not as plain numbers. The viewer shows one timeline at a time; the tabs say which.

    The recording is an explicit :class:`rerun.RecordingStream` (never the global one); the
    blueprint is sent as its default blueprint; the stream is flushed (:func:`flush_recording`,
    in short interruptible steps) and disconnected before returning, so the ``.rrd`` file is
    complete (it carries rerun's footer/manifest).

    Examples
    --------
    >>> log_analysis(signals=sig, psd=psd, modal=mm, rrd_path="run.rrd")  # doctest: +SKIP
    >>> read_rrd("run.rrd")["/psd/imu/wrist.linear_acceleration.z"]["Scalars:scalars"]  # doctest: +SKIP
    """
    if rrd_path is None and not spawn:
        raise ValueError("log_analysis needs rrd_path or spawn=True")
    if psd is None and csd is not None:
        psd = csd.psd()
    ftl, fidx = _frequency_timeline(psd, frf, csd, synthesized)
    positions = None
    if modal is not None and len(np.atleast_1d(modal.natural_frequencies)):
        positions = sensor_geometry(list(modal.points), coords)[0]
    bp = _build_blueprint(signals=signals, spec_entities=psd is not None, frf_present=frf is not None,
                          csd_present=csd is not None, modal=modal, ftl=ftl or "frequency_mHz",
                          f_range=None if fidx is None else (fidx[0], fidx[-1]), positions=positions,
                          stabilization_present=stabilization is not None and len(stabilization.frequency) > 0,
                          kinematics=kinematics)
    if spawn and rrd_path is None:  # the viewer opens a file: one of its own in the system's temporary folder
        import tempfile

        rrd_path = Path(tempfile.mkdtemp(prefix="vibroscope-view-")) / f"{recording_name or application_id}.rrd"
        shown_only = True
    else:
        shown_only = False
    rec, path = _open_recording(application_id, recording_id, recording_name, rrd_path, bp)
    try:
        _log_about(rec, signals=signals, psd=psd, frf=frf, ftl=ftl, max_points=max_points)
        if signals is not None:
            _log_time_series(rec, "signals", signals, max_points)
        for ks in kinematics or ():
            _log_time_series(rec, "velocity" if ks is kinematics[0] else "displacement", ks, max_points)
        if psd is not None:
            log_psd(rec, psd)
        if csd is not None:
            _log_singular_values(rec, csd, singular_values)
        if frf is not None:
            log_frf(rec, frf)
        if synthesized is not None:
            log_frf(rec, synthesized, prefix="synthesized/", coherence=False)
        if stabilization is not None and ftl is not None:
            _log_stabilization(rec, stabilization, ftl)
        if modal is not None:
            _log_modes(rec, modal, coords, frames)
        flush_recording(rec)
    finally:
        rec.disconnect()
    if spawn:
        show_recording(path)
    return None if shown_only else path


def show_recording(path: str | Path) -> bool:
    """:func:`open_in_viewer`, with a one-line warning ``--spawn: no rerun viewer opened: WHY`` when none opens.

    Parameters
    ----------
    path : str or Path
        The complete recording.

    Returns
    -------
    bool
        Whether a viewer took it.
    """
    why = open_in_viewer(path)
    if why is not None:
        warnings.warn(f"--spawn: no rerun viewer opened: {why}", stacklevel=2)
    return why is None


def viewer_executable() -> str | None:
    """The rerun viewer program: the ``rerun`` that the rerun-sdk package installed beside this
    Python (``bin/`` of its virtual environment), else ``rerun`` on ``PATH``, else the binary inside
    the ``rerun_cli`` package; None when there is none.

    Returns
    -------
    str or None
    """
    import importlib.util
    import os
    import shutil
    import sys

    exe = "rerun.exe" if sys.platform.startswith("win") else "rerun"
    beside = Path(sys.executable).parent / exe
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    found = shutil.which("rerun")
    if found:
        return found
    try:
        spec = importlib.util.find_spec("rerun_cli")
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        inner = Path(spec.origin).parent / exe
        if inner.is_file() and os.access(inner, os.X_OK):
            return str(inner)
    return None


def _listening(port: int, timeout: float = 0.2) -> bool:
    import socket

    try:
        with socket.create_connection(("127.0.0.1", port), timeout=timeout):
            return True
    except OSError:
        return False


def open_in_viewer(path: str | Path, *, port: int | None = None, settle_s: float = 1.5,
                   executable: str | None = None) -> str | None:
    """Open a finished ``.rrd`` file in the rerun viewer that rerun-sdk ships; None, or one line saying why not.

    The viewer program (:func:`viewer_executable`) is started detached (its own session: Ctrl-C
    on the command does not close it) as ``rerun PATH``; rerun itself hands the file to a viewer
    already listening on its port, else opens a window. This process never streams to the viewer,
    so nothing here can wait on it (:func:`rerun.spawn` looks on ``PATH`` only, is ignored without
    a global recording, and a gRPC flush to a viewer that never answers waits for ever, deaf to
    Ctrl-C). The viewer is judged after `settle_s`: still running, or ended with status 0 (handed
    over), is success; a viewer that cannot open its window ends at once with an error, whose
    last line is the reason. On Linux with no ``DISPLAY``/``WAYLAND_DISPLAY``/``WAYLAND_SOCKET``
    and no viewer listening, nothing is started.

    Parameters
    ----------
    path : str or Path
        The recording (complete: written and closed).
    port : int, optional
        The port a running viewer listens on; default :data:`VIEWER_PORT` (9876, rerun's), read
        at call time.
    settle_s : float, optional
        How long (s) to watch the started viewer; default 1.5.
    executable : str, optional
        The viewer program; default :func:`viewer_executable`.

    Returns
    -------
    str or None
        None when the viewer took the file, else the reason, one line.
    """
    import os
    import subprocess
    import sys
    import tempfile
    import time

    port = VIEWER_PORT if port is None else int(port)
    running = _listening(port)
    if not running and sys.platform.startswith("linux") and not any(
            os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        return "no display (DISPLAY and WAYLAND_DISPLAY are not set), so no viewer window can open"
    exe = executable or viewer_executable()
    if exe is None:
        return "no rerun viewer program found (pip install rerun-sdk installs one beside Python)"
    log = tempfile.TemporaryFile()  # unlinked at once: the viewer's start-up errors, no file left behind
    try:
        proc = subprocess.Popen([exe, "--port", str(port), str(path)], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
                                env={**os.environ, "RERUN_APP_ONLY": "true"})
    except OSError as exc:
        log.close()
        return f"cannot start {exe}: {exc.strerror or exc}"
    try:
        end = time.monotonic() + settle_s
        while proc.poll() is None and time.monotonic() < end:
            time.sleep(0.05)
        if proc.returncode is None or proc.returncode == 0:
            return None
        log.seek(0)
        text = [_strip_ansi(ln) for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        errs = [ln for ln in text if "error" in ln.lower()] or text
        return f"{exe} ended at start (status {proc.returncode})" + (
            f": {' '.join(errs[-1].split())[:300]}" if errs else "")
    finally:
        log.close()


def _strip_ansi(text: str) -> str:
    import re

    return re.sub(r"\x1b\[[0-9;]*m", "", text)


def flush_recording(rec, *, step_s: float = 0.25) -> None:
    """Flush a recording in short waits, so that Ctrl-C and SIGTERM are never held by the flush.

    :meth:`rerun.RecordingStream.flush` waits without a timeout by default, inside rerun's native
    code where Python's signal handlers cannot run; here each wait is at most `step_s`, repeated
    until the flush is complete.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    step_s : float, optional
        Longest single wait (s); default 0.25.
    """
    while True:
        try:
            rec.flush(timeout_sec=step_s)
            return
        except RuntimeError:  # "Flush timed out - not all log messages were sent": wait on
            continue


def _frequency_timeline(*results) -> tuple[str | None, np.ndarray | None]:
    """The frequency timeline (name, index) of the first of `results` that is given."""
    for src in results:
        if src is not None:
            return frequency_index(src.frequencies)
    return None, None


def _open_recording(application_id: str, recording_id: str | None, recording_name: str | None,
                    rrd_path: str | Path, blueprint):
    """(an explicit :class:`rerun.RecordingStream` saving to `rrd_path` with its default blueprint,
    the ``.rrd`` path)."""
    import rerun as rr

    rec = rr.RecordingStream(application_id, recording_id=recording_id)
    if recording_name:
        rec.send_recording_name(recording_name)
    path = Path(rrd_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path), default_blueprint=blueprint)
    return rec, path


def envelope_indices(x: np.ndarray, max_points: int | None = MAX_POINTS) -> np.ndarray:
    """Indices of the samples kept to draw `x` with at most `max_points` points: a min/max envelope.

    With ``n <= max_points`` finite samples, every finite sample is kept. Otherwise the record is
    cut into ``B = max_points // 2`` consecutive bins of ``w = ceil(n / B)`` samples and, in each
    bin, the sample of the smallest and the sample of the largest finite value are kept, in time
    order (one index when they coincide; none in a bin with no finite sample). Every kept point
    is a true sample at its true time, so each bin's extremes, and hence every peak and the
    record's minimum and maximum, are drawn exactly; only the path between extremes within a bin
    (``w`` samples, one pixel-like column of the plot) is left out. Missing samples (NaN, ±Inf)
    are never kept and never interpolated.

    Parameters
    ----------
    x : array_like, shape (n,)
        One channel.
    max_points : int or None, optional
        Most points kept (default :data:`MAX_POINTS`, 100 000); None keeps every finite sample.

    Returns
    -------
    ndarray of int64, shape (n_kept,)
        Ascending sample indices, ``n_kept <= max_points``.

    Raises
    ------
    ValueError
        If `max_points` is less than 2.
    """
    x = np.asarray(x, dtype=np.float64)
    present = np.isfinite(x)
    n = x.size
    if max_points is not None and max_points < 2:
        raise ValueError(f"{max_points=} must be at least 2 (a min and a max per bin), or None for every sample")
    if max_points is None or n <= max_points:
        return np.flatnonzero(present)
    n_bins = max_points // 2
    w = -(-n // n_bins)  # ceil
    n_bins = -(-n // w)
    clean = bool(present.all())
    if clean and n == n_bins * w:
        lo_src = hi_src = x
    else:  # missing samples never win; the last, partial bin padded with values that never win
        lo_src = np.full(n_bins * w, np.inf)
        hi_src = np.full(n_bins * w, -np.inf)
        lo_src[:n] = x if clean else np.where(present, x, np.inf)
        hi_src[:n] = x if clean else np.where(present, x, -np.inf)
    lo = lo_src.reshape(n_bins, w).argmin(axis=1)
    hi = hi_src.reshape(n_bins, w).argmax(axis=1)
    base = np.arange(n_bins, dtype=np.int64) * w
    idx = np.stack([base + np.minimum(lo, hi), base + np.maximum(lo, hi)], axis=1)
    if not clean:  # a bin with no finite sample keeps nothing (its argmin points at a missing sample)
        idx = idx[present[idx[:, 0]]]
    idx = idx.ravel()
    return idx[np.concatenate(([True], np.diff(idx) != 0))]  # one index where min and max coincide


def _log_time_series(rec, prefix: str, sig, max_points: int | None = None) -> None:
    """Every channel of `sig` under ``/<prefix>/<channel>`` on the ``time`` timeline (exact float64).

    A channel longer than `max_points` samples is logged as its min/max envelope
    (:func:`envelope_indices`): true samples at their true times, at most `max_points` of them;
    None logs every sample. One :meth:`~rerun.RecordingStream.send_columns` per channel.

    Missing samples (NaN, ±Inf) are not sent: the series is broken at each gap by a
    :class:`rerun.Clear` at the gap's first missing sample (scalar plots draw a clear as a hole,
    never a line across the gap), and each gap is a ``WARN`` entry of the :class:`rerun.TextLog`
    ``/<prefix>/gaps`` at its start time: ``"gap (no data) in <channel>: <start>–<stop> s
    (<n> samples)"``.
    """
    import rerun as rr

    for k, ch in enumerate(sig.channels):
        ent = channel_entity(prefix, ch)
        x = np.asarray(sig.data[k], dtype=np.float64)
        rec.log(ent, rr.SeriesLines(names=f"{ch} [{sig.units[k] or '-'}]"), static=True)
        keep = envelope_indices(x, max_points)
        t_ns = np.round(keep / sig.fs * 1e9).astype(np.int64).astype("timedelta64[ns]")  # rounded, not truncated
        rec.send_columns(ent, indexes=[rr.TimeColumn("time", duration=t_ns)],
                         columns=rr.Scalars.columns(scalars=x[keep]))
        if keep.size == x.size:
            continue
        present = np.isfinite(x)
        if present.all():
            continue
        starts, stops = true_runs(~present)
        log_ent = channel_entity(prefix, "gaps")
        for a, b in zip(starts, stops):
            rec.set_time("time", duration=np.timedelta64(int(np.round(a / sig.fs * 1e9)), "ns"))
            rec.log(ent, rr.Clear(recursive=False))
            rec.log(log_ent, rr.TextLog(f"gap (no data) in {ch}: {a / sig.fs:.6g}–{b / sig.fs:.6g} s ({b - a} samples)",
                                        level="WARN"))
        rec.reset_time()


def log_psd(rec, psd) -> None:
    """``/psd/<channel>`` in dB (20 log10 for an amplitude spectrum) on the frequency timeline."""
    import rerun as rr

    ftl, fidx = frequency_index(psd.frequencies)
    fac = 20.0 if psd.scaling == "amplitude" else 10.0
    for k, ch in enumerate(psd.channels):
        ent = channel_entity("psd", ch)
        rec.log(ent, rr.SeriesLines(names=f"{ch} [dB re 1 {psd.units[k] or 'unit'}]"), static=True)
        rec.send_columns(ent, indexes=[rr.TimeColumn(ftl, sequence=fidx)],
                         columns=rr.Scalars.columns(scalars=decibels(psd.values[k], fac)))


def _log_about(rec, *, signals, psd, frf, ftl, max_points=None) -> None:
    import rerun as rr

    lines = ["# vibroscope analysis", "",
             "Timelines (the viewer shows one at a time; each tab names the one its views need):", "",
             "- `time` — time series, seconds since the first sample"
             + (f" (t0 = {signals.t0:.9g} s)" if signals is not None else "") + ";",
             f"- `{ftl or 'frequency_mHz'}` — spectra and FRF; the index is the frequency in "
             + ("µHz (1 000 000 = 1 Hz)" if ftl == "frequency_uHz" else "millihertz (1000 = 1 Hz)")
             + "; power quantities in dB;",
             "- `animation` — mode shape frames, one cycle per mode.", ""]
    if signals is not None and max_points is not None and signals.n_samples > max_points:
        lines += [f"Time series decimated for display: {signals.n_samples} samples per channel shown as their "
                  f"min/max envelope over {max_points // 2} bins (true samples at their true times, every peak "
                  f"kept); the spectra use every sample.", ""]
    if psd is not None:
        lines.append(f"PSD settings: `{dict(psd.settings)}` (scaling: {psd.scaling})")
    if frf is not None:
        lines.append(f"FRF: estimator {frf.estimator}, kind {frf.kind}, units {frf.units or '-'}")
    rec.log("about", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)


def _log_singular_values(rec, csd, sv=None, n_sv: int = 3) -> None:
    import rerun as rr

    ftl, fidx = frequency_index(csd.frequencies)
    if sv is not None and np.array_equal(np.asarray(sv[0]), np.asarray(csd.frequencies)):
        S = np.asarray(sv[1])  # the analysis' own (descending, (n_freqs, n))
    else:
        S = np.linalg.svd(np.asarray(csd.G), compute_uv=False)  # descending, (n_freqs, n)
    for k in range(min(n_sv, S.shape[1])):
        ent = f"/csd/singular_values/s{k + 1}"
        rec.log(ent, rr.SeriesLines(names=f"s{k + 1} [dB]"), static=True)
        rec.send_columns(ent, indexes=[rr.TimeColumn(ftl, sequence=fidx)],
                         columns=rr.Scalars.columns(scalars=decibels(S[:, k])))


#: (entity name, colour, marker) of the stability classes 0–3 of a stabilization diagram
_STAB_CLASSES = {0: ("new", [150, 150, 150], "cross"), 1: ("stable_f", [255, 127, 14], "circle"),
                 2: ("stable_f_damping", [31, 119, 180], "plus"), 3: ("stable_f_damping_mac", [44, 160, 44], "circle")}


def _log_stabilization(rec, st, ftl: str) -> None:
    import rerun as rr

    fac = 1e6 if ftl == "frequency_uHz" else 1e3
    for code, (name, colour, marker) in _STAB_CLASSES.items():
        for order in np.unique(st.order):
            m = (st.stable == code) & (st.order == order)
            if not m.any():
                continue
            idx = np.round(np.asarray(st.frequency[m]) * fac).astype(np.int64)
            idx, first = np.unique(idx, return_index=True)
            ent = f"/stabilization/{name}/order_{int(order):03d}"
            rec.log(ent, rr.SeriesPoints(colors=colour, markers=marker, marker_sizes=2.0 if code == 3 else 1.5,
                                         names=f"{name.replace('_', ' ')}"), static=True)
            rec.send_columns(ent, indexes=[rr.TimeColumn(ftl, sequence=idx)],
                             columns=rr.Scalars.columns(scalars=np.full(idx.size, float(order))))


def log_frf(rec, frf, prefix: str = "", coherence: bool = True) -> None:
    """The FRF's ``frf/magnitude_db`` and ``frf/phase_deg`` series of each output (entity tag
    ``prefix + output``, with ``in<i>/`` for several inputs), and ``frf/coherence`` of the first
    input, on the frequency timeline.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    frf : FRF
        ``H[f, output, input]``.
    prefix : str, optional
        Prefix of the entity tag and, when given, "synthesized" in the series names.
    coherence : bool, optional
        Also log the coherence (default True).
    """
    import rerun as rr

    ftl, fidx = frequency_index(frf.frequencies)
    H = np.asarray(frf.H)
    coh = np.asarray(frf.coherence)
    n_in = H.shape[2]
    for i in range(n_in):
        for o, out in enumerate(frf.outputs):
            tag = prefix + (out if n_in == 1 else f"in{i}/{out}")
            h = H[:, o, i]
            for what, vals, name in (
                    ("frf/magnitude_db", decibels(np.abs(h), 20.0),
                     f"{'synthesized ' if prefix else ''}|H| {out} / {frf.inputs[i]} [dB re 1 {frf.units or 'unit'}]"),
                    ("frf/phase_deg", np.degrees(np.angle(h)),
                     f"{'synthesized ' if prefix else ''}∠H {out} / {frf.inputs[i]} [deg]")):
                ent = channel_entity(what, tag)
                rec.log(ent, rr.SeriesLines(names=name), static=True)
                rec.send_columns(ent, indexes=[rr.TimeColumn(ftl, sequence=fidx)],
                                 columns=rr.Scalars.columns(scalars=vals))
            if coherence and i == 0 and coh.ndim == 2 and coh.shape[1] > o:
                ent = channel_entity("frf/coherence", out)
                rec.log(ent, rr.SeriesLines(names=f"γ² {out}"), static=True)
                rec.send_columns(ent, indexes=[rr.TimeColumn(ftl, sequence=fidx)],
                                 columns=rr.Scalars.columns(scalars=coh[:, o].astype(np.float64)))


def _structure_scale(positions: np.ndarray) -> float:
    ext = float(np.max(np.ptp(positions, axis=0))) if len(positions) > 1 else 0.0
    return 0.15 * ext if ext > 0 else 0.2


def _log_modes(rec, modal, coords, frames: int) -> None:
    import rerun as rr

    fn = np.atleast_1d(np.asarray(modal.natural_frequencies, dtype=float))
    zeta = np.atleast_1d(np.asarray(modal.damping_ratios, dtype=float))
    shapes = np.atleast_2d(np.asarray(modal.shapes, dtype=complex))
    points = list(modal.points)
    pos, dirs, _ = sensor_geometry(points, coords)
    scale = _structure_scale(pos)
    ext = scale / 0.15  # the structure's size (m), for radii
    node_pos, members = _nodes(pos)
    labels = [p.split(".")[0].split("/")[-1] or p for p in points]  # the topic's last name: "m1", "s01"
    rec.log("modes/table", rr.TextDocument(_mode_table(modal), media_type=rr.MediaType.MARKDOWN), static=True)
    n = len(points)
    frame_idx = np.arange(frames)
    grey = [150, 150, 150]
    for r in range(fn.size):
        ent = mode_entity(r, fn[r])
        rec.log(ent + "/undeformed", rr.Points3D(pos, radii=0.01 * ext, colors=grey,
                                                 labels=labels if n <= 8 else None),
                rr.LineStrips3D([node_pos], colors=grey, radii=0.004 * ext), static=True)
        rec.log(ent, rr.TextDocument(f"Mode {r + 1}: {mode_label(fn[r], zeta[r])}; "
                                     f"largest displacement drawn {scale:.3g} m"), static=True)
        X = mode_frames(shapes[r], pos, dirs, scale, frames)  # (frames, n, 3)
        strips = node_frames(X, pos, node_pos, members)  # (frames, n_nodes, 3)
        colour = np.array([220, 80, 40], dtype=np.uint8)
        rec.send_columns(
            ent,
            indexes=[rr.TimeColumn("animation", sequence=frame_idx)],
            columns=[
                *rr.Points3D.columns(positions=X.reshape(-1, 3), colors=np.tile(colour, (frames * n, 1)),
                                     radii=np.full(frames * n, 0.015 * ext, dtype=np.float32)
                                     ).partition(lengths=np.full(frames, n)),
                *rr.LineStrips3D.columns(strips=list(strips)),
            ],
        )


def _nodes(pos: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Distinct sensor locations along the structure's longest extent, and the sensors at each."""
    if len(pos) == 0:
        return pos.reshape(0, 3), []
    axis = int(np.argmax(np.ptp(pos, axis=0)))
    keys = [tuple(np.round(p, 6)) for p in pos]
    uniq = list(dict.fromkeys(keys))
    node_pos = np.array(uniq, dtype=float)
    members = [np.array([k for k, kk in enumerate(keys) if kk == u]) for u in uniq]
    order = np.argsort(node_pos[:, axis], kind="stable")
    return node_pos[order], [members[i] for i in order]


def node_frames(X: np.ndarray, positions: np.ndarray, node_pos: np.ndarray, members: list) -> np.ndarray:
    """Deformed locations: each node moved by the sum of its sensors' displacements.

    Sensors at one location measuring along different axes (a tower's two horizontal axes)
    together give that location's displacement vector; the line strip of the deformed
    structure joins these.

    Parameters
    ----------
    X : ndarray, shape (frames, n_points, 3)
        Displaced sensor positions (:func:`mode_frames`).
    positions : ndarray, shape (n_points, 3)
        Undeformed sensor positions.
    node_pos : ndarray, shape (n_nodes, 3)
        Distinct locations, in strip order.
    members : list of ndarray
        Indices of the sensors at each location.

    Returns
    -------
    ndarray, shape (frames, n_nodes, 3)
    """
    D = X - positions[None]
    return np.stack([node_pos[j][None, :] + D[:, m, :].sum(axis=1) for j, m in enumerate(members)], axis=1)


def read_rrd(path: str | Path, *, blueprint: bool = False) -> dict[str, dict[str, Any]]:
    """Read a recording back with rerun's own reader (:class:`rerun.chunk.RrdReader`).

    Parameters
    ----------
    path : str or Path
        An ``.rrd`` file.
    blueprint : bool, optional
        Read the (first) blueprint store of the file instead of the recording.

    Returns
    -------
    dict
        ``{entity_path: {column: values}}``, entity paths as rerun writes them
        (``"/signals/acc/s1.z"``). Columns are named as rerun names them: timelines by their
        name (int64 values: ns for durations, the index for sequences) and components as
        ``"Archetype:field"`` (``"Scalars:scalars"``, ``"Points3D:positions"``). Rows of the
        temporal chunks of an entity are concatenated in file order; a component with one
        value per row becomes a 1-D (or (n, k)) array, otherwise a list with one array per row.
        Static data are under the key ``"static"`` as ``{component: value of its last row}``.

    Raises
    ------
    ValueError
        If the file holds no such store.
    """
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    store = None
    if blueprint:
        bps = reader.blueprints()
        if not bps:
            raise ValueError(f"{path}: no blueprint store")
        store = bps[0]
    parts: dict[str, dict[str, list]] = {}
    out: dict[str, dict[str, Any]] = {}
    for chunk in reader.stream(store=store):
        ent = chunk.entity_path
        rb = chunk.to_record_batch()
        d = out.setdefault(ent, {})
        for name, col in zip(rb.schema.names, rb.columns):
            if name == "rerun.controls.RowId":
                continue
            vals = _rows(col)
            if chunk.is_static:
                d.setdefault("static", {})[name] = vals[-1] if len(vals) else None
            else:
                parts.setdefault(ent, {}).setdefault(name, []).extend(vals)
    for ent, cols in parts.items():
        for name, rows in cols.items():
            out[ent][name] = _stack(rows)
    return out


def _rows(col) -> list:
    """One value per row of an arrow column: numpy arrays for lists (fixed-size lists reshaped to
    (n, k)), int64 for durations and timestamps (ns), str for strings."""
    import pyarrow as pa

    if pa.types.is_duration(col.type) or pa.types.is_timestamp(col.type):
        return list(np.asarray(col.cast(pa.int64()).to_numpy(zero_copy_only=False)))
    return list(_flat(col))


def _flat(arr):
    import pyarrow as pa

    t = arr.type
    if pa.types.is_fixed_size_list(t):
        return np.asarray(_flat(arr.flatten())).reshape(len(arr), t.list_size)
    if pa.types.is_list(t) or pa.types.is_large_list(t):
        offsets = np.asarray(arr.offsets.to_numpy(zero_copy_only=False), dtype=np.int64)
        inner = _flat(arr.values)
        valid = arr.is_valid().to_numpy(zero_copy_only=False)
        return [inner[offsets[k]:offsets[k + 1]] if valid[k] else None for k in range(len(arr))]
    if pa.types.is_primitive(t):
        return arr.to_numpy(zero_copy_only=False)
    return arr.to_pylist()


def _stack(rows: list):
    if rows and all(r is not None and not isinstance(r, str) and np.ndim(r) >= 1 and len(r) == 1 for r in rows):
        if all(isinstance(r, np.ndarray) for r in rows):
            return np.concatenate(rows)
        return [r[0] for r in rows]
    if rows and all(np.ndim(r) == 0 for r in rows):
        return np.asarray(rows)
    return rows
