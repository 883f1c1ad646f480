"""The outputs of one analysed log: the summary JSON, the rerun recording and the PNG figures,
written atomically."""

from __future__ import annotations

import contextlib
import functools
import json
import shlex
from pathlib import Path

import numpy as np

__all__ = ["write_outputs"]


def write_outputs(an, log: Path, *, coords=None, json_path=None, rrd=None, figures=None, spawn=False,
                  true_modes=None, ods=None, ahead=None, server=None) -> dict:
    """Write the summary JSON, the rerun recording and the figures of an analysis, atomically.

    With `ods` (frequencies in Hz) the operating deflection shapes at those frequencies (from the
    FRFs with an input, the CSD without) are drawn and animated after the modes. Every output is
    written under a temporary name beside its final path and moved into place when all are
    complete (:class:`vibroscope.commands._outputs.AtomicOutputs`): an exception or Ctrl-C
    leaves earlier outputs untouched and no temporary behind. Replacing an earlier output
    prints ``replacing <path> (earlier output)``.

    Parameters
    ----------
    an : Analysis
        The analysis (:func:`vibroscope.pipeline.analyse_signals`), or a streamed one
        (:func:`vibroscope.stream.analyse_stream`: no time series, so no ``signals.png``,
        ``kinematics.png`` or ``/signals`` entities); its `json_path` summary is
        :func:`vibroscope.pipeline.summary_dict`.
    log : Path
        The analysed log (named in the summary and the recording; never written).
    coords : Path, optional
        Sensor coordinates CSV (:func:`vibroscope.io.coords.read_coords`); default a line.
    json_path : Path, optional
        The summary JSON to write.
    rrd : Path, optional
        The rerun recording to write.
    figures : Path, optional
        The PNG figures folder to write.
    spawn : bool, optional
        Also open a rerun viewer; default False.
    true_modes : ModalModel, optional
        Reference modes, written beside the identified ones.
    ods : sequence of float, optional
        Operating deflection shape frequencies in Hz.
    ahead : TimeSeriesAhead, optional
        The integrals and time-series figures made while the modes were identified
        (:class:`vibroscope.viewers.ahead.TimeSeriesAhead`), taken instead of computing them again.
    server : multiprocessing context, optional
        A running drawing server (:func:`vibroscope.viewers.drawing_server.context`): the figure
        workers are forked from it (:class:`vibroscope.viewers.figures.PendingFigures`), and so is
        the one that writes the recording (unless `spawn`), so that this process imports neither
        matplotlib nor rerun.

    Returns
    -------
    dict
        ``"json"``, ``"figures"`` (list of PNG paths), ``"rrd"``: the final paths written.

    Raises
    ------
    VibroscopeError
        When an output is the log or the coordinates file.
    """
    from vibroscope.commands._outputs import AtomicOutputs, check_outputs, preloaded
    from vibroscope.provenance import json_report
    from vibroscope.io.coords import line_coords, read_coords
    from vibroscope.pipeline import summary_dict

    check_outputs({"--json": json_path, "--rrd": rrd, "--figures": figures}, {"log": log, "coordinates": coords})
    outs = an.settings["outputs"]
    sc = read_coords(coords, outs) if coords else line_coords(outs)
    written = {}
    ident = getattr(an, "identification", None)
    stab = ident.stabilization if ident is not None else None
    synth = ident.lsfd.synthesize() if ident is not None and ident.lsfd is not None and an.frf is not None else None
    sig = an.signals  # None: a streamed analysis holds the spectra only
    acc = [] if sig is None else [c for c, u in zip(sig.channels, sig.units) if c in outs and u in ("m/s^2", "m/s²")]
    ods_shapes = []
    if ods:
        from vibroscope.spectral.integration import ods as ods_at

        from vibroscope.errors import VibroscopeError

        for f in ods:
            try:
                o = ods_at(an.frf if an.frf is not None else an.csd, f)
            except ValueError as exc:
                raise VibroscopeError(f"--ods {f:g}: {exc}") from None
            ods_shapes.append(o)
            print(f"ODS at {o.frequency:.4g} Hz: " + ", ".join(f"{p}: {abs(v):.3f}∠{np.degrees(np.angle(v)):.0f}°"
                                                              for p, v in list(zip(o.points, o.shape))[:6]))
    done = []
    preloaded()  # the libraries imported in the background (run): done before the figure workers fork
    with AtomicOutputs(inputs=[log, coords]) as tx:
        if json_path:
            d = summary_dict(an, source=str(log), true_modes=true_modes)
            tx.file(json_path).write_text(json.dumps(json_report(d), indent=2))
            written["json"] = json_path
            done.append(f"summary: {json_path}")
        kin = None
        early = ahead is not None and sig is not None and ahead.holds(sig, acc)
        if acc and (figures or rrd or spawn) and not early:  # integrated once, for the figure and the recording
            from vibroscope.spectral.integration import velocity_and_displacement

            a = an.signals.select(acc)
            kin = velocity_and_displacement(a)
        pending = None
        if figures:  # drawn in worker processes while the recording is written (PendingFigures)
            from vibroscope.viewers.figures import plot_ods
            from vibroscope.viewers.figures import PendingFigures, figure_jobs

            tmp = tx.directory(figures)
            jobs = figure_jobs(tmp, signals=sig, psd=an.psd, frf=an.frf, modal=an.modal, sv=an.singular_values,
                               coords=sc.as_mapping(), true_modes=true_modes, stabilization=stab, synthesized=synth,
                               kinematics=(an.signals.select(acc), *kin) if kin else None,
                               ahead=ahead if early else None)
            jobs += [(functools.partial(plot_ods, o, sc.as_mapping()), tmp / f"ods_{o.frequency:.4g}Hz.png")
                     for o in ods_shapes]
            pending = PendingFigures(jobs, server=server)
        with pending or contextlib.nullcontext():  # an error or Ctrl-C here stops the figure workers
            if rrd or spawn:
                from vibroscope.modal import ods_as_modal_model, with_operating_shapes as _with_ods
                from vibroscope.viewers.rerun_view import log_analysis

                modal = _with_ods(an.modal, [ods_as_modal_model(o) for o in ods_shapes]) if ods_shapes else an.modal
                if early and acc:
                    kin = ahead.kinematics()
                record = dict(kinematics=kin, signals=sig, psd=an.psd, csd=an.csd, frf=an.frf, modal=modal,
                              coords=sc.as_mapping(), rrd_path=tx.file(rrd) if rrd else None,
                              spawn=spawn and not rrd,  # a recording under its final name is opened below
                              recording_name=Path(log).stem, stabilization=stab, synthesized=synth,
                              singular_values=getattr(an, "singular_values", None))
                if server is not None and rrd and not spawn:  # written by a worker of the drawing server,
                    # where rerun is loaded, beside the figure workers: this process never imports rerun
                    path = _in_worker(server, log_analysis, record)
                else:
                    path = log_analysis(**record)
                written["rrd"] = tx.final(path) if path is not None else None
                if rrd:
                    done.append(f"rerun recording: {rrd}  (open with: rerun {shlex.quote(str(rrd))})")
            if pending is not None:
                from vibroscope.viewers.figures import in_figure_order

                written["figures"] = [tx.final(p) for p in in_figure_order(pending.wait())]
                done.insert(len(done) - bool(rrd), f"figures: {', '.join(str(p) for p in written['figures'])}")
    for line in done:
        print(line)
    if spawn and rrd:
        from vibroscope.viewers.rerun_view import show_recording

        show_recording(rrd)
    return written


def _in_worker(server, func, kwargs: dict):
    """``func(**kwargs)`` run in one worker forked from the drawing server `server` (its arguments
    pickled to it, its result back); the worker is stopped on an error or Ctrl-C."""
    from vibroscope.viewers.figures import server_pool

    workers = server_pool(server, 1)
    try:
        return workers.apply_async(func, (), kwargs).get()
    finally:
        workers.terminate()
        workers.join()
