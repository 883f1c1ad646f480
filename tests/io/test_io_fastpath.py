"""The MCAP read fast path (issue 9, target 1) gives exactly what decoding every message gives.

Logs with frame ids of every length 0..40 (mixed within a topic), jittered and gapped stamps,
several topics interleaved in one chunk, zstd / lz4 / uncompressed chunks: the fast path
(chunks opened ahead on threads, records indexed by numpy or the compiled walk, payloads
decoded by strided views or per-field gathers) against the record-by-record scan and the
mcap_ros2 decoder.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType, Writer

from vibroscope.io import _extract, read_mcap
from vibroscope.io._ros2 import FLOAT_FIELDS, MSGDEFS, encode_fixed
from vibroscope.io._index_kernels import index_messages
from vibroscope.io._scan import scan
from vibroscope.io.log_index import LogIndex
from vibroscope.io.paths import parse_path

IMU = "sensor_msgs/msg/Imu"
WRENCH = "geometry_msgs/msg/WrenchStamped"
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def _stamps(rng, n: int, period_ns: int, pattern: str) -> np.ndarray:
    t = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * period_ns
    if pattern in ("jitter", "jitter+gaps"):
        t = t + rng.integers(-period_ns // 20, period_ns // 20, n)
    if pattern in ("gaps", "jitter+gaps"):
        t[n // 3 :] += 40 * period_ns
        t[2 * n // 3 :] += 7 * period_ns + 3
    return t


def _write(path: Path, topics: dict, compression: str, chunk_size: int, extra: dict | None = None) -> Path:
    """topics: {topic: (type, stamps, {field: values}, frame ids per message)}; messages in log-time
    order (log time = stamp), so that topics interleave inside the chunks. `extra`: {(topic, k):
    payload} replaces message k's payload."""
    events = []
    payloads = {}
    for topic, (tname, st, vals, fids) in topics.items():
        sec, nsec = st // 1_000_000_000, st % 1_000_000_000
        for k in range(st.size):
            one = {f: v[k : k + 1] for f, v in vals.items()}
            payloads[topic, k] = encode_fixed(tname, sec[k : k + 1], nsec[k : k + 1], one, fids[k])[0].tobytes()
            events.append((int(st[k]), topic, k))
    payloads.update(extra or {})
    events.sort()
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        w.start("ros2", "test")
        ids = {}
        for topic, (tname, *_rest) in topics.items():
            sid = w.register_schema(tname, "ros2msg", MSGDEFS[tname].encode())
            ids[topic] = w.register_channel(topic, "cdr", sid)
        for seq, (lt, topic, k) in enumerate(events):
            w.add_message(ids[topic], log_time=lt, data=payloads[topic, k], publish_time=lt, sequence=seq)
        w.finish()
    return path


def _frame_ids(rng, n: int, mixed: bool) -> list[str]:
    if not mixed:
        return ["imu_link"] * n
    lens = rng.integers(0, 41, n)
    lens[:41] = np.arange(41)  # every length 0..40 at least once
    return ["".join(chr(97 + (i + j) % 26) for j in range(int(m))) for i, m in enumerate(lens)]


def _log(tmp_path, rng, compression, mixed, pattern, chunk_size=40_000, extra=None):
    n1, n2, n3 = 1500, 700, 300
    topics = {
        "/imu": (IMU, _stamps(rng, n1, 1_000_000, pattern),
                 {f"linear_acceleration.{c}": rng.standard_normal(n1) for c in "xyz"}, _frame_ids(rng, n1, mixed)),
        "/imu2": (IMU, _stamps(rng, n2, 2_000_000, pattern),
                  {"angular_velocity.z": rng.standard_normal(n2), "linear_acceleration.x": rng.standard_normal(n2)},
                  _frame_ids(rng, n2, mixed)),
        "/ft": (WRENCH, _stamps(rng, n3, 5_000_000, pattern),
                {"wrench.force.x": rng.standard_normal(n3), "wrench.torque.z": rng.standard_normal(n3)},
                _frame_ids(rng, n3, mixed)),
    }
    return _write(tmp_path / f"{compression}-{mixed}-{pattern}.mcap", topics, compression, chunk_size, extra), topics


CHANNELS = {
    "/imu": ["linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z", "header.stamp.sec",
             "header.stamp.nanosec", "orientation_covariance[0]"],
    "/imu2": ["angular_velocity.z", "linear_acceleration.x"],
    "/ft": ["wrench.force.x", "wrench.torque.z", "wrench.force.y"],
}


def _same_extraction(log: LogIndex) -> list[bool]:
    """Extract every channel of CHANNELS both ways; asserts they agree; returns the fast flags."""
    flags = []
    for topic, fields in CHANNELS.items():
        cid = log.by_topic[topic][0]
        parsed = [parse_path(f"{topic}.{f}").fields for f in fields]
        fast = _extract.extract(log, cid, parsed, [], [])
        sk, wa = [], []
        gen = _extract.generic_extract(log, cid, parsed, sk, wa)
        assert not sk and not wa
        assert fast.stamps.dtype == gen.stamps.dtype and np.array_equal(fast.stamps, gen.stamps)
        assert fast.values.tobytes() == gen.values.tobytes()
        assert fast.source == gen.source and np.array_equal(fast.log_times, gen.log_times)
        flags.append(fast.fast)
    return flags


def _same_read(path: Path, monkeypatch) -> None:
    chans = [f"{t}.{f}" for t, fs in CHANNELS.items() for f in fs if "stamp" not in f]
    fast = read_mcap(path, chans)
    with monkeypatch.context() as m:
        m.setattr(_extract, "fast_extract", lambda *a, **k: None)
        gen = read_mcap(path, chans)
    assert all(fast.meta["fast_path"].values()) and not any(gen.meta["fast_path"].values())
    assert fast.data.tobytes() == gen.data.tobytes() and fast.fs == gen.fs and fast.t0 == gen.t0
    for key in ("warnings", "skipped", "gaps", "nan_samples", "outliers", "timebase", "t0_ns"):
        assert fast.meta[key] == gen.meta[key], key


def _same_scan(path: Path) -> None:
    """The fast scan (threads, numpy and compiled indexing) equals the record-by-record one."""
    a, b = scan(path), scan(path, fast=False, workers=1)
    assert len(a.blocks) == len(b.blocks)
    for x, y in zip(a.blocks, b.blocks):
        assert x.file_offset == y.file_offset and bytes(x.buf) == bytes(y.buf)
        for f in ("channel_id", "log_time", "start", "length"):
            assert getattr(x, f).dtype == getattr(y, f).dtype and np.array_equal(getattr(x, f), getattr(y, f)), f
    assert a.skipped == b.skipped and a.warnings == b.warnings


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
@pytest.mark.parametrize("mixed", [False, True], ids=["one-frame-id", "frame-ids-0..40"])
@pytest.mark.parametrize("pattern", ["regular", "jitter", "jitter+gaps"])
def test_fast_path_equals_decoding(tmp_path, monkeypatch, compression, mixed, pattern):
    rng = np.random.default_rng(hash((compression, mixed, pattern)) % 2**32)
    path, topics = _log(tmp_path, rng, compression, mixed, pattern)
    _same_scan(path)
    log = LogIndex.open(path)
    assert all(_same_extraction(log))
    got = _extract.fast_extract(log, log.by_topic["/imu"][0], ["linear_acceleration.x"])
    st, ax = got
    assert np.array_equal(np.sort(st), np.sort(topics["/imu"][1]))
    assert np.array_equal(ax[0][np.argsort(st, kind="stable")],
                          topics["/imu"][2]["linear_acceleration.x"][np.argsort(topics["/imu"][1], kind="stable")])
    _same_read(path, monkeypatch)


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_one_topic_in_large_chunks(tmp_path, monkeypatch, compression):
    """The common case (one Imu topic, one frame id: periodic records, strided views) and the
    same with frame ids of mixed lengths (compiled record walk, per-field gathers)."""
    rng = np.random.default_rng(5)
    for mixed in (False, True):
        n = 20_000
        topics = {"/imu": (IMU, _stamps(rng, n, 1_000_000, "jitter"),
                           {f"linear_acceleration.{c}": rng.standard_normal(n) for c in "xyz"},
                           _frame_ids(rng, n, mixed))}
        path = _write(tmp_path / f"one-{mixed}.mcap", topics, compression, 1 << 20)
        _same_scan(path)
        chans = [f"/imu.linear_acceleration.{c}" for c in "xyz"]
        fast = read_mcap(path, chans)
        with monkeypatch.context() as m:
            m.setattr(_extract, "fast_extract", lambda *a, **k: None)
            gen = read_mcap(path, chans)
        assert fast.meta["fast_path"]["/imu"] and fast.data.tobytes() == gen.data.tobytes()
        assert fast.meta["warnings"] == gen.meta["warnings"]


def test_payload_off_layout_falls_back_to_decoding(tmp_path, monkeypatch):
    """A payload with bytes more than its layout (or a frame_id length that disagrees with its
    payload length, or a big-endian encapsulation) is not taken by the fast path: the topic is
    decoded message by message, with the same result as before."""
    rng = np.random.default_rng(7)
    base = _log(tmp_path, rng, "zstd", True, "regular")[1]
    tname, st, vals, fids = base["/imu"]
    good = encode_fixed(tname, st[10:11] // 10**9, st[10:11] % 10**9,
                        {f: v[10:11] for f, v in vals.items()}, fids[10])[0].tobytes()
    for name, bad in {"trailing": good + b"\0" * 8,
                      "flen": good[:12] + (int.from_bytes(good[12:16], "little") + 9).to_bytes(4, "little") + good[16:],
                      "encapsulation": b"\x00\x02" + good[2:]}.items():
        path = _write(tmp_path / f"bad-{name}.mcap", base, "zstd", 40_000, {("/imu", 10): bad})
        _same_scan(path)
        log = LogIndex.open(path)
        cid = log.by_topic["/imu"][0]
        assert _extract.fast_extract(log, cid, ["linear_acceleration.x"]) is None, name
        assert _extract.fast_extract(log, log.by_topic["/imu2"][0], ["linear_acceleration.x"]) is not None
        flags = _same_extraction(log) if name == "trailing" else None
        if flags is not None:
            assert flags == [False, True, True]


def test_damaged_chunk_same_with_threads(tmp_path):
    """A chunk that fails its CRC is skipped and reported the same whether chunks are opened
    ahead on threads or in turn; the others are read."""
    rng = np.random.default_rng(9)
    path, _ = _log(tmp_path, rng, "none", True, "jitter", chunk_size=8_000)
    data = bytearray(path.read_bytes())
    a = scan(path)
    victim = a.blocks[3]
    data[victim.file_offset + 9 + 40 + 500] ^= 0xFF  # inside the uncompressed chunk data
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    r1, r2, r3 = scan(bad), scan(bad, workers=1), scan(bad, workers=2, mode="stream")
    assert r1.skipped == r2.skipped and any("CRC-32 mismatch" in s for _, s in r1.skipped)
    assert [b.file_offset for b in r1.blocks] == [b.file_offset for b in r2.blocks]
    assert victim.file_offset not in [b.file_offset for b in r1.blocks]
    assert len(r1.blocks) == len(a.blocks) - 1 and [b.file_offset for b in r3.blocks] == [b.file_offset for b in r2.blocks]


def test_compiled_walk_equals_record_walk():
    """The compiled record walk indexes a chunk of mixed records exactly as the walk record by
    record does, and leaves a cut-off record to it (which raises)."""
    rng = np.random.default_rng(11)
    recs = []
    for k in range(300):
        payload = bytes(rng.integers(0, 256, int(rng.integers(0, 60)), dtype=np.uint8))
        body = (int(rng.integers(1, 4))).to_bytes(2, "little") + k.to_bytes(4, "little") \
            + int(rng.integers(0, 2**63)).to_bytes(8, "little") + (7).to_bytes(8, "little") + payload
        recs.append(b"\x05" + len(body).to_bytes(8, "little") + body)
    buf = b"".join(recs)
    a, b = index_messages(buf, 0, len(buf), [], True), index_messages(buf, 0, len(buf), [], False)
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    cut = buf[:-5]
    for fast in (True, False):
        with pytest.raises(ValueError, match="needs"):
            index_messages(cut, 0, len(cut), [], fast)
    assert set(FLOAT_FIELDS) == {IMU, WRENCH}
