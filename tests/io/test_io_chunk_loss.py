"""Lost chunks, lying sizes, bad rates and truncation (issue 21, items 1, 4, 5, 6).

A deleted chunk (the first, a middle one, with or without its message indexes) loses only its
own messages: every message of the other chunks comes back with its payload (so its values)
unchanged, and the loss is counted per topic in messages and seconds. A chunk whose stated
size lies, or a decompression bomb, is refused before anything is allocated for it, in well
under a second, and the other chunks are read. Rates are checked before the log is read.
The real logs are the capstan recordings of ``../shared/data/mcap/capstan`` (mcap-bag-parser
0.3.1, MIT).
"""

from __future__ import annotations

import struct
import time
import tracemalloc
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from vibroscope.io import mcap_info, read_mcap
from vibroscope.io._scan import MAX_RATIO, scan
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.signals import Signals

N = 4000
FS = 1000.0
T0 = 50.0
CH = "/imu.linear_acceleration.x"


def _chunks(path: Path, data: bytes) -> list[tuple[int, int, int]]:
    """(offset, end of the chunk record, end of its message indexes) of every chunk, in file order."""
    out = []
    for b in scan(path).blocks:
        if b.file_offset < 0:
            continue
        o = b.file_offset
        end = o + 9 + struct.unpack_from("<Q", data, o + 1)[0]
        e2 = end
        while data[e2] == 0x07:
            e2 += 9 + struct.unpack_from("<Q", data, e2 + 1)[0]
        out.append((o, end, e2))
    return out


def _messages(path: Path) -> Counter:
    """(topic, log time, payload) of every message read."""
    r = scan(path)
    return Counter((r.channels[c].topic, t, p) for c, t, p in r.messages())


def _delete(data: bytes, chunk: tuple[int, int, int], with_indexes: bool) -> bytes:
    o, end, e2 = chunk
    return data[:o] + data[e2 if with_indexes else end :]


@pytest.fixture(scope="module", params=["zstd", "none"])
def synth(request, tmp_path_factory):
    x = np.random.default_rng(3).standard_normal((1, N))
    p = tmp_path_factory.mktemp("loss") / f"ok_{request.param}.mcap"
    write_ros2_mcap(p, Signals(data=x, fs=FS, channels=[CH], t0=T0), chunk_size=32_000, compression=request.param)
    data = p.read_bytes()
    chunks = _chunks(p, data)
    assert len(chunks) >= 5
    return p, data, x[0], chunks


@pytest.mark.parametrize("which", [0, 2])
@pytest.mark.parametrize("with_indexes", [True, False])
def test_deleted_chunk_loses_only_its_messages(tmp_path, synth, which, with_indexes):
    p, data, x, chunks = synth
    lost_msgs = [m for m in scan(p).blocks if m.file_offset == chunks[which][0]][0]
    k = lost_msgs.n
    lost_t = lost_msgs.log_time.astype(np.int64)
    q = tmp_path / "del.mcap"
    q.write_bytes(_delete(data, chunks[which], with_indexes))
    s = read_mcap(q, [CH])
    assert s.fs == FS
    idx = np.rint((s.t0 + np.arange(s.n_samples) / FS - T0) * FS).astype(np.int64)
    ok = ~np.isnan(s.data[0])
    assert np.array_equal(s.data[0][ok], x[idx[ok]])  # every value read is the undamaged log's at its stamp
    got = set(idx[ok].tolist())
    stamps = np.rint((lost_t * 1e-9 - T0) * FS).astype(np.int64)
    assert got == set(range(N)) - set(stamps.tolist())  # every message of the other chunks is there
    assert s.meta["lost"]["/imu"]["messages"] == k
    assert s.meta["lost"]["/imu"]["seconds"] == pytest.approx((k - 1) / FS, abs=1e-9)
    assert any(f"{k} messages lost" in w for w in s.meta["warnings"])
    t = mcap_info(q).topic("/imu")
    assert t.message_count == N - k and t.lost_messages == k


def test_a_summary_with_a_flipped_byte_is_still_not_used(tmp_path, synth):
    """Relocation is no licence to use a damaged summary: a flipped byte fails its CRC-32 at every place."""
    from tests.io._io_helpers import copy_with_damaged_summary

    p, data, x, chunks = synth
    q = copy_with_damaged_summary(p, tmp_path / "flip.mcap")
    r = scan(q)
    assert not r.indexed and any("the summary is not used" in w for w in r.warnings)
    assert sum(b.n for b in r.blocks) == N


CAPSTAN = ["bagfile_0.mcap", "torque_ripple_data_0.mcap"]


@pytest.mark.parametrize("name", CAPSTAN)
@pytest.mark.parametrize("which,with_indexes", [(0, True), (0, False), (4, True), (4, False), (-1, True)])
def test_deleted_chunk_in_real_logs(tmp_path, shared_data, name, which, with_indexes):
    """The first, a middle and the last chunk of real logs deleted (with and without their message
    indexes; the torque-ripple log's summary has no CRC): the other chunks' messages are all read,
    payloads equal, and the loss per topic is that chunk's messages."""
    p = shared_data / "mcap" / "capstan" / name
    data = p.read_bytes()
    chunks = _chunks(p, data)
    ref = scan(p)
    o = chunks[which][0]
    gone = Counter()
    for b in ref.blocks:
        if b.file_offset == o:
            mv = memoryview(b.buf)
            for c, t, s, n in zip(b.channel_id.tolist(), b.log_time.tolist(), b.start.tolist(), b.length.tolist()):
                gone[(ref.channels[c].topic, t, bytes(mv[s : s + n]))] += 1
    q = tmp_path / "del.mcap"
    q.write_bytes(_delete(data, chunks[which], with_indexes))
    assert _messages(q) == _messages(p) - gone
    r = scan(q)
    per_topic = Counter(topic for (topic, _t, _p), k in gone.items() for _ in range(k))
    lost = r.lost_by_topic()
    assert {t: v[0] for t, v in lost.items()} == dict(per_topic)
    info = mcap_info(q)
    assert info.message_count == sum(_messages(p).values()) - sum(gone.values())
    for t, k in per_topic.items():
        assert info.topic(t).lost_messages == k and info.topic(t).lost_s > 0


def test_two_deleted_chunks_in_a_real_log(tmp_path, shared_data):
    """Two chunks deleted (two different shifts: the chunks between them are found by their
    record headers): the others all read, both losses counted."""
    p = shared_data / "mcap" / "capstan" / "bagfile_0.mcap"
    data = p.read_bytes()
    chunks = _chunks(p, data)
    (a, _, b), (c, _, e) = chunks[2], chunks[6]
    q = tmp_path / "two.mcap"
    q.write_bytes(data[:a] + data[b:c] + data[e:])
    ns = {blk.file_offset: blk.n for blk in scan(p).blocks}
    r = scan(q)
    assert sum(blk.n for blk in r.blocks) == sum(ns.values()) - ns[a] - ns[c]
    assert sum(v[0] for v in r.lost_by_topic().values()) == ns[a] + ns[c]
    assert any("2 list chunks no longer in the file" in w for w in r.warnings)


def test_read_mcap_of_a_real_log_without_its_first_chunk(tmp_path, shared_data):
    """bagfile_0 without its first chunk: the joint states of the other chunks, as in the whole log."""
    p = shared_data / "mcap" / "capstan" / "bagfile_0.mcap"
    data = p.read_bytes()
    chunks = _chunks(p, data)
    q = tmp_path / "del.mcap"
    q.write_bytes(_delete(data, chunks[0], True))
    ch = "/robot/joint_state.position[0]"
    a = read_mcap(p, [ch], resample=False, fs=100.0)
    b = read_mcap(q, [ch], resample=False, fs=100.0)
    assert b.n_samples == a.n_samples - b.meta["lost"]["/robot/joint_state"]["messages"]
    assert np.array_equal(a.data[0][-b.n_samples :], b.data[0])  # the later messages, values unchanged


def test_streaming_a_real_log_without_its_first_chunk(tmp_path, shared_data):
    """The block reader (--stream) finds the shifted summary as the whole read does: the joint
    states defined only in the lost first chunk are still named, and the loss is said."""
    from vibroscope.io.blocks import open_grid

    p = shared_data / "mcap" / "capstan" / "bagfile_0.mcap"
    data = p.read_bytes()
    q = tmp_path / "del.mcap"
    q.write_bytes(_delete(data, _chunks(p, data)[0], True))
    ch = "/robot/joint_state.position[0]"
    g = open_grid(q, [ch])
    assert g.channels == (ch,) and g.n_samples > 3000
    assert any("summary" in w and "lost" in w for w in g.warnings)
    whole = open_grid(p, [ch])
    assert abs(g.fs - whole.fs) < 0.02 * whole.fs  # each estimated from its first and last chunks


# -- lying sizes and bombs ----------------------------------------------------------------------
def _chunk_record(start: int, end: int, usize: int, comp: bytes, payload: bytes, crc: int = 0) -> bytes:
    body = struct.pack("<QQQI", start, end, usize, crc) + struct.pack("<I", len(comp)) + comp
    body += struct.pack("<Q", len(payload)) + payload
    return bytes([0x06]) + struct.pack("<Q", len(body)) + body


def _replace_chunk(data: bytes, chunk: tuple[int, int, int], record: bytes) -> bytes:
    o, end, _ = chunk
    return data[:o] + record + data[end:]


def _peak_read(path: Path) -> tuple[object, float, int]:
    """(read_mcap's Signals, seconds, peak traced bytes)."""
    tracemalloc.start()
    t = time.perf_counter()
    try:
        s = read_mcap(path, [CH])
    finally:
        dt = time.perf_counter() - t
        _cur, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return s, dt, peak


@pytest.fixture(scope="module")
def zlog(tmp_path_factory):
    x = np.random.default_rng(5).standard_normal((1, N))
    p = tmp_path_factory.mktemp("bomb") / "ok.mcap"
    write_ros2_mcap(p, Signals(data=x, fs=FS, channels=[CH], t0=T0), chunk_size=32_000, compression="zstd")
    data = p.read_bytes()
    return p, data, x[0], _chunks(p, data)


def _check_others_read(s, x, chunk_n: int, offset: int, what: str, path: Path) -> None:
    ok = ~np.isnan(s.data[0])
    idx = np.rint((s.t0 + np.arange(s.n_samples) / FS - T0) * FS).astype(np.int64)
    assert np.array_equal(s.data[0][ok], x[idx[ok]])
    assert ok.sum() == N - chunk_n
    hits = [w for w in s.meta["warnings"] if f"byte offset {offset}" in w and what in w]
    assert hits and str(path) in hits[0]


def test_lying_uncompressed_size_allocates_nothing(tmp_path, zlog):
    """A chunk header claiming 4 GiB - 1 uncompressed: refused before any allocation (the traced peak
    stays far below the claim), the other chunks read."""
    p, data, x, chunks = zlog
    o = chunks[1][0]
    d = bytearray(data)
    struct.pack_into("<Q", d, o + 9 + 16, 2**32 - 1)
    q = tmp_path / "lie.mcap"
    q.write_bytes(bytes(d))
    n1 = [b.n for b in scan(p).blocks if b.file_offset == o][0]
    s, dt, peak = _peak_read(q)
    assert peak < 64 << 20 and dt < 5.0
    _check_others_read(s, x, n1, o, f"exceeds {MAX_RATIO} times", q)


def test_lying_size_in_block_reading(tmp_path, zlog):
    """The block reader (:func:`vibroscope.io.blocks.open_grid`) refuses the lying chunk the same
    way: its samples NaN, named by its offset, the others equal to the undamaged log's."""
    from vibroscope.io.blocks import open_grid

    p, data, x, chunks = zlog
    o = chunks[1][0]
    d = bytearray(data)
    struct.pack_into("<Q", d, o + 9 + 16, 2**32 - 1)
    q = tmp_path / "lie.mcap"
    q.write_bytes(bytes(d))
    n1 = [b.n for b in scan(p).blocks if b.file_offset == o][0]
    g = open_grid(q, [CH], fs=FS)
    tracemalloc.start()
    try:
        s = g.read(0, g.n_samples)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20
    ok = ~np.isnan(s.data[0])
    idx = np.rint((s.t0 + np.arange(s.n_samples) / FS - T0) * FS).astype(np.int64)
    assert np.array_equal(s.data[0][ok], x[idx[ok]]) and ok.sum() == N - n1
    assert any(f"byte offset {o}" in w and f"exceeds {MAX_RATIO} times" in w for w in s.meta["warnings"])


def test_size_over_the_memory_budget_is_refused(zlog):
    """Honest chunks larger than one thread's share of max_memory (one thread: half) are skipped and
    named; the others are read whole."""
    p, data, x, chunks = zlog
    usize = [struct.unpack_from("<Q", data, c[0] + 9 + 16)[0] for c in chunks]
    top = max(usize)
    r = scan(p, workers=1, max_memory=2 * (top - 1))
    big = {c[0] for c, u in zip(chunks, usize) if u == top}
    assert 0 < len(big) < len(chunks)
    assert {d.offset for d in r.damage} == big
    assert all("memory budget" in d.reason for d in r.damage)
    assert sum(b.n for b in r.blocks) == N - sum(d.messages for d in r.damage)


def _zero_bomb_zstd(size: int, content_size: bool = True) -> bytes:
    import zstandard

    c = zstandard.ZstdCompressor(level=1, write_content_size=content_size).compressobj(size=size)
    piece = bytes(1 << 22)
    out = [c.compress(piece) for _ in range(size // len(piece))]
    return b"".join(out) + c.flush()


@pytest.mark.parametrize("stated", ["honest", "small", "small, frame without a size"])
def test_zstd_bomb_refused_fast(tmp_path, zlog, stated):
    """256 MiB of zeros in a few kB: refused in < 1 s by the ratio limit (stated honestly), by the
    frame's own size (stated as the original chunk's), or by the bounded stream (a frame that
    states no size runs on beyond the chunk's), memory small; the other chunks are read and the
    refusal names file and offset."""
    p, data, x, chunks = zlog
    o, end, _ = chunks[2]
    start, stop, usize = struct.unpack_from("<QQQ", data, o + 9)
    size = 256 << 20
    bomb = _zero_bomb_zstd(size, content_size="without" not in stated)
    rec = _chunk_record(start, stop, size if stated == "honest" else usize, b"zstd", bomb, crc=1)
    q = tmp_path / "bomb.mcap"
    q.write_bytes(_replace_chunk(data, chunks[2], rec))
    n2 = [b.n for b in scan(p).blocks if b.file_offset == o][0]
    s, dt, peak = _peak_read(q)
    assert dt < 1.0 and peak < 64 << 20
    what = {"honest": "decompression bomb", "small": f"zstd frame states {size} bytes, more than the {usize}",
            "small, frame without a size": f"decompresses to more than the {usize} bytes stated"}[stated]
    _check_others_read(s, x, n2, o, what, q)


def test_lz4_bomb_bounded(tmp_path, zlog):
    """An LZ4 frame of 64 MiB of zeros in a chunk stating its original size: decompression stops at
    the stated size (never 64 MiB), the chunk is refused, the others read."""
    lz4f = pytest.importorskip("lz4.frame")
    p, data, x, chunks = zlog
    o, end, _ = chunks[2]
    start, stop, usize = struct.unpack_from("<QQQ", data, o + 9)
    bomb = lz4f.compress(bytes(64 << 20))
    q = tmp_path / "lz4bomb.mcap"
    q.write_bytes(_replace_chunk(data, chunks[2], _chunk_record(start, stop, usize, b"lz4", bomb, crc=1)))
    n2 = [b.n for b in scan(p).blocks if b.file_offset == o][0]
    s, dt, peak = _peak_read(q)
    assert dt < 1.0 and peak < 32 << 20
    _check_others_read(s, x, n2, o, "chunk skipped", q)


# -- rates and channels checked before reading ------------------------------------------------
@pytest.mark.parametrize("kw,match", [
    (dict(fs=float("nan")), r"fs=nan must be finite and > 0"),
    (dict(fs=-1.0), r"fs=-1.0 must be finite and > 0"),
    (dict(fs=0.0), r"must be finite and > 0"),
    (dict(fs=float("inf")), r"must be finite and > 0"),
    (dict(fs=True), r"must be a number"),
    (dict(fs="100"), r"must be a number"),
    (dict(max_memory=-5), r"max_memory=-5 must be finite and > 0"),
])
def test_bad_rates_are_refused_before_reading(kw, match):
    with pytest.raises(ValueError, match=match):
        read_mcap("/nonexistent/never-opened.mcap", [CH], **kw)  # refused before the file is opened


def test_one_string_as_channels_is_refused():
    from vibroscope.io.blocks import open_grid

    for f in (read_mcap, open_grid):
        with pytest.raises(ValueError, match=r"not one string .*\['/imu.linear_acceleration.x'\]"):
            f("/nonexistent/never-opened.mcap", CH)
    with pytest.raises(ValueError, match=r"fs=nan must be finite and > 0"):
        open_grid("/nonexistent/never-opened.mcap", [CH], fs=float("nan"))


@pytest.mark.parametrize("fs", [1e9, 1e12, 2e6])
def test_rates_above_the_upsampling_limit_are_refused_before_the_grid(synth, fs):
    p = synth[0]
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=r"exceeds the limit of 100 times the highest topic rate"):
            read_mcap(p, [CH], fs=fs)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20


def test_grid_over_the_memory_budget_is_refused(synth):
    with pytest.raises(ValueError, match=r"holds 199951 samples x 1 channels, about 3 MiB, more than the memory budget of 1 MiB"):
        read_mcap(synth[0], [CH], fs=50 * FS, max_memory=1 << 20)  # 200 000 samples x 16 bytes


@pytest.mark.parametrize("fs", ["nan", "-1", "0", "inf"])
def test_cli_refuses_bad_fs_in_one_line(tmp_path, synth, fs, capsys):
    from vibroscope.cli import main

    rc = main(["analyse", str(synth[0]), "--outputs", CH, "--fs", fs, "--no-rrd", "--no-figures",
               "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "--fs" in err[0] and "positive, finite" in err[0]


def test_cli_refuses_a_huge_fs_naming_the_limit(tmp_path, synth, capsys):
    from vibroscope.cli import main

    rc = main(["analyse", str(synth[0]), "--outputs", CH, "--fs", "1e9", "--no-rrd", "--no-figures",
               "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "limit of 100 times the highest topic rate" in err[0]


# -- truncation does not change the estimated rate ------------------------------------------------
@pytest.mark.parametrize("name,ch", [("bagfile_0.mcap", "/robot/joint_state.position[0]"),
                                     ("alternate_bagfile_0.mcap", "/robot/joint_state.position[0]"),
                                     ("torque_ripple_data_0.mcap", "/robot/joint_state.position[0]")])
def test_truncation_keeps_the_estimated_rate(tmp_path, shared_data, name, ch):
    """A cut of a real log after each of its first three chunks reads at the whole log's rate within 1 %
    (bagfile_0 cut after its first chunk, 5.6 s, read at 160.5 Hz against 100 Hz)."""
    p = shared_data / "mcap" / "capstan" / name
    data = p.read_bytes()
    full = read_mcap(p, [ch]).fs
    if name == "bagfile_0.mcap":  # log times of a 100 Hz clock (header stamps zero), bursty in the first seconds
        assert full == 100.0
    q = tmp_path / "cut.mcap"
    for o, _end, _e2 in _chunks(p, data)[1:4]:  # after the first, second and third chunk
        q.write_bytes(data[:o])
        s = read_mcap(q, [ch])
        assert s.fs == pytest.approx(full, rel=0.01), f"cut at byte offset {o}"
        if name == "bagfile_0.mcap":  # a clock of 100 Hz, few gaps: about one sample per message
            assert s.fs == pytest.approx(100.0, rel=0.01), f"cut at byte offset {o}"  # 160.5 Hz before
            n = s.meta["timebase_reports"]["/robot/joint_state"].n_messages
            assert s.n_samples <= 1.2 * n  # 547 messages made 907 grid samples
