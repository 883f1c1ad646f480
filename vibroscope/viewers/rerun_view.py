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

Modules
-------
This module composes the recording (:func:`log_analysis`); each concern lives in a module of its
own, whose public names are importable from here too:

- :mod:`vibroscope.viewers.rerun_paths`: entity paths and the frequency timeline;
- :mod:`vibroscope.viewers.rerun_series`: time series and their min/max envelope;
- :mod:`vibroscope.viewers.rerun_spectra`: PSD, singular values, FRF, stabilization diagram;
- :mod:`vibroscope.viewers.rerun_modes`: animated mode shapes and the mode table;
- :mod:`vibroscope.viewers.rerun_blueprint`: the tabs and views;
- :mod:`vibroscope.viewers.rerun_recording`: the recording stream (preload, open, flush);
- :mod:`vibroscope.viewers.rerun_viewer`: opening a finished recording in the viewer program;
- :mod:`vibroscope.viewers.rerun_read`: reading a recording back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from vibroscope.viewers._common import sensor_geometry
from vibroscope.viewers.rerun_blueprint import build_blueprint, whole_time_axis
from vibroscope.viewers.rerun_modes import FRAMES, log_modes, mode_frames, node_frames
from vibroscope.viewers.rerun_paths import channel_entity, frequency_index, frequency_timeline, mode_entity
from vibroscope.viewers.rerun_read import read_rrd
from vibroscope.viewers.rerun_recording import flush_recording, open_recording, preload
from vibroscope.viewers.rerun_series import MAX_POINTS, envelope_indices, log_time_series
from vibroscope.viewers.rerun_spectra import decibels, log_frf, log_psd, log_singular_values, log_stabilization
from vibroscope.viewers.rerun_viewer import VIEWER_PORT, open_in_viewer, show_recording, viewer_executable

__all__ = ["log_analysis", "open_in_viewer", "show_recording", "flush_recording", "viewer_executable", "VIEWER_PORT",
           "read_rrd", "channel_entity", "mode_entity", "frequency_index", "mode_frames", "node_frames",
           "envelope_indices", "MAX_POINTS", "preload", "decibels", "whole_time_axis", "log_psd", "log_frf", "FRAMES"]


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
    ftl, fidx = frequency_timeline(psd, frf, csd, synthesized)
    positions = None
    if modal is not None and len(np.atleast_1d(modal.natural_frequencies)):
        positions = sensor_geometry(list(modal.points), coords)[0]
    bp = build_blueprint(signals=signals, spec_entities=psd is not None, frf_present=frf is not None,
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
    rec, path = open_recording(application_id, recording_id, recording_name, rrd_path, bp)
    try:
        _log_about(rec, signals=signals, psd=psd, frf=frf, ftl=ftl, max_points=max_points)
        if signals is not None:
            log_time_series(rec, "signals", signals, max_points)
        for ks in kinematics or ():
            log_time_series(rec, "velocity" if ks is kinematics[0] else "displacement", ks, max_points)
        if psd is not None:
            log_psd(rec, psd)
        if csd is not None:
            log_singular_values(rec, csd, singular_values)
        if frf is not None:
            log_frf(rec, frf)
        if synthesized is not None:
            log_frf(rec, synthesized, prefix="synthesized/", coherence=False)
        if stabilization is not None and ftl is not None:
            log_stabilization(rec, stabilization, ftl)
        if modal is not None:
            log_modes(rec, modal, coords, frames)
        flush_recording(rec)
    finally:
        rec.disconnect()
    if spawn:
        show_recording(path)
    return None if shown_only else path


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
