"""Property tests (hypothesis) and fuzzing of the MCAP scanner on real recordings and
synthetic Imu logs: cut, flipped, zeroed and re-framed copies never raise anything but a
:class:`~vibroscope.errors.VibroscopeError`, never return a message that is not one of the
original's, and lose no message of a chunk that the mutation left untouched."""

from __future__ import annotations

import struct
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vibroscope.errors import VibroscopeError
from vibroscope.io import read_mcap
from vibroscope.io._scan import scan
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.signals import Signals

CH = "/imu.linear_acceleration.x"
MODES = ["auto", "indexed", "stream"]
SMALL = ["controlled_data_0.mcap", "uncontrolled_data_0.mcap"]
BIG = "bagfile_0.mcap"  # 7.9 MB, ten uncompressed chunks written without CRCs
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
                derandomize=True)


class _Log:
    def __init__(self, path: Path, x: np.ndarray | None = None) -> None:
        self.path, self.x = path, x
        self.data = path.read_bytes()
        res = scan(path)
        assert res.skipped == []
        self.all = Counter(res.messages())
        self.chunks, self.no_crc = [], []
        for b in res.blocks:
            if b.file_offset < 0:
                continue
            (length,) = struct.unpack_from("<Q", self.data, b.file_offset + 1)
            end = b.file_offset + 9 + length
            self.chunks.append((b.file_offset, end, Counter(type(res)(path=path, file_size=0, blocks=[b]).messages())))
            if struct.unpack_from("<I", self.data, b.file_offset + 9 + 24)[0] == 0:
                self.no_crc.append((b.file_offset, end))


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    """Synthetic Imu logs with chunk CRCs: zstd and uncompressed, ~15 chunks each."""
    d = tmp_path_factory.mktemp("mut")
    x = np.random.default_rng(11).standard_normal((1, 2000))
    out = {}
    for comp in ("zstd", "none"):
        p = write_ros2_mcap(d / f"imu_{comp}.mcap", Signals(data=x, fs=1000.0, channels=[CH], t0=10.0),
                            chunk_size=20_000,
                            compression=comp)
        out[comp] = _Log(p, x[0])
    return out


@pytest.fixture(scope="module")
def capstan(shared_data):
    d = shared_data / "mcap" / "capstan"
    return {name: _Log(d / name) for name in SMALL}


@pytest.fixture(scope="module")
def capstan_big(shared_data):
    return _Log(shared_data / "mcap" / "capstan" / BIG)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("mutated") / "m.mcap"


@st.composite
def mutations(draw, n: int, chunks: list):
    """(kind, changed byte ranges [a, b) (a cut: (c, inf)), function of the bytes)."""
    kind = draw(st.sampled_from(["cut", "flip", "zero", "frame", "cut+flip"]))
    if kind == "cut":
        c = draw(st.integers(0, n - 1))
        return kind, [(c, float("inf"))], lambda b: b[:c]
    if kind in ("flip", "cut+flip"):
        flips = draw(st.lists(st.tuples(st.integers(8, n - 1), st.integers(0, 7)), min_size=1, max_size=6))
        c = draw(st.integers(8, n - 1)) if kind == "cut+flip" else n

        def f(b):
            b = bytearray(b)
            for p, bit in flips:
                b[p] ^= 1 << bit
            return bytes(b[:c])

        return kind, [(p, p + 1) for p, _ in flips] + ([(c, float("inf"))] if c < n else []), f
    if kind == "zero":
        a = draw(st.integers(8, n - 1))
        e = min(n, a + draw(st.sampled_from([1, 9, 40, 500, 5000])))
        return kind, [(a, e)], lambda b: b[:a] + bytes(e - a) + b[e:]
    # a record header's opcode or length at a chunk (or anywhere) rewritten
    p = draw(st.sampled_from([c[0] for c in chunks])) if chunks and draw(st.booleans()) else draw(st.integers(8, n - 9))
    if draw(st.booleans()):
        op = draw(st.integers(0, 255))
        return kind, [(p, p + 1)], lambda b: b[:p] + bytes([op]) + b[p + 1 :]
    length = draw(st.one_of(st.integers(0, 2 * n), st.sampled_from([2**63, 2**64 - 1])))
    return kind, [(p + 1, p + 9)], lambda b: b[:p + 1] + struct.pack("<Q", length) + b[p + 9 :]


def _check(log: _Log, work: Path, ranges, mutate, mode: str, fast: bool, samples: bool = False) -> None:
    work.write_bytes(mutate(log.data))
    try:
        res = scan(work, mode=mode, fast=fast)
    except VibroscopeError:
        return
    got = Counter(res.messages())
    touched_no_crc = any(ra < e and a < rb for a, e in log.no_crc for ra, rb in ranges)
    if not touched_no_crc:  # every message returned is one of the original's, unchanged
        assert not got - log.all, f"{sum((got - log.all).values())} messages altered or invented"
        if log.all - got:
            assert res.skipped, "messages lost without a report"
    for a, e, msgs in log.chunks:  # a chunk no mutated byte touched is returned whole
        if not any(ra < e and a < rb for ra, rb in ranges):
            assert not msgs - got, f"untouched chunk at byte offset {a} lost"
    if samples and log.x is not None:
        try:
            r = read_mcap(work, [CH], resample=False)
        except VibroscopeError:
            return
        assert np.isin(r.data[0], log.x).all()


@settings(max_examples=40, **SETTINGS)
@given(data=st.data(), which=st.sampled_from(["zstd", "none"]), mode=st.sampled_from(MODES), fast=st.booleans())
def test_mutated_synthetic_imu_log(synth, work, data, which, mode, fast):
    log = synth[which]
    kind, ranges, mutate = data.draw(mutations(len(log.data), log.chunks))
    _check(log, work, ranges, mutate, mode, fast, samples=True)


@settings(max_examples=40, **SETTINGS)
@given(data=st.data(), which=st.sampled_from(SMALL), mode=st.sampled_from(MODES), fast=st.booleans())
def test_mutated_capstan_recording(capstan, work, data, which, mode, fast):
    log = capstan[which]
    kind, ranges, mutate = data.draw(mutations(len(log.data), log.chunks))
    _check(log, work, ranges, mutate, mode, fast)


@settings(max_examples=8, **SETTINGS)
@given(data=st.data(), mode=st.sampled_from(MODES))
def test_mutated_big_capstan_recording(capstan_big, work, data, mode):
    log = capstan_big
    kind, ranges, mutate = data.draw(mutations(len(log.data), log.chunks))
    _check(log, work, ranges, mutate, mode, True)


@settings(max_examples=60, **SETTINGS)
@given(body=st.binary(min_size=0, max_size=600), mode=st.sampled_from(MODES))
def test_fuzz_random_bytes_after_magic(work, body, mode):
    """Random bytes after the magic: a result or a VibroscopeError, nothing else."""
    work.write_bytes(b"\x89MCAP0\r\n" + body)
    try:
        scan(work, mode=mode)
    except VibroscopeError:
        pass


@st.composite
def records(draw):
    """A sequence of records with random opcodes, lengths (right or wrong) and bodies."""
    out = b""
    for _ in range(draw(st.integers(0, 8))):
        op = draw(st.sampled_from([0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x0B, 0x0F, 0x00, 0x42, 0x80]))
        body = draw(st.binary(max_size=80))
        length = draw(st.one_of(st.just(len(body)), st.integers(0, 200), st.just(2**64 - 1)))
        out += struct.pack("<BQ", op, length) + body
    return out


@settings(max_examples=60, **SETTINGS)
@given(recs=records(), tail=st.booleans(), mode=st.sampled_from(MODES))
def test_fuzz_structured_records(synth, work, recs, tail, mode):
    """A valid header, then random records (and optionally the rest of a real log after them)."""
    data = synth["zstd"].data
    (hlen,) = struct.unpack_from("<Q", data, 9)
    head = data[: 8 + 9 + hlen]
    work.write_bytes(head + recs + (data[len(head) :] if tail else b""))
    try:
        res = scan(work, mode=mode)
    except VibroscopeError:
        return
    got = Counter(res.messages())
    if tail:  # the real records after the fuzz: nothing of theirs altered
        assert not {m for m in got if m[0] == 1} - set(synth["zstd"].all)


# -- regressions: cases the property tests found ------------------------------------------------


def _first_chunk(log):
    off, end, msgs = log.chunks[0]
    return off, end, sum(msgs.values())


@pytest.mark.parametrize("mode", MODES)
def test_regression_chunk_body_zeroed_behind_intact_header(synth, work, mode):
    """Found by hypothesis: 500 zeroed bytes from the third byte of a chunk's length field on
    left opcode and length intact and made the body an empty, CRC-less chunk: it was
    accepted with no messages and nothing said. Now its message indexes (or the summary's
    chunk index) show the loss."""
    log = synth["zstd"]
    off, end, n = _first_chunk(log)
    bad = bytearray(log.data)
    bad[off + 3 : off + 503] = bytes(500)
    work.write_bytes(bytes(bad))
    res = scan(work, mode=mode)
    assert Counter(res.messages()) == log.all - log.chunks[0][2]
    assert res.skipped[0][0] == off and res.skipped[0][1].endswith(f"({n} messages lost)")


@pytest.mark.parametrize("mode", MODES)
def test_regression_header_opcode_and_length_flipped(synth, work, mode):
    """Found by hypothesis: the Header's opcode flipped to a private one and its length one byte
    longer, file cut short (no summary): the walk stepped past the first chunk's opcode and it
    was lost. Now the scan goes back to the valid chunk it passed over."""
    log = synth["zstd"]
    bad = bytearray(log.data)
    bad[8] ^= 1 << 7
    bad[9] ^= 1
    cut = log.chunks[3][1]
    work.write_bytes(bytes(bad[:cut]))
    res = scan(work, mode=mode)
    expect = Counter()
    for c in log.chunks[:4]:
        expect.update(c[2])
    assert Counter(res.messages()) == expect
    assert res.skipped and res.header is None


@pytest.mark.parametrize("mode", MODES)
def test_regression_chunk_opcode_and_size_flipped(synth, work, mode):
    """Found by hypothesis: a chunk's opcode turned into a Message Index (0x07) and a bit of its
    uncompressed size flipped: the record was passed over as a message index, its messages lost
    without a word. Now it is reported as a damaged chunk, with the count."""
    log = synth["zstd"]
    off, n = log.chunks[2][0], sum(log.chunks[2][2].values())
    bad = bytearray(log.data)
    bad[off] ^= 1
    bad[off + 9 + 16] ^= 1
    work.write_bytes(bytes(bad))
    res = scan(work, mode=mode)
    assert Counter(res.messages()) == log.all - log.chunks[2][2]
    (o, reason), = res.skipped
    assert o == off and reason.endswith(f"({n} messages lost)"), reason
