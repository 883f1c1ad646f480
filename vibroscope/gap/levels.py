"""Excitation levels and segment lengths: the period of a periodic input, the FRF segment length
a mode's bandwidth needs, and the level dependence of the best linear approximation (BLA) across
logs and levels, with each resonance's natural frequency and damping ratio per level.

The level dependence of the BLA is the strongest evidence of a nonlinearity: a hardening
(softening) stiffness raises (lowers) the natural frequency of the BLA with the excitation level,
friction lowers it and raises the damping [2]_ [3]_.

References
----------
.. [1] J. S. Bendat, A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, §9.2 (random error of
   H1: ``var|H| / |H|^2 = (1 - gamma^2) / (2 n_d gamma^2)``), §11.5 (Welch estimates).
.. [2] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed.,
   Wiley-IEEE, 2012, ch. 2-3 (periodic excitation, the best linear approximation and its level
   dependence).
.. [3] K. Worden, G. R. Tomlinson, *Nonlinearity in Structural Dynamics*, IOP, 2001, ch. 2
   (FRF distortion with level: hardening / softening).
.. [4] M. H. Richardson, D. L. Formenti, "Parameter estimation from frequency response
   measurements using rational fraction polynomials", Proc. 1st IMAC, 1982; C. K. Sanathanan,
   J. Koerner, "Transfer function synthesis as a ratio of two complex polynomials", IEEE Trans.
   Autom. Control 8, 56-58, 1963 (the iterated linear start of the pole fit).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.optimize
import scipy.signal

from vibroscope.gap.measure import LOG_LEVEL_RATIO, UNEXCITED, excited_band, input_levels
from vibroscope.signals import true_runs
from vibroscope.spectral import csd_matrix

__all__ = ["detect_period", "steady_state_start", "period_floor", "PeriodFloor", "aperiodic_logs", "AperiodicLogs", "frf_segment_length", "level_blas", "fit_mode", "window_kernel", "LevelBLA", "ModeTrend",
           "LevelEvidence"]

#: relative change beyond which a level dependence counts (with |z| > :data:`Z_SIGNIFICANT`)
FREQ_CHANGE = 0.005
DAMPING_CHANGE = 0.10
Z_SIGNIFICANT = 3.0


# --------------------------------------------------------------------------------------------
# period of a periodic input
# --------------------------------------------------------------------------------------------

def detect_period(u, fs: float, *, min_periods: int = 2, tol: float = 0.05,
                  max_candidates: int = 32) -> int | None:
    """Period in samples of a periodic input (a repeated multisine), or None.

    The amplitude may change from one period to the next (level steps between periods): the
    waveform is periodic per block, and that period is returned.

    Parameters
    ----------
    u : array_like, shape (n_samples,) or (n_inputs, n_samples)
        The logged input (N); only the first input is used.
    fs : float
        Sampling frequency in Hz (checked; the period is in samples).
    min_periods : int, optional
        Fewest whole periods the record must hold (candidates are ``<= n // min_periods``);
        default 2.
    tol : float, optional
        Largest relative difference of a block from its scaled predecessor,
        ``||b_{i+1} - a b_i|| / ||b_{i+1}||`` with the least-squares scale ``a``; default 0.05
        (a noise-free logged input gives ~1e-12, white noise of RMS ``e`` relative to the
        signal about ``sqrt(2) e``, so up to ~3 % noise passes; random noise gives ~1).
    max_candidates : int, optional
        Most candidate lags verified; default 32.

    Returns
    -------
    int or None
        The smallest lag ``T`` for which at least half of the pairs of consecutive blocks of
        ``T`` samples (and at least ``min_periods - 1`` pairs) agree within `tol` after
        scaling; None if none does (random input, too short a record, a constant).

    Raises
    ------
    ValueError
        If `fs` is not positive or ``min_periods < 2``.

    Notes
    -----
    Candidates are the local maxima of the cosine-normalised autocorrelation
    ``r(T) = sum x[k] x[k+T] / sqrt(sum_{k<n-T} x^2 sum_{k>=T} x^2)`` (mean removed; one FFT,
    O(n log n)) above 0.5, beyond the main lobe (lags before ``r`` first falls to 0), in
    increasing lag. The cosine normalisation keeps ``r(T)`` high when the level changes between
    periods, where the energy-normalised score of
    :func:`vibroscope.spectral.detect_period` drops (``2ab / (a^2 + b^2)`` for amplitudes a, b).
    Each candidate is verified block by block (O(n)); a pair of blocks straddling a level step
    inside a period fails, the others pass. A multiple of the period also passes, so the
    smallest passing lag is the period [2]_.

    Examples
    --------
    >>> import numpy as np
    >>> one = np.random.default_rng(0).standard_normal(500)
    >>> detect_period(np.tile(one, 6) * np.repeat([1.0, 1.0, 3.0, 3.0, 8.0, 8.0], 500), 1000.0)
    500
    >>> detect_period(np.random.default_rng(1).standard_normal(3000), 1000.0) is None
    True
    """
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
    min_periods = int(min_periods)
    if min_periods < 2:
        raise ValueError(f"{min_periods=} must be at least 2 (a period is seen repeated)")
    x = np.atleast_2d(np.asarray(u, dtype=float))[0]
    n = x.size
    t_hi = n // min_periods
    if t_hi < 2 or not np.all(np.isfinite(x)):
        return None
    x = x - x.mean()
    e = x * x
    if not np.any(e > 0):
        return None
    nfft = scipy.fft.next_fast_len(2 * n, real=True)
    X = scipy.fft.rfft(x, nfft)
    r = scipy.fft.irfft(np.abs(X) ** 2, nfft)[: t_hi + 2]
    c = np.concatenate([[0.0], np.cumsum(e)])
    T = np.arange(r.size)
    den = np.sqrt(c[n - T] * (c[n] - c[T]))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(den > 0, r / np.where(den > 0, den, 1.0), 0.0)
    below = np.flatnonzero(rho[1:t_hi + 1] <= 0.0)
    if below.size == 0:
        return None
    t_lo = int(below[0]) + 1
    seg = rho[t_lo:t_hi + 2]
    if seg.size < 3:
        return None
    peaks = np.flatnonzero((seg[1:-1] >= seg[:-2]) & (seg[1:-1] >= seg[2:]) & (seg[1:-1] > 0.5)) + 1 + t_lo
    peaks = peaks[peaks <= t_hi]
    if peaks.size == 0:
        return None
    # the strongest candidates, verified in increasing lag
    if peaks.size > max_candidates:
        peaks = np.sort(peaks[np.argsort(rho[peaks])[::-1][:max_candidates]])
    for T in peaks:
        T = int(T)
        m = n // T
        B = x[: m * T].reshape(m, T)
        a, b = B[:-1], B[1:]
        aa = np.einsum("ij,ij->i", a, a)
        bb = np.einsum("ij,ij->i", b, b)
        ab = np.einsum("ij,ij->i", a, b)
        ok = (aa > 0) & (bb > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.sqrt(np.maximum(bb - np.where(ok, ab**2 / np.where(ok, aa, 1.0), 0.0), 0.0) / np.where(ok, bb, 1.0))
        good = ok & (rel < tol)
        if good.sum() >= max(min_periods - 1, 1) and good.sum() >= 0.5 * (m - 1):
            return T
    return None


#: a log starts in periodic steady state when the first two periods differ at their start by
#: at most this factor times their difference at their end (the noise)
STEADY_START_RATIO = 2.0
#: ... and their difference at the end is at most this share of the output's RMS (one level)
STEADY_START_LEVEL = 0.2
#: ... and the input's first two periods differ by at most this share of the second's RMS (one
#: level: :func:`detect_period` takes a period at another level as a period)
STEADY_START_INPUT = 0.05


def steady_state_start(u, y, fs: float, *, period: int | None = None) -> int | None:
    """Period in samples when a log of a periodic input is in periodic steady state from its
    first sample (a recording made after the transient, or periods cut from one), else None.

    A model simulated from rest on such a log has a transient of its slowest modes that the
    data do not: the first period is not comparable, however well the model fits. A log
    recorded from rest has the same transient in the data and in the simulation, and a random
    input has no period: both give None.

    Parameters
    ----------
    u : array_like, shape (n_samples,) or (n_inputs, n_samples)
        The logged input (N); the period is detected on the first
        (:func:`detect_period`), unless `period` is given.
    y : array_like, shape (n_samples,) or (n_outputs, n_samples)
        The logged outputs, in their units.
    fs : float
        Sampling frequency in Hz.
    period : int, optional
        The input's period in samples, if known.

    Returns
    -------
    int or None
        The period ``T`` if the record holds at least two periods and its first two are alike
        from their start; None otherwise.

    Raises
    ------
    ValueError
        If `fs` is not positive, or `u` and `y` have different lengths.

    Notes
    -----
    With ``d = y[:, :T] - y[:, T:2T]`` (each output channel divided by its RMS over the second
    period) and ``q = T // 4``: steady from the start when ``rms(d[:, :q]) <=``
    :data:`STEADY_START_RATIO` ``* rms(d[:, -q:])`` and ``rms(d[:, -q:]) <=``
    :data:`STEADY_START_LEVEL`, and the input's first two periods are one level: their
    difference at most :data:`STEADY_START_INPUT` of the second's RMS (three sine sweeps at
    levels 1, 2.5 and 6 are periodic to :func:`detect_period`, which allows a level change,
    and their outputs differ little at both ends of a period, below and above the resonances). A record from rest differs
    most at its start, where the transient is (it decays as ``exp(-t / tau)``); in steady
    state the difference is the noise, alike at both ends. A transient slower than about a
    period, or one over within a few samples, also passes: leaving the first period out then
    costs data, not correctness. The periodic-excitation practice of discarding the transient
    periods: Pintelon & Schoukens [2]_, sec. 2.4; the Bouc-Wen benchmark's validation multisine
    is one steady-state period (Noël & Schoukens, Workshop on Nonlinear System Identification
    Benchmarks, 2016).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> one = np.random.default_rng(0).standard_normal(1000)
    >>> u = np.tile(one, 4)
    >>> y = lfilter([1.0], [1.0, -0.99], u)          # from rest: a transient of ~100 samples
    >>> steady_state_start(u, y, 1000.0) is None
    True
    >>> steady_state_start(u, np.tile(y[-1000:], 4), 1000.0)   # steady-state periods, repeated
    1000
    """
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
    u2 = np.atleast_2d(np.asarray(u, dtype=float))
    y2 = np.atleast_2d(np.asarray(y, dtype=float))
    if u2.shape[1] != y2.shape[1]:
        raise ValueError(f"input and output lengths differ: {u2.shape[1]} and {y2.shape[1]} samples")
    T = detect_period(u2, fs) if period is None else int(period)
    if T is None or T < 8 or y2.shape[1] < 2 * T or not np.all(np.isfinite(y2[:, : 2 * T])):
        return None
    u1, u_2 = u2[0, :T], u2[0, T: 2 * T]
    if np.sqrt(np.mean((u1 - u_2) ** 2)) > STEADY_START_INPUT * np.sqrt(np.mean(u_2**2)):
        return None
    a, b = y2[:, :T], y2[:, T: 2 * T]
    scale = np.sqrt(np.mean(b**2, axis=1))
    ok = scale > 0
    if not np.any(ok):
        return None
    d = (a[ok] - b[ok]) / scale[ok, None]
    q = T // 4
    d_start = float(np.sqrt(np.mean(d[:, :q] ** 2)))
    d_end = float(np.sqrt(np.mean(d[:, -q:] ** 2)))
    if d_end <= STEADY_START_LEVEL and d_start <= STEADY_START_RATIO * d_end + 1e-9:
        return T
    return None


# --------------------------------------------------------------------------------------------
# segment length
# --------------------------------------------------------------------------------------------

#: consecutive periods whose inputs differ by more than this share of their RMS are different
#: runs (a level step); white noise of relative RMS e on the logged input gives about sqrt(2) e
PERIOD_INPUT_TOL = 0.1
#: periods dropped at the start of each run of alike periods (the transient of the level step
#: or of the start from rest)
PERIOD_SETTLE = 2
#: fewest alike periods a run must keep after :data:`PERIOD_SETTLE` to be used
PERIOD_MIN = 3
#: a run whose first period after :data:`PERIOD_SETTLE` changes to the next by more than
#: ``PERIOD_TRANSIENT[0]`` times the median change over the run's second half is still settling,
#: and its leading periods are dropped until one changes by at most ``PERIOD_TRANSIENT[1]`` times
#: it (hysteresis thresholds: the scatter of an unlogged disturbance's response from period to
#: period passes the lower one now and then, not the upper). A lightly damped mode's transient
#: from rest outlasts two short periods: harder blind seed 21 case 001, a 4.2 Hz mode damped
#: 0.74 % (time constant 5 s) under a 2 s periodic chirp, changes 1.63, 0.77, 0.28, 0.10, 0.075,
#: 0.12, 0.11, 0.058, 0.054, 0.039, ... to 0.032 from the 12th period on; all but the first two
#: periods gave a floor of 0.0745, 2.3x the white floor, which the report read as in-band noise
PERIOD_TRANSIENT = (3.0, 1.5)


def _settling_periods(Y: np.ndarray) -> int:
    """How many leading periods of a run of alike periods ``Y`` (shape ``(n_outputs, n_periods,
    T)``) are still settling: :data:`PERIOD_SETTLE`, or more where the run is still settling then
    (:data:`PERIOD_TRANSIENT`: a transient decays; noise, a disturbance or a chaotic response
    change every period alike)."""
    n_p = Y.shape[1]
    if n_p < 2 * (PERIOD_SETTLE + PERIOD_MIN):
        return PERIOD_SETTLE
    d = np.sum(np.diff(Y, axis=1) ** 2, axis=2)
    e = np.maximum(np.sum(Y[:, 1:, :] ** 2, axis=2), 1e-300)
    c = np.sqrt(np.mean(d / e, axis=0))  # (n_periods - 1,): period p's change to p + 1
    ref = float(np.median(c[c.size // 2:]))
    n = PERIOD_SETTLE
    if not (np.isfinite(ref) and ref > 0 and c[n] > PERIOD_TRANSIENT[0] * ref):
        return n
    while n < c.size // 2 and not c[n] <= PERIOD_TRANSIENT[1] * ref:
        n += 1
    return n


#: a period whose input departs from its run's mean period by more than this many times the run's
#: median departure is dropped (a level transition or a fade inside a period that still passed
#: :data:`PERIOD_INPUT_TOL`): its outputs differ from the others' by the response to that change
PERIOD_INPUT_OUTLIER = 2.0
#: stretches per period over which a period's departure is measured (its largest RMS)
PERIOD_WINDOWS = 16
#: the variation grows with level when the run of the highest input level varies this many times
#: (relative) the run of the lowest, their input levels at least :data:`PERIOD_LEVEL_APART` apart
PERIOD_LEVEL_GROWTH = 2.0
PERIOD_LEVEL_APART = 1.5


@dataclass(frozen=True, kw_only=True)
class PeriodFloor:
    """The outputs' part that is not periodic with a periodic input, as a gap (nrmse).

    Attributes
    ----------
    nrmse : float
        ``sqrt(mean_c (s2_c / p_c))`` over the output channels: ``s2_c`` the period-to-period
        variance of channel c (its samples minus their mean over the alike periods of their run,
        pooled with ``P - 1`` degrees of freedom per sample), ``p_c`` its mean square over the same
        samples: the nrmse a model that matches the periodic response exactly would leave.
    per_channel : tuple of float
        Each channel's ``sqrt(s2_c / p_c)``.
    n_periods : int
        Periods used, every log together.
    period_samples : tuple of int
        The period of each log used, samples.
    logs : tuple of int
        The logs used (indices into the lists given).
    run_levels : tuple of float
        Each run's input RMS (input unit, N), in the order found.
    run_nrmse : tuple of float
        Each run's own ``sqrt(mean_c (s2_c / p_c))``.
    grows_with_level : bool
        The run of the highest input level varies (relative) more than :data:`PERIOD_LEVEL_GROWTH`
        times the run of the lowest (their levels at least :data:`PERIOD_LEVEL_APART` apart). Noise
        and a disturbance do not: of fixed size, their relative part falls with level; relative to
        the level, it stays. A response that stops repeating as the level rises (chaos, a
        subharmonic of a strong nonlinearity) does: then the variation is the system's own, not a
        floor (:func:`vibroscope.gap._ranking.ranking_floor` does not rank against it).
    """

    nrmse: float
    per_channel: tuple
    n_periods: int
    period_samples: tuple
    logs: tuple
    run_levels: tuple = ()
    run_nrmse: tuple = ()
    grows_with_level: bool = False

    def to_dict(self) -> dict:
        """The fields as a dict.

        Returns
        -------
        dict
            JSON-ready: ``nrmse``, ``per_channel``, ``n_periods``, ``period_samples``, ``logs``,
            ``run_levels``, ``run_nrmse``, ``grows_with_level``.
        """
        return {"nrmse": self.nrmse, "per_channel": list(self.per_channel), "n_periods": self.n_periods,
                "period_samples": list(self.period_samples), "logs": list(self.logs),
                "run_levels": list(self.run_levels), "run_nrmse": list(self.run_nrmse),
                "grows_with_level": self.grows_with_level}


def _period_blocks(y, u, m, fs: float):
    """One log cut into whole periods of its input (:func:`detect_period`) from its first sample:
    ``(T, ub, yb, ok, same)`` with the period `T` (samples), the input's periods ``ub`` (shape
    ``(nb, T)``), the outputs' ``yb`` (``(n_outputs, nb, T)``), ``ok`` (each period wholly inside
    the mask `m`, its outputs finite) and ``same`` (shape ``(nb - 1,)``: each period's input
    within :data:`PERIOD_INPUT_TOL` of its predecessor's, relative RMS); None without a period."""
    y = np.atleast_2d(np.asarray(y, float))
    u0 = np.atleast_2d(np.asarray(u, float))[0]
    T = detect_period(u0, fs)
    if T is None:
        return None
    nb = u0.size // T
    ub = u0[: nb * T].reshape(nb, T)
    yb = y[:, : nb * T].reshape(y.shape[0], nb, T)
    ok = np.asarray(m[: nb * T]).reshape(nb, T).all(axis=1) & np.all(np.isfinite(yb), axis=(0, 2))
    rms = np.sqrt(np.mean(ub**2, axis=1))
    same = np.sqrt(np.mean(np.diff(ub, axis=0) ** 2, axis=1)) <= PERIOD_INPUT_TOL * np.maximum(rms[1:], 1e-300)
    return T, ub, yb, ok, same


def period_floor(ys: list, us: list, masks: list, fs: float) -> PeriodFloor | None:
    """The noise floor measured in the band: the outputs' variation from period to period.

    With a periodic input (:func:`detect_period`), the steady-state response of a time-invariant
    system, linear or not (unless it is chaotic or subharmonic), repeats with the input; what
    changes from one period to the next is measurement noise of any colour and the response to
    anything the log does not hold (an unlogged disturbance) -- what no model of the logged input
    can explain, in the band as well as beyond it (the white floor of :func:`~vibroscope.gap.measure.noise_floor`
    sees only beyond it). Each log is cut into whole periods from its first sample; consecutive
    periods whose inputs agree within :data:`PERIOD_INPUT_TOL` (relative RMS) form a run, its
    first :data:`PERIOD_SETTLE` periods are dropped (the transient), and more while a slow
    transient still decays (:data:`PERIOD_TRANSIENT`), a period with a sample
    outside the log's mask splits it, a period whose input departs from the piece's mean period
    more than :data:`PERIOD_INPUT_OUTLIER` times the piece's median departure is dropped (a level
    transition or a fade that only part of the period holds: the input noise of a load cell spreads
    every period's departure alike), and each piece of at least :data:`PERIOD_MIN` periods gives each channel's
    sample variance about the run's mean period (Pintelon & Schoukens [1]_, sec. 2.4 and 4.3:
    the sample noise variance from repeated periods).

    Parameters
    ----------
    ys : list of ndarray, shape (n_outputs, n_samples)
        Measured outputs per log, in their units.
    us : list of ndarray, shape (n_inputs, n_samples) or (n_samples,)
        Logged inputs per log; the first sets the period.
    masks : list of ndarray of bool, shape (n_samples,)
        Samples that may be used (not a transient left out of every metric).
    fs : float
        Sampling frequency in Hz.

    Returns
    -------
    PeriodFloor or None
        None when no log holds a run of enough alike periods (a random input, a sweep, too
        short a record).

    References
    ----------
    .. [1] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*,
       2nd ed., Wiley-IEEE, 2012.
    """
    ss = pw = None
    dof = n_used = 0
    n_periods, periods, logs = 0, [], []
    run_levels, run_nrmse = [], []
    for i, (y, u, m) in enumerate(zip(ys, us, masks)):
        blocks = _period_blocks(y, u, m, fs)
        if blocks is None:
            continue
        T, ub, yb, ok, same = blocks
        nb = ub.shape[0]
        if nb < PERIOD_SETTLE + PERIOD_MIN:
            continue
        # runs of alike periods: each period's input against its predecessor's
        alike = np.r_[False, same]
        # a run's first periods settle; a masked period splits a run into consecutive pieces (the
        # system's own response goes on: no settling again)
        settled = np.zeros(nb, bool)
        starts = np.r_[np.flatnonzero(~alike), nb]
        for k, j in zip(starts[:-1], starts[1:]):
            settled[k + _settling_periods(yb[:, k:j, :]):j] = True
        used_here = 0
        for a0, b0 in zip(*true_runs(settled & ok)):
            if b0 - a0 < PERIOD_MIN:
                continue
            keep = _steady_periods(ub[a0:b0])
            k_used = int(keep.sum())
            if k_used < PERIOD_MIN:
                continue
            Y = yb[:, a0:b0, :][:, keep, :]
            r = Y - Y.mean(axis=1, keepdims=True)
            a, b = np.sum(r**2, axis=(1, 2)), np.sum(Y**2, axis=(1, 2))
            ss = a if ss is None else ss + a
            pw = b if pw is None else pw + b
            run_levels.append(float(np.sqrt(np.mean(ub[a0:b0][keep] ** 2))))
            run_nrmse.append(float(np.sqrt(np.mean(a / ((k_used - 1) * T) / np.maximum(b / (k_used * T), 1e-300)))))
            dof += (k_used - 1) * T
            n_used += k_used * T
            used_here += k_used
        if used_here:
            n_periods += used_here
            periods.append(int(T))
            logs.append(i)
    if ss is None or dof == 0 or not np.all(pw > 0):
        return None
    per = np.sqrt((ss / dof) / (pw / n_used))
    lo, hi = int(np.argmin(run_levels)), int(np.argmax(run_levels))
    grows = bool(run_levels[hi] >= PERIOD_LEVEL_APART * run_levels[lo]
                 and run_nrmse[hi] > PERIOD_LEVEL_GROWTH * run_nrmse[lo])
    return PeriodFloor(nrmse=float(np.sqrt(np.mean(per**2))), per_channel=tuple(float(x) for x in per),
                       n_periods=int(n_periods), period_samples=tuple(periods), logs=tuple(logs),
                       run_levels=tuple(run_levels), run_nrmse=tuple(run_nrmse), grows_with_level=grows)


#: a log at a higher input level whose response changes from period to period more than this many
#: times (relative) the quietest log's, whose input repeats, no longer repeats with its input
APERIODIC_GROWTH = 3.0


@dataclass(frozen=True, kw_only=True)
class AperiodicLogs:
    """Logs of a periodic input whose response stops repeating with it as the level rises.

    Attributes
    ----------
    logs : tuple of int
        The aperiodic logs (indices into the logs given), left out of the diagnosis
        (:func:`vibroscope.gap.diagnose`).
    variation : tuple of float
        Each log's period-to-period variation, ``sqrt(mean_c (median over pairs of
        ||y_{j+1} - y_j||^2 / (2 ||y_j||^2)))`` over the output channels c and the pairs of
        consecutive whole periods whose inputs repeat (nan: no such pair).
    levels : tuple of float
        Each log's input RMS over those periods (input unit, N; nan: no such pair).
    period_samples : tuple of int
        Each log's input period, samples (0: not periodic).
    """

    logs: tuple
    variation: tuple
    levels: tuple
    period_samples: tuple

    def to_dict(self) -> dict:
        """The fields as a dict.

        Returns
        -------
        dict
            JSON-ready: ``logs``, ``variation``, ``levels``, ``period_samples`` (nan as None).
        """
        def fin(v):
            return [float(x) if np.isfinite(x) else None for x in v]

        return {"logs": list(self.logs), "variation": fin(self.variation), "levels": fin(self.levels),
                "period_samples": list(self.period_samples)}

    def describe(self) -> str:
        """One line: which logs and why.

        Returns
        -------
        str
        """
        quiet = int(np.nanargmin(np.where(np.isin(np.arange(len(self.variation)), self.logs), np.nan,
                                          self.variation)))
        each = ", ".join(f"log {i + 1} (input RMS {self.levels[i]:.3g}, {self.variation[i]:.3g})" for i in self.logs)
        return (f"the response stops repeating with the periodic input as the level rises: {each} against "
                f"{self.variation[quiet]:.3g} at log {quiet + 1} (input RMS {self.levels[quiet]:.3g}), "
                f"period-to-period nrmse; chaotic or subharmonic, which no model predicts sample by sample: "
                f"left out of the diagnosis")


def aperiodic_logs(ys: list, us: list, masks: list, fs: float) -> AperiodicLogs | None:
    """The logs whose response no longer repeats with a periodic input at a higher level.

    A periodic input drives a time-invariant system, linear or not, to a periodic steady state
    unless the system is chaotic or responds subharmonically -- which a strong nonlinearity does
    beyond some level (the Duffing oscillator's route to chaos: Kovacic & Brennan [1]_, ch. 6;
    Worden & Tomlinson [2]_, ch. 3). Each log is cut into whole periods of its input
    (:func:`detect_period`) from its first sample; each pair of consecutive periods wholly inside
    the log's mask whose inputs agree within :data:`PERIOD_INPUT_TOL` (a fade, a level step or the
    start is not such a pair) gives each output channel's relative change, and the log's variation
    is its median over the pairs (Pintelon & Schoukens [3]_, sec. 2.4: the variation of repeated
    periods). Measurement noise and an unlogged disturbance vary alike at every level, or less
    (relative) at a higher one; a log varying more than :data:`APERIODIC_GROWTH` times the
    quietest log, at an input level above :data:`~vibroscope.gap.measure.LOG_LEVEL_RATIO` times
    every log that does not (logs at one level are not told apart by level), has stopped repeating. Its
    samples are a trajectory no deterministic model reproduces: the truth itself would leave a
    gap there (fresh seed 7359's case 003, a hardening cubic spring of share 0.30: at the
    highest of three levels the truth simulated with 32 and 64 sub-steps differs by nrmse 0.42).

    Parameters
    ----------
    ys : list of ndarray, shape (n_outputs, n_samples)
        Measured outputs per log, in their units.
    us : list of ndarray, shape (n_inputs, n_samples) or (n_samples,)
        Logged inputs per log; the first sets the period.
    masks : list of ndarray of bool, shape (n_samples,)
        Samples that may be used (not a transient).
    fs : float
        Sampling frequency in Hz.

    Returns
    -------
    AperiodicLogs or None
        None when fewer than two logs have a periodic input with a repeating pair of periods,
        or none is aperiodic.

    References
    ----------
    .. [1] I. Kovacic, M. J. Brennan (eds.), *The Duffing Equation: Nonlinear Oscillators and
       their Behaviour*, Wiley, 2011.
    .. [2] K. Worden, G. R. Tomlinson, *Nonlinearity in Structural Dynamics*, IOP, 2001.
    .. [3] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed.,
       Wiley-IEEE, 2012.
    """
    n = len(ys)
    var, lev, per = np.full(n, np.nan), np.full(n, np.nan), [0] * n
    for i, (y, u, m) in enumerate(zip(ys, us, masks)):
        blocks = _period_blocks(y, u, m, fs)
        if blocks is None:
            continue
        T, ub, yb, ok, same = blocks
        per[i] = int(T)
        yb = yb - np.nanmean(yb, axis=(1, 2), keepdims=True)
        j = np.flatnonzero(same & ok[1:] & ok[:-1])
        if not j.size:
            continue
        d2 = np.sum((yb[:, j + 1] - yb[:, j]) ** 2, axis=2) / np.maximum(2 * np.sum(yb[:, j] ** 2, axis=2), 1e-300)
        var[i] = float(np.sqrt(np.mean(np.median(d2, axis=1))))
        lev[i] = float(np.sqrt(np.mean(ub[np.r_[j, j + 1]] ** 2)))
    seen = np.flatnonzero(np.isfinite(var))
    if seen.size < 2:
        return None
    quiet = float(np.min(var[seen]))
    repeats = [i for i in seen if var[i] <= APERIODIC_GROWTH * quiet]
    top = max(lev[i] for i in repeats)
    out = tuple(int(i) for i in seen if var[i] > APERIODIC_GROWTH * quiet and lev[i] > LOG_LEVEL_RATIO * top)
    if not out:
        return None
    return AperiodicLogs(logs=out, variation=tuple(float(v) for v in var), levels=tuple(float(v) for v in lev),
                         period_samples=tuple(per))


def _steady_periods(ub: np.ndarray) -> np.ndarray:
    """Which periods (rows of `ub`, one run's inputs) keep: those whose departure from the run's
    period (the largest RMS over :data:`PERIOD_WINDOWS` stretches of the period: a transition is
    short) is within :data:`PERIOD_INPUT_OUTLIER` times the median departure (the period taken
    first as the sample-wise median of the periods, an outlier's pull left out, then as the mean of
    those kept)."""
    keep = np.ones(ub.shape[0], bool)
    scale = 1e-6 * np.sqrt(np.mean(ub**2))
    nw = min(PERIOD_WINDOWS, max(ub.shape[1] // 8, 1))
    w = ub.shape[1] // nw
    for centre in (np.median(ub, axis=0), None):
        ref = ub[keep].mean(axis=0) if centre is None else centre
        dev = np.sqrt(np.mean(((ub - ref)[:, : nw * w] ** 2).reshape(ub.shape[0], nw, w), axis=2)).max(axis=1)
        keep = dev <= PERIOD_INPUT_OUTLIER * np.median(dev[keep]) + scale
        if keep.sum() < PERIOD_MIN:
            break
    return keep


def _pow2_default(fs: float, n: int) -> int:
    """Today's default of :func:`vibroscope.gap.diagnose`: a power of two about 4 s, at most n / 8."""
    x = min(4 * fs, n / 8)
    return int(2 ** max(6, int(math.floor(math.log2(max(x, 64))))))


def frf_segment_length(u, fs: float, *, mode_bandwidths_hz=None, n_samples: int | None = None,
                       min_averages: int = 8) -> tuple[int, str]:
    """FRF (Welch) segment length for an input record and the modes to resolve.

    Parameters
    ----------
    u : array_like, shape (n_samples,) or (n_inputs, n_samples)
        The logged input (N); only the first input is used.
    fs : float
        Sampling frequency in Hz.
    mode_bandwidths_hz : sequence of float, optional
        Half-power bandwidths ``2 zeta f_n`` (Hz) of the modes to resolve (e.g. the nominal
        model's); non-finite or non-positive entries are ignored.
    n_samples : int, optional
        Samples available for the estimate (e.g. the fitting samples); default ``u``'s length.
    min_averages : int, optional
        Fewest Welch averages (Hann, 50 % overlap) a non-periodic choice leaves; default 8.

    Returns
    -------
    nperseg : int
        Segment length in samples.
    reason : str
        One line for the report: the rule that chose it and the line spacing ``fs / nperseg``.

    Raises
    ------
    ValueError
        If `fs` is not positive or there are fewer than 16 samples.

    Notes
    -----
    Rules, in order:

    1. A periodic input (:func:`detect_period`, at least 2 periods in `n_samples`): one period,
       ``nperseg = T``. A multisine excites only the lines ``k fs / T``; a segment of ``p``
       periods adds ``p - 1`` unexcited lines between them and ``1/p`` of the averages, so one
       period is the finest useful resolution and gives the most averages (with a rectangular
       window, leakage-free [2]_; :func:`level_blas` picks that window).
    2. Mode bandwidths given: the line spacing at most 1/4 of the narrowest half-power
       bandwidth ``B``, ``nperseg = next_fast_len(ceil(4 fs / B))``, capped so that
       `min_averages` segments with 50 % overlap fit: ``nperseg <= 2 n / (min_averages + 1)``
       (the reason says when the cap binds: the H1 bias at a peak grows like
       ``(df / B)^2`` [1]_).
    3. Otherwise the default of :func:`vibroscope.gap.diagnose`: a power of two about 4 s, at
       most ``n / 8``.

    Examples
    --------
    >>> import numpy as np
    >>> u = np.random.default_rng(0).standard_normal(400 * 600)
    >>> nperseg, reason = frf_segment_length(u, 400.0, mode_bandwidths_hz=[0.07])
    >>> 400.0 / nperseg <= 0.07 / 4
    True
    """
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
    x = np.atleast_2d(np.asarray(u, dtype=float))[0]
    n = int(n_samples) if n_samples is not None else x.size
    if n < 16:
        raise ValueError(f"{n=} samples are too few for an FRF")
    T = detect_period(x, fs)
    if T is not None and n // T >= 2:
        return T, (f"one period of the periodic input: nperseg = {T} samples ({T / fs:.4g} s), lines "
                   f"{fs / T:.4g} Hz apart, {n // T} periods averaged")
    cap = max(int(2 * n / (min_averages + 1)), 16)
    cap -= cap % 2
    bw = np.asarray([] if mode_bandwidths_hz is None else mode_bandwidths_hz, dtype=float).ravel()
    bw = bw[np.isfinite(bw) & (bw > 0)]
    if bw.size:
        b = float(bw.min())
        need = scipy.fft.next_fast_len(int(math.ceil(4 * fs / b)), real=True)
        if need <= cap:
            return need, (f"line spacing {fs / need:.4g} Hz <= 1/4 of the narrowest half-power bandwidth "
                          f"{b:.4g} Hz: nperseg = {need} samples")
        return cap, (f"line spacing {fs / cap:.4g} Hz, capped by {min_averages} averages in {n} samples (1/4 of "
                     f"the narrowest half-power bandwidth {b:.4g} Hz needs {need} samples: peaks biased low)")
    nps = _pow2_default(fs, n)
    return nps, f"default: a power of two about 4 s, at most n/8: nperseg = {nps} samples ({fs / nps:.4g} Hz lines)"


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------

def _ro(a, dtype=None):
    a = np.array(a, dtype=dtype)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, kw_only=True)
class LevelBLA:
    """The BLA (H1) at one excitation level, and its resonances.

    Attributes
    ----------
    log : int
        Index of the log it comes from.
    level : int
        Level index within that log (:func:`~vibroscope.gap.measure.input_levels`, 0 = lowest;
        0 when the log holds one level).
    rms : float
        RMS of the input over the samples used (N).
    n_averages : int
        Welch segments averaged.
    frequencies : ndarray, shape (n_f,)
        Hz, the lines within the band of :class:`LevelEvidence`.
    H : ndarray of complex, shape (n_f, n_outputs)
        H1 = G_uy / G_uu per output (output unit per N).
    coherence : ndarray, shape (n_f, n_outputs)
        Ordinary coherence.
    natural_frequencies, natural_frequency_std : ndarray, shape (n_modes,)
        Natural frequency ``f_n`` (Hz) of each mode of :class:`LevelEvidence` and its standard
        deviation; NaN where the mode was not found or the fit failed.
    damping_ratios, damping_std : ndarray, shape (n_modes,)
        Damping ratio ``zeta`` (dimensionless) and its standard deviation; NaN likewise.
    """

    log: int
    level: int
    rms: float
    n_averages: int
    frequencies: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    natural_frequencies: np.ndarray
    natural_frequency_std: np.ndarray
    damping_ratios: np.ndarray
    damping_std: np.ndarray


@dataclass(frozen=True, kw_only=True)
class ModeTrend:
    """The change of one resonance of the BLA from the lowest to the highest level.

    Attributes
    ----------
    natural_frequency : float
        Natural frequency at the lowest level where it was found (Hz).
    output : int
        The output whose FRF was fitted for this mode (0-based).
    frequency_change, damping_change : float
        Relative change ``(x_high - x_low) / x_low`` of ``f_n`` and of ``zeta``.
    frequency_z, damping_z : float
        The change over its combined standard deviation ``sqrt(s_low^2 + s_high^2)``.
        These four: from the lowest to the highest level where the mode was fitted (NaN with
        fewer than two).
    frequency_changes, frequency_zs, damping_changes, damping_zs : ndarray, shape (n_levels,)
        The same from the lowest fitted level to each level of :attr:`LevelEvidence.levels`
        (NaN at the lowest and where not fitted).
    level_dependent : bool
        At some level ``|z| > 3`` and ``|change| > 0.5 %`` (frequency), or ``|z| > 3`` and
        ``|change| > 10 %`` (damping). Every level is compared with the lowest: a strongly
        nonlinear BLA at the top level can be too broad to be precise while a middle level is.
    trend : {'hardening', 'softening', 'none'}
        The sign of the significant frequency change with the largest ``|z|`` (rises:
        hardening).
    damping_rises : bool
        A significant rise of the damping ratio at some level.
    """

    natural_frequency: float
    output: int
    frequency_change: float
    frequency_z: float
    damping_change: float
    damping_z: float
    frequency_changes: np.ndarray
    frequency_zs: np.ndarray
    damping_changes: np.ndarray
    damping_zs: np.ndarray
    level_dependent: bool
    trend: str
    damping_rises: bool


@dataclass(frozen=True, kw_only=True)
class LevelEvidence:
    """Level dependence of the best linear approximation across logs and levels.

    Attributes
    ----------
    levels : tuple of LevelBLA
        One per log and level group, by input RMS (lowest first).
    modes : tuple of ModeTrend
        One per resonance found in the band (by frequency).
    level_dependent : bool
        Any mode level dependent.
    trend : {'hardening', 'softening', 'none'}
        That of the level-dependent mode with the largest ``|frequency_z|``; 'none' without one.
    damping_rises : bool
        Any mode's damping ratio rises significantly with level.
    f_band : tuple of (float, float)
        The band analysed (Hz).
    fs : float
        Sampling frequency (Hz).
    nperseg : int
        Segment length (samples).
    window : str
        'hann' (50 % overlap) or 'boxcar' (no overlap, whole periods of a periodic input).
    description : str
        One line for the report.
    """

    levels: tuple
    modes: tuple
    level_dependent: bool
    trend: str
    damping_rises: bool
    f_band: tuple
    fs: float
    nperseg: int
    window: str
    description: str

    def plot(self, ax=None, *, out_path=None):
        """The figure (lazy matplotlib, :func:`vibroscope.viewers.gap_figures.plot_level_evidence`).

        Parameters
        ----------
        ax : sequence of three matplotlib Axes, optional
            Where to draw (|H| per level, natural frequency and damping ratio vs level); a new
            figure when None.
        out_path : str or Path, optional
            Also write the figure there as PNG.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from vibroscope._plotting import draw

        return draw("plot_level_evidence", self, ax=ax, out_path=out_path)


# --------------------------------------------------------------------------------------------
# the single-mode (rational fraction) fit
# --------------------------------------------------------------------------------------------

def _model(p, s, deg, kernel=None):
    r, z = p[0], p[1]
    b = p[2:2 + deg + 1] + 1j * p[3 + deg:]
    if kernel is None:
        num = sum(b[k] * s**k for k in range(deg + 1))
        return num / (s * s + 2 * z * r * s + r * r)
    ds, w = kernel
    ss = s[:, None] + ds[None, :]
    num = sum(b[k] * ss**k for k in range(deg + 1))
    return (num / (ss * ss + 2 * z * r * ss + r * r)) @ w


def window_kernel(window: str, nperseg: int, fs: float, *, oversample: int = 8, half_bins: int = 4):
    """Spectral window of a Welch estimate: offsets (Hz) and weights of ``|W(nu)|^2``.

    Parameters
    ----------
    window : str
        The segment window (scipy name, periodic).
    nperseg : int
        Samples per segment.
    fs : float
        Hz.
    oversample : int, optional
        Points per line spacing; default 8.
    half_bins : int, optional
        Half-width in lines; default 4 (the Hann main lobe is +-2 lines).

    Returns
    -------
    offsets : ndarray, shape (2 oversample half_bins + 1,)
        Hz.
    weights : ndarray, same shape
        ``|W(nu)|^2`` normalised to sum 1: the expected Welch cross-spectrum of a locally flat
        input is ``E G_uy(f) = sum_i w_i H(f + nu_i) G_uu`` [1]_, so H1 is the FRF smoothed by
        it (the leakage bias of a sharp peak). None for 'boxcar' (whole periods: no leakage).
    """
    if window == "boxcar":
        return None
    w = scipy.signal.get_window(window, nperseg, fftbins=True)
    nfft = nperseg * oversample
    W = np.abs(np.fft.fft(w, nfft)) ** 2
    m = np.arange(-oversample * half_bins, oversample * half_bins + 1)
    wt = W[m % nfft]
    return m * fs / nfft, wt / wt.sum()


def fit_mode(frequencies: np.ndarray, H: np.ndarray, sigma: np.ndarray, f_peak: float, *, kernel=None):
    """Natural frequency and damping ratio of one resonance from FRF lines around its peak.

    Parameters
    ----------
    frequencies : ndarray, shape (n_lines,)
        Hz (at least 5 lines).
    H : ndarray of complex, shape (n_lines,)
        The FRF (any kind: receptance, mobility, accelerance).
    sigma : ndarray, shape (n_lines,)
        Standard deviation of the real and of the imaginary part of each line (units of H).
    f_peak : float
        Hz, the normalising frequency (the peak).
    kernel : tuple of (ndarray, ndarray), optional
        The estimator's spectral window (:func:`window_kernel`): the model is smoothed by it
        before it is compared with `H` (removes the leakage bias of ``zeta``); default none.

    Returns
    -------
    f_n, f_n_std, zeta, zeta_std : float
        NaN when the fit fails (no stable pole).

    Notes
    -----
    Model ``H(s) = (b0 + b1 s + b2 s^2) / (s^2 + 2 zeta r s + r^2)`` in ``s = j f / f_peak``
    with complex ``b`` (a constant phase rotation, e.g. a delay, and the neighbouring modes'
    slowly varying contribution are absorbed in the numerator; ``b2`` only with 8 lines or
    more), ``f_n = r f_peak``. Start: the linearised (Levy) equation error weighted by
    ``1 / (sigma |D|)``, iterated five times (Sanathanan-Koerner) [4]_; then the output error
    ``(H - model) / sigma`` by nonlinear least squares, the model smoothed by `kernel`. Covariance ``(J^T J)^-1`` scaled by the
    reduced chi-square when above 1 (model error, leakage bias).
    """
    f = frequencies
    s = 1j * f / f_peak
    L = f.size
    deg = 2 if L >= 8 else 1
    w0 = 1.0 / np.maximum(sigma, 1e-300)
    D = np.ones(L, complex)
    a1 = a0 = None
    for _ in range(5):
        w = w0 / np.maximum(np.abs(D), 1e-12)
        cols = [H * s, H] + [-(s**k) for k in range(deg + 1)] + [-1j * s**k for k in range(deg + 1)]
        A = np.stack(cols, axis=1) * w[:, None]
        rhs = -H * s * s * w
        AA = np.vstack([A.real, A.imag])
        bb = np.concatenate([rhs.real, rhs.imag])
        sol = np.linalg.lstsq(AA, bb, rcond=None)[0]
        a1, a0 = sol[0], sol[1]
        D = s * s + a1 * s + a0
    if a0 is not None and a0 > 0 and a1 > 0:
        r0, z0 = math.sqrt(a0), a1 / (2 * math.sqrt(a0))
        b0 = sol[2:]
    else:
        r0, z0 = 1.0, 0.01
        b0 = np.zeros(2 * (deg + 1))
    p0 = np.concatenate([[r0, z0], b0])

    kern = None if kernel is None else (1j * np.asarray(kernel[0]) / f_peak, np.asarray(kernel[1]))

    def res(p):
        e = (H - _model(p, s, deg, kern)) * w0
        return np.concatenate([e.real, e.imag])

    try:
        out = scipy.optimize.least_squares(res, p0, x_scale="jac", method="lm" if 2 * L >= p0.size else "trf")
    except (ValueError, np.linalg.LinAlgError):
        return (float("nan"),) * 4
    p = out.x
    if not (p[0] > 0 and p[1] > 0) or not np.all(np.isfinite(p)):
        return (float("nan"),) * 4
    J = out.jac
    dof = max(2 * L - p.size, 1)
    chi2 = float(np.sum(out.fun**2)) / dof
    try:
        cov = np.linalg.pinv(J.T @ J) * max(chi2, 1.0)
    except np.linalg.LinAlgError:
        return float(p[0] * f_peak), float("nan"), float(p[1]), float("nan")
    sr, sz = np.sqrt(max(cov[0, 0], 0.0)), np.sqrt(max(cov[1, 1], 0.0))
    return float(p[0] * f_peak), float(sr * f_peak), float(p[1]), float(sz)


def _fit_lines(Hc, i_pk, lo, hi):
    """The lines around peak index `i_pk` (within [lo, hi)): 1.5 times the half-power
    half-width on each side, at least 4 lines each side."""
    mag = np.abs(Hc)
    half = mag[i_pk] / np.sqrt(2)
    a = i_pk
    while a - 1 >= lo and mag[a - 1] >= half:
        a -= 1
    b = i_pk
    while b + 1 < hi and mag[b + 1] >= half:
        b += 1
    wl = max(int(math.ceil(1.5 * (i_pk - a + 1))), 4)
    wr = max(int(math.ceil(1.5 * (b - i_pk + 1))), 4)
    return slice(max(lo, i_pk - wl), min(hi, i_pk + wr + 1))


# --------------------------------------------------------------------------------------------
# the BLA per level
# --------------------------------------------------------------------------------------------

def _groups(u, mask, fs):
    """(level index, sample mask) per level group of one log."""
    labels, rms = input_levels(u, fs)
    if len(rms) <= 1:
        return [(0, mask)]
    return [(k, mask & (labels == k)) for k in range(len(rms))]


def level_blas(us, ys, masks, fs: float, nperseg: int, *, n_modes: int | None = None, f_band=None,
               window: str | None = None, min_prominence_db: float = 6.0, input_unit: str = "N") -> LevelEvidence:
    """BLA per log and excitation level, each resonance's ``f_n`` and ``zeta`` per level, and the
    test of their level dependence.

    Parameters
    ----------
    us : list of ndarray, shape (n_inputs, n_samples) or (n_samples,)
        Logged input per log (N); the first input is used.
    ys : list of ndarray, shape (n_outputs, n_samples)
        Measured outputs per log (the same channels in every log).
    masks : list of (ndarray of bool, shape (n_samples,), or None)
        Samples to use per log (None: all); only segments wholly inside count.
    fs : float
        Sampling frequency in Hz.
    nperseg : int
        Segment length in samples (e.g. :func:`frf_segment_length`).
    n_modes : int, optional
        Most resonances to follow (the most prominent); default all with `min_prominence_db`.
    f_band : tuple of (float, float), optional
        Band in Hz where resonances are sought (and the H kept); default the input's excited
        band (:func:`~vibroscope.gap.measure.excited_band`).
    window : {'hann', 'boxcar'}, optional
        Default 'boxcar' without overlap when every log's input is periodic with a period that
        divides `nperseg` (whole periods: no leakage), else 'hann' with 50 % overlap.
    min_prominence_db : float, optional
        Least prominence (dB) of a peak of the mode indicator (the normalised mean over outputs
        of ``gamma^2 |H|^2``) at the reference (lowest) level; default 6.
    input_unit : str, optional
        Unit of the input in the description (a closed loop's reference: m); default 'N'.

    Returns
    -------
    LevelEvidence

    Raises
    ------
    ValueError
        If the lists differ in length, `nperseg` or `fs` is not positive, or no log yields a
        segment.

    Notes
    -----
    Levels: each log, split into the level groups of
    :func:`~vibroscope.gap.measure.input_levels` when it holds several. Spectra:
    :func:`vibroscope.spectral.csd_matrix` with the input as the reference channel and the
    samples outside the group set to NaN (so only whole segments inside count), ``H1 = G_uy /
    G_uu``, ``gamma^2 = |G_uy|^2 / (G_uu G_yy)``. Line noise: the real and imaginary parts of H1
    have the standard deviation ``|H| sqrt((1 - gamma^2) / (2 n_e gamma^2))`` (Bendat & Piersol
    [1]_, with ``n_e`` the averages over 1.056 for 50 %-overlapped Hann segments), propagated
    to ``f_n`` and ``zeta`` by the Jacobian of the fit (:func:`fit_mode`); the fitted model is
    smoothed by the Hann spectral window (:func:`window_kernel`), so a resolution of only
    4 lines per half-power bandwidth does not bias ``zeta`` (+15 % without).

    Lines whose input autospectrum lies more than 30 dB below the strongest
    (:data:`~vibroscope.gap.measure.UNEXCITED`) carry no input and are left out (a periodic
    multisine's lines beyond its band, whose H1 at a coherence of 0.2-0.3 otherwise tops the mode
    indicator by 250 dB and hides every resonance).

    Modes: peaks of the normalised mean over outputs of ``gamma^2 |H|^2`` at the lowest level
    (mean coherence at least 0.5, within 40 dB of the highest), kept when the fit there gives a
    half-power bandwidth ``2 zeta f_n`` of at least half a line (narrower: a ripple); each is
    fitted on the output where it is most prominent, at every level, around the highest line
    within +-15 % of its frequency (no closer to a neighbouring mode than half the distance).
    Test: from the lowest level where the mode was fitted to each other level, the relative
    change and its z-score; level dependent when at some level ``|z| > 3`` and the change
    exceeds 0.5 % (frequency) or 10 % (damping) [2]_ [3]_.
    """
    fs = float(fs)
    nperseg = int(nperseg)
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
    if nperseg < 8:
        raise ValueError(f"{nperseg=} must be at least 8 samples")
    if not (len(us) == len(ys) == len(masks)):
        raise ValueError(f"us, ys and masks must have one entry per log: {len(us)=}, {len(ys)=}, {len(masks)=}")
    us = [np.atleast_2d(np.asarray(u, dtype=float))[:1] for u in us]
    ys = [np.atleast_2d(np.asarray(y, dtype=float)) for y in ys]
    masks = [np.ones(u.shape[1], bool) if m is None else np.asarray(m, bool) for u, m in zip(us, masks)]
    if window is None:
        periods = [detect_period(u[0][m] if m.all() else u[0], fs) for u, m in zip(us, masks)]
        window = "boxcar" if all(p is not None and nperseg % p == 0 for p in periods) else "hann"
    if window not in ("hann", "boxcar"):
        raise ValueError(f"{window=} must be 'hann' or 'boxcar'")
    noverlap = nperseg // 2 if window == "hann" else 0
    n_eff_fac = 1.056 if window == "hann" else 1.0
    if f_band is None:
        f_band = excited_band(np.concatenate([u for u in us], axis=1), fs, nperseg)
    f_lo, f_hi = float(f_band[0]), float(f_band[1])

    raw = []
    for i, (u, y, m) in enumerate(zip(us, ys, masks)):
        for k, g in _groups(u, m, fs):
            if g.sum() < nperseg:
                continue
            x = np.vstack([u, y])
            x = np.where(g[None, :], x, np.nan)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    G = csd_matrix(x, fs, nperseg=nperseg, noverlap=noverlap, window=window, references=0, workers=1)
                except ValueError:
                    continue
            n_avg = int(G.n_averages[0, 0]) if G.n_averages is not None else int(G.settings["n_averages"])
            if n_avg < 2:
                continue
            f = G.frequencies
            sel = (f >= f_lo) & (f <= f_hi) & (f > 0)
            # a line whose input lies UNEXCITED (30 dB) below the strongest carries no input (beyond
            # a multisine's band edges, or between its lines over whole periods): its H1 is the
            # ratio of two residues, not a response, and is left out
            g_in = G.G[:, 0, 0].real
            if np.any(f > 0):
                sel &= g_in >= UNEXCITED * float(np.max(g_in[f > 0]))
            Guu = G.G[sel, 0, 0].real
            Guy = G.G[sel, 0, 1:]
            Gyy = np.real(np.diagonal(G.G[sel], axis1=1, axis2=2))[:, 1:]
            with np.errstate(divide="ignore", invalid="ignore"):
                H = Guy / Guu[:, None]
                coh = np.clip(np.abs(Guy) ** 2 / (Guu[:, None] * Gyy), 0.0, 1.0)
            rms = float(np.sqrt(np.mean(u[0, g] ** 2)))
            raw.append((i, k, rms, n_avg, f[sel], H, np.nan_to_num(coh)))
    if not raw:
        raise ValueError(f"no log holds a whole segment of {nperseg=} samples inside its mask")
    raw.sort(key=lambda t: t[2])
    f = raw[0][4]
    n_out = raw[0][5].shape[1]

    # modes from the lowest level
    ind_parts = []
    H0, c0 = raw[0][5], raw[0][6]
    for o in range(n_out):
        p2 = np.abs(H0[:, o]) ** 2 * c0[:, o]
        ind_parts.append(p2 / max(np.nanmax(p2), 1e-300))
    ind = np.nanmean(np.array(ind_parts), axis=0)
    lind = 10 * np.log10(np.maximum(ind, 1e-30))
    pk, props = scipy.signal.find_peaks(lind, prominence=min_prominence_db)
    good = (np.mean(c0[pk], axis=1) >= 0.5) & (lind[pk] >= -40.0)
    pk, props = pk[good], {key: v[good] for key, v in props.items()}
    f_modes = f[pk] if pk.size else np.array([])
    outs = []
    for ip in pk:
        prom = []
        for o in range(n_out):
            mag = np.abs(H0[:, o])
            prom.append(mag[ip] / max(np.median(mag), 1e-300))
        outs.append(int(np.argmax(prom)))

    kernel = window_kernel(window, nperseg, fs)
    df = fs / nperseg
    fits = []
    for (i, k, rms, n_avg, fk, H, coh) in raw:
        cohc = np.clip(coh, 1e-3, 1 - 1e-9)
        eps = np.sqrt((1 - cohc) / (2 * (n_avg / n_eff_fac) * cohc))
        res = np.full((4, f_modes.size), np.nan)
        for j in range(f_modes.size):
            fr = f_modes[j]
            lo_f, hi_f = 0.85 * fr, 1.15 * fr
            if j > 0:
                lo_f = max(lo_f, 0.5 * (f_modes[j - 1] + fr))
            if j < f_modes.size - 1:
                hi_f = min(hi_f, 0.5 * (f_modes[j + 1] + fr))
            lo, hi = int(np.searchsorted(fk, lo_f)), int(np.searchsorted(fk, hi_f, side="right"))
            if hi - lo < 3:
                continue
            o = outs[j]
            Hc = H[:, o]
            mag = np.abs(Hc)
            i_pk = lo + int(np.nanargmax(mag[lo:hi]))
            if (i_pk == lo and lo > 0) or (i_pk == hi - 1 and hi < fk.size):
                # the window's largest line at its edge, with lines beyond: no resonance inside it
                # here, the flank of one outside (a low level's noise split one mode into two
                # peaks, fresh seed 7102 case 001 with an unlogged disturbance: the second's
                # window at the higher levels held the flank of the first, fitted as a +1.8 %
                # shift at z 4.2, and the linear verdict was barred)
                continue
            sl = _fit_lines(Hc, i_pk, lo, hi)
            if sl.stop - sl.start < 5:
                continue
            sig = np.maximum(eps[sl, o] * mag[sl], 1e-9 * mag[i_pk])
            fit = fit_mode(fk[sl], Hc[sl], sig, float(fk[i_pk]), kernel=kernel)
            if 2 * fit[2] * fit[0] >= 0.5 * df and fit[2] < 0.3:  # else a ripple, or no resonance
                res[:, j] = fit
        fits.append(res)
    # a resonance is fitted at the reference (lowest) level, with a half-power bandwidth of at
    # least half a line (narrower ones are ripples of the estimate, not modes)
    ref = fits[0]
    keep = np.flatnonzero(np.isfinite(ref[0]) & np.isfinite(ref[1]))
    if n_modes is not None and keep.size > n_modes:
        keep = np.sort(keep[np.argsort(props["prominences"][keep])[::-1][: int(n_modes)]])
    outs = [outs[j] for j in keep]
    nm = keep.size
    levels = [LevelBLA(log=i, level=k, rms=rms, n_averages=n_avg, frequencies=_ro(fk), H=_ro(H),
                       coherence=_ro(coh), natural_frequencies=_ro(r[0, keep]),
                       natural_frequency_std=_ro(r[1, keep]), damping_ratios=_ro(r[2, keep]),
                       damping_std=_ro(r[3, keep]))
              for (i, k, rms, n_avg, fk, H, coh), r in zip(raw, fits)]

    modes = []
    nan = float("nan")
    for j in range(nm):
        fn = np.array([lv.natural_frequencies[j] for lv in levels])
        sf = np.array([lv.natural_frequency_std[j] for lv in levels])
        ze = np.array([lv.damping_ratios[j] for lv in levels])
        sz = np.array([lv.damping_std[j] for lv in levels])
        ok = np.flatnonzero(np.isfinite(fn) & np.isfinite(sf) & np.isfinite(ze) & np.isfinite(sz))
        dfr, zf, dzr, zz = (np.full(len(levels), np.nan) for _ in range(4))
        if ok.size:
            a0 = ok[0]
            for i_l in ok[1:]:
                dfr[i_l] = (fn[i_l] - fn[a0]) / fn[a0]
                dzr[i_l] = (ze[i_l] - ze[a0]) / ze[a0]
                with np.errstate(divide="ignore", invalid="ignore"):
                    zf[i_l] = (fn[i_l] - fn[a0]) / np.hypot(sf[i_l], sf[a0])
                    zz[i_l] = (ze[i_l] - ze[a0]) / np.hypot(sz[i_l], sz[a0])
        f_ref = float(fn[ok[0]]) if ok.size else float(f_modes[keep[j]])
        sig_f = (np.abs(zf) > Z_SIGNIFICANT) & (np.abs(dfr) > FREQ_CHANGE)
        sig_z = (np.abs(zz) > Z_SIGNIFICANT) & (np.abs(dzr) > DAMPING_CHANGE)
        if sig_f.any():
            i_s = int(np.nanargmax(np.where(sig_f, np.abs(zf), -1.0)))
            trend = "hardening" if dfr[i_s] > 0 else "softening"
        else:
            trend = "none"
        last = ok[-1] if ok.size >= 2 else None
        pick = (lambda v: nan if last is None else float(v[last]))
        modes.append(ModeTrend(natural_frequency=f_ref, output=outs[j], frequency_change=pick(dfr),
                               frequency_z=pick(zf), damping_change=pick(dzr), damping_z=pick(zz),
                               frequency_changes=_ro(dfr), frequency_zs=_ro(zf), damping_changes=_ro(dzr),
                               damping_zs=_ro(zz), level_dependent=bool(sig_f.any() or sig_z.any()),
                               trend=trend, damping_rises=bool(np.any(sig_z & (dzr > 0)))))
    dep = [m for m in modes if m.level_dependent]
    trended = [m for m in modes if m.trend != "none"]
    trend = max(trended, key=lambda m: abs(m.frequency_z)).trend if trended else "none"
    damping_rises = any(m.damping_rises for m in modes)
    if len(levels) < 2:
        desc = "one excitation level: no level dependence can be tested"
    elif not modes:
        desc = f"{len(levels)} levels, no resonance found in {f_lo:.3g}-{f_hi:.3g} Hz"
    else:
        parts = [f"{m.natural_frequency:.4g} Hz: f_n {100 * m.frequency_change:+.2f} % (z {m.frequency_z:+.1f}), "
                 f"zeta {100 * m.damping_change:+.1f} % (z {m.damping_z:+.1f})" for m in modes]
        desc = (f"{len(levels)} levels (input RMS {levels[0].rms:.3g} -> {levels[-1].rms:.3g} {input_unit}): "
                + "; ".join(parts) + (f" -> level dependent, {trend}" if dep else " -> no level dependence"))
    return LevelEvidence(levels=tuple(levels), modes=tuple(modes), level_dependent=bool(dep), trend=trend,
                         damping_rises=damping_rises, f_band=(f_lo, f_hi), fs=fs, nperseg=nperseg,
                         window=window, description=desc)
