"""Periodic excitation: detection of the period of an input, and the period-synchronous FRF.

A periodic excitation (a random-phase multisine repeated P times, a periodic chirp) measured
over an integer number of periods has no leakage with a rectangular window, and averaging the
spectra of consecutive periods separates the periodic signal from the (non-periodic) noise
(Pintelon & Schoukens 2012, ch. 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.fft
import scipy.ndimage
import scipy.signal
import scipy.stats

from vibroscope._checks import check_option
from vibroscope.signals import Signals
from vibroscope.spectral._results import FRF
from vibroscope.spectral.kinds import FRF_KIND_TABLE, FRF_KINDS
from vibroscope.spectral.estimators import frf_kind, unpack_signals

__all__ = ["Periodicity", "detect_period", "frf_periodic"]

Channel = str | int



@dataclass(frozen=True)
class Periodicity:
    """Result of :func:`detect_period`.

    Attributes
    ----------
    period_samples : int or None
        The period in samples (the smallest lag at which the record repeats); None when no
        candidate lag was found.
    period_s : float
        The period in s (``period_samples / fs``); NaN when `period_samples` is None.
    n_periods : int
        Whole periods in the record (``n_samples // period_samples``); 0 when None.
    score : float
        Normalised correlation of the record with itself shifted by one period,
        ``2 Σ x[k] x[k+T] / (Σ x[k]² + Σ x[k+T]²)`` (mean removed): 1 for an exactly periodic
        signal, about ``S / (S + N)`` with a noise-to-signal power ratio ``N / S``, about 0 for
        random noise. Dimensionless, in [−1, 1]; NaN when no candidate was found.
    is_periodic : bool
        ``score >= min_score`` and at least `min_periods` whole periods.
    """

    period_samples: int | None
    period_s: float
    n_periods: int
    score: float
    is_periodic: bool


def _lag_scores(x: np.ndarray) -> np.ndarray:
    """``s[T] = 2 Σ_k x[k] x[k+T] / (Σ_{k<n−T} x[k]² + Σ_{k≥T} x[k]²)`` for T = 0 … n−1 (FFT)."""
    n = x.size
    nfft = scipy.fft.next_fast_len(2 * n, real=True)
    X = scipy.fft.rfft(x, nfft)
    r = scipy.fft.irfft(np.abs(X) ** 2, nfft)[:n]
    c = np.concatenate([[0.0], np.cumsum(x * x)])
    T = np.arange(n)
    head = c[n - T]  # Σ_{k < n−T} x²
    tail = c[n] - c[T]  # Σ_{k ≥ T} x²
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(head + tail > 0, 2 * r / np.where(head + tail > 0, head + tail, 1.0), 0.0)


def detect_period(
    x: np.ndarray,
    fs: float,
    *,
    min_periods: int = 3,
    min_score: float = 0.9,
    fmax: float | None = None,
) -> Periodicity:
    """Period of a periodic signal (a repeated multisine, a periodic chirp), in whole samples.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        One channel, e.g. the measured force of a periodic excitation (any unit).
    fs : float
        Sampling frequency in Hz.
    min_periods : int, optional
        Fewest whole periods the record must hold; candidate periods are ≤ ``n // min_periods``.
        Default 3.
    min_score : float, optional
        Smallest `score` of a periodic signal (default 0.9: the record repeats with less than
        about 10 % of its power non-periodic, i.e. noise up to about 30 % RMS of the signal).
    fmax : float, optional
        Highest frequency of interest in Hz: the record is first low-passed there (zero-phase
        Butterworth, order 8, :func:`scipy.signal.sosfiltfilt`), so that noise above the analysed
        band does not lower the score (the period of a decimated record, found at the full
        rate). Default None (the record as given).

    Returns
    -------
    Periodicity
        ``(period_samples, period_s, n_periods, score, is_periodic)``.

    Raises
    ------
    ValueError
        If `x` is not 1-D, `fs` is not positive, ``min_periods < 1``, or `fmax` is not positive.

    Notes
    -----
    With the mean removed, the normalised lag correlation ``s(T)`` (the `score` formula) is
    computed for every lag by one FFT (the autocorrelation) and cumulative energies. Lags inside
    the main lobe of the autocorrelation (before ``s`` first falls to 0) are skipped; among the
    lags up to ``n // min_periods``, the smallest one whose score comes within
    ``0.1 (1 − s_max) + 0.02`` of the best score ``s_max`` is taken (multiples of the period score
    as well as the period itself) and moved uphill to the local maximum of ``s``. This finds the
    exact integer period of an excitation generated synchronously with the sampling clock, the
    condition for leakage-free periodic measurements (Pintelon & Schoukens 2012, §2.2); a period
    that is not a whole number of samples reads as its nearest integer with a lower score.

    References
    ----------
    .. [1] R. Pintelon and J. Schoukens, *System Identification: A Frequency Domain Approach*,
       2nd ed., Wiley–IEEE Press, 2012, ch. 2.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> one = rng.standard_normal(500)          # any record repeated is periodic
    >>> p = detect_period(np.tile(one, 6), fs=1000.0)
    >>> p.period_samples, p.n_periods, p.is_periodic
    (500, 6, True)
    >>> detect_period(rng.standard_normal(3000), fs=1000.0).is_periodic
    False
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"x must be one channel (n_samples,), got {x.shape=}")
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
    min_periods = int(min_periods)
    if min_periods < 1:
        raise ValueError(f"{min_periods=} must be at least 1")
    if fmax is not None and not (np.isfinite(fmax) and fmax > 0):
        raise ValueError(f"{fmax=} must be a positive frequency in Hz")
    none = Periodicity(None, float("nan"), 0, float("nan"), False)
    n = x.size
    t_hi = n // min_periods
    if t_hi < 2 or not np.all(np.isfinite(x)):
        return none
    if fmax is not None and fmax < 0.5 * fs and n > 64:  # sosfiltfilt's padding needs a few dozen samples
        x = scipy.signal.sosfiltfilt(scipy.signal.butter(8, fmax, fs=fs, output="sos"), x)
    s = _lag_scores(x - x.mean())
    below = np.flatnonzero(s[1 : t_hi + 1] <= 0.0)
    if below.size == 0:
        return none
    t_lo = int(below[0]) + 1
    cand = s[t_lo : t_hi + 1]
    s_max = float(cand.max())
    if s_max <= 0:
        return none
    T = t_lo + int(np.flatnonzero(cand >= s_max - (0.1 * (1 - s_max) + 0.02))[0])
    while T + 1 <= t_hi and s[T + 1] > s[T]:
        T += 1
    score = float(s[T])
    n_per = n // T
    return Periodicity(T, T / fs, n_per, score, bool(score >= min_score and n_per >= min_periods))


def frf_periodic(
    signals: Signals | np.ndarray,
    input: Channel,
    outputs: Sequence[Channel] | Channel | None = None,
    *,
    fs: float | None = None,
    period: int | None = None,
    periods_per_segment: int = 1,
    drop_periods: int = 1,
    min_line_snr: float = 10.0,
    kind: str | None = None,
) -> FRF:
    """FRF of a periodic excitation from period-synchronous averaged spectra.

    Parameters
    ----------
    signals : Signals or array_like, shape (n_channels, n_samples)
        The record: the input (force) channel and the response channels.
    input : str or int
        The input (excitation, ``exc``) channel, name or index.
    outputs : channel or sequence of channels, optional
        Response (``resp``) channels; default every channel but `input`.
    fs : float, optional
        Sampling frequency in Hz (taken from `signals` when it is a Signals; default 1.0 for an
        array).
    period : int, optional
        The excitation period in samples; default found by :func:`detect_period` on the input.
    periods_per_segment : int, optional
        Periods per analysed segment (default 1: the lines ``k fs / period``). With ``p > 1`` the
        resolution is ``fs / (p · period)`` and only every ``p``-th line is excited.
    drop_periods : int, optional
        Periods left out at the start of the record as the transient; default 1. (The segments end
        at the last whole segment of the record, so a partial period is dropped at the start as
        well).
    min_line_snr : float, optional
        An excited line must have ``|X̄|² ≥ min_line_snr · σ²_X`` (the averaged input line above
        the noise of the mean, ``σ²_X`` estimated from the spread of the segments and pooled by a
        running median over ±16 lines) and ``|X̄|² ≥ 1e-10 · max |X̄|²`` (numerical zero);
        default 10 (a noise-only line passes with probability about ``e^-10 ≈ 5e-5``).
    kind : {'accelerance', 'mobility', 'receptance'}, optional
        Declare the FRF kind; default inferred from the channel units (N in; m/s², m/s or m out).

    Returns
    -------
    FRF
        ``estimator='periodic'``; ``H[f, output, 0]`` on the lines ``k fs / nperseg``, NaN at
        lines that are not excited (and the coherence NaN there too). ``settings``: ``fs``,
        ``period_samples``, ``periods_per_segment``, ``nperseg``, ``n_segments``,
        ``n_periods_used``, ``drop_periods``, ``first_sample`` (index of the first sample used),
        ``window='boxcar'``, ``detrend=False``, ``periodicity_score`` (None when `period` was
        given), ``excited_lines`` (list of int line indices) and ``H_std`` (ndarray, shape like
        `H`: the standard deviation of `H` from the segment scatter, in the units of `H`).

    Raises
    ------
    ValueError
        If the input channel is not periodic (``detect_period(...).is_periodic`` False, the
        message names the channel), fewer than two whole segments remain after `drop_periods`,
        `input` is also an output, or an option is unknown.
    KeyError
        If a channel name is not in the record.

    See Also
    --------
    detect_period : The period of the input, when it is not known.
    vibroscope.spectral.frf : H1, H2 or Hv by Welch averaging, for random excitation.

    Notes
    -----
    With ``M`` segments of ``L = periods_per_segment · period`` samples (rectangular window: the
    segments hold whole periods, so the periodic part has no leakage) and their DFTs ``X_m``,
    ``Y_m``, the sample means ``X̄ = (1/M) Σ X_m``, ``Ȳ`` give the averaged-spectra estimator
    ``H = Ȳ / X̄``, which is consistent for noise on input and output alike (it is the ratio of
    the periodic parts; Pintelon & Schoukens 2012, §2.5). Sample (co)variances of the means,
    ``σ²_X = Σ |X_m − X̄|² / (M (M − 1))`` and likewise ``σ²_Y``, ``σ²_YX``, give the first-order
    variance ``σ²_H = |H|² (σ²_Y / |Ȳ|² + σ²_X / |X̄|² − 2 Re(σ²_YX / (Ȳ conj X̄)))``
    (``settings['H_std'] = σ_H``). The coherence is the ordinary one of the rectangular-window
    segment spectra, ``γ² = |Σ conj(X_m) Y_m|² / (Σ |X_m|² Σ |Y_m|²)`` (Bendat & Piersol 2010):
    1 without noise, lower with the noise-to-signal ratio of either channel.

    References
    ----------
    .. [1] R. Pintelon and J. Schoukens, *System Identification: A Frequency Domain Approach*,
       2nd ed., Wiley–IEEE Press, 2012, ch. 2.
    .. [2] J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, §9.2.

    Examples
    --------
    A 3-tap FIR filter driven by a repeated random period is recovered exactly:

    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> u = np.tile(rng.standard_normal(256), 5)
    >>> y = np.convolve(u, [1.0, 0.5, 0.25])[: u.size]
    >>> h = frf_periodic(np.vstack([u, y]), 0, fs=256.0)
    >>> H_true = 1 + 0.5 * np.exp(-2j * np.pi * h.frequencies / 256) + 0.25 * np.exp(-4j * np.pi * h.frequencies / 256)
    >>> bool(np.nanmax(np.abs(h.H[:, 0, 0] - H_true)) < 1e-10)
    True
    """
    data, fs, channels, units = unpack_signals(signals, fs)
    n_ch, n = data.shape
    i_in = _index(channels, input)
    if outputs is None:
        oo = [i for i in range(n_ch) if i != i_in]
    else:
        outs = [outputs] if isinstance(outputs, (str, int, np.integer)) else list(outputs)
        oo = [_index(channels, o) for o in outs]
    if i_in in oo:
        raise ValueError(f"channel {channels[i_in]!r} is both input and output")
    if not oo:
        raise ValueError("no output channel")
    if kind is not None:
        check_option("kind", kind, FRF_KINDS)
    name = channels[i_in]
    score = None
    if period is None:
        p = detect_period(data[i_in], fs)
        if not p.is_periodic:
            raise ValueError(
                f"input channel {name!r} is not periodic (best period {p.period_samples} samples, "
                f"score {p.score:.3g}); give period= or use frf() for random excitation")
        period, score = p.period_samples, p.score
    period = int(period)
    periods_per_segment, drop_periods = int(periods_per_segment), int(drop_periods)
    if period < 2 or periods_per_segment < 1 or drop_periods < 0:
        raise ValueError(f"{period=} must be >= 2, {periods_per_segment=} >= 1 and {drop_periods=} >= 0")
    L = period * periods_per_segment
    M = (n - drop_periods * period) // L
    if M < 2:
        raise ValueError(
            f"input channel {name!r}: {n=} samples hold {n // period} periods of {period} samples; after "
            f"{drop_periods=} fewer than 2 segments of {periods_per_segment=} remain")
    start = n - M * L
    seg = data[[i_in] + oo, start:].reshape(1 + len(oo), M, L)
    F = scipy.fft.rfft(seg, axis=-1)  # (channel, segment, line)
    X, Y = F[0], F[1:]
    Xm, Ym = X.mean(axis=0), Y.mean(axis=1)  # (line,), (o, line)
    dX, dY = X - Xm, Y - Ym[:, None, :]
    vX = np.sum(np.abs(dX) ** 2, axis=0) / (M * (M - 1))
    vY = np.sum(np.abs(dY) ** 2, axis=1) / (M * (M - 1))
    cYX = np.sum(dY * np.conj(dX)[None], axis=1) / (M * (M - 1))
    pX = np.abs(Xm) ** 2
    excited = (pX >= min_line_snr * _local_noise(vX, M)) & (pX >= 1e-10 * pX.max()) & (pX > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        H = Ym / Xm
        varH = np.abs(H) ** 2 * (vY / np.abs(Ym) ** 2 + vX / pX - 2 * np.real(cYX / (Ym * np.conj(Xm))))
        Sxy = np.sum(np.conj(X)[None] * Y, axis=1)
        Sxx = np.sum(np.abs(X) ** 2, axis=0)
        Syy = np.sum(np.abs(Y) ** 2, axis=1)
        coh = np.abs(Sxy) ** 2 / (Sxx * Syy)
    H[:, ~excited] = np.nan
    coh[:, ~excited] = np.nan
    stdH = np.sqrt(np.maximum(varH, 0.0))
    stdH[:, ~excited] = np.nan
    k_inf, unit = frf_kind([units[i_in]], [units[o] for o in oo])
    if kind is not None:
        k_inf, unit = kind, FRF_KIND_TABLE[kind].unit
    std_arr = np.ascontiguousarray(stdH.T[:, :, None])
    std_arr.flags.writeable = False
    settings = dict(fs=fs, period_samples=period, periods_per_segment=periods_per_segment, nperseg=L,
                    n_segments=M, n_periods_used=M * periods_per_segment, drop_periods=drop_periods,
                    first_sample=start, window="boxcar", detrend=False, periodicity_score=score,
                    excited_lines=[int(k) for k in np.flatnonzero(excited)], H_std=std_arr)
    freqs = scipy.fft.rfftfreq(L, 1.0 / fs)
    return FRF(frequencies=freqs, H=H.T[:, :, None], coherence=coh.T, inputs=[name], outputs=[channels[o] for o in oo],
               estimator="periodic", kind=k_inf, units=unit, settings=settings)


def _local_noise(v: np.ndarray, M: int, half_width: int = 16) -> np.ndarray:
    """Noise variance of each line's mean, pooled over ±`half_width` lines: the running median of
    the per-line sample variances `v` (each ∝ χ² with 2(M − 1) degrees of freedom), divided by that
    distribution's median so that it estimates the mean. Robust to a few lines with more scatter."""
    dof = 2 * (M - 1)
    med = scipy.ndimage.median_filter(v, size=2 * half_width + 1, mode="mirror")
    return med / (scipy.stats.chi2.median(dof) / dof)


def _index(channels: tuple[str, ...], c: Channel) -> int:
    if isinstance(c, (int, np.integer)):
        if not -len(channels) <= c < len(channels):
            raise KeyError(f"channel index {c} out of range for {len(channels)} channels")
        return int(c) % len(channels)
    try:
        return channels.index(c)
    except ValueError:
        raise KeyError(f"no channel {c!r}; channels are {list(channels)}") from None
