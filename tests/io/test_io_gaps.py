"""Gaps and lost chunks become NaN (never interpolated), outlier stamps are dropped and
reported, and one bad message does not sink a channel: checked against the samples written."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from mcap.writer import CompressionType, Writer
from mcap_ros2.writer import Writer as Ros2Writer

from vibroscope.errors import ChannelError
from vibroscope.io import read_mcap
from vibroscope.io._ros2 import MSGDEFS
from vibroscope.io._scan import scan
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.io.timebase import outlier_stamps
from vibroscope.signals import Signals

from _io_helpers import IMU, imu_msg, write_imu_log

T0 = 20_000_000_000  # 20 s in ns
CH = "/imu.linear_acceleration.x"


def _sine(t_ns, f=13.0):
    return np.sin(2 * np.pi * f * (t_ns - T0) * 1e-9)


def _gap_mask(r, topic=None):
    m = np.zeros(r.n_samples, bool)
    for g in r.meta["gaps"]:
        if topic is None or g["topic"] == topic:
            i0 = round((g["start_s"] - r.t0) * r.fs)
            m[i0 : i0 + g["n_samples"]] = True
    return m


def test_on_grid_topic_placed_by_index_nan_in_gaps(tmp_path):
    """A regular 1 kHz log with a lost stretch and dropped messages: no interpolation at all."""
    n = 4000
    st = T0 + np.arange(n, dtype=np.int64) * 1_000_000
    x = np.random.default_rng(2).standard_normal(n)  # white noise: any interpolation would show
    drop = np.zeros(n, bool)
    drop[1200:1700] = True  # 0.5 s lost
    drop[[50, 51, 52, 3000]] = True  # dropped messages
    p = tmp_path / "g.mcap"
    write_imu_log(p, {"/imu": (st[~drop], x[~drop])})
    r = read_mcap(p, [CH])
    assert r.fs == 1000.0 and r.n_samples == n and r.meta["t0_ns"] == T0
    assert r.meta["timebase"]["/imu"]["resampled"] is False
    nan = np.isnan(r.data[0])
    assert np.array_equal(nan, drop)  # NaN exactly where nothing was logged
    assert np.array_equal(r.data[0, ~nan], x[~drop])  # every other sample the logged one, exactly
    assert [(g["n_samples"], g["start_s"]) for g in r.meta["gaps"]] == [
        (3, pytest.approx(20.050)), (500, pytest.approx(21.2)), (1, pytest.approx(23.0))]
    assert all(g["length_s"] == pytest.approx(g["n_samples"] * 1e-3) for g in r.meta["gaps"])
    assert r.meta["nan_samples"] == {CH: 504}
    assert "topic '/imu': 3 gaps, 0.504 s in all (first at 0.05 s): 504 samples are NaN (not interpolated)" \
        in r.meta["warnings"]


def test_resampled_topic_interpolated_per_run_nan_in_gaps(tmp_path):
    """A jittered topic: a spline within each run (the sine within its error), NaN across the gap."""
    rng = np.random.default_rng(4)
    n = 3000
    st = T0 + np.arange(n, dtype=np.int64) * 2_000_000 + rng.integers(-200_000, 200_001, n)  # 500 Hz +-0.2 ms
    keep = np.ones(n, bool)
    keep[1000:1100] = False  # 0.2 s gap
    st = st[keep]
    p = tmp_path / "j.mcap"
    write_imu_log(p, {"/imu": (st, _sine(st))})
    r = read_mcap(p, [CH], fs=500.0)
    assert r.meta["timebase"]["/imu"]["resampled"] is True
    grid = r.meta["t0_ns"] + np.round(np.arange(r.n_samples) / r.fs * 1e9).astype(np.int64)
    # the grid samples strictly between the stamps bracketing the gap are NaN, and only those
    a, b = st[999], st[1000]
    expect_nan = (grid > a) & (grid < b)
    assert expect_nan.sum() >= 99
    assert np.array_equal(np.isnan(r.data[0]), expect_nan)
    assert np.array_equal(_gap_mask(r), expect_nan)
    ok = ~expect_nan
    # the shape-preserving interpolant (PCHIP, never outside its two samples) errs near an extremum by up
    # to A (w h)^2 / 8: 13 Hz, h <= 2.4 ms (2 ms +- 0.2 ms jitter) gives 4.8e-3; RMS well below
    err = r.data[0, ok] - _sine(grid[ok])
    assert np.max(np.abs(err)) < (2 * np.pi * 13.0 * 2.4e-3) ** 2 / 8 and np.sqrt(np.mean(err**2)) < 1e-3


def test_downsampled_per_run_nan_in_gap(tmp_path):
    """Downsampling: the anti-alias filter runs per run too; the gap stays NaN."""
    n = 6000
    st = T0 + np.arange(n, dtype=np.int64) * 1_000_000
    keep = np.ones(n, bool)
    keep[3000:3500] = False
    st = st[keep]
    p = tmp_path / "d.mcap"
    write_imu_log(p, {"/imu": (st, _sine(st, 2.0))})
    r = read_mcap(p, [CH], fs=100.0)
    grid = r.meta["t0_ns"] + np.round(np.arange(r.n_samples) / r.fs * 1e9).astype(np.int64)
    expect_nan = (grid > st[2999]) & (grid < st[3000])
    assert np.array_equal(np.isnan(r.data[0]), expect_nan) and expect_nan.sum() == 50
    inner = np.abs(grid - (T0 + 3.25e9)) < 2.5e9  # away from the run ends' filter transients
    inner &= np.abs(grid - (T0 + 3.25e9)) > 0.5e9
    assert np.max(np.abs(r.data[0, inner] - _sine(grid[inner], 2.0))) < 1e-3


def test_lost_chunk_is_a_gap(tmp_path):
    """A chunk skipped for its CRC: its span is NaN, everything else the written samples."""
    n = 4000
    x = np.random.default_rng(7).standard_normal((1, n))
    p = write_ros2_mcap(tmp_path / "u.mcap", Signals(data=x, fs=1000.0, channels=[CH], t0=50.0), chunk_size=32_000,
                        compression="none")
    data = bytearray(p.read_bytes())
    blocks = scan(p).blocks
    b = blocks[2]
    end = b.file_offset + 9 + struct.unpack_from("<Q", data, b.file_offset + 1)[0]
    data[end - 40] ^= 0x01
    q = tmp_path / "crc.mcap"
    q.write_bytes(bytes(data))
    r = read_mcap(q, [CH])
    lost = np.zeros(n, bool)
    first = sum(bl.n for bl in blocks[:2])
    lost[first : first + b.n] = True
    assert r.n_samples == n and np.array_equal(np.isnan(r.data[0]), lost)
    assert np.array_equal(r.data[0, ~lost], x[0, ~lost])
    assert r.meta["gaps"] == [{"topic": "/imu", "start_s": pytest.approx(50.0 + first / 1000),
                               "length_s": pytest.approx(b.n / 1000), "n_samples": b.n}]
    assert any(f"{b.n} samples are NaN (not interpolated)" in w for w in r.meta["warnings"])


def _write_no_crc(path, st, x, log_times):
    with open(path, "wb") as fh:
        w = Ros2Writer(fh, chunk_size=50_000, compression=CompressionType.NONE, enable_crcs=False)
        schema = w.register_msgdef(IMU, MSGDEFS[IMU])
        for k in range(len(st)):
            w.write_message("/imu", schema, imu_msg(int(st[k]), x[k]), log_time=int(log_times[k]))
        w.finish()


def test_flipped_stamp_bit_is_an_outlier_not_a_longer_grid(tmp_path):
    n = 3795
    st = T0 + np.arange(n, dtype=np.int64) * 10_000_000  # 100 Hz, 38 s
    x = np.random.default_rng(8).standard_normal(n)
    p = tmp_path / "ok.mcap"
    _write_no_crc(p, st, x, st)
    data = bytearray(p.read_bytes())
    k = 1234
    sec, nsec = int(st[k] // 1_000_000_000), int(st[k] % 1_000_000_000)
    pat = struct.pack("<Ii", sec, nsec)
    assert data.count(pat) == 1  # the header stamp of message k, in the uncompressed chunk
    pos = data.index(pat)
    data[pos + 2] ^= 0x10  # bit 20 of sec: +12 days
    q = tmp_path / "flip.mcap"
    q.write_bytes(bytes(data))
    r = read_mcap(q, [CH])
    assert r.n_samples == n and r.fs == 100.0
    assert np.isnan(r.data[0, k]) and np.isnan(r.data[0]).sum() == 1
    assert np.array_equal(np.delete(r.data[0], k), np.delete(x, k))
    out = r.meta["outliers"]
    assert out == [{"topic": "/imu", "count": 1, "stamps_ns": [int(st[k]) + (1 << 20) * 1_000_000_000],
                    "log_times_ns": [int(st[k])]}]
    assert any("'/imu': 1 outlier stamps dropped" in w for w in r.meta["warnings"])
    assert r.meta["timebase"]["/imu"]["outliers"] == 1


def test_outlier_stamps_rules():
    t = T0 + np.arange(500, dtype=np.int64) * 1_000_000
    assert not outlier_stamps(t).any() and not outlier_stamps(t, t).any()
    u = t.copy()
    u[[0, 200, 499]] += 10**12  # isolated jumps, at both ends too
    assert np.flatnonzero(outlier_stamps(u)).tolist() == [0, 200, 499]
    v = t.copy()
    v[300:302] -= 5 * 10**11  # two adjacent: the log times tell
    assert np.flatnonzero(outlier_stamps(v, t)).tolist() == [300, 301]
    assert np.flatnonzero(outlier_stamps(v)).tolist() == [300, 301]  # a small far cluster
    g = np.r_[t, t[-1] + 600 * 10**9 + t[:100] - T0]  # a 10 min logging gap is no outlier
    assert not outlier_stamps(g).any()


def test_grid_far_larger_than_the_messages_refused(tmp_path):
    st = T0 + np.arange(400, dtype=np.int64) * 1_000_000
    st[-200:] += 3600 * 10**9  # half the messages an hour later: a 3.6e6-sample grid for 400 messages
    p = tmp_path / "far.mcap"
    write_imu_log(p, {"/imu": (st, np.zeros(400))})
    with pytest.raises(ChannelError, match=r"topic '/imu'.*more than 10 times the 400 messages"):
        read_mcap(p, [CH])


def _json_log(path, payloads, period=1_000_000, jitter=None):
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start("", "test")
        sid = w.register_schema("m", "jsonschema", b"{}")
        cid = w.register_channel("/j", "json", sid)
        for k, pl in enumerate(payloads):
            lt = T0 + k * period + (int(jitter[k]) if jitter is not None else 0)
            w.add_message(cid, log_time=lt, data=pl, publish_time=lt)
        w.finish()


def test_one_bad_message_gives_nan_not_a_lost_channel(tmp_path):
    n = 200
    v = np.arange(n, dtype=float) * 0.5
    pl = [json.dumps({"a": {"b": float(x)}, "c": 1.0}).encode() for x in v]
    pl[10] = json.dumps({"c": 1.0}).encode()  # field missing
    pl[20] = json.dumps({"a": {"b": "oops"}, "c": 1.0}).encode()  # not a number
    pl[30] = b"{not json"  # does not decode: no stamp, dropped
    p = tmp_path / "j.mcap"
    _json_log(p, pl)
    r = read_mcap(p, ["/j.a.b", "/j.c"])
    assert r.n_samples == n and r.fs == 1000.0
    assert np.flatnonzero(np.isnan(r.data[0])).tolist() == [10, 20, 30]
    assert np.flatnonzero(np.isnan(r.data[1])).tolist() == [30]
    ok = ~np.isnan(r.data[0])
    assert np.array_equal(r.data[0, ok], v[ok])
    sk = [s for s in r.meta["skipped"] if s.get("topic") == "/j"]
    assert [s.get("field") for s in sk if "field" in s] == ["/j.a.b", "/j.a.b"]
    assert all(isinstance(s["offset"], int) for s in sk)
    assert any("does not decode" in s["reason"] for s in sk)
    w = " | ".join(r.meta["warnings"])
    assert "2 messages lack field '/j.a.b'" in w and "1 messages do not decode" in w
    assert r.meta["nan_samples"] == {"/j.a.b": 3, "/j.c": 1}
    # a field absent from the first decodable message still fails, naming topic and field
    with pytest.raises(ChannelError, match=r"'/j'.*a\.x"):
        read_mcap(p, ["/j.a.x"])


# -- the grid layer on its own, over many drop patterns ---------------------------------------
from hypothesis import given, settings, strategies as hst  # noqa: E402

from vibroscope.io._grid import TopicSamples, onto_grid  # noqa: E402
from vibroscope.io.timebase import analyse_stamps, fit_stamps  # noqa: E402


@settings(max_examples=60, deadline=None)
@given(n=hst.integers(8, 300), seed=hst.integers(0, 2**32 - 1), p_drop=hst.floats(0.0, 0.5),
       jitter=hst.sampled_from([0, 2_000, 100_000, 300_000]))
def test_grid_never_fills_a_gap(n, seed, p_drop, jitter):
    rng = np.random.default_rng(seed)
    keep = rng.random(n) >= p_drop
    keep[[0, -1]] = True
    k_src = np.flatnonzero(keep)
    t = T0 + k_src * 1_000_000 + rng.integers(-jitter, jitter + 1, k_src.size) * (k_src > 0) * (k_src < n - 1)
    t = np.sort(t)
    if np.any(np.diff(t) <= 0):
        return
    y = np.vstack([_sine(t, 5.0), rng.standard_normal(t.size)])
    _, rep = analyse_stamps("/x", t)
    warnings: list[str] = []
    start, rows, resampled, gaps = onto_grid("f", ["/x"], {"/x": TopicSamples(t, y, rep)}, 1000.0, warnings)
    out = rows["/x"]
    m = out.shape[1]
    grid = start + np.round(np.arange(m) / 1000.0 * 1e9).astype(np.int64)
    nan = np.isnan(out[0])
    assert np.array_equal(nan, np.isnan(out[1]))
    assert sum(g["n_samples"] for g in gaps) == nan.sum()
    if jitter <= 2_000 and not resampled["/x"]:  # on the grid: placed by index, exactly the logged values
        k = np.rint((t - start) * 1e-6).astype(int)
        assert np.array_equal(out[:, k], y) and nan.sum() == m - k.size
        return
    # interpolated: finite exactly where a run (no gap of fit_stamps, >= 2 samples) brackets
    cut = np.flatnonzero(fit_stamps(t).gap)
    assert rep.gaps == cut.size
    firsts, lasts = np.r_[0, cut + 1], np.r_[cut, t.size - 1]
    inside = np.zeros(m, bool)
    down = rep.fs_est > 1000.0 * 1.01  # anti-alias filtered: a run needs 28 samples at fs_est
    for a, b in zip(firsts, lasts):
        if b > a and (not down or np.floor((t[b] - t[a]) * 1e-9 * rep.fs_est) + 1 > 27):
            inside |= (grid >= t[a]) & (grid <= t[b])
    assert np.array_equal(~nan, inside)
    if not down:  # (the anti-alias filter, applied when +-30 % jitter biases fs_est up, rings at run ends)
        assert np.all(np.abs(out[0, ~nan] - _sine(grid[~nan], 5.0)) < 1e-3)


def test_bad_message_in_a_resampled_topic_is_nan_around_its_stamp(tmp_path):
    """Jittered log times (resampled): the bad message's row breaks its run, the other row does not."""
    n = 400
    rng = np.random.default_rng(12)
    jit = rng.integers(-50_000, 50_001, n)
    t = T0 + np.arange(n) * 1_000_000 + jit
    pl = [json.dumps({"a": float(_sine(tk)), "c": float(_sine(tk, 3.0))}).encode() for tk in t]
    pl[200] = json.dumps({"c": float(_sine(t[200], 3.0))}).encode()  # "a" missing
    p = tmp_path / "jj.mcap"
    _json_log(p, pl, jitter=jit)
    r = read_mcap(p, ["/j.a", "/j.c"], fs=1000.0)
    assert r.meta["timebase"]["/j"]["resampled"] is True
    grid = r.meta["t0_ns"] + np.round(np.arange(r.n_samples) / r.fs * 1e9).astype(np.int64)
    expect = (grid > t[199]) & (grid < t[201])  # between the good neighbours of the bad message
    assert np.array_equal(np.isnan(r.data[0]), expect) and not np.isnan(r.data[1]).any()
    ok = ~expect
    # PCHIP's bound A (w h)^2 / 8 at 13 Hz, h <= 1.1 ms: 1.0e-3
    assert np.max(np.abs(r.data[0, ok] - _sine(grid[ok]))) < (2 * np.pi * 13.0 * 1.1e-3) ** 2 / 8
    assert r.meta["gaps"] == []  # the topic has no gap; the NaN is the field's, counted per channel
    assert r.meta["nan_samples"] == {"/j.a": int(expect.sum()), "/j.c": 0}


def test_a_topic_cropped_to_the_common_span_is_said(tmp_path):
    """/imu/a runs 10 s, /imu/b stops after 4 s: the record is their common 4 s and the warning says
    that 6 s of /imu/a are not analysed (before: silently cropped); a topic of one message is named
    when nothing overlaps."""
    from _io_helpers import write_imu_log

    t = 5_000_000_000 + np.arange(10_000, dtype=np.int64) * 1_000_000
    ax = np.sin(np.arange(10_000) / 7.0)
    p = tmp_path / "crop.mcap"
    write_imu_log(p, {"/imu/a": (t, ax), "/imu/b": (t[:4000], ax[:4000])})
    sig = read_mcap(p, ["/imu/a.linear_acceleration.x", "/imu/b.linear_acceleration.x"])
    assert sig.n_samples == 4000
    w = [x for x in sig.meta["warnings"] if "outside the span all topics cover" in x]
    assert len(w) == 1 and w[0].startswith("topic '/imu/a': 6 s of its 9.999 s")
    q = tmp_path / "one.mcap"
    write_imu_log(q, {"/imu/a": (t, ax), "/imu/b": (t[:1], ax[:1])})
    with pytest.raises(ChannelError, match=r"do not overlap in time: /imu/b \(1 message\)"):
        read_mcap(q, ["/imu/a.linear_acceleration.x", "/imu/b.linear_acceleration.x"])
