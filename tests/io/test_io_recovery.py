"""Recovery after damage: every reading path of the scanner resynchronises after a damaged
record and returns every intact message unchanged, reporting each loss by byte offset (and,
when the summary or message indexes know them, topics and message count)."""

from __future__ import annotations

import json
import struct
from collections import Counter

import numpy as np
import pytest

from vibroscope.errors import LogFormatError, VibroscopeError
from vibroscope.io import iter_raw_messages, mcap_info, read_mcap
from vibroscope.io._scan import scan
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.signals import Signals

CH = "/imu.linear_acceleration.x"
MODES = ["auto", "indexed", "stream"]


def _chunks(path, data):
    """(offset, end, Counter of messages) of each chunk of an intact log."""
    res = scan(path)
    out = []
    for b in res.blocks:
        (length,) = struct.unpack_from("<Q", data, b.file_offset + 1)
        one = type(res)(path=path, file_size=0, blocks=[b])
        out.append((b.file_offset, b.file_offset + 9 + length, Counter(one.messages())))
    return out


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    """A 12 000-message Imu log in ~60 zstd chunks (chunk CRCs, summary CRC)."""
    x = np.random.default_rng(3).standard_normal((1, 12_000))
    p = tmp_path_factory.mktemp("rec") / "big.mcap"
    write_ros2_mcap(p, Signals(data=x, fs=1000.0, channels=[CH], t0=5.0), chunk_size=8_000)
    data = p.read_bytes()
    chunks = _chunks(p, data)
    assert len(chunks) > 20
    return p, data, x[0], chunks, Counter(scan(p).messages())


def _write(tmp_path, data, name="bad.mcap"):
    q = tmp_path / name
    q.write_bytes(bytes(data))
    return q


@pytest.mark.parametrize("mode", MODES)
def test_zeroed_chunk_start_loses_at_most_that_chunk(tmp_path, big, mode):
    """9 zeroed bytes (the record header) at one chunk's start: the summary's chunk index
    recovers the chunk (auto, indexed); the stream path loses that chunk only, reported."""
    p, data, x, chunks, orig = big
    off, end, msgs = chunks[len(chunks) // 2]
    bad = bytearray(data)
    bad[off : off + 9] = bytes(9)
    res = scan(_write(tmp_path, bad), mode=mode)
    got = Counter(res.messages())
    if mode == "stream":
        assert got == orig - msgs
        assert [o for o, _ in res.skipped] == [off]
        assert "invalid opcode 0x00" in res.skipped[0][1]
        assert res.skipped[0][1].endswith(f"topic /imu ({sum(msgs.values())} messages lost)")
    else:
        assert got == orig and res.skipped == [] and res.recovered == 1
        assert any(f"chunk record header at byte offset {off} damaged" in w for w in res.warnings)


def test_zeroed_chunk_start_read_mcap_keeps_every_sample(tmp_path, big):
    p, data, x, chunks, orig = big
    off = chunks[3][0]
    bad = bytearray(data)
    bad[off : off + 9] = bytes(9)
    r = read_mcap(_write(tmp_path, bad), [CH], resample=False)
    assert np.array_equal(r.data[0], x)


@pytest.mark.parametrize("mode", MODES)
def test_zeroed_header_record(tmp_path, big, mode):
    """The Header record zeroed (bytes 8..8+9+len): every message read, the header reported damaged."""
    p, data, x, chunks, orig = big
    (hlen,) = struct.unpack_from("<Q", data, 9)
    bad = bytearray(data)
    bad[8 : 8 + 9 + hlen] = bytes(9 + hlen)
    q = _write(tmp_path, bad)
    res = scan(q, mode=mode)
    assert Counter(res.messages()) == orig
    assert res.header is None
    assert any("header record damaged at byte offset 8" in w for w in res.warnings)
    assert res.skipped and res.skipped[0][0] == 8
    if mode == "auto":
        r = read_mcap(q, [CH], resample=False)
        assert np.array_equal(r.data[0], x)
        assert any("header record damaged" in w for w in r.meta["warnings"])


@pytest.mark.parametrize("mode", MODES)
def test_zeroed_whole_chunk_is_reported(tmp_path, big, mode):
    """A chunk record zeroed whole: reported at its offset (with its topic and message count
    from the summary when it is used); every other message returned."""
    p, data, x, chunks, orig = big
    off, end, msgs = chunks[5]
    bad = bytearray(data)
    bad[off:end] = bytes(end - off)
    res = scan(_write(tmp_path, bad), mode=mode)
    assert Counter(res.messages()) == orig - msgs
    (o, reason), = res.skipped
    assert o == off
    # the count from the summary's chunk index, or (stream) from the intact message indexes
    # that end where the scan resumed
    assert reason.endswith(f"; topic /imu ({sum(msgs.values())} messages lost)"), reason


def test_zeroed_whole_chunk_reported_by_read_mcap_and_info(tmp_path, big):
    p, data, x, chunks, orig = big
    off, end, msgs = chunks[5]
    bad = bytearray(data)
    bad[off:end] = bytes(end - off)
    q = _write(tmp_path, bad)
    r = read_mcap(q, [CH], resample=False)
    n = sum(msgs.values())
    before = sum(sum(c[2].values()) for c in chunks[:5])
    assert np.array_equal(r.data[0], np.concatenate([x[:before], x[before + n :]]))
    assert any(f"{q}: skipped at byte offset {off}" in w and f"({n} messages lost)" in w and "/imu" in w
               for w in r.meta["warnings"])
    assert mcap_info(q).skipped[0][0] == off


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("length", [0, 1, 2**63, 2**64 - 1, 5000])
def test_bad_chunk_record_length(tmp_path, big, mode, length):
    """A chunk's record length rewritten: the chunk is recovered through the index or lost and
    reported; the scan resynchronises at the next chunk and loses nothing else."""
    p, data, x, chunks, orig = big
    off, end, msgs = chunks[7]
    bad = bytearray(data)
    struct.pack_into("<Q", bad, off + 1, length)
    res = scan(_write(tmp_path, bad), mode=mode)
    got = Counter(res.messages())
    assert not got - orig  # nothing invented
    if mode != "stream":
        assert got == orig and res.recovered == 1
    else:  # a length too long still frames the chunk's fields: read on where they end
        assert not (orig - msgs) - got  # every other chunk returned
        if got != orig:
            assert got == orig - msgs and res.skipped[0][0] == off
        else:
            assert any(f"chunk at byte offset {off}: record length {length}" in w for w in res.warnings)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("opcode", [0x00, 0x05, 0x07, 0x0F, 0x10, 0x42, 0x7F, 0x80, 0xFF])
def test_damaged_chunk_opcode(tmp_path, big, mode, opcode):
    """A chunk's opcode byte rewritten: its body still validates (framing, size, CRC), so it is
    read as the chunk, with a warning; nothing is lost."""
    p, data, x, chunks, orig = big
    off = chunks[9][0]
    bad = bytearray(data)
    bad[off] = opcode
    res = scan(_write(tmp_path, bad), mode=mode)
    assert Counter(res.messages()) == orig
    assert any(f"byte offset {off}" in w for w in res.warnings)


@pytest.mark.parametrize("mode", MODES)
def test_zeroed_message_indexes_lose_nothing(tmp_path, big, mode):
    """The message index records after a chunk zeroed: damage reported, no message lost."""
    p, data, x, chunks, orig = big
    off, end, msgs = chunks[4]
    nxt = chunks[5][0]
    bad = bytearray(data)
    bad[end:nxt] = bytes(nxt - end)
    res = scan(_write(tmp_path, bad), mode=mode)
    assert Counter(res.messages()) == orig
    if mode == "indexed":  # message indexes are passed over by the length the chunk index states
        assert res.skipped == []
    else:
        assert res.skipped[0][0] == end


@pytest.mark.parametrize("mode", MODES)
def test_flipped_bits_in_summary(tmp_path, big, mode):
    """Any flipped bit of the summary section: never an exception other than VibroscopeError,
    every message read (the summary fails its CRC and is not used)."""
    p, data, x, chunks, orig = big
    (start,) = struct.unpack_from("<Q", data, len(data) - 8 - 20)
    rng = np.random.default_rng(5)
    for pos in sorted(set(rng.integers(start, len(data) - 8 - 29, 8).tolist()) | {start, start + 1}):
        bad = bytearray(data)
        bad[pos] ^= 1 << int(rng.integers(8))
        res = scan(_write(tmp_path, bad), mode=mode)
        assert Counter(res.messages()) == orig, pos
        assert res.skipped == []
        if mode != "stream":
            assert any("summary" in w for w in res.warnings), pos


def test_summary_bit_flip_does_not_escape_from_info(tmp_path, big):
    """Regression: a bit flip in the summary escaped as ``mcap.exceptions.EndOfFile``."""
    p, data, x, chunks, orig = big
    (start,) = struct.unpack_from("<Q", data, len(data) - 8 - 20)
    for pos in range(start, min(start + 400, len(data) - 8), 10):
        bad = bytearray(data)
        bad[pos] ^= 0x10
        q = _write(tmp_path, bad)
        try:
            info = mcap_info(q)
        except VibroscopeError:
            continue
        assert info.message_count == 12_000, pos


def test_missing_summary_and_footer(tmp_path, big):
    """Summary and footer cut away: every message read by a linear pass; the missing footer reported."""
    p, data, x, chunks, orig = big
    (start,) = struct.unpack_from("<Q", data, len(data) - 8 - 20)
    q = _write(tmp_path, data[:start])
    for mode in MODES:
        res = scan(q, mode=mode)
        assert Counter(res.messages()) == orig and not res.indexed and not res.complete
        assert res.skipped == [(start, "file ends without a footer (log not closed?)")]
    assert any("linear pass" in w for w in scan(q, mode="indexed").warnings)


@pytest.mark.parametrize("mode", MODES)
def test_truncated_at_many_positions(tmp_path, big, mode):
    """Cut at 25 positions: exactly the chunks ending before the cut are returned, unchanged;
    a loss is reported at or after the last intact chunk."""
    p, data, x, chunks, orig = big
    for cut in np.linspace(9, len(data) - 1, 25).astype(int).tolist():
        q = _write(tmp_path, data[:cut])
        whole = [c for c in chunks if c[1] <= cut]
        expect = Counter()
        for c in whole:
            expect.update(c[2])
        if not whole:
            with pytest.raises(LogFormatError, match="byte offset"):
                scan(q, mode=mode)
            continue
        res = scan(q, mode=mode)
        assert Counter(res.messages()) == expect, cut
        if len(whole) < len(chunks):
            assert res.skipped and res.skipped[0][0] >= whole[-1][1] - (whole[-1][1] - whole[-1][0]), cut


def test_repeat_channels_false_filtered_read(tmp_path):
    """Regression: a log written with ``repeat_channels=False`` has its channels only inside the
    chunks; a read filtered by topic passed over the chunks of the wanted topic ("no such topic")."""
    from mcap.writer import CompressionType, Writer

    p = tmp_path / "norepeat.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, chunk_size=2000, compression=CompressionType.NONE, repeat_channels=False)
        w.start()
        sid = w.register_schema("v", "jsonschema", json.dumps({"type": "object"}).encode())
        ids = {}
        for k in range(300):
            topic = "/a" if k < 150 else "/b"  # /b's channel first appears in a later chunk
            if topic not in ids:
                ids[topic] = w.register_channel(topic, "json", sid)
            w.add_message(ids[topic], 10**9 + k * 10**7, json.dumps({"x": float(k)}).encode(), 10**9 + k * 10**7)
        w.finish()
    res = scan(p)
    assert res.indexed and {ch.topic for ch in res.channels.values()} == {"/a", "/b"}
    for topic, xs in (("/a", np.arange(150.0)), ("/b", np.arange(150.0, 300.0))):
        got = scan(p, topics={topic})
        cid = next(c for c, ch in got.channels.items() if ch.topic == topic)
        assert sum(int((b.channel_id == cid).sum()) for b in got.blocks) == 150
        r = read_mcap(p, [f"{topic}.x"], resample=False)
        assert np.array_equal(r.data[0], xs)
    # the chunks of /b list a channel the summary does not know: they cannot be passed over
    assert scan(p, topics={"/a"}).chunks_skipped_by_index == 0


def test_hostile_files_raise_log_format_error(tmp_path, big):
    p, data, x, chunks, orig = big
    cases = {
        "empty": (b"", "empty file.*byte offset 0"),
        "not_mcap": (b"PK\x03\x04 a zip file, not a log", "not an MCAP file.*byte offset 0"),
        "magic_only": (data[:8], "byte offset 8"),
        "cut_header": (data[:14], "byte offset 8"),
        "garbage": (data[:8] + bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8)), "byte offset"),
    }
    for name, (content, match) in cases.items():
        q = _write(tmp_path, content, f"{name}.mcap")
        for mode in MODES:
            with pytest.raises(LogFormatError, match=match) as ei:
                scan(q, mode=mode)
            assert str(q) in str(ei.value)
        with pytest.raises(LogFormatError, match=match):
            iter_raw_messages(q)


def test_schema_that_cannot_be_decoded(tmp_path):
    """A channel whose ROS 2 schema text is garbage: its messages are found by the scan, the
    read names the topic and says why it cannot decode them; other topics read normally."""
    from mcap.writer import Writer

    p = tmp_path / "badschema.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2")
        bad = w.register_schema("sensor_msgs/msg/Imu", "ros2msg", b"\xff\xfe not a msg definition {{{")
        good = w.register_schema("v", "jsonschema", b"{}")
        cb = w.register_channel("/broken", "cdr", bad)
        cg = w.register_channel("/ok", "json", good)
        for k in range(50):
            w.add_message(cb, 10**9 + k * 10**7, b"\x00\x01\x00\x00" + bytes(40), 10**9 + k * 10**7)
            w.add_message(cg, 10**9 + k * 10**7, json.dumps({"x": float(k)}).encode(), 10**9 + k * 10**7)
        w.finish()
    assert sum(b.n for b in scan(p).blocks) == 100
    with pytest.raises(VibroscopeError, match="/broken"):
        read_mcap(p, ["/broken.linear_acceleration.x"], resample=False)
    r = read_mcap(p, ["/ok.x"], resample=False)
    assert np.array_equal(r.data[0], np.arange(50.0))


def test_invalid_mode_is_a_value_error(big):
    with pytest.raises(ValueError, match="mode='fast'"):
        scan(big[0], mode="fast")


def test_fast_and_record_by_record_indexing_agree(big):
    p = big[0]
    a, b = scan(p), scan(p, fast=False)
    assert [(x.file_offset, x.n) for x in a.blocks] == [(y.file_offset, y.n) for y in b.blocks]
    for x, y in zip(a.blocks, b.blocks):
        for f in ("channel_id", "log_time", "start", "length"):
            assert np.array_equal(getattr(x, f), getattr(y, f))
