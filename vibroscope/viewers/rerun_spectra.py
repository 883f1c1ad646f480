"""Spectra in a rerun recording, on the frequency timeline: PSDs and the CSD's singular values in
dB, FRF magnitude, phase and coherence, and the poles of a stabilization diagram.

rerun is imported inside the functions: importing this module never imports it.
"""

from __future__ import annotations

import numpy as np

from vibroscope.viewers.rerun_paths import channel_entity, frequency_index

__all__ = ["decibels", "log_psd", "log_singular_values", "log_stabilization", "log_frf", "STABILITY_CLASSES"]


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


def log_psd(rec, psd) -> None:
    """Log ``/psd/<channel>`` in dB (20 log10 for an amplitude spectrum) on the frequency timeline.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    psd : Spectrum
        ``frequencies`` (Hz), ``values`` (n_channels, n_freqs), ``channels``, ``units``,
        ``scaling``; 10 log10 of a power quantity (NaN where it is 0).
    """
    import rerun as rr

    ftl, fidx = frequency_index(psd.frequencies)
    fac = 20.0 if psd.scaling == "amplitude" else 10.0
    for k, ch in enumerate(psd.channels):
        ent = channel_entity("psd", ch)
        rec.log(ent, rr.SeriesLines(names=f"{ch} [dB re 1 {psd.units[k] or 'unit'}]"), static=True)
        rec.send_columns(ent, indexes=[rr.TimeColumn(ftl, sequence=fidx)],
                         columns=rr.Scalars.columns(scalars=decibels(psd.values[k], fac)))


def log_singular_values(rec, csd, sv=None, n_sv: int = 3) -> None:
    """Log ``/csd/singular_values/s1..s<n_sv>``: 10 log10 of the first singular values of the CSD.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    csd : CrossSpectralMatrix
        ``G[f, i, j]``, ``frequencies`` (Hz).
    sv : (ndarray, ndarray), optional
        Singular values already computed: frequencies (Hz) and ``S`` (n_freqs, n), descending
        (:func:`vibroscope.modal.fdd.singular_values`); used only when its frequencies are those
        of `csd`, else they are computed (:func:`numpy.linalg.svd`).
    n_sv : int, optional
        Most singular values logged; default 3.
    """
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
STABILITY_CLASSES = {0: ("new", [150, 150, 150], "cross"), 1: ("stable_f", [255, 127, 14], "circle"),
                 2: ("stable_f_damping", [31, 119, 180], "plus"), 3: ("stable_f_damping_mac", [44, 160, 44], "circle")}


def log_stabilization(rec, st, ftl: str) -> None:
    """Log the poles of a stabilization diagram as points on the frequency timeline.

    One series per stability class (:data:`STABILITY_CLASSES`) and model order,
    ``/stabilization/<class>/order_<n>``, whose value is the order; poles rounding to one index of
    the timeline are logged once.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    st : Stabilization
        ``order``, ``frequency`` (Hz) and ``stable`` (0–3) of every pole.
    ftl : str
        The frequency timeline, ``"frequency_mHz"`` or ``"frequency_uHz"``.
    """
    import rerun as rr

    fac = 1e6 if ftl == "frequency_uHz" else 1e3
    orders = np.unique(st.order)
    for code, (name, colour, marker) in STABILITY_CLASSES.items():
        style = None  # one archetype per class, logged on each of its series (built once)
        for order in orders:
            m = (st.stable == code) & (st.order == order)
            if not m.any():
                continue
            idx = np.round(np.asarray(st.frequency[m]) * fac).astype(np.int64)
            idx = np.unique(idx)
            ent = f"/stabilization/{name}/order_{int(order):03d}"
            if style is None:
                style = rr.SeriesPoints(colors=colour, markers=marker, marker_sizes=2.0 if code == 3 else 1.5,
                                        names=f"{name.replace('_', ' ')}")
            rec.log(ent, style, static=True)
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
