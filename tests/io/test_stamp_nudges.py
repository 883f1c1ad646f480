"""A slightly wrong stamp must not change a value (issue 21, item 2): a header stamp moved by less than
the outlier threshold, or with a ``nanosec`` of 1e9 or more, is an outlier (its sample NaN, counted),
never a reason to interpolate the topic; and the interpolation of a jittered topic never gives a
value outside its two neighbours."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst
from mcap_ros2.writer import Writer as Ros2Writer

from vibroscope.io import read_mcap
from vibroscope.io._ros2 import MSGDEFS
from vibroscope.io.timebase import INVALID_STAMP_NS, nudged_stamps, outlier_stamps, resample_to_grid, stamps_ns

from _io_helpers import IMU, imu_msg, write_imu_log

T0 = 1_700_000_000_000_000_000
N = 3000
PER = 1_000_000  # 1 kHz
CH = "/imu.linear_acceleration.x"


def _signal(k: np.ndarray) -> np.ndarray:
    """A ±1 signal (a sum of two sines at 0.5), the kind whose samples a cubic spline overshoots."""
    return 0.5 * np.sin(2 * np.pi * 37.0 * k / 1000.0) + 0.5 * np.sin(2 * np.pi * 211.0 * k / 1000.0)


def _log(path, stamps: np.ndarray, y: np.ndarray, log_times: np.ndarray, nanosec_at: dict | None = None):
    """An Imu log with `stamps` as header stamps (and, at the indices of `nanosec_at`, that raw nanosec)."""
    with open(path, "wb") as fh:
        w = Ros2Writer(fh, chunk_size=1 << 15)
        schema = w.register_msgdef(IMU, MSGDEFS[IMU])
        for k in range(stamps.size):
            m = imu_msg(int(stamps[k]), y[k])
            if nanosec_at and k in nanosec_at:
                m["header"]["stamp"]["nanosec"] = nanosec_at[k]
            w.write_message("/imu", schema, m, log_time=int(log_times[k]))
        w.finish()
    return path


@pytest.mark.parametrize("delta_periods", [0.3, 0.5, 2.5, 37.3, -11.7, 400.2, 999.0])
def test_nudged_stamp_of_an_on_grid_topic_changes_no_value(tmp_path, delta_periods):
    """Before: the message moved, the topic was spline-interpolated (values up to 1.21 from samples in ±1)
    with only "1 out-of-order stamps (sorted)" said. Now: one outlier, counted; every other sample
    placed by index, equal to the truth; the nudged message's grid sample NaN."""
    k = np.arange(N)
    lt = T0 + k * PER
    y = _signal(k)
    st = lt.copy()
    i = 1234
    st[i] += int(round(delta_periods * PER))  # below 1000 periods and 1 s: not a gross outlier
    s = read_mcap(_log(tmp_path / "n.mcap", st, y, lt), [CH])
    tb = s.meta["timebase"]["/imu"]
    assert tb["outliers"] == 1 and tb["resampled"] is False
    assert s.fs == 1000.0 and s.n_samples == N
    assert np.isnan(s.data[0, i]) and np.isnan(s.data).sum() == 1
    assert np.array_equal(np.delete(s.data[0], i), np.delete(y, i))  # to the bit
    assert s.meta["outliers"][0]["count"] == 1 and s.meta["gaps"][0]["n_samples"] == 1


@pytest.mark.parametrize("nanosec", [1_000_000_000, 1_000_000_000 + 300_000, 1_600_000_000, 4_294_967_295])
def test_invalid_nanosec_is_an_invalid_stamp(tmp_path, nanosec):
    """A nanosec field of 1e9 or more (a flipped high bit) is no time at all: the message is an outlier,
    whatever time sec * 1e9 + nanosec would name (here 0.0003 s to 3.3 s later)."""
    k = np.arange(N)
    lt = T0 + k * PER
    y = _signal(k)
    i = 777
    sec = int(lt[i] // 1_000_000_000)
    p = _log(tmp_path / "ns.mcap", lt, y, lt, {i: nanosec})
    s = read_mcap(p, [CH])
    assert s.meta["fast_path"]["/imu"]  # the numpy fast path checks the field too
    tb = s.meta["timebase"]["/imu"]
    assert tb["outliers"] == 1 and not tb["resampled"]
    assert np.isnan(s.data[0, i]) and np.array_equal(np.delete(s.data[0], i), np.delete(y, i))
    assert stamps_ns(np.array([sec]), np.array([nanosec]))[0] == INVALID_STAMP_NS


def test_stamps_ns_and_outlier_rule_for_invalid_stamps():
    t = stamps_ns(np.array([5, 5, 5, 5]), np.array([0, 999_999_999, 1_000_000_000, 2]))
    assert t.tolist() == [5_000_000_000, 5_999_999_999, INVALID_STAMP_NS, 5_000_000_002]
    st = T0 + np.arange(50) * PER
    st[[3, 40]] = INVALID_STAMP_NS
    assert np.flatnonzero(outlier_stamps(st, T0 + np.arange(50) * PER)).tolist() == [3, 40]


def test_legitimate_reordering_late_log_times_and_gaps_are_not_nudges():
    """Two messages logged in swapped order (their stamps on the grid), a late log time, gaps, jitter
    of the stamps: none is a nudged stamp; a moved stamp among them is."""
    rng = np.random.default_rng(3)
    k = np.delete(np.arange(5000), np.r_[1000:1003, 2500:2600])  # two gaps
    st = T0 + k * PER
    lt = st + 2_000_000 + rng.integers(0, 50_000, k.size)  # logged 2 ms later, 0-50 µs jitter
    st[[300, 301]] = st[[301, 300]]  # swapped in logging order
    lt[700] += 3 * PER  # one late log time
    assert not nudged_stamps(st, lt).any()
    st[4000] += 1_700_000  # 1.7 periods later
    st[4500] -= 300_000  # 0.3 periods earlier
    assert np.flatnonzero(nudged_stamps(st, lt)).tolist() == [4000, 4500]
    jst = T0 + np.round((np.arange(4000) + rng.normal(0, 0.1, 4000)) * PER).astype(np.int64)
    jlt = T0 + np.arange(4000) * PER + 5_000_000  # the log times follow the true clock
    assert not nudged_stamps(jst, jlt).any()  # jitter of 0.1 periods is no nudge
    jst[2000] += 6 * PER
    assert np.flatnonzero(nudged_stamps(jst, jlt)).tolist() == [2000]


def test_nudge_in_a_jittered_topic_never_leaves_the_neighbours_range(tmp_path):
    """Stamps with jitter (0.1 period): the topic is interpolated, but the moved stamp is dropped, and no
    grid value lies outside the two samples of the undamaged log around its time."""
    rng = np.random.default_rng(8)
    k = np.arange(N)
    st = T0 + np.round((k + rng.normal(0, 0.1, N)) * PER).astype(np.int64)
    st = np.sort(st)
    lt = T0 + k * PER + 1_000_000
    y = _signal(k)
    bad = st.copy()
    bad[1500] += 23 * PER + 411_000
    s = read_mcap(_log(tmp_path / "j.mcap", bad, y, lt), [CH])
    tb = s.meta["timebase"]["/imu"]
    assert tb["outliers"] == 1 and tb["resampled"]
    tg = s.meta["t0_ns"] + np.round(np.arange(s.n_samples) / s.fs * 1e9).astype(np.int64)
    j = np.searchsorted(st, tg, "right")
    ok = (j > 0) & (j < N)
    lo = np.minimum(y[j[ok] - 1], y[j[ok]])
    hi = np.maximum(y[j[ok] - 1], y[j[ok]])
    v = s.data[0, ok]
    assert np.all(np.isnan(v) | ((v >= lo - 1e-12) & (v <= hi + 1e-12)))


@settings(max_examples=60, deadline=None)
@given(n=hst.integers(2, 200), seed=hst.integers(0, 2**32 - 1), jit=hst.floats(0.0, 0.45))
def test_interpolation_never_leaves_the_range_of_its_two_neighbours(n, seed, jit):
    """resample_to_grid (no low-pass: output rate at or above the source rate) puts every grid value
    between the two samples around its time, for any values (here uniform in ±1, spikes included)."""
    rng = np.random.default_rng(seed)
    t = np.sort(np.arange(n) + rng.uniform(-jit, jit, n)) / 100.0
    if np.any(np.diff(t) <= 0):
        return
    y = rng.uniform(-1, 1, (2, n))
    y[:, rng.integers(0, n)] = 1.0  # a spike
    grid = np.linspace(t[0], t[-1], 3 * n)
    v = resample_to_grid(t, y, grid, fs=300.0, fs_src=100.0)
    j = np.clip(np.searchsorted(t, grid, "right"), 1, n - 1)
    lo = np.minimum(y[:, j - 1], y[:, j])
    hi = np.maximum(y[:, j - 1], y[:, j])
    assert np.all((v >= lo - 1e-12) & (v <= hi + 1e-12))


def test_stray_stamp_the_log_times_cannot_show_is_left_out_of_an_on_grid_topic(tmp_path):
    """Log times that jitter by several periods hide a stamp moved by 0.3 periods (no outlier), but the
    stamp is off the grid all the others lie on: its sample is left out (NaN, said), the topic is still
    placed by index, every other value exact."""
    rng = np.random.default_rng(2)
    k = np.arange(N)
    st = T0 + k * PER
    lt = st + rng.integers(0, 5 * PER, N)  # logged 0-5 ms late
    y = _signal(k)
    bad = st.copy()
    bad[2000] += 300_000
    order = np.argsort(lt, kind="stable")  # written in log-time order, as a recorder would
    s = read_mcap(_log(tmp_path / "s.mcap", bad[order], y[order], lt[order]), [CH])
    tb = s.meta["timebase"]["/imu"]
    assert tb["resampled"] is False and tb["outliers"] == 0  # not told by the log times: by the grid
    assert np.isnan(s.data[0, 2000]) and np.isnan(s.data).sum() == 1
    assert np.array_equal(np.delete(s.data[0], 2000), np.delete(y, 2000))
    assert any("1 stamps off the grid" in w for w in s.meta["warnings"])
    assert sum(g["n_samples"] for g in s.meta["gaps"]) == 1
