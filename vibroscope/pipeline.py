"""The analyser's composition: Signals → spectra, FRFs, coherence, modal vectors → summary.

This module chooses settings and calls the numerical rooms (:mod:`vibroscope.spectral`,
:mod:`vibroscope.modal`); it holds no numerics of its own. :mod:`vibroscope.commands.analyse`
adds the edges (reading MCAP, writing rerun recordings and figures).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import scipy.signal

from vibroscope.signals import Signals
from vibroscope.spectral import FRF, CrossSpectralMatrix, Spectrum, csd_matrix, frf

__all__ = ["Analysis", "analyse_signals", "decimate", "default_nperseg", "summary_dict"]


@dataclass(frozen=True, eq=False)
class Analysis:
    """Everything one analysis produced.

    Attributes
    ----------
    signals : Signals
        The analysed record (after any decimation), input channel first when there is one.
    psd : Spectrum
        Welch PSD of every channel (unit²/Hz).
    csd : CrossSpectralMatrix
        Cross-spectral matrix of the response channels (output-only modal analysis uses it).
    frf : FRF or None
        H1/H2/Hv estimate from the input to every response, with coherence; None without input.
    modal : ModalModel
        Natural frequencies (Hz), damping ratios, complex mode shapes over the response channels.
    singular_values : tuple of ndarray
        ``(frequencies Hz, S (n_freqs, n_channels))`` of the response CSD (FDD).
    settings : dict
        Welch settings and the band analysed.
    warnings : list of str
        What the reader and the analysis noticed (gaps, jitter, skipped channels, ...).
    """

    signals: Signals
    psd: Spectrum
    csd: CrossSpectralMatrix
    frf: FRF | None
    modal: Any
    singular_values: tuple
    settings: dict
    warnings: list = field(default_factory=list)


def default_nperseg(n: int, fs: float, *, fmin: float | None = None, averages: int = 16) -> int:
    """Segment length giving about `averages` half-overlapping segments, a power of two.

    When `fmin` (Hz) is given, the segment is lengthened if needed so that the resolution
    ``fs / nperseg`` is at most ``fmin / 8`` (a lightly damped mode near fmin still spans bins),
    down to a minimum of 4 averages.
    """
    target = max(16, int(2 * n / (averages + 1)))
    nper = 2 ** int(np.floor(np.log2(target)))
    if fmin:
        need = 2 ** int(np.ceil(np.log2(8 * fs / fmin)))
        nper = max(nper, min(need, 2 ** int(np.floor(np.log2(2 * n / 5)))))
    return int(min(nper, n))


def decimate(signals: Signals, fmax: float) -> Signals:
    """Low-pass and decimate so that `fmax` (Hz) stays below 0.4·fs; unchanged if no gain.

    Uses :func:`scipy.signal.decimate` (order-8 Chebyshev I, zero phase) in stages of at most 10.
    """
    q = int(np.floor(signals.fs / (2.5 * fmax)))
    if q < 2:
        return signals
    data, fs, left = signals.data, signals.fs, q
    stages = []
    while left >= 2:  # stages of at most 10 (scipy's advice); total factor <= q keeps fs >= 2.5 fmax
        f = min(left, 10)
        data = scipy.signal.decimate(data, f, axis=-1, zero_phase=True)
        fs /= f
        stages.append(f)
        left //= f
    meta = {**signals.meta, "decimated": {"factors": stages, "fs_in": signals.fs, "fs_out": fs}}
    return Signals(data, fs, signals.channels, signals.units, signals.t0, meta)


def _identify(sig, input, outputs, nperseg, window, fmin, fmax, n_modes, estimator, prominence, method):
    """One identification pass at one resolution: (CSD of all channels, FRF or None, modal model)."""
    from vibroscope import modal

    G = csd_matrix(sig, nperseg=nperseg, window=window)
    Gout = G.select(outputs)
    if input:
        h = frf(G, input, outputs, estimator=estimator)
        return G, h, modal.peak_picking(h, n_modes=n_modes, fmin=fmin, fmax=fmax)
    if method == "ssi":
        # 60 block rows (or fewer for short records) and orders 10..120: Peeters & De Roeck 1999
        n_lags = int(min(60, sig.n_samples // 20))
        orders = range(10, int(min(120, n_lags * len(outputs))) + 1, 4)
        st = modal.ssi_cov(sig.select(outputs), n_lags=n_lags, orders=orders)
        mm = st.modal_model(fmin=fmin, fmax=fmax)
        mm = dataclasses.replace(mm, extra={**mm.extra, "stabilization": st})
        if n_modes is not None and len(mm) > n_modes:
            warnings.warn(f"SSI-COV found {len(mm)} modes; all are reported (n_modes={n_modes} applies to FDD)",
                          stacklevel=3)
        return G, None, mm
    # two singular values: close modes (e.g. a tower's two bending directions) both show
    mm = modal.fdd(Gout, n_modes=n_modes, fmin=fmin, fmax=fmax, n_singular=min(2, len(outputs)),
                   prominence=prominence)
    return G, None, mm


def analyse_signals(
    signals: Signals,
    *,
    input: str | None = None,
    outputs: Sequence[str] | None = None,
    nperseg: int | None = None,
    window: str = "hann",
    fmin: float | None = None,
    fmax: float | None = None,
    n_modes: int | None = None,
    estimator: str = "H1",
    prominence: float = 10.0,
    method: str = "fdd",
) -> Analysis:
    """Spectra, FRFs, coherence and modal vectors of a record.

    Parameters
    ----------
    signals : Signals
        The record (SI units).
    input : str, optional
        The force channel. With it: FRFs from it to every output (`estimator`) and modal vectors
        by peak picking (quadrature response); without: output-only FDD of the outputs' CSD.
    outputs : sequence of str, optional
        Response channels; default every channel but the input.
    nperseg : int, optional
        Welch segment length; default :func:`default_nperseg`, then, with an input, doubled while an
        identified mode's half-power band ``2 ζ f_n`` spans fewer than 8 bins and at least 5
        averages remain (the damping needs the resolution; a warning says so).
    window : str, optional
        Welch window (default Hann).
    fmin, fmax : float, optional
        Band (Hz) searched for modes; fmax also sets a decimation before the analysis.
    n_modes : int, optional
        Number of modes to report (default: every clear peak).
    estimator : {'H1', 'H2', 'Hv'}, optional
        FRF estimator with an input.
    prominence : float, optional
        Smallest prominence (dB) of a peak of the first singular values for output-only FDD;
        default 10 dB (ambient records average few segments at the resolution modes need, and
        their singular values fluctuate by several dB). Peak picking with a force uses its own
        3 dB default on the far smoother FRFs.
    method : {'fdd', 'ssi'}, optional
        Output-only identification: FDD with EFDD damping (default; Brincker et al. 2001) or
        covariance-driven SSI with clustering of stable poles (Peeters & De Roeck 1999), which
        resolves light damping that the FDD bell cannot at the resolution a short record allows.

    Returns
    -------
    Analysis

    Raises
    ------
    KeyError
        If `input` or an output is not a channel of `signals`.
    ValueError
        If the record is too short for the segment length.
    """
    from vibroscope import modal
    from vibroscope.spectral._engine import check_option

    check_option("method", method, ("fdd", "ssi"))
    notes = list(signals.meta.get("warnings", []))
    outputs = [c for c in signals.channels if c != input] if outputs is None else list(outputs)
    flat = [c for c in outputs if np.ptp(signals[c]) == 0]
    if flat:  # e.g. the unused axes of a one-axis IMU: no information, singular spectra
        more = f" and {len(flat) - 3} more" if len(flat) > 3 else ""
        notes.append(f"{len(flat)} constant channels skipped (no vibration): {flat[:3]}{more}")
        outputs = [c for c in outputs if c not in flat]
    if not outputs:
        raise ValueError("no non-constant response channel to analyse")
    chans = ([input] if input else []) + outputs
    sig = signals.select(chans)
    if fmax is not None and fmax < 0.4 * sig.fs:
        sig = decimate(sig, fmax)
    fmax_eff = fmax if fmax is not None else 0.4 * sig.fs
    auto = nperseg is None
    if auto:
        nperseg = default_nperseg(sig.n_samples, sig.fs, fmin=fmin)
    refinements = []
    while True:
        G, h, mm = _identify(sig, input, outputs, nperseg, window, fmin, fmax_eff, n_modes, estimator, prominence,
                             method)
        # half-power bands should span several bins for the damping to be resolved (Brandt 2011,
        # §14.3): refine the resolution while that is not so and >= 5 averages remain. FRFs only:
        # output-only FDD loses more to the fewer averages than it gains in resolution
        bw = 2 * np.asarray(mm.damping_ratios) * np.asarray(mm.natural_frequencies)
        df = sig.fs / nperseg
        if not auto or not input or not np.any(np.isfinite(bw) & (bw < 8 * df)) or 2 * nperseg > 2 * sig.n_samples / 6:
            break
        refinements.append(nperseg)
        nperseg *= 2
    if refinements:
        notes.append(f"resolution refined for the damping: nperseg {refinements[0]} -> {nperseg} "
                        f"(df {sig.fs / refinements[0]:.4g} -> {sig.fs / nperseg:.4g} Hz)")
    psd = G.psd()
    Gout = G.select(outputs)
    sv = modal.singular_values(Gout)
    settings = dict(G.settings, fmin=fmin, fmax=fmax_eff, estimator=estimator if input else None,
                    input=input, outputs=list(outputs))
    return Analysis(sig, psd, Gout, h, mm, sv, settings, notes)


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def summary_dict(analysis: Analysis, *, source: str | None = None, true_modes: Any = None) -> dict:
    """The machine-readable summary (the ``--json`` file of ``vibroscope analyse``).

    Keys: ``fs`` (Hz), ``channels``, ``warnings``, ``modes`` (each ``frequency_hz``,
    ``damping_ratio``, ``shape`` {path: [re, im]}, ``method``), plus ``input``, ``outputs``,
    ``settings``, ``timebase`` and, with `true_modes`, ``true_modes``.
    """
    sig = analysis.signals
    out = {
        "source": source,
        "fs": sig.fs,
        "n_samples": sig.n_samples,
        "duration_s": sig.duration,
        "channels": list(sig.channels),
        "units": dict(zip(sig.channels, sig.units)),
        "input": analysis.settings.get("input"),
        "outputs": analysis.settings.get("outputs"),
        "warnings": list(analysis.warnings),
        "modal_method": analysis.modal.method,
        "modes": analysis.modal.to_dict()["modes"],
        "settings": {k: v for k, v in analysis.settings.items() if k not in ("outputs",)},
    }
    for key in ("timebase", "skipped", "decimated", "resampled"):
        if key in sig.meta:
            out[key] = sig.meta[key]
    if true_modes is not None:
        out["true_modes"] = [
            {"frequency_hz": float(f), "damping_ratio": float(z)}
            for f, z in zip(true_modes.natural_frequencies, true_modes.damping_ratios)
        ]
    return _jsonable(out)
