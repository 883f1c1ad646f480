"""The printed report of ``vibroscope analyse`` (and ``modal``, ``demo``): the record, the signal
faults and warnings, and the modes."""

from __future__ import annotations

import numpy as np

__all__ = ["report_text", "stream_report_text", "decimation_text", "stream_summary", "percent", "not_estimated"]


def report_text(an, *, source: str = "", true_modes=None, verbose: bool = False) -> str:
    """Human-readable report: record, plan, signal faults, warnings, and the modes (beside true ones when given).

    One report for both kinds of analysis: a whole read (:func:`vibroscope.pipeline.analyse_signals`)
    and a streamed one (:func:`vibroscope.stream.analyse_stream`, ``an.streamed``: the record said
    "streamed", no decimation, no faults, candidates or severity, which need the time series).

    Parameters
    ----------
    an : Analysis
        From :func:`vibroscope.pipeline.analyse_signals` or :func:`vibroscope.stream.analyse_stream`.
    source : str, optional
        What was analysed (the log's path), at the head of the first line.
    true_modes : ModalModel, optional
        Known modes, listed beside the identified ones with the errors.
    verbose : bool, optional
        Every fault kind on its own line (:func:`vibroscope.faults.fault_lines`) and the notes
        (``Analysis.notes``: gravity, constant channels); default False: one line counting the
        faults per kind (:func:`vibroscope.faults.fault_summary`) and no note.

    Returns
    -------
    str
    """
    from vibroscope.faults import fault_lines, fault_summary
    from vibroscope.modal.methods import display_name

    s = an.settings
    n_seg = None if an.streamed else s.get("n_segments")
    avg = f"{s['n_averages']} of {n_seg} averages" if n_seg else f"{s['n_averages']} averages"
    how_read = ", streamed" if an.streamed else decimation_text(s.get("decimation"))
    lines = [f"{source}: {len(an.channels)} channels x {an.n_samples} samples at {an.fs:g} Hz "
             f"({an.duration_s:.2f} s){how_read}; nperseg={s['nperseg']} (df={an.fs / s['nperseg']:.4g} Hz, {avg})"]
    how = display_name(an.modal.method)
    if s.get("input"):
        lines.append(f"input {s['input']} -> {len(s['outputs'])} outputs, {s['estimator']} FRF, modes by {how}")
    else:
        lines.append(f"output-only: {len(s['outputs'])} responses, modes by {how}")
    if an.input_choice:  # the force-like channel taken as the input, or why none was
        lines.append(an.input_choice)
    if an.plan is not None:
        lines.append(an.plan.line())
    faults = tuple(f for f in an.faults if not f.note)
    notes = tuple(an.notes)
    if verbose:
        lines += [f"  fault: {line}" for line in fault_lines(faults)]
        lines += [f"  note: {line}" for line in fault_lines(notes)]
    elif faults:
        lines.append(f"  faults: {fault_summary(faults)} (details: --verbose or --json)")
    shown = {str(f) for f in faults + notes}
    lines += [f"  warning: {w}" for w in an.warnings if w not in shown]
    mm = an.modal
    fstd = mm.extra.get("frequency_std_hz")
    zstd = mm.extra.get("damping_std")
    ident = an.identification
    unc = (not an.streamed and isinstance(fstd, np.ndarray) and fstd.shape == mm.natural_frequencies.shape
           and np.any(np.isfinite(fstd)) and ident is not None
           and "bootstrap" in str(ident.settings.get("uncertainty")))
    lines.append(f"{'mode':>4} {'f_n [Hz]':>10}" + (f" {'+-std':>7}" if unc else "") + f" {'zeta [%]':>9}"
                 + (f" {'+-std':>7}" if unc else "")
                 + (f" {'true f_n':>10} {'err [%]':>8} {'true zeta':>9}" if true_modes is not None else "") + "  method")
    for k in range(len(mm.natural_frequencies)):
        f, z = mm.natural_frequencies[k], mm.damping_ratios[k]
        row = f"{k + 1:>4} {f:>10.3f}" + (f" {fstd[k]:>7.3f}" if unc else "") + f" {percent(z):>9}" \
            + (f" {100 * zstd[k]:>7.3f}" if unc else "")
        if true_modes is not None:
            tf = true_modes.natural_frequencies
            j = int(abs(tf - f).argmin())
            row += f" {tf[j]:>10.3f} {100 * (f - tf[j]) / tf[j]:>8.3f} {100 * true_modes.damping_ratios[j]:>8.3f}%"
        lines.append(row + f"  {mm.method}")
    if len(mm.natural_frequencies) == 0:
        lines.append("   (no mode passed the physical-mode selection in the band)")
    elif not np.isfinite(mm.damping_ratios).all():
        lines.append(not_estimated(mm.method))
    if ident is not None and ident.rejected and not an.streamed:
        lines.append(f"  {len(ident.rejected)} candidates rejected (listed in the --json summary), e.g.:")
        for r in ident.rejected[:4]:
            lines.append(f"    {r.natural_frequency:9.3f} Hz: {r.reason}")
    if ident is not None and ident.settings.get("uncertainty") and unc:
        lines.append(f"  std: {ident.settings['uncertainty']}")
    sev = an.severity
    if sev is not None:
        v = sev.velocity_rms_mm_s
        k = int(np.argmax(v))
        lines.append(f"vibration severity (ISO 20816, velocity RMS {sev.band_hz[0]:g}–{sev.band_hz[1]:g} Hz): "
                     f"max {v[k]:.3g} mm/s at {sev.channels[k]}; median {np.median(v):.3g} mm/s over "
                     f"{len(v)} channels" + (f" ({sev.note})" if sev.note else ""))
    return "\n".join(lines)


#: the report of a streamed analysis is :func:`report_text` (one result type, one report)
stream_report_text = report_text


def decimation_text(dec: dict | None) -> str:
    """What the report's first line says about the decimation.

    Parameters
    ----------
    dec : dict or None
        ``Analysis.settings["decimation"]`` (:func:`vibroscope.pipeline.analyse_signals`): ``fs_in``,
        ``fs_out`` (Hz), ``factors``, ``reason``.

    Returns
    -------
    str
        ``"; decimated 400 → 50 Hz (why)"``, ``"; not decimated (why)"`` or ``""`` (no decimation
        needed).
    """
    if not dec or not dec.get("reason"):
        return ""
    if dec.get("factors"):
        return f"; decimated {dec['fs_in']:g} → {dec['fs_out']:g} Hz ({dec['reason']})"
    return f"; not decimated ({dec['reason']})"


def percent(z: float) -> str:
    """A damping ratio in % with 3 decimals, or "-" when it was not estimated (NaN).

    Parameters
    ----------
    z : float
        The damping ratio (a fraction; NaN when not estimated).

    Returns
    -------
    str
    """
    return f"{100 * z:.3f}" if np.isfinite(z) else "-"


def not_estimated(method: str) -> str:
    """The report's line saying why a damping ratio reads "-" (the method's ``no_damping_note`` in
    :data:`~vibroscope.modal.methods.MODAL_METHODS`).

    Parameters
    ----------
    method : str
        The modal method (``ModalModel.method``; a name not registered gets the generic note).

    Returns
    -------
    str
    """
    from vibroscope.modal.methods import MODAL_METHODS, ModalMethod

    m = MODAL_METHODS.get(method)
    return f"   (zeta -: {m.no_damping_note if m is not None else ModalMethod.no_damping_note})"


def stream_summary(an, *, source: str | None = None) -> dict:
    """The ``--json`` summary of a streamed analysis: :func:`vibroscope.pipeline.summary_dict`, the
    one summary of the one result type (kept under this name for its callers).

    Parameters
    ----------
    an : Analysis
        The streamed analysis (:func:`vibroscope.stream.analyse_stream`).
    source : str, optional
        The log.

    Returns
    -------
    dict
        JSON-serialisable.
    """
    from vibroscope.pipeline import summary_dict

    return summary_dict(an, source=source)
