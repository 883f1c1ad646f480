"""The ingestion speed paths of the MCAP scan (issue 9, target 1) change no value.

Chunks decompressed into a buffer reused from chunk to chunk (zstd through a stream reader,
LZ4 frames through cramjam) and the wanted fields decoded on the scan's threads right after
decompression: the bytes, the decoded fields and ``read_mcap``'s result equal the plain
path's, for every LZ4 frame option, for mixed frame ids, irregular stamps, interleaved topics,
damaged chunks and a file changed after its scan.
"""

from __future__ import annotations

import zlib

import lz4.frame
import numpy as np
import pytest
import zstandard
from mcap.records import Chunk, ChunkIndex

from vibroscope.errors import LogFormatError
from vibroscope.io import _chunks, _extract, _records, _scan, _summary, read_mcap
from vibroscope.io.log_index import LogIndex
from vibroscope.io.mcap_read import _wanted_topics

from test_io_fastpath import CHANNELS, _log


def _payload(rng, n: int) -> bytes:
    """Bytes both compressible (runs, repeats) and not (noise): LZ4 stores some blocks raw."""
    parts = [bytes(rng.integers(0, 256, n // 3, dtype=np.uint8)), b"\0" * (n // 3),
             bytes(rng.integers(0, 4, n - 2 * (n // 3), dtype=np.uint8))]
    return b"".join(parts)


@pytest.mark.parametrize("block_size", [lz4.frame.BLOCKSIZE_MAX64KB, lz4.frame.BLOCKSIZE_MAX256KB,
                                        lz4.frame.BLOCKSIZE_MAX1MB, lz4.frame.BLOCKSIZE_MAX4MB])
@pytest.mark.parametrize("linked", [True, False])
@pytest.mark.parametrize("checksums", [False, True])
def test_lz4_frame_into_buffer_equals_lz4(block_size, linked, checksums):
    """Every LZ4 frame option decompresses into the reused buffer to the bytes ``lz4.frame``
    gives; a frame cut short, with trailing garbage, not LZ4, or longer than the chunk states is
    left to the usual path (None)."""
    rng = np.random.default_rng(block_size + 2 * linked + checksums)

    def chunk(frame, n):
        return Chunk(compression="lz4", data=memoryview(frame), message_end_time=0, message_start_time=0,
                           uncompressed_crc=0, uncompressed_size=n)

    for n in (1, 1000, 300_000, 1_500_000):
        data = _payload(rng, n)
        for store_size in (True, False):
            frame = lz4.frame.compress(data, block_size=block_size, block_linked=linked, content_checksum=checksums,
                                       block_checksum=checksums, store_size=store_size)
            got = _chunks.decompress_into(chunk(frame, n))
            assert got is not None and bytes(got) == data == lz4.frame.decompress(frame)
    data = _payload(rng, 200_000)
    frame = lz4.frame.compress(data, block_size=block_size, block_linked=linked)
    assert _chunks.decompress_into(chunk(frame[:-3], len(data))) is None  # cut off: the usual path decides
    assert _chunks.decompress_into(chunk(frame + b"\0" * 4, len(data))) is None  # trailing bytes
    assert _chunks.decompress_into(chunk(b"\x05" + frame[1:], len(data))) is None  # not an LZ4 frame
    assert _chunks.decompress_into(chunk(frame, len(data) - 1)) is None  # more data than the chunk states


def _chunk(data: bytes, compression: str) -> Chunk:
    comp = {"zstd": zstandard.ZstdCompressor().compress, "lz4": lz4.frame.compress}[compression](data)
    return Chunk(compression=compression, data=comp, message_end_time=0, message_start_time=0,
                       uncompressed_crc=zlib.crc32(data), uncompressed_size=len(data))


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_decompress_into_reused_buffer(compression):
    """The thread's buffer is reused across chunks and gives exactly the chunk's bytes; a chunk
    stating another size, or a damaged one, is left to the usual path (None)."""
    rng = np.random.default_rng(3)
    big, small = _payload(rng, 2_500_000), _payload(rng, 70_000)
    a = _chunks.decompress_into(_chunk(big, compression))
    assert bytes(a) == big
    b = _chunks.decompress_into(_chunk(small, compression))
    assert bytes(b) == small and b.obj is a.obj  # the same buffer, not fresh pages
    c = _chunk(small, compression)
    for usize in (len(small) - 1, len(small) + 1):
        wrong = Chunk(compression=c.compression, data=c.data, message_end_time=0, message_start_time=0,
                            uncompressed_crc=c.uncompressed_crc, uncompressed_size=usize)
        assert _chunks.decompress_into(wrong) is None
    cut = Chunk(compression=c.compression, data=c.data[: len(c.data) // 2], message_end_time=0,
                      message_start_time=0, uncompressed_crc=c.uncompressed_crc, uncompressed_size=len(small))
    assert _chunks.decompress_into(cut) is None
    with pytest.raises(Exception):
        _chunks.decompress(cut)


def test_crc32_equals_zlib():
    rng = np.random.default_rng(4)
    for n in (0, 1, 7, 4096, 1_000_003):
        data = bytes(rng.integers(0, 256, n, dtype=np.uint8))
        assert _chunks.crc32(data) == zlib.crc32(data)


def _chans() -> list[str]:
    return [f"{t}.{f}" for t, fs in CHANNELS.items() for f in fs]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
@pytest.mark.parametrize("mixed", [False, True], ids=["one-frame-id", "frame-ids-0..40"])
def test_fields_decoded_on_threads_equal_the_chunk_path(tmp_path, compression, mixed):
    """Three topics interleaved, jittered and gapped stamps: the scan given the wanted fields
    decodes them on its threads, drops the reusable bytes of compressed chunks, and every value
    (and every byte given back on use) equals the scan without them."""
    rng = np.random.default_rng(hash((compression, mixed)) % 2**32)
    path, topics = _log(tmp_path, rng, compression, mixed, "jitter+gaps")
    top = _wanted_topics(_chans())
    for workers in (1, 2):
        got = _scan.scan(path, topics=top, workers=workers)
        ref = _scan.scan(path, workers=1)
        assert len(got.blocks) == len(ref.blocks) and got.skipped == ref.skipped and got.warnings == ref.warnings
        dropped = [b._buf is None for b in got.blocks]
        assert all(b.decoded for b in got.blocks)
        assert all(dropped) if compression != "none" else not any(dropped)
        for x, y in zip(got.blocks, ref.blocks):
            for f in ("channel_id", "log_time", "start", "length"):
                assert np.array_equal(getattr(x, f), getattr(y, f)), f
            assert bytes(x.buf) == bytes(y.buf) and x._buf is not None  # given back on use, then kept
        log_fast, log_ref = LogIndex.open(path, topics=top), LogIndex.open(path)
        for topic, fields in CHANNELS.items():
            cid = log_ref.by_topic[topic][0]
            a = _extract.fast_extract(log_fast, cid, fields)
            b = _extract.fast_extract(log_ref, cid, fields)
            assert np.array_equal(a[0], b[0]) and a[1].tobytes() == b[1].tobytes()
            assert np.array_equal(np.sort(a[0]), np.sort(topics[topic][1]))  # the stamps written
    known = [c for c in _chans() if "stamp" not in c]
    fast, plain = read_mcap(path, known), read_mcap(LogIndex.open(path), known)
    assert fast.data.tobytes() == plain.data.tobytes() and fast.meta["warnings"] == plain.meta["warnings"]


def test_explicit_fields_and_undecodable_topics_keep_bytes(tmp_path):
    """`fields` names what is decoded; a chunk holding wanted messages that are not decoded
    (a field the fixed layout does not have) keeps its bytes."""
    rng = np.random.default_rng(12)
    path, _ = _log(tmp_path, rng, "zstd", True, "jitter")
    got = _scan.scan(path, fields={"/imu": ["linear_acceleration.y", "header.stamp.sec"]})
    cid = next(c for c, ch in got.channels.items() if ch.topic == "/imu")
    assert all(set(b.decoded) == {cid} for b in got.blocks)
    assert all(b._buf is not None for b in got.blocks)  # the other topics may be wanted: bytes kept
    t, names, _vals = got.blocks[0].decoded[cid]
    assert t == "sensor_msgs/msg/Imu" and set(_vals) == {"linear_acceleration.y", "header.stamp.sec"}
    only = _scan.scan(path, topics={"/imu", "/imu.linear_acceleration.y"})
    assert all(b._buf is None for b in only.blocks)  # the other topics are not wanted
    odd = _scan.scan(path, topics={"/imu", "/imu.linear_acceleration.y", "/ft", "/ft.no_such_field"})
    holds_ft = [b for b in odd.blocks if any(odd.channels[c].topic == "/ft" for c in np.unique(b.channel_id).tolist())]
    assert holds_ft and all(b._buf is not None for b in holds_ft)


def test_damaged_chunk_reported_on_the_speed_path(tmp_path):
    """A chunk whose data fails its CRC-32 is skipped and reported the same with the fields
    decoded on the threads; the others are read."""
    rng = np.random.default_rng(13)
    path, _ = _log(tmp_path, rng, "lz4", False, "regular", chunk_size=8_000)
    top = _wanted_topics(_chans())
    a = _scan.scan(path, topics=top)
    victim = a.blocks[2].file_offset
    data = bytearray(path.read_bytes())
    data[victim + 9 + 40 + 3 + 200] ^= 0xFF  # inside the compressed data
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    r1, r2 = _scan.scan(bad, topics=top), _scan.scan(bad, workers=1)
    assert r1.skipped == r2.skipped and any(o == victim for o, _ in r1.skipped)
    assert [b.file_offset for b in r1.blocks] == [b.file_offset for b in r2.blocks]
    assert victim not in [b.file_offset for b in r1.blocks] and len(r1.blocks) == len(a.blocks) - 1


def test_bytes_given_back_from_a_changed_file_raise(tmp_path):
    """A dropped chunk is decompressed again on use: when the file changed since the scan (the
    chunk no longer matches its CRC-32), a LogFormatError names the chunk's byte offset."""
    rng = np.random.default_rng(14)
    path, _ = _log(tmp_path, rng, "zstd", False, "regular", chunk_size=8_000)
    got = _scan.scan(path, topics=_wanted_topics(_chans()))
    b = got.blocks[1]
    assert b._buf is None
    # the same length, other content: rewritten in place, the map sees it
    size = path.stat().st_size
    with open(path, "r+b") as fh:
        fh.seek(b.file_offset + 9 + 40 + 4 + 8 + 30)
        fh.write(b"\xff" * 8)
    assert path.stat().st_size == size
    with pytest.raises(LogFormatError, match=f"byte offset {b.file_offset}"):
        b.buf


def test_chunk_index_parse_equals_mcap(tmp_path, monkeypatch):
    """The summary's Chunk Index records parsed with struct equal mcap's own parse; a record
    cut short is left to mcap's parser, which raises."""
    rng = np.random.default_rng(15)
    path, _ = _log(tmp_path, rng, "lz4", True, "regular", chunk_size=8_000)
    data = path.read_bytes()
    summary, why = _summary.read_summary(data, len(data))
    assert why is None and len(summary.chunks) > 5
    n, pos, seen = 0, summary.start, 0
    while data[pos] != 0x02:  # up to the footer
        op, length = _records.REC_HDR.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        if op == 0x08:  # chunk index
            ref = _records.parse_record(ChunkIndex, data[body:end])
            with monkeypatch.context() as m:
                m.setattr(_summary, "parse_record", None)  # the struct parse alone
                ci = _summary.chunk_index(data, body, end)
            assert ci == ref == summary.chunks[ci.chunk_start_offset]
            n += len(ci.message_index_offsets) > 1
            seen += 1
            with pytest.raises(Exception):
                _summary.chunk_index(data, body, end - 3)
        pos = end
    assert seen == len(summary.chunks) and n  # chunks holding several channels among them


def test_data_section_crc_computed_ahead(tmp_path):
    """The data section CRC-32, computed on a thread while the chunks are read, gives the same
    verdict as computed in turn: none on the intact file, a mismatch on an altered one."""
    from vibroscope import Signals
    from vibroscope.io import write_ros2_mcap

    rng = np.random.default_rng(16)
    sig = Signals(data=rng.standard_normal((3, 3000)), fs=1000.0,
                  channels=[f"/imu.linear_acceleration.{c}" for c in "xyz"], t0=5.0)
    p = write_ros2_mcap(tmp_path / "d.mcap", sig, chunk_size=20_000, compression="lz4")
    top = _wanted_topics(list(sig.channels))
    for workers in (1, 2):
        assert not _scan.scan(p, topics=top, workers=workers).warnings
    data = bytearray(p.read_bytes())
    ref = _scan.scan(p)
    mi = ref.blocks[1].file_offset - 3  # the last byte but 2 of the message index records after chunk 0
    data[mi] ^= 0x01
    q = tmp_path / "d2.mcap"
    q.write_bytes(bytes(data))
    w1, w2 = _scan.scan(q, topics=top, workers=1).warnings, _scan.scan(q, topics=top, workers=2).warnings
    assert w1 == w2 and any("data section CRC-32 mismatch" in w for w in w1)


def test_compiled_gather_equals_numpy_gather():
    """The compiled check-and-gather of payloads of mixed lengths gives numpy's result bit for
    bit (negative seconds, the largest nanoseconds, NaN payload bits), and None at the same
    payloads that do not fit the layout."""
    from vibroscope.io._ros2 import FLOAT_FIELDS, decode_block, encode_fixed

    rng = np.random.default_rng(17)
    tname = "sensor_msgs/msg/Imu"
    floats = FLOAT_FIELDS[tname]
    parts, st, ln, pos = [], [], [], 3
    for k in range(400):
        vals = {f: rng.standard_normal(1) for f in floats[:: 1 + k % 5]}
        if k == 7:
            vals["linear_acceleration.x"] = np.frombuffer(b"\x01\x00\x00\x00\x00\x00\xf8\x7f", "<f8")  # a NaN's bits
        sec = np.array([-(2**31) if k == 5 else int(rng.integers(-(2**31), 2**31 - 1))])
        nsec = np.array([2**32 - 1 if k == 6 else int(rng.integers(0, 10**9))])
        p = encode_fixed(tname, sec, nsec, vals, frame_id="x" * int(rng.integers(0, 41)))[0].tobytes()
        gap = bytes(int(rng.integers(0, 9)))
        parts += [gap, p]
        pos += len(gap)
        st.append(pos)
        ln.append(len(p))
        pos += len(p)
    buf = b"\0\0\0" + b"".join(parts)
    st, ln = np.array(st), np.array(ln)
    names = ["header.stamp.nanosec", "linear_acceleration.x", "orientation.w", "header.stamp.sec",
             "linear_acceleration_covariance[8]"]
    a = decode_block(buf, st, ln, tname, names)
    b = decode_block(buf, st, ln, tname, names, compiled=False)
    assert a is not None and np.array_equal(a[0], b[0]) and a[0][5] < 0
    assert all(x.dtype == y.dtype and x.tobytes() == y.tobytes() for x, y in zip(a[1], b[1]))
    assert np.isnan(a[1][1][7]) and a[1][0][6] == 2**32 - 1
    bad = bytearray(buf)
    for mutate in ("cdr", "flen", "short", "past end"):
        b2, ln2 = bytearray(bad), ln.copy()
        if mutate == "cdr":
            b2[st[99] + 1] = 0  # big-endian encapsulation
        elif mutate == "flen":
            b2[st[99] + 12] += 8
        elif mutate == "short":
            ln2[99] = 12
        else:
            ln2[-1] += 5
        got = [decode_block(bytes(b2), st, ln2, tname, names, compiled=c) for c in (True, False)]
        assert got == [None, None], mutate
