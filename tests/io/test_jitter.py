"""Stamp jitter is not a gap: the rate of a jittered stamp stream is the slope of its stamps against
the message count, and only a missing message makes a gap (sweep report, problem 1: sigma 0.1-0.2 ms
at 1 kHz gave 1026 Hz and hundreds of fake gaps)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as hst

from vibroscope.io import read_mcap
from vibroscope.io.blocks import open_grid
from vibroscope.io.log_index import mcap_info
from vibroscope.io.timebase import analyse_stamps, fit_stamps

from _io_helpers import write_imu_log

T0 = 1_700_000_000_000_000_000
FS = 1000.0
F1, F2 = 18.39, 60.38


def _truth(k: np.ndarray) -> np.ndarray:
    """Samples taken on the true uniform clock at 1 kHz (the stamps only jitter)."""
    t = k / FS
    return np.sin(2 * np.pi * F1 * t) + 0.5 * np.sin(2 * np.pi * F2 * t)


def _jittered(n: int, sigma_s: float, seed: int, drop=()) -> tuple[np.ndarray, np.ndarray]:
    """(message counts kept, stamps ns increasing) of a 1 kHz clock with Gaussian stamp jitter."""
    rng = np.random.default_rng(seed)
    keep = np.ones(n, bool)
    for a, m in drop:
        keep[a : a + m] = False
    k = np.flatnonzero(keep)
    st = T0 + np.round(k * 1e9 / FS + rng.normal(0.0, sigma_s * 1e9, k.size)).astype(np.int64)
    order = np.argsort(st, kind="stable")  # a stamp jittered past its neighbour is logged after it
    return k[order], st[order]


def _log(path, sigma_s: float, seed: int, n: int = 8000, drop=()):
    """Two Imu topics at 1 kHz, stamps = log times jittered by `sigma_s`, chunks of ~64 kB."""
    topics = {}
    for i, topic in enumerate(("/imu/a", "/imu/b")):
        k, st = _jittered(n, sigma_s, seed + i, drop)
        topics[topic] = (st, _truth(k))
    write_imu_log(path, topics, chunk_size=1 << 16)
    return path


@pytest.mark.parametrize("sigma_s", [1e-4, 2e-4])
def test_jitter_is_neither_a_gap_nor_a_rate_change(tmp_path, sigma_s):
    path = _log(tmp_path / "jitter.mcap", sigma_s, seed=5)
    info = mcap_info(path)
    assert [t.gaps for t in info.topics] == [0, 0]
    chans = ["/imu/a.linear_acceleration.x", "/imu/b.linear_acceleration.x"]
    s = read_mcap(path, chans)
    assert abs(s.fs - FS) <= 1e-3
    for rep in s.meta["timebase"].values():
        assert abs(rep["fs_est"] - FS) <= 1e-3 and rep["gaps"] == 0 and rep["missing"] == 0
        assert rep["jitter_s"] > 0.5 * sigma_s  # (std of the increments: sqrt(2) sigma)
    assert not np.isnan(s.data).any() and s.meta["gaps"] == []
    assert s.n_samples >= 7990
    # the values follow the signal: the spline at jittered stamps errs by ~2 pi f sigma A
    t_grid = (s.t0 - T0 * 1e-9) + np.arange(s.n_samples) / s.fs  # s after the clock's sample 0
    err = s.data - _truth(t_grid * FS)[None, :]
    assert np.sqrt(np.mean(err ** 2)) < 2 * np.pi * F2 * sigma_s * 1.5
    # streaming: the same rate from the first and last chunks, no NaN
    grid = open_grid(path, chans)
    assert abs(grid.fs - FS) <= 1e-3
    assert len(grid.chunks) > 4
    blocks = [b.data for b in grid.blocks(1500)]
    assert not np.isnan(np.hstack(blocks)).any()


def test_lost_messages_in_jittered_stamps_are_found_exactly(tmp_path):
    drop = ((1500, 1), (3000, 2), (5000, 300))
    path = _log(tmp_path / "drop.mcap", 2e-4, seed=11, drop=drop)
    assert [t.gaps for t in mcap_info(path).topics] == [3, 3]
    s = read_mcap(path, ["/imu/a.linear_acceleration.x", "/imu/b.linear_acceleration.x"])
    assert abs(s.fs - FS) <= 1e-3
    for rep in s.meta["timebase"].values():
        assert rep["gaps"] == 3 and rep["missing"] == 303
    for topic in ("/imu/a", "/imu/b"):
        g = sorted((x for x in s.meta["gaps"] if x["topic"] == topic), key=lambda x: x["start_s"])
        assert len(g) == 3
        for x, (a, m) in zip(g, drop):
            # NaN: the grid samples strictly between the two stamps around the gap, (m + 1) periods
            # apart +- their jitter, off the grid: m to m + 2 of them
            assert m <= x["n_samples"] <= m + 2
            assert abs(x["start_s"] - (T0 * 1e-9 + a / FS)) < 1.5 / FS
    assert np.isnan(s.data).sum() == sum(x["n_samples"] for x in s.meta["gaps"])


def test_regular_stamps_keep_the_median_rule():
    """Stamps on a clock (ns rounding only): increments over 1.5 periods are gaps, rate 1 / mean."""
    t = T0 + np.round(np.r_[np.arange(100), np.arange(103, 200)] * 1e9 / 3000.0).astype(np.int64)
    fit = fit_stamps(t)
    assert fit.regular and fit.jitter_s == 0.0
    assert np.flatnonzero(fit.gap).tolist() == [99] and fit.missing[99] == 3  # 100, 101, 102
    _o, rep = analyse_stamps("/x", t)
    assert rep.gaps == 1 and rep.missing == 3 and abs(rep.fs_est - 3000.0) < 1e-3


def test_bursts_keep_the_median_rule():
    """Pairs of messages 1 ms apart every 10 ms with every third pair late: not a jittered clock."""
    rng = np.random.default_rng(0)
    base = np.arange(400) * 10_000_000 + np.where(np.arange(400) % 3 == 0, 4_000_000, 0)
    t = np.sort(np.r_[base, base + 1_000_000 + rng.integers(0, 1000, 400)]) + T0
    fit = fit_stamps(t)
    dt = np.diff(t)
    assert np.array_equal(fit.gap, dt > 1.5 * np.median(dt))


@settings(max_examples=40, deadline=None)
@given(fs=hst.floats(50.0, 5000.0), rel_sigma=hst.floats(0.0, 0.08), seed=hst.integers(0, 2**32 - 1),
       drops=hst.lists(hst.tuples(hst.integers(0, 39), hst.integers(1, 40)), max_size=5))
def test_fit_finds_each_lost_message_and_the_rate(fs, rel_sigma, seed, drops):
    """Jitter up to 8 % of a period (a lost message: an increment of 2 periods, 12 sigma away):
    every gap is found at its place with its count, no other; the rate to its standard error."""
    rng = np.random.default_rng(seed)
    n = 4000
    keep = np.ones(n, bool)
    where = []
    for slot, m in drops:  # slots 100 messages apart: no two gaps in one window
        a = 50 + slot * 100
        if keep[a - 1] and keep[a]:
            keep[a : a + m] = False
            where.append((a, m))
    k = np.flatnonzero(keep)
    t = T0 + np.round((k + rng.normal(0.0, rel_sigma, k.size)) * 1e9 / fs).astype(np.int64)
    t = np.sort(t)
    if np.any(np.diff(t) <= 0):
        return
    fit = fit_stamps(t)
    expect = sorted((int(np.searchsorted(k, a)) - 1, m) for a, m in where)
    got = [(int(i), int(fit.missing[i])) for i in np.flatnonzero(fit.gap)]
    assert got == expect
    if rel_sigma > 0.003:  # the largest of ~4000 increments beyond 1 % of a period: a line is fitted
        assert not fit.regular
    if fit.regular:  # 1 / mean increment: the end stamps' jitter over the span
        se = rel_sigma * np.sqrt(2.0) / n
    else:  # the relative standard error of the slope within the gap-free runs (one intercept each)
        m = np.diff(np.r_[0, np.flatnonzero(fit.gap) + 1, t.size])
        se = rel_sigma / np.sqrt(np.sum((m ** 3 - m) / 12.0))
    # 6 standard errors of noise, 3 more for the rounding of fs within 3 of them; or the ns rounding
    # of the stamps, 1 ns per run over the span, and the rounding of fs within 1.5 ns over the span
    span = (t[-1] - t[0]) * 1e-9
    assert abs(fit.fs - fs) <= fs * max(9 * se, (len(where) + 2.5) * 1e-9 / span)


def test_header_clock_stepping_back_falls_back_to_log_time(tmp_path):
    """Header stamps that jump back 3 s halfway (a clock reset) while the log times go on: read on
    the log times, with a warning naming the step (before: every stamp was an outlier of the
    stamp-to-log-time offset and the topic read as "no messages")."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from _io_helpers import write_imu_log

    from vibroscope.io import read_mcap

    n = 4000
    lt = 10_000_000_000 + np.arange(n, dtype=np.int64) * 1_000_000
    st = lt.copy()
    st[2000:] -= 3_000_000_000
    ax = np.sin(np.arange(n) / 9.0)
    p = tmp_path / "clock.mcap"
    write_imu_log(p, {"/imu": (st, ax)}, log_times={"/imu": lt})
    sig = read_mcap(p, ["/imu.linear_acceleration.x"])
    assert sig.n_samples == n and np.array_equal(sig.data[0], ax) and sig.fs == 1000.0
    assert any("steps back by 2.999 s after message 2000" in w and "using log_time" in w for w in sig.meta["warnings"])
