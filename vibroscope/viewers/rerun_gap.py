"""Log a sim-to-real gap diagnosis (:class:`vibroscope.gap.report.GapReport`) to one rerun
recording, with a blueprint.

rerun is imported inside the functions: importing this module never imports it. The
conventions are those of :mod:`vibroscope.viewers.rerun_view`: channel names are split on ``/``
into entity path parts (:func:`~vibroscope.viewers.rerun_paths.channel_entity`), time series
go on the ``time`` duration timeline (s since the first sample), spectra and FRFs on the
``frequency_mHz`` sequence timeline whose index is ``round(1000 f)``
(:func:`~vibroscope.viewers.rerun_paths.frequency_index`; ``frequency_uHz`` when bins are finer
than 1 mHz), power quantities and |H| in dB since the time series view has no log axis.

Entities
--------
``/signals/<channel>/{measured,nominal,refit,augmented}``
    Output traces (``time``), :class:`rerun.Scalars` float64, one ``send_columns`` each.
``/input``, ``/validation``
    The (first) input in N, and the held-out mask (1 on validation samples, 0 on fitting ones).
``/psd/<channel>/{measured,residual_before,residual_refit,residual_after,noise}``
    ``10 log10`` of the PSDs (NaN where 0); ``/psd/bands``: a markdown table of the bands.
``/frf/{magnitude_db,phase_deg}/<channel>/{measured,nominal,augmented}``, ``/frf/coherence/<channel>``
    ``20 log10 |H|``, phase in degrees, coherence γ² of the measured H1.
``/candidates/gap_after``
    :class:`rerun.BarChart` of every candidate's held-out gap, in report order (best first);
    ``/candidates/verdict`` the same length, zero but for the verdict's bar (drawn over it in
    green); ``/candidates/table`` a markdown table naming the bars; ``/gaps`` a bar chart of
    the nominal, refit and augmented gaps and the noise floor.
``/summary``
    :meth:`GapReport.summary` as a plain :class:`rerun.TextDocument`; ``/about`` the timelines
    and the report's settings (markdown).
"""

from __future__ import annotations

from pathlib import Path
import numpy as np

from vibroscope.viewers.gap_figures import candidate_label, held_out_spans, verdict_index
from vibroscope.viewers.rerun_blueprint import whole_time_axis
from vibroscope.viewers.rerun_paths import channel_entity, frequency_index
from vibroscope.viewers.rerun_recording import flush_recording
from vibroscope.viewers.rerun_spectra import decibels
from vibroscope.viewers.rerun_viewer import show_recording

__all__ = ["log_gap_report", "TRACES", "SPECTRA", "FRF_CURVES", "GAP_BARS"]

#: the output traces logged per channel, with their colours (dark viewer background)
TRACES = {"measured": (225, 225, 225), "nominal": (214, 39, 40), "refit": (255, 127, 14),
          "augmented": (44, 160, 44)}
#: the PSD curves logged per channel
SPECTRA = {"measured": (225, 225, 225), "residual_before": (214, 39, 40), "residual_refit": (255, 127, 14),
           "residual_after": (44, 160, 44), "noise": (140, 140, 140)}
#: the FRF curves logged per output
FRF_CURVES = {"measured": (225, 225, 225), "nominal": (214, 39, 40), "augmented": (44, 160, 44)}
#: the bars of ``/gaps``, in order
GAP_BARS = ("nominal", "refit", "augmented", "noise_floor")

_BAR = (155, 180, 204)
_VERDICT = (44, 160, 44)


def _channels(report, n: int) -> list[str]:
    if report.traces is not None and len(report.traces.channels) == n:
        return [str(c) for c in report.traces.channels]
    if len(report.channels) == n:
        return [c.channel for c in report.channels]
    return [f"output_{k + 1}" for k in range(n)]


def _units(report, n: int) -> list[str]:
    if report.traces is not None and len(report.traces.units) == n:
        return [str(u) for u in report.traces.units]
    return [""] * n


def _f64(v) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    return np.where(np.isfinite(a), a, np.nan)


def _num(x) -> str:
    return f"{float(x):.4f}" if x is not None and np.isfinite(float(x)) else "n/a"


def _series(rec, ent: str, name: str, color, index, values) -> None:
    import rerun as rr

    rec.log(ent, rr.SeriesLines(names=name, colors=[color]), static=True)
    rec.send_columns(ent, indexes=[index], columns=rr.Scalars.columns(scalars=_f64(values)))


def _candidate_table(report) -> str:
    vi = verdict_index(report)
    lines = [f"# Candidates (verdict: **{report.verdict}**)", "",
             f"Held-out gap ({report.metric}, {report.validation}): nominal {_num(report.gap_before)}, "
             f"refit {_num(report.gap_refit)}, augmented {_num(report.gap_after)}, "
             f"noise floor {_num(report.noise_floor)}.", "",
             "Bar *k* of `/candidates/gap_after` is row *k* below (best first).", "",
             "| bar | effect @ where | gap_after | score | gap_fit | parameters |",
             "|---|---|---|---|---|---|"]
    for k, c in enumerate(report.candidates):
        par = ", ".join(f"{p}={float(v):.4g}" for p, v in c.parameters.items())
        name = candidate_label(c).replace("|", "/")
        if k == vi:
            name = f"**{name}** (verdict)"
        lines.append(f"| {k} | {name} | {_num(c.gap_after)} | {float(c.score):+.3f} | {_num(c.gap_fit)} | {par} |")
    return "\n".join(lines)


def _band_table(report) -> str:
    lines = ["# Gap bands", "", "Share of the nominal model's residual energy.", "",
             "| band | f_lo [Hz] | f_hi [Hz] | share [%] |", "|---|---|---|---|"]
    for k, b in enumerate(report.bands):
        lines.append(f"| {k + 1} | {b.fmin:.3f} | {b.fmax:.3f} | {100 * b.share:.1f} |")
    if not report.bands:
        lines.append("| - | - | - | - |")
    return "\n".join(lines)


def _about(report, ftl_s, ftl_f) -> str:
    tr = report.traces
    lines = ["# vibroscope gap diagnosis", "",
             f"Model `{report.model_name or '-'}`, verdict **{report.verdict}**; validation: {report.validation}; "
             f"noise floor from {report.noise_floor_method or '-'}.", "",
             "Timelines (the viewer shows one at a time; each tab names the one its views need):", "",
             "- `time` — output traces, input and held-out mask, s since the first sample"
             + (f" (t0 = {tr.t0:.9g} s, log `{tr.log or '-'}`)" if tr is not None else "") + ";"]
    for name, what in ((ftl_s, "gap spectra (PSDs in dB)"), (ftl_f, "FRFs (|H| in dB, phase in deg)")):
        if name:
            unit = "µHz (1 000 000 = 1 Hz)" if name == "frequency_uHz" else "millihertz (1000 = 1 Hz)"
            lines.append(f"- `{name}` — {what}; the index is the frequency in {unit};")
    if tr is not None:
        spans = held_out_spans(tr.validation)
        txt = ", ".join(f"{a / tr.fs:.3f}–{b / tr.fs:.3f} s" for a, b in spans[:8])
        lines += ["", f"Held-out spans: {txt or 'none'}" + (f" (+{len(spans) - 8} more)" if len(spans) > 8 else "")]
    if report.meta:
        lines += ["", f"Settings: `{dict(report.meta)}`"]
    if report.timings:
        lines += ["", "Timings [s]: " + ", ".join(f"{k} {float(v):.3g}" for k, v in report.timings.items())]
    return "\n".join(lines)


def _blueprint(report, *, chans, units, ftl_s, fr_s, ftl_f, fr_f):
    import rerun.blueprint as rrb

    tabs = []
    legend = rrb.PlotLegend(corner=rrb.Corner2D.RightTop)
    tr = report.traces
    if tr is not None:
        dur = float(np.asarray(tr.measured).shape[-1] / tr.fs)
        tx = whole_time_axis(rrb, "time", dict(seconds=0.0), dict(seconds=dur))
        views = [rrb.TimeSeriesView(origin=channel_entity("signals", c), name=f"{c} [{u or '-'}]",
                                    plot_legend=legend, **tx) for c, u in zip(chans, units)]
        views.append(rrb.TimeSeriesView(origin="/input", name="input [N]", plot_legend=legend, **tx))
        views.append(rrb.TimeSeriesView(origin="/validation", name="held-out (1) / fitting (0)",
                                        axis_y=rrb.ScalarAxis(range=(-0.1, 1.1)), plot_legend=legend, **tx))
        tabs.append(rrb.Vertical(*views, row_shares=[3] * len(chans) + [1.5, 1],
                                 name="Time: measured / nominal / augmented (timeline: time)"))
    if ftl_s:
        fx = whole_time_axis(rrb, ftl_s, dict(seq=int(fr_s[0])), dict(seq=int(fr_s[1])))
        views = [rrb.TimeSeriesView(origin=channel_entity("psd", c),
                                    name=f"{c}: PSD [dB re 1 ({u or 'unit'})²/Hz] vs frequency ({ftl_s})",
                                    plot_legend=legend, **fx) for c, u in zip(chans, units)]
        tabs.append(rrb.Horizontal(rrb.Vertical(*views), rrb.TextDocumentView(origin="/psd/bands", name="Gap bands"),
                                   column_shares=[4, 1], name=f"Gap spectrum (timeline: {ftl_s})"))
    if ftl_f:
        fx = whole_time_axis(rrb, ftl_f, dict(seq=int(fr_f[0])), dict(seq=int(fr_f[1])))
        tabs.append(rrb.Vertical(
            rrb.TimeSeriesView(origin="/frf/magnitude_db", name=f"FRF magnitude [dB] vs frequency ({ftl_f})",
                               plot_legend=legend, **fx),
            rrb.TimeSeriesView(origin="/frf/phase_deg", name=f"FRF phase [deg] vs frequency ({ftl_f})",
                               axis_y=rrb.ScalarAxis(range=(-180.0, 180.0)), plot_legend=legend, **fx),
            rrb.TimeSeriesView(origin="/frf/coherence", name=f"coherence γ² [-] vs frequency ({ftl_f})",
                               axis_y=rrb.ScalarAxis(range=(0.0, 1.05)), plot_legend=legend, **fx),
            row_shares=[2, 1.3, 1], name=f"FRF (timeline: {ftl_f})"))
    if report.candidates:
        tabs.append(rrb.Horizontal(
            rrb.Vertical(
                rrb.BarChartView(origin="/candidates", contents=["/candidates/gap_after", "/candidates/verdict"],
                                 name="held-out gap (nrmse) per candidate; bar k = table row k", plot_legend=legend),
                rrb.BarChartView(origin="/gaps", name="gaps: nominal, refit, augmented, noise floor",
                                 plot_legend=legend),
                row_shares=[2, 1]),
            rrb.TextDocumentView(origin="/candidates/table", name="Candidates"),
            column_shares=[1, 1], name="Candidates"))
    tabs.append(rrb.Horizontal(rrb.TextDocumentView(origin="/summary", name="Summary"),
                               rrb.TextDocumentView(origin="/about", name="About this recording"),
                               name="Summary"))
    panel = rrb.TimePanel(timeline="time" if tr is not None else (ftl_s or ftl_f or "time"))
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), panel, collapse_panels=False)


def log_gap_report(report, *, recording=None, path: str | Path | None = None, spawn: bool = False,
                   application_id: str = "vibroscope", recording_name: str | None = None,
                   recording_id: str | None = None) -> Path | None:
    """Log a gap diagnosis to one rerun recording, with a blueprint of tabs.

    Tabs: time (measured / nominal / augmented per output channel, the input, the held-out
    mask), gap spectrum (PSDs of the measured outputs and of the residuals, the noise floor,
    the bands), FRF (magnitude, phase, coherence), candidates (bar chart of the held-out gaps,
    the verdict in green, and a table naming the bars), summary (:meth:`GapReport.summary`).
    The entities are listed in the module docstring.

    Parameters
    ----------
    report : GapReport
        Its ``traces`` and ``spectrum`` may be None (their tabs are then left out).
    recording : rerun.RecordingStream, optional
        Log into this stream instead of a new one. Without `path` and `spawn` it keeps its own
        sinks: the blueprint is sent with ``send_blueprint`` and the stream is only flushed;
        with them it is redirected there (as a new stream would be) and disconnected at the end.
    path : str or Path, optional
        Write the recording (and its blueprint) to this ``.rrd`` file.
    spawn : bool, optional
        Once the recording is complete, open it in the rerun viewer
        (:func:`vibroscope.viewers.rerun_viewer.open_in_viewer`; without `path`, a file of its own
        in the system's temporary folder); a one-line warning says why when none opens.
    application_id : str, optional
        Application id of a new stream.
    recording_name : str, optional
        Shown in the viewer as the recording's name (default for a new stream:
        ``"gap: <model>"``; a given `recording` keeps its name unless this is set).
    recording_id : str, optional
        Fixed recording id of a new stream (a random one when None).

    Returns
    -------
    Path or None
        `path` once written and closed; None when only spawned or logged into `recording`.

    Raises
    ------
    ValueError
        If none of `recording`, `path`, `spawn` is given.

    Examples
    --------
    >>> log_gap_report(report, path="gap.rrd")  # doctest: +SKIP
    >>> read_rrd("gap.rrd")["/candidates/gap_after"]["static"]["BarChart:values"]  # doctest: +SKIP
    """
    if recording is None and path is None and not spawn:
        raise ValueError("log_gap_report needs path, spawn=True or a recording")
    import rerun as rr

    tr, sp = report.traces, report.spectrum
    if tr is not None:
        n_ch = np.atleast_2d(tr.measured).shape[0]
    elif sp is not None:
        n_ch = np.atleast_2d(sp.measured).shape[0]
    else:
        n_ch = len(report.channels)
    chans, units = _channels(report, n_ch), _units(report, n_ch)
    ftl_s = fidx_s = ftl_f = fidx_f = None
    if sp is not None and np.asarray(sp.frequencies).size:
        ftl_s, fidx_s = frequency_index(sp.frequencies)
    if sp is not None and np.asarray(sp.frf_frequencies).size:
        ftl_f, fidx_f = frequency_index(sp.frf_frequencies)
    bp = _blueprint(report, chans=chans, units=units,
                    ftl_s=ftl_s, fr_s=None if fidx_s is None else (fidx_s[0], fidx_s[-1]),
                    ftl_f=ftl_f, fr_f=None if fidx_f is None else (fidx_f[0], fidx_f[-1]))

    rec = recording if recording is not None else rr.RecordingStream(application_id, recording_id=recording_id)
    if recording_name or recording is None:
        rec.send_recording_name(recording_name or f"gap: {report.model_name or 'model'}")
    out = Path(path) if path is not None else None
    shown_only = spawn and out is None
    if shown_only:  # the viewer opens a complete file (rerun_viewer.open_in_viewer): one of its own
        import tempfile

        out = Path(tempfile.mkdtemp(prefix="vibroscope-view-")) / "gap.rrd"
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
    redirected = out is not None
    if out is not None:
        rec.save(str(out), default_blueprint=bp)
    else:
        rec.send_blueprint(bp, make_active=True, make_default=True)

    try:
        rec.log("summary", rr.TextDocument(report.summary(), media_type=rr.MediaType.TEXT), static=True)
        rec.log("about", rr.TextDocument(_about(report, ftl_s, ftl_f), media_type=rr.MediaType.MARKDOWN),
                static=True)
        if tr is not None:
            _log_traces(rec, tr, chans, units)
        if ftl_s is not None:
            idx = rr.TimeColumn(ftl_s, sequence=fidx_s)
            for c, ch in enumerate(chans):
                u = units[c] or "unit"
                for what, col in SPECTRA.items():
                    v = np.atleast_2d(getattr(sp, what))[c]
                    _series(rec, channel_entity("psd", ch) + f"/{what}",
                            f"{what} [dB re 1 ({u})²/Hz]", col, idx, decibels(v, 10.0))
            rec.log("psd/bands", rr.TextDocument(_band_table(report), media_type=rr.MediaType.MARKDOWN), static=True)
        if ftl_f is not None:
            _log_frf(rec, sp, chans, units, ftl_f, fidx_f)
        if report.candidates:
            g = _f64([c.gap_after for c in report.candidates])
            vi = verdict_index(report)
            hi = np.zeros_like(g)
            if vi is not None:
                hi[vi] = g[vi]
            rec.log("candidates/gap_after", rr.BarChart(g, color=_BAR), static=True)
            rec.log("candidates/verdict", rr.BarChart(hi, color=_VERDICT), static=True)
            rec.log("candidates/table", rr.TextDocument(_candidate_table(report), media_type=rr.MediaType.MARKDOWN),
                    static=True)
        rec.log("gaps", rr.BarChart(_f64([report.gap_before, report.gap_refit, report.gap_after,
                                          report.noise_floor]), color=_BAR), static=True)
        flush_recording(rec)
    finally:
        if redirected:
            rec.disconnect()
    if spawn:
        show_recording(out)
    return None if shown_only else out


def _log_traces(rec, tr, chans, units) -> None:
    import rerun as rr

    n = np.atleast_2d(tr.measured).shape[1]
    t_ns = np.round(np.arange(n) / tr.fs * 1e9).astype(np.int64).astype("timedelta64[ns]")
    idx = rr.TimeColumn("time", duration=t_ns)
    for c, ch in enumerate(chans):
        for what, col in TRACES.items():
            _series(rec, channel_entity("signals", ch) + f"/{what}", f"{what} [{units[c] or '-'}]", col, idx,
                    np.atleast_2d(getattr(tr, what))[c])
    u = np.asarray(tr.input, dtype=float).ravel()
    if u.size == n:
        _series(rec, "/input", "input [N]", (31, 119, 180), idx, u)
    v = np.asarray(tr.validation, dtype=bool).ravel()
    if v.size == n:
        _series(rec, "/validation", "held-out (1) / fitting (0)", (255, 200, 60), idx, v.astype(np.float64))


def _log_frf(rec, sp, chans, units, ftl, fidx) -> None:
    import rerun as rr

    f = np.asarray(sp.frf_frequencies)
    idx = rr.TimeColumn(ftl, sequence=fidx)
    H = {what: np.asarray(getattr(sp, f"frf_{what}")).reshape(f.size, -1) for what in FRF_CURVES}
    coh = np.asarray(sp.coherence, dtype=float).reshape(f.size, -1)
    for o, ch in enumerate(chans):
        if o >= H["measured"].shape[1]:
            break
        for what, col in FRF_CURVES.items():
            h = H[what][:, o]
            _series(rec, channel_entity("frf/magnitude_db", ch) + f"/{what}",
                    f"|H| {what} [dB re 1 {units[o] or 'unit'}/N]", col, idx, decibels(np.abs(h), 20.0))
            _series(rec, channel_entity("frf/phase_deg", ch) + f"/{what}", f"∠H {what} [deg]", col, idx,
                    np.degrees(np.angle(h)))
        if o < coh.shape[1]:
            _series(rec, channel_entity("frf/coherence", ch), f"γ² {ch}", (31, 119, 180), idx, coh[:, o])
