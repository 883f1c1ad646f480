"""Time bases of logged topics: rate, jitter, gaps, duplicates, reordering, outlier stamps;
resampling topics of different rates onto one uniform grid, never across a gap.

Tolerances (documented here, used by :mod:`vibroscope.io._grid`): consecutive stamps more
than :data:`GAP_PERIODS` median periods apart bracket a *gap* (for stamps with jitter only
when the stamps around them are a whole period later than their message count says,
:func:`fit_stamps`), and nothing is interpolated in it (the grid samples there are NaN); a
stamp within :data:`ON_GRID_TOL` of a period of a grid point *is on the grid*; a stamp more
than :data:`OUTLIER_PERIODS` periods (and at least :data:`OUTLIER_MIN_S`) away from its
neighbours or its own log time is an *outlier* (:func:`outlier_stamps`) and dropped.

:func:`resample_to_grid` is the resampler for *time-stamped* samples (jitter, gaps, any rate
ratio). Integer-factor rate changes of uniform records are elsewhere, for reasons given in
:mod:`vibroscope.models.resample` (band-limited upsampling and FIR decimation of simulations)
and :func:`vibroscope.pipeline.decimate` (IIR decimation to the analysis band).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Sequence

import numpy as np

__all__ = ["TimebaseReport", "StampFit", "analyse_stamps", "fit_stamps", "outlier_stamps", "nudged_stamps",
           "resample_to_grid", "stamps_ns", "GAP_PERIODS", "GAP_WINDOW", "GAP_SIGMAS", "ON_GRID_TOL",
           "OUTLIER_PERIODS", "OUTLIER_MIN_S", "NUDGE_SIGMAS", "DOWNSAMPLE_RATIO", "INVALID_STAMP_NS"]

#: increments longer than this many median periods are gaps: no interpolation across them
GAP_PERIODS = 1.5
#: a stamp within this fraction of a period of a grid point is taken as that grid sample
ON_GRID_TOL = 0.01
#: a stamp this many median periods (and at least OUTLIER_MIN_S) off its neighbours is an outlier
OUTLIER_PERIODS = 1000.0
#: least deviation in s of an outlier stamp
OUTLIER_MIN_S = 1.0
#: a stamp whose offset from its log time departs from its neighbours' by this many robust standard
#: deviations of that offset (and by more than ON_GRID_TOL of a period) is a nudged stamp (:func:`nudged_stamps`)
NUDGE_SIGMAS = 8.0
#: the stamp of a message whose ``header.stamp.nanosec`` is not below 1e9 (an invalid time, :func:`stamps_ns`):
#: far below any real stamp, so every rule of :func:`outlier_stamps` drops it; no difference of stamps overflows
INVALID_STAMP_NS = -(1 << 62)
#: a source rate this much above the output rate is low-passed before resampling (below, the
#: band that could alias, ``fs/2 .. fs_src/2``, is under 0.5 % of the output band)
DOWNSAMPLE_RATIO = 1.01


@dataclass(frozen=True, kw_only=True)
class TimebaseReport:
    """What the time stamps of one topic look like and what was done to them.

    Attributes
    ----------
    topic : str
        Topic name.
    n_messages : int
        Messages read (before dropping duplicates).
    fs_est : float
        Estimated sample rate in Hz (:func:`fit_stamps`): for regular stamps 1 / mean of the
        increments dt outside gaps, rounded to the fewest decimals that stay within the ns
        rounding of the stamps; for stamps with jitter 1 / the slope of the stamps against
        the message count within the gap-free runs, rounded within three standard errors of
        the slope (``nan`` with fewer than 2 stamps).
    jitter_s : float
        Standard deviation of the stamp increments dt in s (gaps excluded).
    max_dev_s : float
        Largest ``|dt - median(dt)|`` in s (gaps excluded).
    gaps : int
        Increments that hold missing messages (:func:`fit_stamps`: longer than
        :data:`GAP_PERIODS` (1.5) median periods for regular stamps; for stamps with jitter,
        only where the stamps around are a whole period later than their count). On the output grid
        nothing is interpolated across them: the grid samples inside are NaN and listed in
        ``Signals.meta["gaps"]``.
    gap_time_s : float
        Time missing in gaps, ``sum(dt - T)`` over gaps, in s (``T`` the median increment,
        or for stamps with jitter the fitted period, :func:`fit_stamps`).
    gap_where_s : tuple of (float, float)
        (start time relative to the first stamp in s, increment across the gap in s) of the
        first 20 gaps.
    duplicates : int
        Messages dropped because their stamp equals the previous one.
    out_of_order : int
        Stamps earlier than the one logged before them (they were sorted).
    time_source : str
        ``"header.stamp"`` or ``"log_time"``.
    resampled : bool
        Whether the samples were interpolated onto the output grid (within each contiguous
        run of stamps; False: placed by index, or taken as they are).
    outliers : int
        Messages dropped before this analysis because their stamp was an outlier
        (:func:`outlier_stamps`); default 0.
    missing : int
        Messages missing in the gaps (:func:`fit_stamps`); default 0.
    """

    topic: str
    n_messages: int
    fs_est: float
    jitter_s: float
    max_dev_s: float
    gaps: int
    gap_time_s: float
    gap_where_s: tuple[tuple[float, float], ...]
    duplicates: int
    out_of_order: int
    time_source: str = "log_time"
    resampled: bool = False
    outliers: int = 0
    missing: int = 0

    def as_dict(self) -> dict[str, Any]:
        """A plain dict (JSON-serialisable)."""
        d = asdict(self)
        d["gap_where_s"] = [list(g) for g in self.gap_where_s]
        return d


def median(x: np.ndarray) -> float:
    """``np.median`` of a 1-D array without NaN (the same value, to the bit), faster on long arrays.

    A sorted strided sample brackets the middle ranks; only the elements inside that bracket are
    partitioned (the median of stamp increments or offsets lies in a narrow band). Falls back to
    ``np.median`` when the bracket misses, so the result never depends on the sample.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Integer or float values, no NaN.

    Returns
    -------
    float
        The median (mean of the two middle values for even `n`), as ``np.median`` gives it.
    """
    x = np.asarray(x)
    n = x.size
    if n < 1 << 14:
        return float(np.median(x))
    s = np.sort(x[:: max(1, n >> 12)])
    k, d = s.size // 2, 4 * int(np.sqrt(s.size)) + 2
    lo, hi = s[max(0, k - d)], s[min(s.size - 1, k + d)]
    below = int(np.count_nonzero(x < lo))
    r1, r2 = (n - 1) // 2 - below, n // 2 - below
    if lo == hi:  # one value fills the bracket (stamps exactly on a grid): count it, no partition
        if r1 >= 0 and r2 < np.count_nonzero(x == lo):
            return float(lo)
        return float(np.median(x))
    inside = x[(x >= lo) & (x <= hi)]
    if r1 < 0 or r2 >= inside.size:
        return float(np.median(x))
    inside.partition((r1, r2))  # a copy already: in place
    return float(np.mean(inside[[r1, r2]]))


def analyse_stamps(topic: str, stamps_ns: np.ndarray, *, time_source: str = "log_time", outliers: int = 0):
    """Sort stamps, drop duplicates and describe the time base.

    Parameters
    ----------
    topic : str
        Topic name (for the report).
    stamps_ns : ndarray of int64, shape (n,)
        Stamps in ns, in the order the messages were logged.
    time_source : str, optional
        Where the stamps came from, recorded in the report.
    outliers : int, optional
        Outlier stamps dropped before (recorded in the report); default 0.

    Returns
    -------
    order : ndarray of int, shape (m,)
        Indices into `stamps_ns` of the kept messages, in increasing stamp order.
    report : TimebaseReport

    Notes
    -----
    The rate and the gaps are those of :func:`fit_stamps` (a line fit of the stamps against
    the message count for stamps with jitter).
    """
    t = np.asarray(stamps_ns, np.int64)
    n = t.size
    d = np.diff(t)
    out_of_order = int(np.count_nonzero(d < 0)) if n > 1 else 0
    if n < 2 or d.min() > 0:  # the usual case: increasing, no duplicate (no sort, no gather)
        order, ts, duplicates = np.arange(n), t, 0
    else:
        order = np.argsort(t, kind="stable")
        ts = t[order]
        keep = np.ones(n, bool)
        keep[1:] = ts[1:] != ts[:-1]
        duplicates = int(n - keep.sum())
        order, ts = order[keep], ts[keep]
    fs_est = jitter = max_dev = gap_time = float("nan")
    gaps = missing = 0
    where: tuple[tuple[float, float], ...] = ()
    if ts.size >= 2:
        dt = np.diff(ts).astype(np.float64) * 1e-9
        fit = fit_stamps(ts, dt_s=dt)
        isgap = fit.gap
        fs_est = fit.fs
        gaps = int(isgap.sum())
        missing = int(fit.missing.sum())
        gap_time = float(np.sum(dt[isgap] - fit.period_s))
        idx = np.flatnonzero(isgap)[:20]
        where = tuple((float((ts[i] - ts[0]) * 1e-9), float(dt[i])) for i in idx)
        reg = dt[~isgap] if isgap.any() else dt
        jitter = float(np.std(reg)) if reg.size else 0.0
        max_dev = (fit.max_dev_s if np.isfinite(fit.max_dev_s) else
                   float(np.max(np.abs(reg - fit.median_s))) if reg.size else 0.0)
    rep = TimebaseReport(
        topic=topic, n_messages=n, fs_est=fs_est, jitter_s=jitter, max_dev_s=max_dev, gaps=gaps, gap_time_s=gap_time,
        gap_where_s=where, duplicates=duplicates, out_of_order=out_of_order, time_source=time_source,
        outliers=outliers, missing=missing,
    )
    return order, rep


@dataclass(frozen=True, kw_only=True)
class StampFit:
    """The time base of one stream of increasing stamps (:func:`fit_stamps`).

    Attributes
    ----------
    fs : float
        Rate in Hz, ``1 / period_s`` rounded to the fewest decimals within its uncertainty
        (the ns rounding of the stamps, or three standard errors of the fitted slope).
    period_s : float
        Period in s, unrounded (the median increment for regular stamps).
    median_s : float
        Median stamp increment in s.
    jitter_s : float
        Robust standard deviation (1.4826 MAD) in s of the stamps about the fitted line
        (0 for regular stamps).
    regular : bool
        Whether the increments outside gaps are all within :data:`ON_GRID_TOL` of a period
        of the median (then no line is fitted: the rate is that of the mean increment).
    gap : ndarray of bool, shape (n - 1,)
        Whether each increment holds missing messages.
    missing : ndarray of int, shape (n - 1,)
        Messages missing in each increment (0 outside gaps).
    max_dev_s : float
        Largest deviation in s of an increment outside the gaps from the median increment
        (regular stamps; NaN when a line was fitted).
    """

    fs: float
    period_s: float
    median_s: float
    jitter_s: float
    regular: bool
    gap: np.ndarray
    missing: np.ndarray
    max_dev_s: float = float("nan")


def _window_means(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Means of ``x[lo:hi]`` per pair (``hi > lo``), by a cumulative sum."""
    c = np.r_[0.0, np.cumsum(x)]
    return (c[hi] - c[lo]) / (hi - lo)


def fit_stamps(ts_ns: np.ndarray, dt_s: np.ndarray | None = None) -> StampFit:
    """Rate, gaps and jitter of increasing stamps: a line fit against the message count.

    Parameters
    ----------
    ts_ns : ndarray of int64, shape (n,)
        Stamps in ns, strictly increasing, ``n >= 2``.
    dt_s : ndarray of float64, shape (n - 1,), optional
        Their increments in s, ``np.diff(ts_ns) * 1e-9``, when the caller has them already.

    Returns
    -------
    StampFit

    Notes
    -----
    Let ``T0`` be the median increment. *Regular stamps* (every increment that is not a gap
    within :data:`ON_GRID_TOL` of ``T0``): an increment over :data:`GAP_PERIODS` ``T0`` is a
    gap, the rate is 1 / the mean increment outside gaps (exactly as before jitter was
    considered; clean logs keep their results to the bit).

    *Stamps with jitter* (``t_i = a_r + T n_i + e_i``: message count ``n_i``, one intercept
    ``a_r`` per gap-free run ``r``, jitter ``e_i``): an increment over :data:`GAP_PERIODS`
    periods is only a candidate, since the jitter of its two stamps can make it so. It is a gap
    when the stamps around it, averaged over up to :data:`GAP_WINDOW` stamps on each side
    (first not beyond the neighbouring candidates, then, twice more, not beyond the
    neighbouring gaps found), lie at least half a period further apart than
    their message count says: ``shift = mean(t - T n)_after - mean(t - T n)_before >= T / 2``;
    or, where a side has fewer than ``GAP_WINDOW / 4`` stamps to average (gaps or candidates
    close by), when the increment itself exceeds ``T + 6 sqrt(2) sigma`` (:data:`GAP_SIGMAS`;
    ``sigma`` the jitter of the stamps about the line, so ``sqrt(2) sigma`` that of an
    increment: a candidate the jitter of its two stamps cannot explain).
    A missing message shifts every later stamp by a whole period ``T``, while the jitter of
    the averages is ``sigma sqrt(2 / L)``, so jitter of a few tenths of a period (``sigma``
    0.2 T: 7 standard deviations at L = 16) is not a gap and a lost message is. Missing
    messages in a gap: ``round(shift / T)`` when the stamps around show the step, else
    ``round(dt / T) - 1`` (at least 1; the same for stamps without jitter).
    Where the gaps so found come more often than every :data:`GAP_WINDOW` messages on average,
    the stamps are not a clock with jitter and lost messages (bursts of log times, messages
    kept at irregular multiples of a base period): the gap rule of regular stamps applies
    (gaps over 1.5 median increments), and the rate is 1 / ``Tw`` (below), which does not
    depend on where the log ends (1 / the mean increment outside the gaps did: it keeps the
    short increments of a burst and drops the long one before it).
    The period ``T`` is the least-squares slope of the stamps against the message count with
    one intercept per gap-free run, refitted once without stamps more than 6 robust standard
    deviations off the line. It starts from the runs between increments over 1.5 ``Tw``
    (``Tw`` the median increment over :data:`GAP_WINDOW` messages, divided by their number:
    robust to bursts), and gaps and line are iterated three times.
    """
    ts = np.asarray(ts_ns, np.int64)
    n = ts.size
    dt = np.diff(ts).astype(np.float64) * 1e-9 if dt_s is None else dt_s
    med = float(median(dt))
    isgap = dt > GAP_PERIODS * med
    anygap = bool(isgap.any())
    reg = dt[~isgap] if anygap else dt
    dev = float(max(reg.max() - med, med - reg.min())) if reg.size else 0.0
    if dev <= ON_GRID_TOL * med:
        miss = (np.where(isgap, np.maximum(1, np.rint(dt / med) - 1), 0).astype(np.int64) if anygap
                else np.zeros(n - 1, np.int64))
        return StampFit(fs=_rate(reg, med), period_s=med, median_s=med, jitter_s=0.0, regular=True, gap=isgap,
                        missing=miss, max_dev_s=dev)
    rel = (ts - ts[0]).astype(np.float64) * 1e-9  # s from the first stamp
    w = min(GAP_WINDOW, n - 1)  # the median increment over w messages / w: robust to bursts of stamps
    tw = float(median(ts[w:] - ts[:-w])) * 1e-9 / w
    isgap = dt > GAP_PERIODS * tw
    T, jit = _fit_period(rel, isgap)  # first from the runs between increments over 1.5 such periods
    miss = np.zeros(n - 1, np.int64)
    bounds = None
    for _ in range(3):
        cand = np.flatnonzero(dt > GAP_PERIODS * T)
        isgap = np.zeros(n - 1, bool)
        miss = np.zeros(n - 1, np.int64)
        if cand.size:
            resid = rel - T * np.arange(n)  # count without gaps: a lost message is a step of T
            b = cand if bounds is None else bounds  # windows end at the candidates, then at the gaps found
            j = np.searchsorted(b, cand)  # b[j] == cand when cand is in b
            prev = np.where(j > 0, b[np.maximum(j - 1, 0)] if b.size else -1, -1)
            k = np.searchsorted(b, cand, "right")
            nxt = np.where(k < b.size, b[np.minimum(k, b.size - 1)] if b.size else n - 1, n - 1)
            lo = np.maximum(prev + 1, cand + 1 - GAP_WINDOW)
            hi = np.minimum(nxt, cand + GAP_WINDOW)  # right window: stamps cand+1 .. hi
            shift = _window_means(resid, cand + 1, hi + 1) - _window_means(resid, lo, cand + 1)
            step = shift >= 0.5 * T
            # with few stamps on a side to average, an increment beyond what the jitter of 2 stamps explains
            short = np.minimum(cand + 1 - lo, hi - cand) < GAP_WINDOW // 4
            long = short & (dt[cand] > T + GAP_SIGMAS * np.sqrt(2.0) * jit)
            m = np.where(step, np.rint(shift / T), np.rint(dt[cand] / T) - 1).astype(np.int64)
            ok = step | long
            isgap[cand[ok]] = True
            miss[cand[ok]] = np.maximum(1, m[ok])
        bounds = np.flatnonzero(isgap)
        T, jit = _fit_period(rel, isgap)
    if (isgap.sum() + 1) * GAP_WINDOW > n:  # runs shorter than the window on average: not a clock with
        isgap = dt > GAP_PERIODS * med  # jitter and lost messages (bursts): the rule of regular stamps
        miss = np.where(isgap, np.maximum(1, np.rint(dt / med) - 1), 0).astype(np.int64)
        # rate: 1 / the median increment over GAP_WINDOW messages per message (``tw``), not 1 / the mean
        # increment outside the gaps: that mean keeps the short increments of a burst and drops the long
        # ones before it, so it grew with the share of bursty stretches (a log's first seconds read at
        # 160 Hz, the whole log at 100 Hz); the windowed median is the same wherever the log ends
        return StampFit(fs=round_rate(1.0 / tw, 1.5e-9 / max(rel[-1], 1e-300)), period_s=med, median_s=med,
                        jitter_s=jit, regular=False, gap=isgap, missing=miss)
    snap = 3.0 * _slope_se(rel, isgap, jit) / T if np.isfinite(jit) else 0.0
    fs = round_rate(1.0 / T, max(1.5e-9 / max(rel[-1], 1e-300), snap))
    return StampFit(fs=fs, period_s=T, median_s=med, jitter_s=jit, regular=False, gap=isgap, missing=miss)


#: stamps averaged on each side of a candidate gap (:func:`fit_stamps`)
GAP_WINDOW = 16
#: an increment this many standard deviations of the increments' jitter over the period is a gap
#: (where too few stamps around it can be averaged, :func:`fit_stamps`)
GAP_SIGMAS = 6.0


def _run_ids(isgap: np.ndarray) -> np.ndarray:
    """Run number of each stamp (n,) from the gap flags of the increments (n - 1,)."""
    return np.r_[0, np.cumsum(isgap)]


def _fit_period(rel: np.ndarray, isgap: np.ndarray) -> tuple[float, float]:
    """(period, robust residual std) in s: slope of `rel` against the count within runs, one
    intercept per run; refitted once without the stamps more than 6 robust std off the line."""
    run = _run_ids(isgap)
    nr = int(run[-1]) + 1
    idx = np.arange(rel.size, dtype=np.float64)
    if nr > 1:
        idx -= np.flatnonzero(np.r_[True, isgap])[run]  # count within its run
    w = None
    T = jit = 0.0
    for _ in range(2):
        if nr == 1:  # one run (no gap): plain means
            sel = slice(None) if w is None else w
            mi, mt = np.mean(idx[sel]), np.mean(rel[sel])
            di, dtm = idx - mi, rel - mt
        else:
            wf = None if w is None else w.astype(np.float64)
            cnt = np.bincount(run, wf, nr)
            cnt[cnt == 0] = 1
            mi = np.bincount(run, idx if wf is None else wf * idx, nr) / cnt
            mt = np.bincount(run, rel if wf is None else wf * rel, nr) / cnt
            di, dtm = idx - mi[run], rel - mt[run]
        sxx = float(np.dot(di, di) if w is None else np.dot(di[w], di[w]))
        if sxx <= 0:  # every run a single stamp: no slope to fit
            d = np.diff(rel)
            T = float(np.median(d[~isgap])) if (~isgap).any() else float(np.median(d))
        else:
            T = float(np.dot(di, dtm) if w is None else np.dot(di[w], dtm[w])) / sxx
        r = dtm - T * di
        jit = 1.4826 * float(median(np.abs(r - median(r))))
        keep = np.abs(r) <= 6.0 * jit
        if jit <= 0 or keep.all():
            break
        w = keep
    return T, jit


def _slope_se(rel: np.ndarray, isgap: np.ndarray, jit: float) -> float:
    """Standard error in s of the fitted period: jitter / sqrt(sum of squared centred counts)."""
    run = _run_ids(isgap)
    idx = np.arange(rel.size) - np.flatnonzero(np.r_[True, isgap])[run]
    nr = run.max() + 1
    cnt = np.bincount(run, None, nr)
    mi = np.bincount(run, idx, nr) / np.where(cnt > 0, cnt, 1)
    sxx = float(np.sum((idx - mi[run]) ** 2))
    return jit / np.sqrt(sxx) if sxx > 0 else float("inf")


def round_rate(fs: float, rel_tol: float) -> float:
    """`fs` rounded to the fewest decimals (0 to 6) within the relative tolerance `rel_tol`."""
    for d in range(0, 7):
        r = round(fs, d)
        if r > 0 and abs(r - fs) <= rel_tol * fs:
            return r
    return fs


def stamps_ns(sec: np.ndarray, nanosec: np.ndarray) -> np.ndarray:
    """ROS 2 ``builtin_interfaces/Time`` fields as int64 ns; an invalid time is :data:`INVALID_STAMP_NS`.

    Parameters
    ----------
    sec : ndarray of int, shape (n,)
        ``header.stamp.sec``.
    nanosec : ndarray of int, shape (n,)
        ``header.stamp.nanosec``; valid below 1e9 (ROS 2 ``builtin_interfaces/msg/Time``:
        "nanosec: the nanoseconds component, valid in the range [0, 1e9)").

    Returns
    -------
    ndarray of int64, shape (n,)
        ``sec * 1e9 + nanosec``, and :data:`INVALID_STAMP_NS` where ``nanosec >= 1e9`` (a flipped
        bit there would move the stamp by up to 3.3 s while looking like any other stamp); such
        stamps are outliers of :func:`outlier_stamps`, dropped and counted.
    """
    ns = np.asarray(nanosec)
    t = np.asarray(sec).astype(np.int64) * 1_000_000_000 + ns
    bad = ns >= 1_000_000_000
    if bad.any():
        t = np.where(bad, INVALID_STAMP_NS, t)
    return t


def _robust_std(x: np.ndarray) -> float:
    """1.4826 times the median absolute deviation of `x` (0 for an empty array)."""
    if x.size == 0:
        return 0.0
    return 1.4826 * float(median(np.abs(x - median(x))))


def _nanmedian_rows(a: np.ndarray) -> np.ndarray:
    """Median of each row of `a` without its NaN (NaN for an all-NaN row), no warning."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(a, axis=1) if a.size else np.zeros(a.shape[0])


def nudged_stamps(stamps_ns: np.ndarray, log_times_ns: np.ndarray, *, sigmas: float = NUDGE_SIGMAS,
                  window: int = 4) -> np.ndarray:
    """Which header stamps were moved by less than the outlier threshold: they disagree with their
    log time and with the stamps around them.

    Parameters
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Header stamps in ns, in the order the messages were logged.
    log_times_ns : ndarray of int64, shape (n,)
        The messages' log times in ns (the second clock).
    sigmas : float, optional
        Threshold in robust standard deviations (default :data:`NUDGE_SIGMAS`, 8).
    window : int, optional
        Neighbours on each side that a stamp is compared with (default 4).

    Returns
    -------
    ndarray of bool, shape (n,)
        True for a nudged stamp (False everywhere with fewer than ``2 window + 1`` stamps).

    Notes
    -----
    With ``T`` the median positive stamp increment, a stamp ``t_i`` with log time ``l_i`` is nudged
    when

    1. its offset ``t_i - l_i`` departs from the median offset of its ``2 window`` neighbours (in
       logging order) by more than ``tol_l = max(sigmas s_l, ON_GRID_TOL T)``, ``s_l`` the robust
       standard deviation (1.4826 MAD) of the offsets' second differences
       ``o_i - (o_{i-1} + o_{i+1}) / 2``: the stamp moved against the log time, and
    2. either (a) it is off the grid of the stamps around it *in time*: the phase
       ``|(t_i - t_j) mod T|`` (the mod taken in ``[-T/2, T/2]``) has a median beyond
       ``tol_p = max(sigmas s_p, ON_GRID_TOL T)`` over the ``window`` stamps before it and over
       the ``window`` after it (``s_p`` the robust standard deviation of the phases of
       consecutive stamps; only where ``tol_p < T / 2``, i.e. the stamps keep a grid), or (b) it
       is off the sequence *in logging order*: it departs, with the same sign, by more than
       ``max(sigmas s_t, 1.5 T)`` from both predictions ``median(t_j - (j - i) T)`` of the
       ``window`` stamps logged before it and after it (``s_t`` the robust standard deviation of
       the stamps' second differences).

    A stamp moved by ``delta`` meets 1 and 2(a) for ``ON_GRID_TOL T < |delta|`` (off the grid,
    above the log times' jitter), and 1 and 2(b) for ``|delta| > 1.5 T`` (beyond the neighbour
    it passes). Two messages logged in swapped order (stamps one period out of logging order,
    each on the grid) meet neither 2(a) nor 2(b); a late log time alone, or a gap, fails 1 or 2.
    Not told apart: a move by a whole number of periods of at most 1.5 (onto a neighbour's grid
    point, or into a gap), and moves below ``tol_l`` where the log times jitter more than the
    stamps (such a stamp, off the grid of the others, is still left out of an on-grid topic by
    :mod:`vibroscope.io._grid`).
    """
    t = np.asarray(stamps_ns, np.int64)
    n = t.size
    out = np.zeros(n, bool)
    if n < 2 * window + 1:
        return out
    off = t - np.asarray(log_times_ns, np.int64)
    r2o = 2 * off[1:-1] - off[:-2] - off[2:]  # twice the second difference, exact in int64
    if not r2o.any():  # the usual case: a constant offset (or stamps that are the log times)
        return out
    step = max(1, n >> 16)  # tolerances from a strided sample of 65536: statistics, not every stamp
    d = np.diff(t[::step]) if step > 1 else np.diff(t)
    pos = d[d > 0]
    if pos.size == 0:
        return out
    T = float(median(pos)) / step
    tol_l = max(sigmas * _robust_std(r2o[::step].astype(np.float64)) / 2, ON_GRID_TOL * T)
    cand = np.flatnonzero(np.abs(r2o) > tol_l) + 1  # a moved stamp moves its own second difference fully
    cand = np.unique(np.r_[cand, [0, n - 1]])  # the ends have no second difference: always examined
    w = window
    rel = np.r_[np.arange(-w, 0), np.arange(1, w + 1)]
    j = cand[:, None] + rel[None, :]
    inr = (j >= 0) & (j < n)
    jc = np.clip(j, 0, n - 1)
    nb = np.where(inr, (off[jc] - off[cand][:, None]).astype(np.float64), np.nan)
    c1 = np.abs(_nanmedian_rows(nb)) > tol_l  # the offset against the median of its neighbours'
    cand, jc, inr = cand[c1], jc[c1], inr[c1]
    if cand.size == 0:
        return out
    # 2(a): off the grid of its neighbours in time
    dt = (np.diff(np.sort(t[::step])) if step > 1 else np.diff(np.sort(t))).astype(np.float64)
    ph = dt / (T * step) if step > 1 else dt / T
    tol_p = max(sigmas * _robust_std((ph - np.rint(ph)) * T), ON_GRID_TOL * T)
    c2a = np.zeros(cand.size, bool)
    if tol_p < 0.5 * T:
        ts = np.sort(t)
        r = np.searchsorted(ts, t[cand])  # rank of each candidate among the stamps (its first copy)
        k = r[:, None] + rel[None, :]
        ok = (k >= 0) & (k < n)
        x = (t[cand][:, None] - ts[np.clip(k, 0, n - 1)]).astype(np.float64) / T
        x = np.where(ok, np.abs(x - np.rint(x)) * T, np.nan)  # |phase|: half a period is +-T/2 alike
        left, right = _nanmedian_rows(x[:, :w]), _nanmedian_rows(x[:, w:])
        left = np.where(np.isnan(left), right, left)  # an end: its one side decides
        right = np.where(np.isnan(right), left, right)
        c2a = (np.abs(left) > tol_p) & (np.abs(right) > tol_p)
    # 2(b): off the sequence in logging order (stamps less their count: level between gaps)
    r2t = (2 * t[1:-1:step] - t[:-2:step] - t[2::step]).astype(np.float64) / 2
    tol_t = max(sigmas * _robust_std(r2t), 1.5 * T)
    lin = np.where(inr, (t[jc] - t[cand][:, None]).astype(np.float64) - (jc - cand[:, None]) * T, np.nan)
    pl, pr = _nanmedian_rows(lin[:, :w]), _nanmedian_rows(lin[:, w:])
    el, er = -pl, -pr  # the stamp's own level is 0 relative to itself
    el = np.where(np.isnan(el), er, el)
    er = np.where(np.isnan(er), el, er)
    c2b = (np.sign(el) == np.sign(er)) & (np.minimum(np.abs(el), np.abs(er)) > tol_t)
    out[cand[c2a | c2b]] = True
    return out


def outlier_stamps(stamps_ns: np.ndarray, log_times_ns: np.ndarray | None = None, *,
                   periods: float = OUTLIER_PERIODS, min_s: float = OUTLIER_MIN_S) -> np.ndarray:
    """Which stamps are outliers: far off their neighbours or their own log time.

    Parameters
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Stamps in ns, in the order the messages were logged.
    log_times_ns : ndarray of int64, shape (n,), optional
        The messages' log times in ns, when the stamps are header stamps (a second,
        independent clock); None when the stamps are the log times.
    periods : float, optional
        Threshold in median periods (default :data:`OUTLIER_PERIODS`, 1000).
    min_s : float, optional
        Least threshold in s (default :data:`OUTLIER_MIN_S`, 1 s).

    Returns
    -------
    ndarray of bool, shape (n,)
        True for an outlier.

    Notes
    -----
    With ``thr = max(min_s, periods * median period)``, a stamp is an outlier when

    1. its offset from its log time differs from the median offset by more than ``thr``
       (header stamps only: a flipped bit in one clock, not in the other);
    2. it is more than ``thr`` from both its neighbours in logging order while they are
       within ``thr`` of each other (an isolated jump; at the ends, one neighbour and the
       next pair);
    3. it lies in a small cluster (at most 1 % of the stamps, at least 1) separated from
       the rest by more than ``thr`` and by more than 10 times the span of the rest.

    4. its ``nanosec`` field was not below 1e9 (:data:`INVALID_STAMP_NS`, :func:`stamps_ns`);
    5. (header stamps only) it was moved by less than ``thr``, disagreeing with its log time and with
       the stamps on both sides of it (:func:`nudged_stamps`).

    Such a stamp is dropped with its sample (NaN on the grid, counted), never trusted: a message
    placed at a wrong time would give a value that was never measured there.
    """
    t = np.asarray(stamps_ns, np.int64)
    n = t.size
    invalid = t == INVALID_STAMP_NS
    if invalid.any():  # the rest judged without them
        out = invalid.copy()
        keep = np.flatnonzero(~invalid)
        out[keep] = outlier_stamps(t[keep], None if log_times_ns is None else np.asarray(log_times_ns)[keep],
                                   periods=periods, min_s=min_s)
        return out
    out = np.zeros(n, bool)
    if n < 3:
        return out
    dt = np.diff(t)
    increasing = bool(np.all(dt > 0))
    if increasing:  # the usual case: no sort needed
        order_all, pos = None, dt
    else:
        order_all = np.argsort(t, kind="stable")
        d = np.diff(t[order_all])
        pos = d[d > 0]
    if pos.size == 0:
        return out
    thr = max(min_s * 1e9, periods * float(median(pos)))
    if log_times_ns is not None:
        off = t - np.asarray(log_times_ns, np.int64)
        out |= np.abs(off - median(off)) > thr
    jump = np.abs(dt.astype(np.float64)) > thr  # (n-1,)
    if increasing and not jump.any():
        return _with_nudged(out, t, log_times_ns)  # no increment beyond thr: no isolated jump, no far cluster
    if order_all is None:
        order_all = np.arange(n)
    tf = t.astype(np.float64)
    inner = np.zeros(n, bool)
    inner[1:-1] = jump[:-1] & jump[1:] & (np.abs(tf[2:] - tf[:-2]) <= thr)
    inner[0] = jump[0] and not jump[1]
    inner[-1] = jump[-1] and not jump[-2]
    out |= inner
    for _ in range(4):  # clusters far outside the span of the rest
        order = order_all[~out[order_all]]
        if order.size < 3:
            break
        ts = tf[order]
        dd = np.diff(ts)
        j = int(np.argmax(dd))
        small = max(1, int(0.01 * ts.size))
        left, right = j + 1, ts.size - j - 1
        if dd[j] <= thr or min(left, right) > small:
            break
        span_rest = (ts[-1] - ts[j + 1]) if left <= right else (ts[j] - ts[0])
        if dd[j] <= 10 * span_rest:
            break
        out[order[: j + 1] if left <= right else order[j + 1 :]] = True
    return _with_nudged(out, t, log_times_ns)


def _with_nudged(out: np.ndarray, t: np.ndarray, log_times_ns: np.ndarray | None) -> np.ndarray:
    """`out` or the nudged stamps among the rest (:func:`nudged_stamps`; header stamps only)."""
    if log_times_ns is None:
        return out
    keep = np.flatnonzero(~out)
    out[keep] = nudged_stamps(t[keep], np.asarray(log_times_ns, np.int64)[keep])
    return out


def _rate(dt_reg: np.ndarray, med: float) -> float:
    """1 / mean period of the regular increments, snapped to a round number when the
    difference is below the ns rounding of the stamps."""
    if dt_reg.size == 0:
        return 1.0 / med
    span = float(dt_reg.sum())
    fs = dt_reg.size / span
    tol = 1.5e-9 / span  # relative error of the mean period from stamps rounded to 1 ns
    for d in range(0, 7):
        r = round(fs, d)
        if r > 0 and abs(r - fs) <= tol * fs:
            return r
    return fs


#: fewest uniform samples the anti-alias filter runs on (``sosfiltfilt``'s pad length + 1)
_MIN_FILTER_LEN = 27


def _lowpass_uniform(y: np.ndarray, fs_src: float, fs: float) -> np.ndarray:
    """Zero-phase Butterworth low-pass (order 8, cut-off 0.4 fs) before decimating to `fs`."""
    from scipy import signal

    sos = signal.butter(8, 0.4 * fs, fs=fs_src, output="sos")
    return signal.sosfiltfilt(sos, y, axis=-1)


def resample_to_grid(
    t_s: np.ndarray, y: np.ndarray, grid_s: np.ndarray, *, fs: float, fs_src: float
) -> np.ndarray:
    """Anti-aliased interpolation of samples at times `t_s` onto `grid_s`.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Increasing sample times in s (possibly irregular).
    y : ndarray, shape (n_channels, n)
        Samples.
    grid_s : ndarray, shape (m,)
        Output times in s, within ``[t_s[0], t_s[-1]]``.
    fs : float
        Output rate in Hz.
    fs_src : float
        Estimated source rate in Hz.

    Returns
    -------
    ndarray, shape (n_channels, m)
        All NaN when downsampling a record too short for the anti-alias filter (fewer than
        28 samples at `fs_src`).

    Notes
    -----
    The samples must form one contiguous run (no gap): the caller splits a topic at its gaps
    (:mod:`vibroscope.io._grid`) and calls this per run, so an interpolant never spans a gap.
    The interpolant is the shape-preserving piecewise cubic Hermite (PCHIP, Fritsch & Carlson,
    "Monotone piecewise cubic interpolation", SIAM J. Numer. Anal. 17(2), 1980; scipy's
    ``PchipInterpolator``): monotone on every interval, so **an interpolated value always lies
    between the two samples around it** (a cubic spline overshoots: a single misplaced stamp made
    it give 1.21 from samples within +-1). Its error is therefore bounded by the increment
    between those two samples, ``|y(t) - y_k| <= |y_{k+1} - y_k|``; for a sine of amplitude A
    and frequency f sampled every h it is below ``A (2 pi f h)^2 / 8`` near the extrema (where
    PCHIP flattens) and O(h^3) elsewhere (a sine at 3 % of the rate: < 0.5 % of A).
    Downsampling (``fs_src > 1.01 fs``, :data:`DOWNSAMPLE_RATIO`): the samples are first put on
    a uniform grid at `fs_src` (PCHIP: points within the stamps' jitter of a sample), low-passed
    (8th-order Butterworth at 0.4 `fs`, forward-backward so with no phase shift), then
    interpolated by a cubic spline (the low-passed record is band-limited: error O(h^4)); the
    output is then the low-passed signal, which may leave the range of the raw samples (a
    filter's ringing), as the output of any anti-alias filter does.
    """
    from scipy.interpolate import CubicSpline, PchipInterpolator

    y = np.atleast_2d(np.asarray(y, float))
    if fs_src > fs * DOWNSAMPLE_RATIO:
        n_u = int(np.floor((t_s[-1] - t_s[0]) * fs_src)) + 1
        if n_u <= _MIN_FILTER_LEN:  # too short to low-pass: no samples rather than aliased ones
            return np.full((y.shape[0], np.size(grid_s)), np.nan)
    if t_s.size < 4:
        return np.vstack([np.interp(grid_s, t_s, row) for row in y])
    if fs_src > fs * DOWNSAMPLE_RATIO:
        tu = t_s[0] + np.arange(n_u) / fs_src
        yu = PchipInterpolator(t_s, y, axis=1)(tu)
        yu = _lowpass_uniform(yu, fs_src, fs)
        # the low-passed uniform record is band-limited (below 0.4 fs): a cubic spline, O(h^4)
        return CubicSpline(tu, yu, axis=1)(np.clip(grid_s, tu[0], tu[-1]))
    return PchipInterpolator(t_s, y, axis=1)(grid_s)


def on_grid(t_ns: np.ndarray, start_ns: int, fs: float, tol: float = 0.01) -> bool:
    """Whether stamps `t_ns` are samples ``start + k / fs`` (k = 0, 1, ...) within `tol` periods."""
    k = np.arange(t_ns.size)
    ideal = (k / fs) * 1e9
    dev = np.abs((t_ns - start_ns).astype(np.float64) - ideal)
    return bool(dev.max(initial=0.0) <= tol * 1e9 / fs)


def grid_for(spans: Sequence[tuple[int, int]], fs: float) -> tuple[int, int]:
    """(start_ns, n_samples) of the grid at `fs` over the common overlap of `spans` (ns)."""
    start = max(s for s, _ in spans)
    stop = min(e for _, e in spans)
    if stop < start:
        return start, 0
    n = int(np.floor((stop - start) * 1e-9 * fs + 1e-6)) + 1
    return start, n
