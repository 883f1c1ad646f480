"""Damaged logs: truncation and flipped bytes yield every intact message, never altered
numbers, plus a report naming the byte offset."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from vibroscope.errors import LogFormatError
from vibroscope.io import iter_raw_messages, mcap_info, read_mcap
from vibroscope.io._scan import scan
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.signals import Signals

N = 4000
CH = "/imu.linear_acceleration.x"


@pytest.fixture(scope="module", params=["zstd", "none"])
def log(request, tmp_path_factory):
    x = np.random.default_rng(7).standard_normal((1, N))
    p = tmp_path_factory.mktemp("dmg") / f"ok_{request.param}.mcap"
    write_ros2_mcap(p, Signals(data=x, fs=1000.0, channels=[CH], t0=50.0), chunk_size=32_000, compression=request.param)
    data = p.read_bytes()
    chunks = []  # (offset, end, n_messages)
    for b in scan(p).blocks:
        length = struct.unpack_from("<Q", data, b.file_offset + 1)[0]
        chunks.append((b.file_offset, b.file_offset + 9 + length, b.n))
    assert len(chunks) >= 5 and sum(c[2] for c in chunks) == N
    return p, data, x[0], chunks


def _read(path):
    return read_mcap(path, [CH], resample=False)


@pytest.mark.parametrize("frac", [0.0, 0.2, 0.5, 0.77, 0.999])
def test_truncated(tmp_path, log, frac):
    p, data, x, chunks = log
    first, last_end = chunks[0][0], chunks[-1][1]
    cut = int(first + 1 + frac * (last_end - first - 1))
    q = tmp_path / "cut.mcap"
    q.write_bytes(data[:cut])
    expect = sum(n for off, end, n in chunks if end <= cut)
    if expect == 0:
        with pytest.raises(LogFormatError, match="byte offset"):
            _read(q)
        return
    r = _read(q)
    assert r.n_samples == expect
    assert np.array_equal(r.data[0], x[:expect])  # the intact prefix, unchanged
    offs = [s["offset"] for s in r.meta["skipped"] if "offset" in s]
    damaged = [off for off, end, n in chunks if off < cut < end]
    if damaged:  # the cut chunk is reported by its offset
        assert damaged[0] in offs
        assert any(f"byte offset {damaged[0]}" in w for w in r.meta["warnings"])
    else:  # cut between chunks (in a message index): reported after the last intact chunk
        last = max(end for off, end, n in chunks if end <= cut)
        assert any(last <= o <= cut for o in offs)


def test_cut_in_header_raises(tmp_path, log):
    p, data, x, chunks = log
    q = tmp_path / "tiny.mcap"
    q.write_bytes(data[:12])
    with pytest.raises(LogFormatError, match="byte offset"):
        _read(q)
    q.write_bytes(b"not an mcap file at all")
    with pytest.raises(LogFormatError, match="byte offset 0"):
        _read(q)


def test_iter_raw_messages_is_a_lazy_iterator_of_the_intact_messages(tmp_path, log):
    p, data, x, chunks = log
    it = iter_raw_messages(p)
    assert iter(it) is it and not isinstance(it, (list, tuple))
    topic, cid, t, payload = next(it)
    assert topic == "/imu" and t == 50_000_000_000 and isinstance(payload, bytes)
    assert 1 + sum(1 for _ in it) == N
    # a cut file: the messages of the intact chunks, in file order
    q = tmp_path / "cut.mcap"
    q.write_bytes(data[: chunks[2][1] + 3])
    got = list(iter_raw_messages(q))
    assert len(got) == chunks[0][2] + chunks[1][2] + chunks[2][2]
    assert [m[2] for m in got] == sorted(m[2] for m in got)
    # nothing readable: raised by the call itself, not on the first next()
    q.write_bytes(b"not an mcap file at all")
    with pytest.raises(LogFormatError, match="byte offset 0"):
        iter_raw_messages(q)


@pytest.mark.parametrize("which", [1, 3])
def test_flipped_byte_in_chunk(tmp_path, log, which):
    p, data, x, chunks = log
    off, end, n = chunks[which]
    pos = (off + end) // 2 + 7
    bad = bytearray(data)
    bad[pos] ^= 0x5A
    q = tmp_path / "flip.mcap"
    q.write_bytes(bytes(bad))
    r = _read(q)
    assert r.n_samples == N - n
    # every returned value is an original value, in order, with the damaged chunk's missing
    before = sum(c[2] for c in chunks[:which])
    expect = np.concatenate([x[:before], x[before + n:]])
    assert np.array_equal(r.data[0], expect)
    sk = [s for s in r.meta["skipped"] if s.get("offset") == off]
    assert sk and "chunk skipped" in sk[0]["reason"]
    assert f"({n} messages lost)" in sk[0]["reason"]  # counted from the message indexes
    info = mcap_info(q)
    assert info.skipped and info.skipped[0][0] == off


def test_crc_damage_detected_in_uncompressed_chunk(tmp_path):
    """A flipped bit inside a float of an uncompressed chunk: only the CRC can tell. The
    mcap library's reader (validate_crcs off by default) returns the altered number; ours
    drops the chunk and says where."""
    from mcap.reader import make_reader

    x = np.random.default_rng(9).standard_normal((1, N))
    p = write_ros2_mcap(tmp_path / "u.mcap", Signals(data=x, fs=1000.0, channels=[CH], t0=50.0), chunk_size=32_000,
                        compression="none")
    data = p.read_bytes()
    blocks = scan(p).blocks
    b = blocks[2]
    end = b.file_offset + 9 + struct.unpack_from("<Q", data, b.file_offset + 1)[0]
    pos = end - 40  # inside the last message's linear_acceleration_covariance... or a float before it
    bad = bytearray(data)
    bad[pos] ^= 0x01
    q = tmp_path / "crc.mcap"
    q.write_bytes(bytes(bad))
    r = _read(q)
    sk = [s for s in r.meta["skipped"] if s.get("offset") == b.file_offset]
    assert sk and "CRC-32 mismatch" in sk[0]["reason"] and f"({b.n} messages lost)" in sk[0]["reason"]
    assert r.n_samples == N - b.n and np.isin(r.data[0], x[0]).all()
    with open(q, "rb") as fh:  # the library without CRC checks hands back the altered payload
        payloads = [m.data for _, _, m in make_reader(fh).iter_messages()]
    with open(p, "rb") as fh:
        original = [m.data for _, _, m in make_reader(fh).iter_messages()]
    assert len(payloads) == N and sum(a != o for a, o in zip(payloads, original)) == 1
    # the summary is intact, so the reader still knows every topic; the data section CRC is wrong
    assert any("data section CRC-32 mismatch" in w for w in r.meta["warnings"])


def test_info_command_on_damaged_log(tmp_path, log, capsys):
    from vibroscope.cli import main

    p, data, x, chunks = log
    q = tmp_path / "cut.mcap"
    q.write_bytes(data[: chunks[2][0] + 100])
    assert main(["info", str(q)]) == 0
    out = capsys.readouterr().out
    assert f"skipped at byte offset {chunks[2][0]}" in out
    q.write_bytes(data[:20])
    assert main(["info", str(q)]) == 1
    assert "byte offset" in capsys.readouterr().err
