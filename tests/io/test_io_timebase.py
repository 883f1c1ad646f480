"""Time-base faults with known counts, and multi-rate resampling accuracy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vibroscope.io import read_mcap
from vibroscope.io.timebase import analyse_stamps

from _io_helpers import write_imu_log

T0 = 10_000_000_000  # 10 s in ns


def test_analyse_stamps_counts():
    period = 1_000_000  # 1 kHz
    t = T0 + np.arange(1000, dtype=np.int64) * period
    t = np.delete(t, np.r_[100:110, 500:503])  # two gaps: 10 and 3 samples missing
    t = np.insert(t, 50, t[50])  # one duplicate
    t = np.insert(t, 201, t[200])  # another duplicate
    t[[300, 301]] = t[[301, 300]]  # one swap: one out-of-order step
    t[[600, 601]] = t[[601, 600]]
    order, rep = analyse_stamps("/x", t)
    assert rep.n_messages == t.size
    assert rep.duplicates == 2
    assert rep.out_of_order == 2
    assert rep.gaps == 2
    assert rep.gap_time_s == pytest.approx(13 * 1e-3, abs=1e-12)
    assert [g[0] for g in rep.gap_where_s] == pytest.approx([0.099, 0.499])
    assert rep.fs_est == 1000.0
    assert rep.jitter_s == pytest.approx(0.0, abs=1e-15) and rep.max_dev_s == pytest.approx(0.0, abs=1e-15)
    assert np.all(np.diff(t[order]) > 0) and order.size == t.size - 2


def test_faulty_log_reported(tmp_path):
    rng = np.random.default_rng(5)
    n = 2000
    period = 2_000_000  # 500 Hz
    st = T0 + np.arange(n, dtype=np.int64) * period
    jit = rng.integers(-100_000, 100_001, n)  # +-0.1 ms jitter
    st = st + jit
    keep = np.ones(n, bool)
    keep[700:720] = False  # a 20-sample gap
    st, ax = st[keep], rng.standard_normal(keep.sum())
    st = np.insert(st, 10, st[10])  # duplicate stamp
    ax = np.insert(ax, 10, 99.0)
    st[[1000, 1001]] = st[[1001, 1000]]  # reordered stamps (logged in this order)
    ax[[1000, 1001]] = ax[[1001, 1000]]
    log_times = {"/imu": T0 + np.arange(st.size, dtype=np.int64) * period}
    p = tmp_path / "faulty.mcap"
    write_imu_log(p, {"/imu": (st, ax)}, log_times=log_times)
    r = read_mcap(p, ["/imu.linear_acceleration.x"])
    tb = r.meta["timebase"]["/imu"]
    assert tb["n_messages"] == n - 20 + 1
    assert tb["duplicates"] == 1 and tb["out_of_order"] == 1 and tb["gaps"] == 1
    assert tb["gap_time_s"] == pytest.approx(20 * 2e-3, abs=3e-4)
    assert 1e-5 < tb["jitter_s"] < 1e-4 and tb["max_dev_s"] <= 2.0e-4 + 1e-9
    assert tb["fs_est"] == pytest.approx(500.0, rel=1e-3)
    assert tb["resampled"] is True
    rep = r.meta["timebase_reports"]["/imu"]
    assert rep.resampled and rep.duplicates == 1 and rep.time_source == "header.stamp"
    w = " ".join(r.meta["warnings"])
    assert "duplicate" in w and "out-of-order" in w and "gaps" in w and "resampled" in w


def _sine_logs(tmp_path, f=7.0, extra=None):
    rng = np.random.default_rng(6)
    ta = T0 + np.arange(3000, dtype=np.int64) * 1_000_000  # 1 kHz, 3 s
    tb = T0 + 333_333 + np.arange(750, dtype=np.int64) * 4_000_000  # 250 Hz, offset
    tb = tb + rng.integers(-400_000, 400_001, tb.size)  # +-10 % jitter
    ya = np.sin(2 * np.pi * f * (ta - T0) * 1e-9)
    if extra is not None:
        ya = ya + extra * np.sin(2 * np.pi * 400.0 * (ta - T0) * 1e-9)
    yb = np.sin(2 * np.pi * f * (tb - T0) * 1e-9)
    p = tmp_path / "multi.mcap"
    write_imu_log(p, {"/a": (ta, ya), "/b": (tb, yb)})
    return p


@pytest.mark.parametrize("fs", [None, 100.0])
def test_multirate_resampling_band_limited_sine(tmp_path, fs):
    f = 7.0
    p = _sine_logs(tmp_path, f, extra=0.5 if fs else None)
    r = read_mcap(p, ["/a.linear_acceleration.x", "/b.linear_acceleration.x"], fs=fs)
    assert r.fs == (1000.0 if fs is None else 100.0)
    t = r.meta["t0_ns"] * 1e-9 - T0 * 1e-9 + np.arange(r.n_samples) / r.fs
    ref = np.sin(2 * np.pi * f * t)
    inner = slice(r.n_samples // 10, -r.n_samples // 10)
    # the shape-preserving interpolant (PCHIP) stays between the two samples around each grid time, so
    # near an extremum it errs by up to A (1 - cos(w h / 2)) <= A (w h)^2 / 8 (h the longest increment:
    # 1 ms for /a; 4 ms + 2 x 0.4 ms jitter for /b); a low-passed record (fs=100) to 1e-3 as before
    for k, h in enumerate((1e-3, 4.8e-3)):
        bound = (2 * np.pi * f * h) ** 2 / 8 if fs is None else 1e-3
        assert np.max(np.abs(r.data[k, inner] - ref[inner])) < bound
        assert np.sqrt(np.mean((r.data[k, inner] - ref[inner]) ** 2)) < bound / 2
    tb = r.meta["timebase"]
    assert tb["/b"]["resampled"] is True
    assert tb["/a"]["resampled"] is True  # the common span starts at /b's first stamp, off /a's grid
    # grid within the common overlap
    assert r.meta["t0_ns"] >= T0 + 333_333 - 400_000


def test_no_resample_requires_equal_counts(tmp_path):
    p = _sine_logs(tmp_path)
    with pytest.raises(ValueError, match="resample=False"):
        read_mcap(p, ["/a.linear_acceleration.x", "/b.linear_acceleration.x"], resample=False)


@settings(max_examples=60, deadline=None)
@given(n=st.one_of(st.integers(1, 100), st.integers(16_384, 60_000)), kind=st.sampled_from(["jitter", "normal", "ties", "sorted", "bimodal"]),
       seed=st.integers(0, 2**32 - 1))
def test_median_equals_numpy_to_the_bit(n, kind, seed):
    """The bracketed median of the stamp analysis is ``np.median`` exactly, for integer and float
    arrays long enough to take the bracketed path (n ≥ 16384) and short ones, with ties, sorted
    input and two far clusters (where the bracket can miss and numpy decides)."""
    from vibroscope.io.timebase import median

    rng = np.random.default_rng(seed)
    x = {"jitter": lambda: rng.integers(-4000, 4000, n) + 1_000_000,
         "normal": lambda: rng.standard_normal(n),
         "ties": lambda: rng.integers(0, 3, n),
         "sorted": lambda: np.sort(rng.integers(0, 10**12, n)),
         "bimodal": lambda: rng.standard_normal(n) * 1e-9 + (rng.random(n) < 0.5) * 1e3}[kind]()
    assert median(x) == float(np.median(x))
