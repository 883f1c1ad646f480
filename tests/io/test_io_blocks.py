"""Reading a log in blocks on one fixed grid (vibroscope.io.blocks): the concatenated blocks are
read_mcap's record, sample for sample, for on-grid topics; lost chunks are NaN; each block
decompresses only the chunks overlapping it."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tests.io._io_helpers import copy_without_summary
from vibroscope.io import read_mcap, write_ros2_mcap
from vibroscope.io import blocks as blocks_mod
from vibroscope.io._scan import scan
from vibroscope.io.blocks import iter_blocks, open_grid
from vibroscope.signals import Signals

CHS = [f"/imu.linear_acceleration.{a}" for a in "xyz"]


@pytest.fixture(scope="module")
def imu_log(tmp_path_factory):
    """3 axes of random data at 1024 Hz (a period of 976562.5 ns: stamps rounded to ns), many chunks."""
    x = np.random.default_rng(3).standard_normal((3, 20_000))
    p = tmp_path_factory.mktemp("blocks") / "imu.mcap"
    write_ros2_mcap(p, Signals(data=x, fs=1024.0, channels=CHS, t0=100.0), chunk_size=40_000)
    return p, x


@pytest.mark.parametrize("block", [1, 997, 4096, 50_000])
def test_blocks_concatenate_to_read_mcap(imu_log, block):
    p, x = imu_log
    whole = read_mcap(p)
    g = open_grid(p)
    assert g.fs == whole.fs and g.n_samples == whole.n_samples == x.shape[1]
    assert g.t0_ns == whole.meta["t0_ns"] and g.channels == tuple(whole.channels) and g.units == tuple(whole.units)
    bl = list(g.blocks(block)) if block > 1 else [g.read(i, i + 1) for i in (0, 1, 12_345, x.shape[1] - 1)]
    if block > 1:
        got = np.concatenate([b.data for b in bl], axis=1)
        assert np.array_equal(got, whole.data) and np.array_equal(got, x)
        assert [b.meta["grid_index"] for b in bl] == list(range(0, x.shape[1], block))
        assert all(b.t0 == pytest.approx(whole.t0 + b.meta["grid_index"] / whole.fs, abs=1e-9) for b in bl)
    else:  # single samples anywhere on the grid
        assert [b.data[0, 0] for b in bl] == [x[0, i] for i in (0, 1, 12_345, x.shape[1] - 1)]


def test_iter_blocks_time_range_and_grid_outside(imu_log):
    p, x = imu_log
    bl = list(iter_blocks(p, CHS[:2], block_s=1.0, time_range=(105.0, 110.0)))
    got = np.concatenate([b.data for b in bl], axis=1)
    i0 = 5 * 1024
    assert got.shape == (2, 5 * 1024) and np.array_equal(got, x[:2, i0 : i0 + 5 * 1024])
    assert len(bl) == 5 and bl[0].t0 == pytest.approx(105.0, abs=1e-9)
    # samples before the first and after the last message are NaN, the rest is the data
    g = open_grid(p)
    edge = g.read(-3, 3)
    assert np.isnan(edge.data[:, :3]).all() and np.array_equal(edge.data[:, 3:], x[:, :3])
    # a grid origin given explicitly: blocks of different calls line up on it
    g2 = open_grid(p, t0_ns=g.time_of(-10))
    assert np.array_equal(g2.read(0, 20).data, g.read(-10, 10).data, equal_nan=True)
    with pytest.raises(ValueError, match="block_s"):
        next(iter_blocks(p, block_s=0.0))
    with pytest.raises(ValueError, match="time_range"):
        next(iter_blocks(p, time_range=(110.0, 105.0)))


def test_a_block_reads_only_its_chunks(imu_log, monkeypatch):
    p, x = imu_log
    g = open_grid(p, margin_s=0.0)
    opened = []
    real = blocks_mod._open_chunk
    monkeypatch.setattr(blocks_mod, "_open_chunk", lambda fd, span: (opened.append(span), real(fd, span))[1])
    b = g.read(8000, 8100)  # 0.1 s out of 19.5 s
    assert np.array_equal(b.data, x[:, 8000:8100])
    assert 1 <= len(opened) <= 2 < len(g.chunks) // 10
    assert all(s.end_ns >= g.time_of(8000) and s.start_ns <= g.time_of(8099) for s in opened)


def test_lost_chunk_is_nan_in_the_blocks(imu_log, tmp_path):
    p, x = imu_log
    data = bytearray(p.read_bytes())
    b = scan(p).blocks[5]
    end = b.file_offset + 9 + struct.unpack_from("<Q", data, b.file_offset + 1)[0]
    data[end - 40] ^= 0x01  # inside the compressed data: the chunk fails to decompress or its CRC
    q = tmp_path / "lost.mcap"
    q.write_bytes(bytes(data))
    whole = read_mcap(q)
    got = np.concatenate([bl.data for bl in iter_blocks(q, block_s=3.0)], axis=1)
    lost = np.isnan(whole.data[0])
    assert lost.sum() == b.n and np.array_equal(np.isnan(got), np.isnan(whole.data))
    assert np.array_equal(got[:, ~lost], x[:, ~lost]) and np.array_equal(np.isnan(got[0]), lost)
    blk = open_grid(q).read(0, x.shape[1])
    assert any(s.get("offset") == b.file_offset for s in blk.meta["skipped"])


def test_log_without_summary_is_planned_by_one_linear_pass(imu_log, tmp_path):
    p, x = imu_log
    q = copy_without_summary(p, tmp_path / "nosummary.mcap")
    g = open_grid(q)
    assert not g.indexed and any("linear pass" in w for w in g.warnings)
    assert len(g.chunks) == len(open_grid(p).chunks)
    got = np.concatenate([b.data for b in g.blocks(3000)], axis=1)
    assert np.array_equal(got, x)


def test_off_grid_topic_is_interpolated_per_block(tmp_path):
    """Jittered stamps: each block is interpolated from its own (and its margin's) stamps; away from
    the block edges it agrees with the whole-log read to the spline's accuracy."""
    from tests.io._io_helpers import write_imu_log

    fs, n = 500.0, 6000
    rng = np.random.default_rng(4)
    t = (1e9 * (10.0 + np.arange(n) / fs + rng.uniform(-0.2, 0.2, n) / fs)).astype(np.int64)
    ax = np.sin(2 * np.pi * 7.0 * (t - t[0]) * 1e-9)
    p = tmp_path / "jitter.mcap"
    write_imu_log(p, {"/imu": (t, ax)}, chunk_size=20_000)
    whole = read_mcap(p, ["/imu.linear_acceleration.x"], fs=fs)
    g = open_grid(p, ["/imu.linear_acceleration.x"], fs=fs)
    assert g.t0_ns == whole.meta["t0_ns"] and g.n_samples == whole.n_samples
    got = np.concatenate([b.data for b in g.blocks(1000)], axis=1)
    ok = np.isfinite(got[0]) & np.isfinite(whole.data[0])
    assert ok.sum() > 0.95 * n
    assert np.max(np.abs(got[0, ok] - whole.data[0, ok])) < 1e-3


def test_errors_name_the_problem(imu_log, tmp_path):
    p, _ = imu_log
    from vibroscope.errors import ChannelError, LogFormatError

    with pytest.raises(ChannelError, match="no such topic"):
        open_grid(p, ["/nope.x"])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(LogFormatError, match="bad magic"):
        open_grid(bad)
    with pytest.raises(ValueError, match="fs="):
        open_grid(p, fs=-1.0)
    with pytest.raises(ValueError, match="i0="):
        open_grid(p).read(5, 5)


def test_lost_last_chunk_ends_the_grid_before_it(imu_log, tmp_path):
    """The last chunk lost: the grid ends with the last chunk that reads (as read_mcap's)."""
    p, x = imu_log
    data = bytearray(p.read_bytes())
    bl = scan(p).blocks
    b = bl[-1]
    end = b.file_offset + 9 + struct.unpack_from("<Q", data, b.file_offset + 1)[0]
    data[end - 40] ^= 0x01
    q = tmp_path / "lastlost.mcap"
    q.write_bytes(bytes(data))
    whole = read_mcap(q)
    g = open_grid(q)
    assert g.n_samples == whole.n_samples == x.shape[1] - b.n
    assert np.array_equal(np.concatenate([k.data for k in g.blocks(5000)], axis=1), x[:, : g.n_samples])


def test_damaged_summary_is_not_trusted(imu_log, tmp_path):
    from tests.io._io_helpers import copy_with_damaged_summary

    p, x = imu_log
    q = copy_with_damaged_summary(p, tmp_path / "badsummary.mcap")
    g = open_grid(q)
    assert not g.indexed and any("no usable summary" in w for w in g.warnings)
    assert np.array_equal(np.concatenate([b.data for b in g.blocks(7000)], axis=1), x)


def _lagged_log(path, lag_s=30.0):
    """Two Imu topics at 200 Hz logged `lag_s` (plus 0–3 ms of jitter) after their header stamps:
    /imu stamped on the grid, /imu2 with jittered (off-grid) stamps. Returns (path, /imu's x, /imu2's x)."""
    from tests.io._io_helpers import write_imu_log

    n = 2400  # 200 Hz
    rng = np.random.default_rng(11)
    t = (10_000_000_000 + np.arange(n) * 5_000_000).astype(np.int64)
    t2 = t + rng.integers(-1_000_000, 1_000_000, n)
    x, x2 = rng.standard_normal(n), np.sin(2 * np.pi * 3.0 * (t2 - t2[0]) * 1e-9)
    lag = int(lag_s * 1e9)
    lt = {"/imu": t + lag + rng.integers(0, 3_000_000, n), "/imu2": t2 + lag + rng.integers(0, 3_000_000, n)}
    write_imu_log(path, {"/imu": (t, x), "/imu2": (t2, x2)}, chunk_size=8_000, log_times=lt)
    return path, x, x2


def test_stamps_far_before_their_log_times(tmp_path):
    """Header stamps 30 s before their log times (the capstan joint states: 46 s): each block reads the
    chunks holding its stamps (the per-topic offset learnt while planning), not those of its log time,
    so the blocks are read_mcap's record (before: every block NaN)."""
    p, x, _ = _lagged_log(tmp_path / "lag.mcap")
    chs = ["/imu.linear_acceleration.x", "/imu2.linear_acceleration.x"]
    whole = read_mcap(p, chs, fs=200.0)
    g = open_grid(p, chs, fs=200.0)
    assert g.t0_ns == whole.meta["t0_ns"] and g.n_samples == whole.n_samples
    assert len(g.chunks) > 20
    got = np.concatenate([b.data for b in g.blocks(150)], axis=1)
    assert np.array_equal(got[0], whole.data[0]) and np.array_equal(got[0], x[: g.n_samples])
    off = dict((t, (lo, hi)) for t, lo, hi in g.stamp_offsets)
    for t in ("/imu", "/imu2"):  # stamp - log time: -30 s and up to 3 ms of jitter
        assert -30_003_000_000 < off[t][0] <= off[t][1] <= -30_000_000_000
    # the interpolated topic: one block over the whole grid reads every chunk as read_mcap does
    assert np.max(np.abs(g.read(0, g.n_samples).data - whole.data)) <= 1e-12
    # and block by block, away from the edges, to the spline's accuracy (as for any off-grid topic)
    ok = np.isfinite(got[1])
    assert ok.mean() > 0.95 and np.max(np.abs(got[1, ok] - whole.data[1, ok])) < 1e-3
    # a block reads few chunks: those stamped near it, mapped back by the offset
    opened = []
    real = blocks_mod._open_chunk
    import unittest.mock as um

    with um.patch.object(blocks_mod, "_open_chunk", lambda fd, span: (opened.append(span), real(fd, span))[1]):
        assert np.array_equal(g.read(1000, 1100).data[0], x[1000:1100])
    assert 0 < len(opened) < len(g.chunks) // 2
    # the offsets given (a Dask task's path: no chunk opened to plan) read the same
    opened.clear()
    with um.patch.object(blocks_mod, "_open_chunk", lambda fd, span: (opened.append(span), real(fd, span))[1]):
        g2 = open_grid(p, chs, fs=g.fs, t0_ns=g.t0_ns, n_samples=g.n_samples, stamp_offsets=g.stamp_offsets)
    assert not opened and g2.stamp_offsets == g.stamp_offsets
    assert np.array_equal(g2.read(500, 700).data, g.read(500, 700).data)
    # without them, they are learnt from the first and last chunks again
    g3 = open_grid(p, chs, fs=g.fs, t0_ns=g.t0_ns, n_samples=g.n_samples)
    assert g3.stamp_offsets == g.stamp_offsets
