"""Topics' time-stamped samples onto one uniform grid, never inventing a sample.

A topic whose stamps lie on the grid (within :data:`~vibroscope.io.timebase.ON_GRID_TOL` of
a period, at the grid's rate) is placed by index, ``k = round((t - start) fs)``: no
interpolation at all, NaN where nothing was logged. So is a topic all but a few of whose
stamps do (at most :data:`MAX_OFF_GRID_SHARE`, 1 %, and at least one): the samples of the
stray stamps are left out (NaN, counted in a warning), since one wrong stamp must not make the
whole topic interpolated. Any other topic is interpolated (shape-preserving PCHIP,
:func:`~vibroscope.io.timebase.resample_to_grid`: never a value outside its two neighbours)
within each contiguous run of its stamps (no increment holding a missing message,
:func:`~vibroscope.io.timebase.fit_stamps`: jitter of the stamps is not a gap), so the
interpolant and the anti-alias filter never span a gap; the grid samples in a gap are NaN.
Chunks lost to damage are gaps like any other. Every gap is reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from vibroscope.errors import ChannelError
from vibroscope.io.timebase import (DOWNSAMPLE_RATIO, ON_GRID_TOL, TimebaseReport, fit_stamps, grid_for,
                                    resample_to_grid)

#: refuse a grid with more samples than this many times the messages read (x the rate ratio)
MAX_GRID_FACTOR = 10


@dataclass
class TopicSamples:
    """The samples of one topic's requested fields, sorted by stamp and free of duplicates.

    Attributes
    ----------
    t_ns : ndarray of int64, shape (n,)
        Stamps in ns, increasing.
    values : ndarray, shape (k, n)
        One row per requested field of the topic.
    report : TimebaseReport
        The topic's time base.
    """

    t_ns: np.ndarray
    values: np.ndarray
    report: TimebaseReport


#: at most this share of a topic's stamps (and at least one) may lie off the grid of the others for the
#: topic to be placed by index: those samples are left out (NaN, counted), not interpolated
MAX_OFF_GRID_SHARE = 0.01


def _on_grid_index(t: np.ndarray, start: int, fs: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(grid indices of the stamps on the grid, which stamps those are (bool, `t`'s shape)) when stamps
    `t` are samples of the grid at `fs` (one per period), all but at most :data:`MAX_OFF_GRID_SHARE`
    of them (at least one); else None (interpolate)."""
    rel = (t - start).astype(np.float64) * 1e-9 * fs
    k = np.rint(rel)
    on = np.abs(rel - k) <= ON_GRID_TOL
    n_off = t.size - int(np.count_nonzero(on))
    if n_off > max(1, int(MAX_OFF_GRID_SHARE * t.size)) or n_off == t.size:
        return None
    k = k.astype(np.int64)
    if n_off:
        k = k[on]
    if k.size > 1:
        d = np.diff(k)
        # increasing, and median step 1 (steps ≥ 1: more than half of them are 1): else stamps at a
        # multiple of the grid period (upsampling): interpolate
        if np.any(d <= 0) or 2 * np.count_nonzero(d == 1) <= d.size:
            return None
    return k, on


def off_grid_stamps(s: TopicSamples, start: int, fs: float) -> int:
    """Stamps of a topic placed by index (:func:`place_topic`) that lie off the grid of the others and
    were left out (their samples NaN, not interpolated); 0 for a topic that is interpolated."""
    got = _on_grid_index(s.t_ns, start, fs)
    return 0 if got is None else int(s.t_ns.size - np.count_nonzero(got[1]))


def _runs(t: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) indices of the contiguous runs of increasing stamps `t` (split at the gaps
    of :func:`~vibroscope.io.timebase.fit_stamps`)."""
    if t.size < 2:
        return [(0, t.size - 1)] if t.size else []
    cut = np.flatnonzero(fit_stamps(t).gap)
    firsts = np.r_[0, cut + 1]
    lasts = np.r_[cut, t.size - 1]
    return list(zip(firsts.tolist(), lasts.tolist()))


def _interp_runs(t: np.ndarray, y: np.ndarray, grid_ns: np.ndarray, start: int, fs: float, fs_src: float,
                 runs: list[tuple[int, int]], out: np.ndarray, covered: np.ndarray) -> None:
    """Interpolate each run of `t` onto the grid points it brackets (in place)."""
    for a, b in runs:
        if b <= a:
            continue  # a lone sample between gaps: not on the grid, nothing to interpolate with
        g0 = int(np.searchsorted(grid_ns, t[a], "left"))
        g1 = int(np.searchsorted(grid_ns, t[b], "right"))
        if g1 <= g0:
            continue
        v = resample_to_grid((t[a : b + 1] - start) * 1e-9, y[:, a : b + 1],
                             (grid_ns[g0:g1] - start) * 1e-9, fs=fs, fs_src=fs_src)
        out[:, g0:g1] = v
        covered[g0:g1] = np.isfinite(v).any(axis=0)  # a run too short to low-pass stays NaN


def place_topic(s: TopicSamples, start: int, n: int, fs: float, *,
                first: int = 0) -> tuple[np.ndarray, np.ndarray, bool]:
    """(rows (k, n) with NaN where nothing was logged, covered (n,) bool, resampled) of one topic.

    With `first`, the rows are the grid samples ``first .. first + n - 1`` of the grid that
    starts at `start` (a block of a longer grid, :mod:`vibroscope.io.blocks`).

    Parameters
    ----------
    s : TopicSamples
        The topic's samples.
    start : int
        Grid start in ns.
    n : int
        Grid length.
    fs : float
        Grid rate in Hz.
    first : int, optional
        Index on the grid of the first sample returned; default 0.

    Returns
    -------
    (ndarray, ndarray, bool)
    """
    t, y = s.t_ns, s.values
    out = np.full((y.shape[0], n), np.nan)
    covered = np.zeros(n, bool)
    got = _on_grid_index(t, start, fs)
    if got is not None:
        k, on = got
        if k.size < t.size:  # a few stamps off the grid of the others (a nudged stamp): left out, not interpolated
            y = y[:, on]
        k = k - first
        i0, i1 = np.searchsorted(k, [0, n])  # k is increasing
        k, y = k[i0:i1], y[:, i0:i1]
        if k.size and k[-1] - k[0] == k.size - 1:  # contiguous: a plain copy
            out[:, k[0] : k[-1] + 1] = y
            covered[k[0] : k[-1] + 1] = True
        else:
            out[:, k] = y
            covered[k] = True
        return out, covered, False
    grid_ns = start + np.round(np.arange(first, first + n) / fs * 1e9).astype(np.int64)
    fs_src = s.report.fs_est
    if not np.isnan(y).any():
        _interp_runs(t, y, grid_ns, start, fs, fs_src, _runs(t), out, covered)
        out[:, ~covered] = np.nan
        return out, covered, True
    # NaN samples (fields missing in some messages): each row's runs end at its NaN samples too
    all_runs = _runs(t)
    for r in range(y.shape[0]):
        ok = np.isfinite(y[r])
        cov_r = np.zeros(n, bool)
        brk = np.flatnonzero(~ok)
        runs = []
        for a, b in all_runs:
            edges = [a - 1, *brk[(brk >= a) & (brk <= b)].tolist(), b + 1]
            runs += [(e0 + 1, e1 - 1) for e0, e1 in zip(edges[:-1], edges[1:]) if e1 - 1 >= e0 + 1]
        _interp_runs(t, y[r : r + 1], grid_ns, start, fs, fs_src, runs, out[r : r + 1], cov_r)
        covered |= cov_r
    return out, covered, True


def _nan_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first index, length) of the runs of True in `mask`."""
    if not mask.any():
        return []
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    a = np.flatnonzero(d == 1)
    b = np.flatnonzero(d == -1)
    return list(zip(a.tolist(), (b - a).tolist()))


def check_grid_size(path: Any, topics: list[str], samples: dict[str, TopicSamples], n: int, fs: float) -> None:
    """Refuse a grid far larger than the messages read (damaged stamps), naming the topic.

    Raises
    ------
    ChannelError
        If ``n`` exceeds :data:`MAX_GRID_FACTOR` times the messages of every topic (scaled by
        the ratio of `fs` to the topic's rate when upsampling).
    """
    def allowed(t: str) -> float:
        r = samples[t].report.fs_est
        ratio = fs / r if np.isfinite(r) and r > 0 else 1.0
        return MAX_GRID_FACTOR * samples[t].t_ns.size * max(1.0, ratio)

    if n <= 100_000 or n <= max(allowed(t) for t in topics):
        return
    worst = min(topics, key=allowed)
    raise ChannelError(
        f"{path}: topic {worst!r}: the grid at {fs:.6g} Hz over the topics' span of {(n - 1) / fs:.6g} s would "
        f"hold {n} samples, more than {MAX_GRID_FACTOR} times the {samples[worst].t_ns.size} messages read "
        "(damaged or inconsistent stamps?); check the stamps (vibroscope info), read the topics separately, "
        "or give a lower fs"
    )


def onto_grid(path: Any, topics: list[str], samples: dict[str, TopicSamples], fs: float,
              warnings: list[str]) -> tuple[int, dict[str, np.ndarray], dict[str, bool], list[dict]]:
    """All topics onto the grid at `fs` over their common span.

    Parameters
    ----------
    path : str or Path
        The log (for messages).
    topics : list of str
        Topics, in output order.
    samples : dict of str to TopicSamples
        Their samples.
    fs : float
        Grid rate in Hz.
    warnings : list of str
        Appended to: resampling and gaps, one line per topic.

    Returns
    -------
    start : int
        Grid start in ns.
    rows : dict of str to ndarray, shape (k, n)
        Per topic, its rows on the grid (NaN in gaps).
    resampled : dict of str to bool
    gaps : list of dict
        ``{"topic", "start_s" (absolute, s), "length_s", "n_samples"}`` per gap.

    Raises
    ------
    ChannelError
        If the topics do not overlap in time, or the grid would be far larger than the
        messages read (:func:`check_grid_size`).
    """
    spans = {t: (int(samples[t].t_ns[0]), int(samples[t].t_ns[-1])) for t in topics}
    start, n = grid_for(list(spans.values()), fs)
    if n < 2:
        few = [f"{t} ({samples[t].t_ns.size} message{'s' if samples[t].t_ns.size != 1 else ''})" for t in topics
               if samples[t].t_ns.size < 2]
        raise ChannelError(f"{path}: the topics {topics} do not overlap in time"
                           + (f": {', '.join(few)}" if few else ""))
    check_grid_size(path, topics, samples, n, fs)
    stop = start + (n - 1) / fs * 1e9
    for t, (a, b) in spans.items():  # the record is the topics' common span: say what it leaves out
        cut = max(0, start - a) + max(0.0, b - stop)
        if cut * 1e-9 > max(1.0 / fs, 0.01 * (b - a) * 1e-9):
            warnings.append(f"topic {t!r}: {cut * 1e-9:.4g} s of its {(b - a) * 1e-9:.4g} s lie outside the span all "
                            f"topics cover ({start * 1e-9:.6f}–{stop * 1e-9:.6f} s) and are not analysed; read it "
                            f"alone (or without the shorter topics) to keep them")
    rows: dict[str, np.ndarray] = {}
    resampled: dict[str, bool] = {}
    gaps: list[dict] = []
    for t in topics:
        out, covered, resampled[t] = place_topic(samples[t], start, n, fs)
        rows[t] = out
        stray = 0 if resampled[t] else off_grid_stamps(samples[t], start, fs)
        if stray:
            warnings.append(f"topic {t!r}: {stray} stamps off the grid that its other stamps lie on (moved stamps?): "
                            "their samples left out (NaN), not interpolated")
        if resampled[t]:
            fs_src = samples[t].report.fs_est
            warnings.append(
                f"topic {t!r} ({fs_src:.6g} Hz est.) resampled onto {fs:.6g} Hz within each contiguous run of stamps"
                + (" with anti-alias low-pass" if fs_src > fs * DOWNSAMPLE_RATIO else "")
            )
        runs = _nan_runs(~covered)
        for i0, m in runs:
            gaps.append({"topic": t, "start_s": start * 1e-9 + i0 / fs, "length_s": m / fs, "n_samples": int(m)})
        if runs:
            tot = sum(m for _, m in runs)
            warnings.append(
                f"topic {t!r}: {len(runs)} gaps, {tot / fs:.4g} s in all (first at {runs[0][0] / fs:.6g} s): "
                f"{tot} samples are NaN (not interpolated)"
            )
    return start, rows, resampled, gaps
