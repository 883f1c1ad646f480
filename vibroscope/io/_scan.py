"""Record-level MCAP scanning that survives damage.

Three reading paths (``scan(..., mode=...)``), with one result:

``"stream"``
    One linear pass over the records from byte 8, never looking at the summary section.
``"indexed"``
    Chunks located through the summary section's chunk indexes (each chunk read at the
    offset its index gives, its message indexes passed over by their stated length); the
    records between chunks are still read, so messages outside chunks are found. When the
    summary is missing or does not validate, the linear pass is used instead and
    ``ScanResult.warnings`` says so.
``"auto"`` (default)
    The linear pass, helped by the summary when it validates: its channels are known up
    front, chunks holding none of the wanted topics are passed over, and its chunk indexes
    serve to recover after damage.

The summary *validates* when it parses, lies inside the file, and its CRC-32 matches (a
summary without a CRC must also have every chunk index pointing at a chunk opcode).

Every chunk's CRC-32 of its uncompressed data is checked (``mcap.reader`` does so only
with ``validate_crcs=True``; here always), and the data section CRC when the writer stored
one. A chunk that fails to parse, decompress or match its CRC is skipped whole and
reported with its byte offset and, when its message indexes (after it, or in the summary's
chunk index) say so, the topics and number of messages lost.

Resynchronisation: a damaged record — an opcode of 0x00 or in the undefined range
0x10–0x7F, a length running past the end of the file (or over a chunk the summary lists),
a record that does not parse (Header, Schema, Channel, Attachment, Metadata, Message
Index), a summary-only record, a footer or data end record in the middle of the data
section — is reported (byte offset, what was found) and the scan resumes at the next valid
record: the next offset where a Chunk record (opcode 0x06) parses and decompresses to its
stated size and CRC, or, when the summary validates, the next chunk offset its chunk
indexes list (whichever comes first). A valid chunk found *behind* the damaged record (a
damaged length that still looked well framed led the walk into it) is gone back to. A
chunk whose record header is damaged but which the summary's chunk index knows is read
through the index when its body agrees with the index and its CRC; a record with a
damaged opcode whose body is exactly a valid chunk is read as that chunk. A record length
longer than the record's own fields, followed where the fields end by well-framed
records, is taken as damaged and the walk goes on where the fields end. A chunk that
holds fewer messages than its message indexes list is reported. Chunks lost in the bytes
passed over are reported one by one from the summary when it knows them, else with the
count of the intact message index records that end where the scan resumed; when the
summary's statistics count more messages than were found and no damage explains it, that
too is reported. Nothing in a damaged byte range is ever decoded, and no message outside
a chunk is taken from bytes the walk later finds to belong to a chunk.

Message records are indexed as arrays (channel id, log time, payload offset and length)
into their chunk's bytes, so that the decoders can work on whole blocks with numpy.

Speed (issue 9): chunks are opened (decompressed, CRC-checked, indexed) on a pool of threads
ahead of the walk, which takes them in file order (the result is that of opening them in
turn). When the caller names the fields it wants (``fields``, or message paths among
``topics`` as :func:`~vibroscope.io.read_mcap` passes them), the threads also decode those
fields of fixed-layout CDR messages (:func:`vibroscope.io._ros2.decode_block`) right after
decompression, and a zstd or LZ4 chunk whose wanted messages are all decoded is
decompressed into a buffer each thread reuses (fresh memory for every chunk costs more
than decompressing it): its bytes are not kept, and ``Block.buf`` decompresses it again if
they are asked for. A chunk that fails on that path is opened again the usual way, which
reports it. The CRC-32 is ISA-L's when the ``isal`` package is installed (the same value,
several times faster), else zlib's.
"""

from __future__ import annotations

import bisect
import functools
import mmap
import os
import struct
import threading
import zlib
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from functools import partial
from io import BytesIO
from pathlib import Path
from typing import Any, Literal

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, ChunkIndex, Header, Metadata, Schema, Statistics

from vibroscope.errors import LogFormatError
from vibroscope.io import _ros2

MAGIC = b"\x89MCAP0\r\n"
_MSG_HDR = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time
_REC_HDR = struct.Struct("<BQ")
_FOOTER_LEN = 1 + 8 + 20
_MAX_CHUNK_USIZE = 1 << 32  # a stated uncompressed size beyond this is damage, not data
#: the largest ratio of a compressed chunk's stated uncompressed size to its compressed size (plus
#: :data:`RATIO_SLACK` bytes) that is decompressed; beyond it the chunk is refused as a lying size
#: or a decompression bomb. Real logs reach ~10 (zstd) and LZ4 frames cannot exceed ~255.
MAX_RATIO = 1000
RATIO_SLACK = 1 << 20
_COMPRESSIONS = (b"", b"zstd", b"lz4")
MODES = ("auto", "stream", "indexed")
_MAX_WORKERS = 8
_SUMMARY_ONLY_OPS = {Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX, Opcode.METADATA_INDEX, Opcode.STATISTICS,
                     Opcode.SUMMARY_OFFSET}
_DATA_OPS = {Opcode.CHUNK, Opcode.MESSAGE, Opcode.MESSAGE_INDEX, Opcode.ATTACHMENT, Opcode.METADATA, Opcode.HEADER}

try:  # optional codecs of mcap
    import zstandard as _zstd
except ImportError:  # pragma: no cover
    _zstd = None
try:
    import lz4.frame as _lz4
except ImportError:  # pragma: no cover
    _lz4 = None
try:  # LZ4 frames decompressed into a given buffer, with the GIL released (lz4's own API has no "into")
    from cramjam import lz4 as _cramjam_lz4
except ImportError:  # pragma: no cover - lz4.frame is the fallback
    _cramjam_lz4 = None
try:  # optional: CRC-32 of ISA-L, the same value as zlib's, several times faster
    from isal.isal_zlib import crc32 as _crc32
except ImportError:  # pragma: no cover - zlib's is the fallback
    _crc32 = zlib.crc32


def _opname(op: int) -> str:
    try:
        return Opcode(op).name
    except ValueError:
        return f"opcode 0x{op:02x}"


def _valid_opcode(op: int) -> bool:
    """Defined opcodes (0x01–0x0F) and the private range (0x80–0xFF); 0x00 and 0x10–0x7F are damage."""
    return 0x01 <= op <= 0x0F or op >= 0x80


class Block:
    """Messages found in one container (a chunk, or the loose messages of the data section).

    Parameters
    ----------
    buf : bytes-like or None
        The container's bytes (a decompressed chunk, or the file for loose messages); None
        when the scan dropped them after decoding the wanted fields (`reopen` gives them
        back on first use of :attr:`buf`).
    file_offset : int
        Byte offset of the chunk record (-1 for loose messages).
    channel_id : ndarray of uint16, shape (n,)
        Channel id of each message.
    log_time : ndarray of uint64, shape (n,)
        Log time of each message in ns.
    start : ndarray of int64, shape (n,)
        Payload offset of each message in :attr:`buf`.
    length : ndarray of int64, shape (n,)
        Payload length of each message in bytes.
    decoded : dict, optional
        Fields decoded by the scan's threads: channel id to (message type, stamps ns int64
        shape (k,), {field name: ndarray shape (k,)}) for the k messages of that channel in
        this block, in order.
    reopen : callable, optional
        Gives the chunk's bytes again (decompressed, size and CRC-32 checked) when `buf`
        is None.
    """

    __slots__ = ("_buf", "file_offset", "channel_id", "log_time", "start", "length", "decoded", "_reopen")

    def __init__(self, buf: Any, file_offset: int, channel_id: np.ndarray, log_time: np.ndarray, start: np.ndarray,
                 length: np.ndarray, decoded: dict | None = None, reopen: Any = None) -> None:
        if buf is None and reopen is None:
            raise ValueError("a block without its bytes needs `reopen`")
        self._buf = buf
        self.file_offset = file_offset
        self.channel_id = channel_id
        self.log_time = log_time
        self.start = start
        self.length = length
        self.decoded = decoded if decoded is not None else {}
        self._reopen = reopen

    @property
    def buf(self) -> Any:
        """The container's bytes (decompressed again, and kept, on first use when dropped).

        Raises
        ------
        LogFormatError
            If the chunk no longer decompresses to its size and CRC-32 (the file changed).
        """
        if self._buf is None:
            self._buf = self._reopen()
        return self._buf

    @property
    def n(self) -> int:
        """Number of messages."""
        return int(self.channel_id.size)

    def __repr__(self) -> str:
        return (f"Block(file_offset={self.file_offset}, n={self.n}, decoded={sorted(self.decoded)}, "
                f"bytes={'kept' if self._buf is not None else 'dropped'})")


@dataclass(frozen=True)
class Damage:
    """One damaged place of a file and what was lost there.

    Parameters
    ----------
    offset : int
        Byte offset of the damaged record (or of the chunk lost).
    reason : str
        What was found there, and where the scan resumed.
    messages : int or None, optional
        Messages lost, when the message indexes (after the chunk, or listed by the summary)
        say so; None when unknown.
    channel_ids : tuple of int, optional
        Channels of the messages lost, when known.
    per_channel : tuple of (int, int), optional
        (channel id, messages lost) for each channel, when the message indexes say so.
    span_ns : (int, int) or None, optional
        First and last log time in ns of the messages lost (the lost chunk's time range, as its
        chunk index or its intact record header states it), when known.
    """

    offset: int
    reason: str
    messages: int | None = None
    channel_ids: tuple[int, ...] = ()
    per_channel: tuple[tuple[int, int], ...] = ()
    span_ns: tuple[int, int] | None = None

    def describe(self, channels: dict[int, Channel]) -> str:
        """The reason with the topics and message count lost (``"...; topics /a, /b (12 messages lost)"``)."""
        text = self.reason
        if self.channel_ids:
            topics = sorted({channels[c].topic for c in self.channel_ids if c in channels})
            unknown = [f"channel id {c}" for c in self.channel_ids if c not in channels]
            names = ([f"topic{'s' if len(topics) > 1 else ''} {', '.join(topics)}"] if topics else []) + unknown
            text += "; " + ", ".join(names)
        if self.messages is not None:
            text += f" ({self.messages} messages lost)"
        return text


@dataclass
class ScanResult:
    """What a scan found: schemas, channels, message blocks, and the damage.

    ``skipped`` lists (byte offset, reason) for every damaged place, in file order; a reason
    ends in ``"; topic /t (N messages lost)"`` when the loss is known (channel ids stand
    for topics no channel record names). ``damage`` holds the same as :class:`Damage`
    entries. ``warnings`` carries what cost no message (a damaged header, a chunk read
    through the summary's index, a summary not used, a data section CRC mismatch), each
    starting with the file's path. ``mode`` is the reading path asked for; ``indexed`` says
    whether a valid summary was used; ``recovered`` counts chunks read through the index
    despite a damaged record header.
    """

    path: Path
    file_size: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    blocks: list[Block] = field(default_factory=list)
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (byte offset, reason)
    warnings: list[str] = field(default_factory=list)
    complete: bool = False  # footer and closing magic seen
    indexed: bool = False  # a valid summary (chunk indexes) was used
    chunks_skipped_by_index: int = 0  # chunks not decompressed: none of the wanted topics in them
    mode: str = "auto"  # the reading path taken: "stream", "indexed" or "auto"
    damage: list[Damage] = field(default_factory=list)  # every damaged place, in file order
    recovered: int = 0  # chunks with a damaged record header read through the summary's index

    def lost_by_topic(self) -> dict[str, tuple[int | None, float]]:
        """Messages and seconds lost per topic, over every :attr:`damage` entry that says so.

        Returns
        -------
        dict of str to (int or None, float)
            Topic (``"channel id N"`` for a channel no record names) -> (messages lost, None
            when a damaged place lists the topic without a count for it; seconds covered by the
            log time ranges of the chunks lost that held it, overlaps counted once, 0.0 when no
            range is known).
        """
        count: dict[str, int | None] = {}
        spans: dict[str, list[tuple[int, int]]] = {}
        for d in self.damage:
            per = dict(d.per_channel)
            for c in d.channel_ids:
                name = self.channels[c].topic if c in self.channels else f"channel id {c}"
                k = per.get(c)
                if k is None and d.messages is not None and len(d.channel_ids) == 1:
                    k = d.messages
                prev = count.get(name, 0)
                count[name] = None if k is None or prev is None else prev + k
                if d.span_ns is not None:
                    spans.setdefault(name, []).append(d.span_ns)
        out = {}
        for name, k in count.items():
            sec, hi = 0, None
            for a, b in sorted(spans.get(name, [])):
                if hi is None or a > hi:
                    sec += b - a
                    hi = b
                elif b > hi:
                    sec += b - hi
                    hi = b
            out[name] = (k, sec * 1e-9)
        return out

    def messages(self) -> list[tuple[int, int, bytes]]:
        """Every message found, undecoded, blocks in order (chunks in file order, then the loose ones).

        Returns
        -------
        list of (int, int, bytes)
            (channel id, log time in ns, payload copied out).
        """
        out = []
        for b in self.blocks:
            mv = memoryview(b.buf)
            for c, t, s, n in zip(b.channel_id.tolist(), b.log_time.tolist(), b.start.tolist(), b.length.tolist()):
                out.append((c, t, bytes(mv[s : s + n])))
        return out


@dataclass
class _Summary:
    start: int
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    chunks: dict[int, ChunkIndex]
    message_count: int | None
    lost: list[ChunkIndex] = field(default_factory=list)  # chunk indexes of chunks not in the file
    note: str | None = None  # how the summary was found, when not where the footer says
    shift: int = 0  # bytes the footer's summary start (and chunk offsets after a deletion) point too far


def _read_summary(data: Any, n: int) -> tuple[_Summary | None, str | None]:
    """The summary section, or None and why not (None, None: the file has none).

    Every record is parsed defensively: a summary that does not parse, lies outside the file,
    fails its CRC-32, or (without a CRC) has a chunk index not pointing at a chunk opcode is
    not used. A summary whose stated start is wrong because bytes before it were deleted
    (a lost chunk) is found again (:func:`_relocated_summary`).
    """
    if n < 8 + _FOOTER_LEN + 8 or bytes(data[n - 8 : n]) != MAGIC:
        return None, None
    fpos = n - 8 - _FOOTER_LEN
    op, length = _REC_HDR.unpack_from(data, fpos)
    if op != Opcode.FOOTER or length != 20:
        return None, f"no footer record at byte offset {fpos} (found {_opname(op)}, length {length})"
    summary_start, _sos, summary_crc = struct.unpack_from("<QQI", data, fpos + 9)
    if summary_start == 0:
        return None, None
    why = None
    if not 8 <= summary_start <= fpos:
        why = f"the footer's summary start {summary_start} lies outside the file"
    elif summary_crc != 0:
        crc = zlib.crc32(memoryview(data)[summary_start : fpos + 9 + 16])
        if crc != summary_crc:
            why = (f"summary section at byte offset {summary_start} fails its CRC-32 "
                   f"(stored {summary_crc:#010x}, computed {crc:#010x})")
    if why is not None:
        moved = _relocated_summary(data, fpos, summary_start, summary_crc)
        return (moved, None) if moved is not None else (None, why)
    return _parse_summary(data, summary_start, fpos, summary_crc)


_DATA_END_HEAD = bytes([Opcode.DATA_END]) + struct.pack("<Q", 4)
_MAX_CHUNK_SEARCHES = 256  # chunk indexes looked for byte by byte when neither offset holds their chunk


def _relocated_summary(data: Any, fpos: int, stated: int, crc: int) -> _Summary | None:
    """The summary section found where it lies when bytes before it were deleted, or None.

    The footer's summary start then points `shift` bytes too far. The section is looked for
    right after a Data End record (where writers put it) and proven by the footer's CRC-32,
    or without one by parsing to the footer with more than half of its chunk indexes matching
    chunk records. Its chunk indexes are then matched to the chunk
    records of the file (:func:`_place_chunks`): at their stated offset (before the deleted
    bytes), `shift` bytes earlier (after them), or where a chunk record with the same length,
    log time range and uncompressed size lies; a chunk index matching no chunk record lists
    a chunk that is not in the file (``_Summary.lost``).
    """
    mv = memoryview(data)
    hi, tries = fpos, 0
    while tries < 8:
        p = data.rfind(_DATA_END_HEAD, 8, hi)
        if p < 0:
            return None
        hi, tries = p + len(_DATA_END_HEAD) - 1, tries + 1
        start = p + 13
        if start == stated or start > fpos or (crc != 0 and zlib.crc32(mv[start : fpos + 9 + 16]) != crc):
            continue
        summary, _why = _parse_summary(data, start, fpos, crc, placed=False)
        if summary is None:
            continue
        shift = stated - start
        chunks, lost, moved = _place_chunks(data, summary.chunks, shift, start)
        if crc == 0 and len(chunks) <= len(lost):  # no CRC to prove it: most chunk indexes must match
            continue
        summary.chunks, summary.lost, summary.shift = chunks, lost, shift
        summary.note = (f"the footer's summary start {stated} is wrong by {shift:+d} bytes (bytes deleted before "
                        f"it?); the summary section found at byte offset {start} ({'its CRC-32 checked' if crc else 'no CRC-32'}) is used: "
                        f"{len(chunks)} of its {len(chunks) + len(lost)} chunk indexes match chunk records "
                        f"({moved} shifted); {len(lost)} list{'s a chunk' if len(lost) == 1 else ' chunks'} no longer in the file")
        return summary
    return None


def _chunk_signature(ci: ChunkIndex) -> bytes:
    """The first 33 bytes of the chunk record a chunk index lists: opcode, record length, log
    time range and uncompressed size."""
    return bytes([Opcode.CHUNK]) + struct.pack("<QQQQ", ci.chunk_length - 9, ci.message_start_time,
                                               ci.message_end_time, ci.uncompressed_size)


def _place_chunks(data: Any, stated: dict[int, ChunkIndex], shift: int,
                  stop: int) -> tuple[dict[int, ChunkIndex], list[ChunkIndex], int]:
    """(chunk indexes by the offset where their chunk record lies, chunk indexes whose chunk is
    not in ``data[8:stop]``, how many were moved); see :func:`_relocated_summary`."""
    placed: dict[int, ChunkIndex] = {}
    lost: list[ChunkIndex] = []
    moved = searches = 0
    for o, ci in sorted(stated.items()):
        sig = _chunk_signature(ci)
        where = None
        for q in (o, o - shift):
            if 8 <= q and q + ci.chunk_length <= stop and q not in placed and bytes(data[q : q + 33]) == sig:
                where = q
                break
        if where is None and searches < _MAX_CHUNK_SEARCHES:
            searches += 1
            q = data.find(sig, 8, stop)
            if q >= 0 and q + ci.chunk_length <= stop and q not in placed:
                where = q
        if where is None:
            lost.append(ci)
            continue
        d = o - where
        moved += d != 0
        placed[where] = ci if d == 0 else ChunkIndex(
            message_start_time=ci.message_start_time, message_end_time=ci.message_end_time,
            chunk_start_offset=where, chunk_length=ci.chunk_length,
            message_index_offsets={c: off - d for c, off in ci.message_index_offsets.items()},
            message_index_length=ci.message_index_length, compression=ci.compression,
            compressed_size=ci.compressed_size, uncompressed_size=ci.uncompressed_size)
    return placed, lost, moved


def index_counts(ci: ChunkIndex) -> dict[int, int] | None:
    """Messages per channel id of the chunk a chunk index lists, from the lengths of its message
    index records (their offsets and total length in the index), or None when they do not add up.

    Parameters
    ----------
    ci : mcap.records.ChunkIndex
        The chunk index.

    Returns
    -------
    dict of int to int or None
    """
    items = sorted(ci.message_index_offsets.items(), key=lambda kv: kv[1])
    if not items:
        return None
    ends = [off for _, off in items[1:]] + [ci.chunk_start_offset + ci.chunk_length + ci.message_index_length]
    out = {}
    for (cid, off), end in zip(items, ends):
        k, r = divmod(end - off - 15, 16)
        if k < 0 or r:
            return None
        out[cid] = k
    return out


def _parse_summary(data: Any, summary_start: int, fpos: int, summary_crc: int,
                   placed: bool = True) -> tuple[_Summary | None, str | None]:
    """The summary records in ``data[summary_start:fpos]``; `placed`: its chunk indexes must
    point into the data section (else they are matched to chunk records by the caller)."""
    schemas, channels, chunks, count = {}, {}, {}, None
    pos = summary_start
    while pos < fpos:
        if pos + 9 > fpos:
            return None, f"summary record header cut off at byte offset {pos}"
        op, length = _REC_HDR.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        if end > fpos or not _valid_opcode(op):
            return None, f"summary record at byte offset {pos} is damaged ({_opname(op)}, length {length})"
        try:
            if op == Opcode.SCHEMA:
                sc = _parse(Schema, data[body:end])
                schemas[sc.id] = sc
            elif op == Opcode.CHANNEL:
                ch = _parse(Channel, data[body:end])
                channels[ch.id] = ch
            elif op == Opcode.CHUNK_INDEX:
                ci = _chunk_index(data, body, end)
                o = ci.chunk_start_offset
                if placed and not (8 <= o and ci.chunk_length >= 9 and o + ci.chunk_length <= summary_start):
                    return None, f"chunk index at byte offset {pos} points outside the data section ({o})"
                if placed and summary_crc == 0 and data[o] != Opcode.CHUNK:
                    return None, f"chunk index at byte offset {pos} points at {_opname(data[o])}, not a chunk ({o})"
                if not placed and ci.chunk_length < 9 + 40:
                    return None, f"chunk index at byte offset {pos} states a chunk length of {ci.chunk_length}"
                chunks[o] = ci
            elif op == Opcode.STATISTICS:
                count = _parse(Statistics, data[body:end]).message_count
        except Exception as exc:  # noqa: BLE001 - any parse failure invalidates the summary
            return None, f"summary {_opname(op)} record at byte offset {pos} does not parse ({type(exc).__name__}: {exc})"
        pos = end
    return _Summary(summary_start, schemas, channels, chunks, count), None


def _parse(cls: Any, body: bytes) -> Any:
    return cls.read(ReadDataStream(BytesIO(body)))


_CI_HEAD = struct.Struct("<QQQQI")
_CI_ENTRY = struct.Struct("<HQ")


def _chunk_index(data: Any, body: int, end: int) -> ChunkIndex:
    """The Chunk Index record ``data[body:end]``, parsed with struct (the summary of a long log
    holds thousands); anything unusual is left to mcap's own parser (and its errors)."""
    try:
        t0, t1, off, length, mlen = _CI_HEAD.unpack_from(data, body)
        p = body + 36
        if mlen % 10 or p + mlen + 12 > end:
            raise ValueError
        offsets = dict(_CI_ENTRY.iter_unpack(data[p : p + mlen]))
        p += mlen
        milen, slen = struct.unpack_from("<QI", data, p)
        p += 12
        if p + slen + 16 > end:
            raise ValueError
        comp = str(data[p : p + slen], "utf-8")
        csize, usize = struct.unpack_from("<QQ", data, p + slen)
    except Exception:  # noqa: BLE001 - mcap's parser decides
        return _parse(ChunkIndex, data[body:end])
    return ChunkIndex(message_start_time=t0, message_end_time=t1, chunk_start_offset=off, chunk_length=length,
                      message_index_offsets=offsets, message_index_length=milen, compression=comp,
                      compressed_size=csize, uncompressed_size=usize)


def memory_budget() -> int:
    """The default memory budget in bytes: half the available memory, or half the address-space
    limit (``ulimit -v``, ``RLIMIT_AS``), whichever is smaller.

    Returns
    -------
    int
    """
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = 8 << 30
    budget = avail // 2
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY:
            budget = min(budget, soft // 2)
    except (ImportError, OSError, ValueError):
        pass
    return int(budget)


def check_chunk_size(chunk: Chunk, limit: int) -> None:
    """Refuse, before anything is allocated, a chunk whose stated uncompressed size exceeds
    `limit` bytes (a share of the memory budget), or :data:`MAX_RATIO` times its compressed size
    plus :data:`RATIO_SLACK`, or (uncompressed) differs from its data length.

    Parameters
    ----------
    chunk : mcap.records.Chunk
        The chunk record (its data not yet decompressed).
    limit : int
        Bytes one chunk may take decompressed.

    Raises
    ------
    ValueError
        Naming the stated size and the limit it exceeds.
    """
    usize, csize = chunk.uncompressed_size, len(chunk.data)
    if chunk.compression == "":
        if usize != csize:
            raise ValueError(f"uncompressed chunk states {usize} bytes but holds {csize}")
        return
    if usize > MAX_RATIO * csize + RATIO_SLACK:
        raise ValueError(f"stated uncompressed size {usize} exceeds {MAX_RATIO} times its {csize} compressed bytes "
                         f"(+{RATIO_SLACK}): a lying size or a decompression bomb, not decompressed")
    if usize > limit:
        raise ValueError(f"stated uncompressed size {usize} exceeds this chunk's share of the memory budget "
                         f"({limit} bytes; max_memory): not decompressed")


def _read_chunk(mv: memoryview, body: int, end: int) -> Chunk:
    """Parse a Chunk record without copying its (possibly large) data."""
    if end - body < 40:
        raise ValueError(f"chunk record of {end - body} bytes is shorter than its fixed fields (40)")
    start_t, end_t, usize, crc, clen = struct.unpack_from("<QQQII", mv, body)
    if body + 40 + clen > end:
        raise ValueError(f"compression name length {clen} runs past the record end")
    if usize > _MAX_CHUNK_USIZE:
        raise ValueError(f"uncompressed size {usize} is implausible")
    p = body + 32
    comp = bytes(mv[p : p + clen]).decode()
    p += clen
    (dlen,) = struct.unpack_from("<Q", mv, p)
    p += 8
    if p + dlen > end:
        raise ValueError(f"chunk data length {dlen} runs past the record end")
    return Chunk(compression=comp, data=mv[p : p + dlen], message_end_time=end_t, message_start_time=start_t,
                 uncompressed_crc=crc, uncompressed_size=usize)


_LOCAL = threading.local()


def _decompress(chunk: Chunk) -> Any:
    """The chunk's data decompressed, never to more than its stated uncompressed size (a frame
    header claiming more is not believed: the output buffer is the stated size, filled by a
    stream; a frame that goes on beyond it raises)."""
    if chunk.compression == "":
        return chunk.data
    size = chunk.uncompressed_size
    if chunk.compression == "zstd":
        if _zstd is None:
            raise ValueError("zstd compression but the zstandard module is not installed")
        dec = getattr(_LOCAL, "zstd", None)
        if dec is None:  # one decompression context per thread, reused (zstandard objects are not thread-safe)
            dec = _LOCAL.zstd = _zstd.ZstdDecompressor()
        try:
            stated = _zstd.frame_content_size(chunk.data)  # the frame header's size, when it has one
        except Exception:  # noqa: BLE001 - not a zstd frame: the stream below names the fault
            stated = -1
        if stated == size:  # one call, into exactly the size already checked (zstd stops at the frame's size)
            return dec.decompress(chunk.data, max_output_size=size)
        if stated > size:
            raise ValueError(f"zstd frame states {stated} bytes, more than the {size} the chunk states: not "
                             f"decompressed")
        out = bytearray(size)
        got = _zstd_stream_into(dec, chunk.data, memoryview(out))
        if got != size:
            raise ValueError(f"decompresses to more than the {size} bytes stated" if got > size else
                             f"decompresses to {got} bytes, not the {size} stated")
        return out
    if chunk.compression == "lz4":
        if _cramjam_lz4 is not None:
            out = bytearray(size)
            try:
                got = _cramjam_lz4.decompress_into(chunk.data, out)
            except Exception as exc:  # noqa: BLE001 - cramjam's errors: too long for the buffer, or damaged
                raise ValueError(f"LZ4 frame does not decompress into the {size} bytes stated ({exc})") from None
            if got != size:
                raise ValueError(f"decompresses to {got} bytes, not the {size} stated")
            return out
        if _lz4 is None:
            raise ValueError("lz4 compression but the lz4 module is not installed")
        d = _lz4.LZ4FrameDecompressor()
        out = d.decompress(bytes(chunk.data), max_length=size + 1)
        if len(out) != size or not d.eof:
            raise ValueError(f"decompresses to {'more than ' if len(out) > size else ''}{len(out)} bytes, not the "
                             f"{size} stated")
        return out
    raise ValueError(f"unsupported chunk compression {chunk.compression!r}")


def _zstd_stream_into(dec: Any, data: Any, out: memoryview) -> int:
    """Decompress the zstd frame `data` into `out` by a stream (never more than ``len(out)`` + 1
    bytes produced); returns the bytes written, ``len(out) + 1`` when the frame goes on."""
    reader = dec.stream_reader(data, read_size=max(min(len(data), 1 << 20), 1), read_across_frames=False)
    size, got = len(out), 0
    while got < size:
        k = reader.readinto(out[got:])
        if not k:
            break
        got += k
    if got == size and reader.read(1):
        return size + 1
    return got


def _scratch(size: int) -> memoryview:
    """This thread's reused output buffer, at least `size` bytes (fresh pages for every chunk
    cost more than decompressing it)."""
    buf = getattr(_LOCAL, "buf", None)
    if buf is None or len(buf) < size:
        buf = _LOCAL.buf = bytearray(max(size, 1 << 20))
    return memoryview(buf)[:size]


def _checked(chunk: Chunk, validate_crcs: bool = True) -> Any:
    """The chunk's data decompressed (:func:`_decompress`), its size and (when stored and
    `validate_crcs`) its CRC-32 checked; raises ValueError naming the fault."""
    raw = _decompress(chunk)
    if len(raw) != chunk.uncompressed_size:
        raise ValueError(f"uncompressed size {len(raw)} != {chunk.uncompressed_size} stated")
    if validate_crcs and chunk.uncompressed_crc != 0 and (crc := _crc32(raw)) != chunk.uncompressed_crc:
        raise ValueError(f"CRC-32 mismatch: stored {chunk.uncompressed_crc:#010x}, computed {crc:#010x}")
    return raw


def _decompress_into(chunk: Chunk) -> memoryview | None:
    """The chunk's data decompressed into this thread's reused buffer (a view of it, valid until
    the thread's next chunk), or None where that does not apply (then :func:`_decompress`, which
    also gives the error of a damaged chunk)."""
    size = chunk.uncompressed_size
    try:
        if chunk.compression == "zstd" and _zstd is not None:
            out = _scratch(size)
            dec = getattr(_LOCAL, "zstd", None)
            if dec is None:
                dec = _LOCAL.zstd = _zstd.ZstdDecompressor()
            return out if _zstd_stream_into(dec, chunk.data, out) == size else None
        if chunk.compression == "lz4" and _cramjam_lz4 is not None:
            out = _scratch(size)
            return out if _cramjam_lz4.decompress_into(chunk.data, out) == size else None
    except Exception:  # noqa: BLE001 - the usual path decides (and names the fault)
        return None
    return None


@functools.lru_cache(maxsize=64)
def _periodic_dtype(stride: int) -> np.dtype:
    """Message records of `stride` bytes laid end to end: opcode, record length, channel id, log time."""
    return np.dtype({"names": ["op", "len", "cid", "log_time"], "formats": ["u1", "<u8", "<u2", "<u8"],
                     "offsets": [0, 1, 9, 15], "itemsize": stride})


def _index_messages(buf: bytes, pos: int, end: int, out_records: list, fast: bool = True) -> tuple[np.ndarray, ...]:
    """Index the records of `buf[pos:end]`; Schema/Channel records go to `out_records`.

    Message records of one equal length laid end to end (the usual case for a sensor
    topic) are indexed with numpy in one step (unless `fast` is false); anything else
    record by record.
    """
    cids: list[np.ndarray] = []
    logs: list[np.ndarray] = []
    starts: list[np.ndarray] = []
    lens: list[np.ndarray] = []
    py_c: list[int] = []
    py_l: list[int] = []
    py_s: list[int] = []
    py_n: list[int] = []

    def flush_py() -> None:
        if py_c:
            cids.append(np.array(py_c, np.uint16))
            logs.append(np.array(py_l, np.uint64))
            starts.append(np.array(py_s, np.int64))
            lens.append(np.array(py_n, np.int64))
            py_c.clear(), py_l.clear(), py_s.clear(), py_n.clear()

    unpack_rec = _REC_HDR.unpack_from
    unpack_msg = _MSG_HDR.unpack_from
    tried_periodic = not fast
    while pos < end:
        if pos + 9 > end:
            raise ValueError(f"record header cut off at {pos} of {end} bytes")
        op, length = unpack_rec(buf, pos)
        if pos + 9 + length > end:
            raise ValueError(f"{_opname(op)} record at {pos} needs {length} bytes, {end - pos - 9} left")
        if op == Opcode.MESSAGE:
            if not tried_periodic:
                tried_periodic = True
                stride = 9 + length
                rest = end - pos
                if length >= 22 and rest % stride == 0 and rest // stride > 8:
                    m = rest // stride
                    a = np.ndarray((m,), _periodic_dtype(stride), buf, pos)
                    if (a["op"] == _OP_MESSAGE).all() and (a["len"] == length).all():
                        flush_py()
                        cids.append(a["cid"].astype(np.uint16))
                        logs.append(a["log_time"].astype(np.uint64))
                        starts.append(pos + 31 + stride * np.arange(m, dtype=np.int64))
                        lens.append(np.full(m, length - 22, np.int64))
                        pos = end
                        break
                if fast:  # any other layout: the record walk compiled (numba), else record by record below
                    got = _index_compiled(buf, pos, end, out_records)
                    if got is not None:
                        flush_py()
                        for col, arr in zip((cids, logs, starts, lens), got):
                            col.append(arr)
                        pos = end
                        break
            cid, _seq, log_time, _pub = unpack_msg(buf, pos + 9)
            py_c.append(cid)
            py_l.append(log_time)
            py_s.append(pos + 31)
            py_n.append(length - 22)
        elif op == Opcode.SCHEMA:
            out_records.append(_parse(Schema, buf[pos + 9 : pos + 9 + length]))
        elif op == Opcode.CHANNEL:
            out_records.append(_parse(Channel, buf[pos + 9 : pos + 9 + length]))
        pos += 9 + length
    flush_py()
    if not cids:
        e = np.empty(0, np.int64)
        return np.empty(0, np.uint16), np.empty(0, np.uint64), e, e.copy()
    return (np.concatenate(cids), np.concatenate(logs), np.concatenate(starts), np.concatenate(lens))


def _walk_records(buf, pos, end, op, start, length, cid, logt):  # pragma: no cover - compiled by numba
    """Walk the records of ``buf[pos:end]`` (numba kernel): fill op, payload start, length and, for
    messages, channel id and log time; returns (records, 0) or (records so far, 1) at anything the
    record-by-record walk would treat specially (a cut-off record, a message shorter than its
    header, more records than the arrays hold)."""
    n = 0
    while pos < end:
        if pos + 9 > end or n >= op.size:
            return n, 1
        ln = 0
        for k in range(8):
            ln |= np.int64(buf[pos + 1 + k]) << np.int64(8 * k)
        if ln < 0 or ln > end - pos - 9:
            return n, 1
        o = buf[pos]
        op[n] = o
        length[n] = ln
        if o == 0x05:
            if ln < 22:
                return n, 1
            c = np.int64(buf[pos + 9]) | (np.int64(buf[pos + 10]) << np.int64(8))
            t = np.uint64(0)
            for k in range(8):
                t |= np.uint64(buf[pos + 15 + k]) << np.uint64(8 * k)
            cid[n] = c
            logt[n] = t
            start[n] = pos + 31
            length[n] = ln - 22
        else:
            start[n] = pos
        n += 1
        pos += 9 + ln
    return n, 0


_COMPILED: dict[str, Any] = {}
_OP_MESSAGE, _OP_SCHEMA, _OP_CHANNEL = int(Opcode.MESSAGE), int(Opcode.SCHEMA), int(Opcode.CHANNEL)  # plain ints: fast
_COMPILE_LOCK = threading.Lock()


def _index_compiled(buf: Any, pos: int, end: int, out_records: list) -> tuple[np.ndarray, ...] | None:
    """The records of ``buf[pos:end]`` indexed by the compiled walk (the same result as the
    record-by-record walk), or None where that walk must decide (it raises the same errors)."""
    with _COMPILE_LOCK:
        walk = _COMPILED.get("walk")
        if walk is None:
            try:
                import numba
            except ImportError:  # pragma: no cover - numba is a dependency
                return None
            walk = _COMPILED["walk"] = numba.njit(cache=True, nogil=True)(_walk_records)
    cap = (end - pos) // 23 + 1  # every record of a chunk (schema, channel, message) has at least 23 bytes
    work = getattr(_LOCAL, "walk", None)  # this thread's arrays, reused (fresh pages cost more than the walk)
    if work is None or work[0].size < cap:
        work = _LOCAL.walk = (np.empty(cap, np.uint8), np.empty(cap, np.int64), np.empty(cap, np.int64),
                              np.empty(cap, np.uint16), np.empty(cap, np.uint64))
    op, start, length, cid, logt = (a[:cap] for a in work)
    u8 = np.frombuffer(buf, np.uint8, count=end, offset=0)
    m, status = walk(u8, pos, end, op, start, length, cid, logt)
    if status:
        return None
    op = op[:m]
    msg = op == _OP_MESSAGE
    for i in np.flatnonzero((op == _OP_SCHEMA) | (op == _OP_CHANNEL)).tolist():
        s, ln = int(start[i]), int(length[i])
        out_records.append(_parse(Schema if op[i] == _OP_SCHEMA else Channel, buf[s + 9 : s + 9 + ln]))
    return cid[:m][msg], logt[:m][msg], start[:m][msg], length[:m][msg]  # copies (boolean indexing)


def _fields_end(data: Any, op: int, body: int, end: int) -> int | None:
    """Where the fields of a Header, Schema, Channel, Message Index or Data End record end
    (from their own length prefixes), or None for other records or when they run past `end`."""
    try:
        if op == Opcode.HEADER:
            p = body
            for _ in range(2):
                p += 4 + struct.unpack_from("<I", data, p)[0]
        elif op == Opcode.SCHEMA:
            p = body + 2
            for _ in range(3):
                p += 4 + struct.unpack_from("<I", data, p)[0]
        elif op == Opcode.CHANNEL:
            p = body + 4
            for _ in range(3):
                p += 4 + struct.unpack_from("<I", data, p)[0]
        elif op == Opcode.MESSAGE_INDEX:
            p = body + 6 + struct.unpack_from("<I", data, body + 2)[0]
        elif op == Opcode.DATA_END:
            p = body + 4
        else:
            return None
    except struct.error:
        return None
    return p if p <= end else None


def _open(path: Path) -> Any:
    """The file's bytes: a read-only map (chunk data and loose payloads are sliced without copying)."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
    except (OSError, ValueError) as exc:
        raise LogFormatError(f"{path}: cannot read ({exc})") from exc


def _decode_plan(summary: _Summary | None, topics: Any, fields: Any) -> dict[int, tuple[str, tuple[str, ...]]]:
    """Channel id -> (message type, field names) that the threads decode right after
    decompression: channels the summary knows, CDR of a fixed-layout type, with wanted fields
    (`fields`, else the entries of `topics` that extend a topic by a field path)."""
    if summary is None or (fields is None and topics is None):
        return {}
    plan = {}
    for cid, ch in summary.channels.items():
        sc = summary.schemas.get(ch.schema_id)
        floats = _ros2.FLOAT_FIELDS.get(sc.name) if sc is not None and ch.message_encoding == "cdr" else None
        if floats is None:
            continue
        if fields is not None:
            names = list(fields.get(ch.topic, ()))
        else:
            names = [t[len(ch.topic) + 1 :] for t in topics if len(t) > len(ch.topic) + 1 and t.startswith(ch.topic + ".")]
        names = sorted({nm for nm in names if nm in floats or nm in _ros2.STAMP_FIELDS})
        if names:
            plan[cid] = (sc.name, tuple(names))
    return plan


def _reopen_chunk(mview: memoryview, path: Path, pos: int, end: int, validate_crcs: bool) -> Any:
    """The bytes of the chunk record at `pos` again (it was read whole and valid before)."""
    try:
        chunk = _read_chunk(mview, pos + 9, end)
        raw = _decompress(chunk)
    except Exception as exc:  # noqa: BLE001 - only VibroscopeError escapes
        raise LogFormatError(f"{path}: chunk at byte offset {pos} no longer decompresses ({type(exc).__name__}: "
                             f"{exc}); the file changed since it was scanned?") from exc
    if len(raw) != chunk.uncompressed_size or (
            validate_crcs and chunk.uncompressed_crc != 0 and _crc32(raw) != chunk.uncompressed_crc):
        raise LogFormatError(f"{path}: chunk at byte offset {pos} no longer matches its size and CRC-32; the file "
                             f"changed since it was scanned?")
    return raw


class _Scanner:
    """Walks the records of the data section, filling a :class:`ScanResult`."""

    def __init__(self, res: ScanResult, data: Any, *, validate_crcs: bool, fast: bool, summary: _Summary | None,
                 skip_chunks: set[int], search: bool, seek: bool, bar: Any,
                 plan: dict[int, tuple[str, tuple[str, ...]]] | None = None, unwanted: set[int] | None = None) -> None:
        self.res = res
        self.plan = plan or {}  # channel id -> (type, fields) decoded on the threads
        self.unwanted = unwanted or set()  # channel ids whose payloads will not be read
        self.data = data
        self.n = len(data)
        self.mview = memoryview(data)
        self.validate_crcs = validate_crcs
        self.fast = fast
        self.summary = summary
        self.index = summary.chunks if summary is not None else {}
        self.targets = sorted(self.index)
        self.skip_chunks = skip_chunks
        self.search = search  # look for chunk records byte by byte after damage
        self.seek = seek  # jump over each indexed chunk's message indexes by the stated length
        self.bar = bar
        self.done: set[int] = set()  # chunk offsets read, skipped or reported
        self.opened: dict[int, tuple] = {}  # chunks opened while resynchronising
        self.loose: tuple[list, list, list, list] = ([], [], [], [])  # channel id, log time, start, length
        self.ended = False  # data end or footer reached
        self.last_good = 8  # just after the start of the last chunk read: a back-search starts here
        self.pool: ThreadPoolExecutor | None = None  # opens the chunks ahead of the walk (see prefetch)
        self.pending: dict[tuple[int, int], Future] = {}  # (body, end) -> open_chunk(body, end) under way
        self.frontier = 0  # where the look-ahead for chunk records stopped
        self.window = 1
        self.data_crc: dict[int, Future] = {}  # data end offset -> CRC-32 of the bytes before it, under way
        self.max_chunk = _MAX_CHUNK_USIZE  # bytes one chunk may take decompressed (start_pool sets the budget's share)

    # -- chunks opened ahead of the walk -----------------------------------------------------
    def start_pool(self, workers: int, max_memory: int | None = None) -> None:
        """Open chunks ahead of the walk on `workers` threads (decompression and CRC-32 release the GIL);
        each chunk may take decompressed at most the share of `max_memory` (bytes, default
        :func:`memory_budget`) of one of the ``workers + 1`` threads."""
        budget = memory_budget() if max_memory is None else int(max_memory)
        self.max_chunk = min(_MAX_CHUNK_USIZE, budget // (max(workers, 1) + 1))
        if workers > 1:
            self.pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="vibroscope-mcap")
            self.window = 2 * workers + 2

    def crc_ahead(self) -> None:
        """Start the data section CRC-32 on a thread, for a data end record just before the summary
        (where writers put it); used only when the walk finds the data end record there."""
        s = self.summary
        if self.pool is not None and self.validate_crcs and s is not None and s.start >= 8 + 13:
            op, length = _REC_HDR.unpack_from(self.data, s.start - 13)
            if op == Opcode.DATA_END and length == 4:
                self.data_crc[s.start - 13] = self.pool.submit(_crc32, self.mview[: s.start - 13])

    def close_pool(self) -> None:
        """Drop what was opened ahead and not used (damage sent the walk elsewhere); stop the threads."""
        for fut in [*self.pending.values(), *self.data_crc.values()]:
            fut.cancel()
        self.pending.clear()
        self.data_crc.clear()
        if self.pool is not None:
            self.pool.shutdown(wait=True)
            self.pool = None

    def prefetch(self, pos: int, stop: int) -> None:
        """Start opening the chunk records that follow one another from `pos` (hopping over records
        by their lengths, as the walk will): a guess only, the walk decides what is read; a chunk
        opened ahead is used only for the very record bytes ``(body, end)`` the walk reads, so the
        result is that of opening it in turn."""
        if self.pool is None:
            return
        for key in [k for k in self.pending if k[0] < pos]:  # the walk went elsewhere
            self.pending.pop(key).cancel()
        p = self.frontier if self.frontier > pos else pos
        data, hops = self.data, 0
        while len(self.pending) < self.window and p + 9 <= stop and hops < 1024:
            op, length = _REC_HDR.unpack_from(data, p)
            e = p + 9 + length
            if not _valid_opcode(op) or e > stop:
                break
            if op == Opcode.CHUNK and length >= 40 and p not in self.skip_chunks and p not in self.done:
                key = (p + 9, e)
                if key not in self.pending:
                    self.pending[key] = self.pool.submit(self.open_chunk, p + 9, e)
            p, hops = e, hops + 1
        self.frontier = p

    # -- the walk ---------------------------------------------------------------------------
    def walk(self, pos: int, stop: int) -> int:
        """Read records in ``[pos, stop)``; returns where the walk ended."""
        data = self.data
        while pos < stop and not self.ended:
            if pos in self.index and pos not in self.done:
                nxt = self.indexed_chunk(pos, stop)
                if nxt is not None:
                    self._progress(pos, nxt)
                    pos = nxt
                    continue
                if data[pos] != Opcode.CHUNK:  # the index says a chunk is here: what is here is damaged
                    ci = self.index[pos]
                    end = pos + ci.chunk_length
                    if self._plausible(end, stop):
                        msgs, cids = self.loss_of_chunk(pos, end, stop)
                        self.res.damage.append(Damage(pos, f"chunk record damaged (found {_opname(data[pos])} where "
                                                           f"the summary's chunk index lists a chunk)", msgs, cids))
                        self.done.add(pos)
                        pos = end
                        continue
                    pos = self.damaged(pos, f"{_opname(data[pos])} where the summary's chunk index lists a chunk", stop)
                    continue
            if pos + 9 > stop:
                pos = self.damaged(pos, f"{stop - pos} bytes left where a record header needs 9"
                                   + (" (file cut off?)" if stop == self.n else ""), stop)
                continue
            op, length = _REC_HDR.unpack_from(data, pos)
            body, end = pos + 9, pos + 9 + length
            if not _valid_opcode(op):
                if length >= 40 and end <= stop and self.disguised_chunk(pos, op, body, end):
                    self._progress(pos, end)
                    pos = end
                    continue
                pos = self.damaged(pos, f"invalid opcode 0x{op:02x} (record length {length})", stop)
                continue
            if end > stop:
                where = "cut off by the end of the file" if stop == self.n else f"running past byte offset {stop}"
                pos = self.damaged(pos, f"{_opname(op)} record {where}: needs {length} bytes, {stop - body} left", stop)
                continue
            over = self.jumps_over_chunk(pos, end)
            if over is not None:
                pos = self.damaged(pos, f"{_opname(op)} record of {length} bytes runs over the chunk the summary "
                                        f"lists at byte offset {over}", stop)
                continue
            if op != Opcode.CHUNK and op != Opcode.MESSAGE and length >= 40 and self.disguised_chunk(pos, op, body, end):
                self._progress(pos, end)
                pos = end
                continue
            nxt = self.record(op, pos, body, end, stop)
            self._progress(pos, nxt)
            pos = nxt
        return pos

    def _progress(self, a: int, b: int) -> None:
        if self.bar is not None and b > a:
            self.bar.update(b - a)

    def record(self, op: int, pos: int, body: int, end: int, stop: int) -> int:
        """Handle one well-framed record; returns the offset to continue at."""
        res, data = self.res, self.data
        fit = _fields_end(data, op, body, end)
        if fit is not None and fit < end and self._plausible(fit, stop):
            # a record length longer than the record's own fields, and well-framed records where
            # they end: the length is damaged (padding is not followed by records that way)
            res.warnings.append(f"{res.path}: {_opname(op)} record at byte offset {pos}: record length {end - body} "
                                f"disagrees with its fields ({fit - body} bytes); read on at byte offset {fit}")
            end = fit
        if op == Opcode.FOOTER or op == Opcode.DATA_END:
            if op == Opcode.FOOTER and not (end - body == 20 and end + 8 == self.n):
                return self.bad_record(pos, end, stop, f"footer record of {end - body} bytes inside the file")
            if op == Opcode.DATA_END and not self.summary_follows(end):
                return self.bad_record(pos, end, stop, f"data end record of {end - body} bytes followed by more of "
                                                       f"the data section")
            if op == Opcode.DATA_END:
                self.data_end(pos, body, end - body)
            self.ended = True
            return end
        if op == Opcode.MESSAGE_INDEX:
            rl = struct.unpack_from("<I", data, body + 2)[0] if end - body >= 6 else -1
            if rl < 0 or rl % 16 or body + 6 + rl > end:
                return self.bad_record(pos, end, stop, f"message index record of {end - body} bytes does not parse")
            return end
        if op in _SUMMARY_ONLY_OPS:
            return self.bad_record(pos, end, stop, f"{_opname(op)} record inside the data section")
        if op == Opcode.CHUNK:
            if pos in self.skip_chunks:
                res.chunks_skipped_by_index += 1
                self.done.add(pos)
                return end
            exc = self.chunk(pos, body, end)
            if exc is None:
                fit = self.chunk_fit(body, end)
                if fit != end and self._plausible(fit, stop):
                    self.res.warnings.append(
                        f"{self.res.path}: chunk at byte offset {pos}: record length {end - body} disagrees with its "
                        f"fields ({fit - body} bytes); read on at byte offset {fit}")
                    return fit
                return self.after_chunk(pos, end, stop)
            return self.bad_record(pos, end, stop, f"chunk skipped: {exc}", chunk=True)
        if op == Opcode.MESSAGE:
            if end - body < 22:
                return self.bad_record(pos, end, stop, f"message record too short ({end - body} bytes)")
            cid, _s, lt, _p = _MSG_HDR.unpack_from(data, body)
            if cid not in self.res.channels:
                if end - body >= 40 and self.disguised_chunk(pos, op, body, end):
                    return end
                return self.bad_record(pos, end, stop, f"message record on channel id {cid}, which no channel record "
                                                       f"defines before it")
            for col, v in zip(self.loose, (cid, lt, body + 22, end - body - 22)):
                col.append(v)
            return end
        if op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.HEADER, Opcode.ATTACHMENT, Opcode.METADATA):
            cls = {Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel, Opcode.HEADER: Header, Opcode.ATTACHMENT: Attachment,
                   Opcode.METADATA: Metadata}[op]
            try:
                rec = _parse(cls, data[body:end])
            except Exception as exc:  # noqa: BLE001 - a record that does not parse is skipped and reported
                return self.bad_record(pos, end, stop, f"{_opname(op)} record does not parse ({type(exc).__name__}: {exc})")
            if op == Opcode.HEADER:
                if pos == 8:  # a header anywhere else is not the file's
                    res.header = rec
            elif op in (Opcode.SCHEMA, Opcode.CHANNEL):
                (res.schemas if op == Opcode.SCHEMA else res.channels).setdefault(rec.id, rec)
        return end

    def bad_record(self, pos: int, end: int, stop: int, reason: str, chunk: bool = False) -> int:
        """A framed record that failed: go on after it when what follows looks like a record,
        else resynchronise from the next byte."""
        if self._plausible(end, stop):
            msgs, cids = self.loss_of_chunk(pos, end, stop) if chunk else (None, ())
            self.res.damage.append(Damage(pos, reason, msgs, cids))
            self.done.add(pos)
            return end
        return self.damaged(pos, reason + "; its record length is not trustworthy", stop)

    def jumps_over_chunk(self, pos: int, end: int) -> int | None:
        """The offset of a chunk of the summary's index not yet read that ``(pos, end)`` would
        pass over (a damaged record length), or None."""
        if not self.targets:
            return None
        i = bisect.bisect_right(self.targets, pos)
        while i < len(self.targets) and self.targets[i] < end:
            if self.targets[i] not in self.done:
                return self.targets[i]
            i += 1
        return None

    def summary_follows(self, p: int) -> bool:
        """Whether what lies at `p` may follow a data end record: anything but a well-framed
        data section record (a chunk, message, message index, attachment or metadata), which
        would mean that the data end record is a damaged one inside the data section."""
        if p + 9 > self.n:
            return True
        op, length = _REC_HDR.unpack_from(self.data, p)
        return op not in _DATA_OPS or p + 9 + length > self.n

    def disguised_chunk(self, pos: int, op: int, body: int, end: int) -> bool:
        """A record whose opcode is damaged but whose body is exactly a valid chunk (framing that
        fits its length, decompression to the stated size, a matching CRC-32): read as the chunk."""
        data = self.data
        (clen,) = struct.unpack_from("<I", data, body + 28)
        if clen > 4 or body + 40 + clen > end or bytes(data[body + 32 : body + 32 + clen]) not in _COMPRESSIONS:
            return False
        (dlen,) = struct.unpack_from("<Q", data, body + 32 + clen)
        (crc,) = struct.unpack_from("<I", data, body + 24)
        if body + 40 + clen + dlen != end or (crc == 0 and clen == 0) or not self.validate_crcs:
            return False
        try:
            opened = self.open_chunk(body, end)
        except Exception as exc:  # noqa: BLE001 - framed like a chunk, but damaged
            msgs, cids = self.loss_of_chunk(pos, end, self.n)
            self.res.damage.append(Damage(pos, f"record with a damaged opcode ({_opname(op)}) framed like a chunk, "
                                               f"chunk skipped: {type(exc).__name__}: {exc}", msgs, cids))
            self.done.add(pos)
            return True
        self.take(pos, opened, end)
        self.res.warnings.append(f"{self.res.path}: record at byte offset {pos} has a damaged opcode ({_opname(op)}) "
                                 f"but holds a valid chunk (its CRC-32 checked): read as the chunk")
        return True

    def chunk_fit(self, body: int, end: int) -> int:
        """Where a chunk record's own fields end (its compression name and data lengths)."""
        (clen,) = struct.unpack_from("<I", self.data, body + 28)
        (dlen,) = struct.unpack_from("<Q", self.data, body + 32 + clen)
        return body + 40 + clen + dlen

    def _plausible(self, p: int, stop: int, depth: int = 2) -> bool:
        """Whether `depth` well-framed records (valid opcodes, lengths inside the file) start at `p`."""
        if p == stop or depth == 0:
            return True
        if p + 9 > stop:
            return False
        op, length = _REC_HDR.unpack_from(self.data, p)
        return _valid_opcode(op) and p + 9 + length <= stop and self._plausible(p + 9 + length, stop, depth - 1)

    def after_chunk(self, pos: int, end: int, stop: int) -> int:
        """Where to go on after a chunk read: past its message indexes when seeking by the index."""
        ci = self.index.get(pos)
        if self.seek and ci is not None:
            nxt = end + ci.message_index_length
            if end <= nxt <= stop and self._plausible(nxt, stop):
                return nxt
        return end

    # -- chunks -----------------------------------------------------------------------------
    def open_chunk(self, body: int, end: int) -> tuple[Any, list, tuple[np.ndarray, ...], dict]:
        """Decompress, check (size, CRC-32) and index the chunk record ``[body - 9, end)``; decode
        the fields of :attr:`plan` (runs on the threads).

        Returns (bytes or None, Schema/Channel records, index arrays, decoded): the bytes are
        None when they were decompressed into this thread's reused buffer and every message that
        may be wanted later was decoded (:class:`Block` gets them back on use), else a copy.
        """
        chunk = _read_chunk(self.mview, body, end)
        check_chunk_size(chunk, self.max_chunk)
        raw = _decompress_into(chunk) if self.plan else None
        scratch = raw is not None
        if scratch and self.validate_crcs and chunk.uncompressed_crc != 0 and _crc32(raw) != chunk.uncompressed_crc:
            scratch, raw = False, None  # damaged: the usual path below names the fault
        if raw is None:
            raw = _checked(chunk, self.validate_crcs)
        recs: list = []
        idx = _index_messages(raw, 0, len(raw), recs, self.fast)
        decoded, present = self.decode(raw, idx[0], idx[2], idx[3]) if self.plan else ({}, ())
        if scratch:  # the bytes are kept (copied out of the reused buffer) while a wanted message is not decoded
            keep = any(c not in decoded and c not in self.unwanted for c in present)
            raw = bytes(raw) if keep else None
        return raw, recs, idx, decoded

    def decode(self, raw: Any, cid: np.ndarray, st: np.ndarray, ln: np.ndarray) -> tuple[dict, list[int]]:
        """({channel id: (type, stamps, {field: values})} of the :attr:`plan` channels in one chunk
        whose every message fits the fixed layout (copies, not views of `raw`), the channel ids
        present)."""
        out: dict = {}
        if not cid.size:
            return out, []
        lo, hi = int(cid.min()), int(cid.max())
        present = [lo] if lo == hi else np.unique(cid).tolist()
        for c in present:
            got = self.plan.get(c)
            if got is None:
                continue
            tname, names = got
            idx = np.flatnonzero(cid == c) if len(present) > 1 else None
            s, n = (st, ln) if idx is None else (st[idx], ln[idx])
            vals = _ros2.decode_block(raw, s, n, tname, names)
            if vals is None:
                continue
            out[c] = (tname, np.array(vals[0], np.int64), {nm: np.array(v) for nm, v in zip(names, vals[1])})
        return out, present

    def chunk(self, pos: int, body: int, end: int) -> str | None:
        """Decompress, check and index one chunk; returns why it failed, or None."""
        try:
            opened = self.opened.pop(pos, None)
            if opened is None:
                self.prefetch(pos, self.summary.start if self.summary is not None else self.n)
                fut = self.pending.pop((body, end), None)
                if fut is None:
                    self.frontier = 0
                opened = fut.result() if fut is not None else self.open_chunk(body, end)
        except Exception as exc:  # noqa: BLE001 - any failure skips this chunk only
            return f"{type(exc).__name__}: {exc}"
        self.take(pos, opened, end)
        return None

    def take(self, pos: int, opened: tuple, end: int) -> None:
        """Keep the messages of a chunk that validated; a chunk holding fewer messages than its
        message indexes (or the summary's chunk index) list is reported as damaged."""
        raw, recs, (cid, lt, st, ln), decoded = opened
        self.done.add(pos)
        self.last_good = max(self.last_good, pos + 1)
        for r in recs:
            (self.res.schemas if isinstance(r, Schema) else self.res.channels)[r.id] = r
        if cid.size:
            reopen = None if raw is not None else partial(_reopen_chunk, self.mview, self.res.path, pos, end,
                                                          self.validate_crcs)
            self.res.blocks.append(Block(raw, pos, cid, lt, st, ln, decoded, reopen))
        listed, cids = self.loss_of_chunk(pos, end, self.n)
        if listed is not None and listed > cid.size:
            self.res.damage.append(Damage(pos, f"chunk holds {cid.size} messages where its message indexes list "
                                               f"{listed}: damaged", listed - int(cid.size), cids))

    def indexed_chunk(self, pos: int, stop: int) -> int | None:
        """A chunk the summary's index lists at `pos`: passed over when not wanted, read through
        the index when its record header is damaged; None to read it as any record."""
        ci = self.index[pos]
        end = pos + ci.chunk_length
        if end > stop:
            return None
        if pos in self.skip_chunks:
            self.res.chunks_skipped_by_index += 1
            self.done.add(pos)
            return end
        op, length = _REC_HDR.unpack_from(self.data, pos)
        if op == Opcode.CHUNK and length == ci.chunk_length - 9:
            return None
        try:
            chunk = _read_chunk(self.mview, pos + 9, end)
            if (chunk.compression != ci.compression or len(chunk.data) != ci.compressed_size
                    or chunk.uncompressed_size != ci.uncompressed_size or chunk.uncompressed_crc == 0
                    or pos + 9 + 40 + len(chunk.compression) + len(chunk.data) != end):
                return None  # the body does not agree with the index (or has no CRC to prove it)
            opened = self.open_chunk(pos + 9, end)
        except Exception:  # noqa: BLE001 - not recoverable: reported as damage by the walk
            return None
        self.take(pos, opened, end)
        self.res.recovered += 1
        self.res.warnings.append(
            f"{self.res.path}: chunk record header at byte offset {pos} damaged ({_opname(op)}, length {length}); "
            f"the chunk was read through the summary's chunk index and its CRC-32 checked"
        )
        return self.after_chunk(pos, end, stop)

    def loss_of_chunk(self, pos: int, end: int | None, stop: int) -> tuple[int | None, tuple[int, ...]]:
        """Messages and channel ids lost with the chunk at `pos`: from the summary's chunk index
        when it lists the chunk, else from the message index records that follow it."""
        data, n = self.data, self.n
        ci = self.index.get(pos)
        if ci is not None and ci.message_index_offsets:
            total: int | None = 0
            for cid, off in ci.message_index_offsets.items():
                ok = off + 15 <= n and data[off] == Opcode.MESSAGE_INDEX
                if ok:
                    (length,) = struct.unpack_from("<Q", data, off + 1)
                    c, rl = struct.unpack_from("<HI", data, off + 9)
                    ok = c == cid and 6 + rl <= length and off + 9 + length <= n
                if not ok or total is None:
                    total = None
                else:
                    total += rl // 16
            return total, tuple(sorted(ci.message_index_offsets))
        if end is None:
            return None, ()
        total, cids, p = 0, [], end
        while p + 15 <= stop and data[p] == Opcode.MESSAGE_INDEX:
            (length,) = struct.unpack_from("<Q", data, p + 1)
            if p + 9 + length > stop or length < 6:
                break
            c, rl = struct.unpack_from("<HI", data, p + 9)
            if rl % 16 or 6 + rl > length:
                break
            total += rl // 16
            cids.append(c)
            p += 9 + length
        return (total, tuple(sorted(set(cids)))) if cids else (None, ())

    # -- damage and resynchronisation -------------------------------------------------------
    def damaged(self, pos: int, problem: str, stop: int) -> int:
        """Report the damaged record at `pos`, find where to resume, report the chunks lost in
        between; returns the offset to resume at.

        A valid chunk between the last chunk read and `pos` means that a damaged record length
        (one that still looked well framed) led the walk into it: the scan goes back to it, and
        the messages outside chunks taken from those bytes are dropped."""
        back = self.search_chunk(self.last_good, pos, stop) if self.search and self.last_good < pos else None
        if back is not None:
            keep = [i for i, st in enumerate(self.loose[2]) if st < back]
            for col in self.loose:
                col[:] = [col[i] for i in keep]
            self.res.damage.append(Damage(pos, f"damaged record: {problem}; resumed back at byte offset {back} (a "
                                               f"valid chunk that a damaged record length had passed over)"))
            return back
        nxt = self.resync(pos + 1, stop)
        if nxt >= self.n:
            tail = f"{nxt - pos} bytes to the end of the file passed over"
        elif nxt == stop and (self.summary is None or nxt != self.summary.start) and nxt not in self.index:
            tail = f"{nxt - pos} bytes passed over up to byte offset {nxt}"
        else:
            what = "the summary section" if self.summary is not None and nxt == self.summary.start else "a valid chunk"
            tail = f"{nxt - pos} bytes passed over; resumed at byte offset {nxt} ({what})"
        lost = [o for o in self.targets if o not in self.done and (pos <= o < nxt or o < pos < o + self.index[o].chunk_length)]
        msgs, cids = (None, ())
        if pos in lost:
            msgs, cids = self.loss_of_chunk(pos, None, stop)
        elif not lost and not self.index:
            msgs, cids = self.trailing_indexes(pos, nxt)
        self.res.damage.append(Damage(pos, f"damaged record: {problem}; {tail}", msgs, cids))
        for o in lost:
            self.done.add(o)
            if o != pos:
                m, c = self.loss_of_chunk(o, None, stop)
                self.res.damage.append(Damage(o, "chunk lost in the damaged bytes", m, c))
        return nxt

    def trailing_indexes(self, a: int, b: int) -> tuple[int | None, tuple[int, ...]]:
        """Messages and channel ids listed by a run of intact message index records that ends
        exactly at `b` inside the damaged bytes ``[a, b)`` (those of the chunk lost there), or
        (None, ()) when there is no such run."""
        data, find = self.data, self.data.find
        q = find(b"\x07", a + 1, b)
        while 0 <= q < b:
            p, total, cids = q, 0, []
            while p + 15 <= b and data[p] == Opcode.MESSAGE_INDEX:
                (length,) = struct.unpack_from("<Q", data, p + 1)
                c, rl = struct.unpack_from("<HI", data, p + 9)
                if length < 6 or rl % 16 or 6 + rl > length or p + 9 + length > b:
                    break
                total += rl // 16
                cids.append(c)
                p += 9 + length
            if p == b and cids:
                return total, tuple(sorted(set(cids)))
            q = find(b"\x07", q + 1, b)
        return None, ()

    def resync(self, p: int, stop: int) -> int:
        """The next offset in ``[p, stop]`` to resume at: the next chunk offset of the summary's
        index, or an earlier offset where a valid chunk record lies."""
        i = bisect.bisect_left(self.targets, p)
        t = stop
        while i < len(self.targets):
            if self.targets[i] < stop and self.targets[i] not in self.done:
                t = self.targets[i]
                break
            i += 1
        if self.search:
            q = self.search_chunk(p, t)
            if q is not None:
                return q
        return t

    def search_chunk(self, p: int, t: int, limit: int | None = None) -> int | None:
        """The first offset in ``[p, t)`` where a whole, valid chunk record lies (it parses,
        decompresses to its stated size and matches its CRC-32) ending by `limit` (default
        `t`), or None."""
        limit = t if limit is None else limit
        data, find = self.data, self.data.find
        unpack_q, unpack_i = struct.Struct("<Q").unpack_from, struct.Struct("<I").unpack_from
        while True:
            q = find(b"\x06", p, t)
            if q < 0:
                return None
            p = q + 1
            if q in self.done:
                continue
            if q + 9 + 40 > limit:
                return None
            (length,) = unpack_q(data, q + 1)
            end = q + 9 + length
            if end > limit or length < 40:
                continue
            (clen,) = unpack_i(data, q + 9 + 28)  # after start/end time, sizes and CRC
            if clen > 4 or q + 9 + 40 + clen > end:
                continue
            if bytes(data[q + 41 : q + 41 + clen]) not in _COMPRESSIONS:
                continue
            (dlen,) = unpack_q(data, q + 41 + clen)
            if q + 9 + 40 + clen + dlen != end:
                continue
            try:
                self.opened[q] = self.open_chunk(q + 9, end)
            except Exception:  # noqa: BLE001 - not a valid chunk: keep looking
                continue
            return q

    # -- the rest ---------------------------------------------------------------------------
    def data_end(self, pos: int, body: int, length: int) -> None:
        """Check the data section CRC, when the writer stored one."""
        stored = struct.unpack_from("<I", self.data, body)[0] if length >= 4 else 0
        if self.validate_crcs and stored != 0:
            ahead = self.data_crc.pop(pos, None)  # computed on a thread while the chunks were read
            crc = ahead.result() if ahead is not None else _crc32(memoryview(self.data)[:pos])
            if crc != stored:
                self.res.warnings.append(
                    f"{self.res.path}: data section CRC-32 mismatch (stored {stored:#010x}, computed {crc:#010x}; "
                    f"data section ends at byte offset {pos})"
                )

    def loose_block(self) -> Block | None:
        """The messages found outside chunks, as one block over the whole file."""
        if not self.loose[0]:
            return None
        c, lt, st, ln = self.loose
        return Block(self.data, -1, np.array(c, np.uint16), np.array(lt, np.uint64), np.array(st, np.int64),
                     np.array(ln, np.int64))


def _with_loss(d: Damage, sc: "_Scanner") -> Damage:
    """`d` with its messages per channel and its log time range, where the chunk index of the
    summary (``sc.index`` or the lost chunks) or the intact chunk record header at its offset
    says them."""
    if d.messages is None or d.per_channel or not d.channel_ids:
        return d
    ci = sc.index.get(d.offset)
    per: tuple[tuple[int, int], ...] = ()
    span = None
    if ci is not None:
        counts = index_counts(ci)
        if counts is not None and sum(counts.values()) == d.messages:
            per = tuple(sorted(counts.items()))
        span = (int(ci.message_start_time), int(ci.message_end_time))
    elif d.offset + 9 + 24 <= sc.n and sc.data[d.offset] == Opcode.CHUNK:
        a, b = struct.unpack_from("<QQ", sc.data, d.offset + 9)
        lo = min((int(b_.log_time.min()) for b_ in sc.res.blocks if b_.n), default=None)
        hi = max((int(b_.log_time.max()) for b_ in sc.res.blocks if b_.n), default=None)
        if lo is not None and a <= b and lo - (hi - lo) <= a and b <= hi + (hi - lo):
            span = (int(a), int(b))  # a record header in the time range of the log: believed
    if not per and len(d.channel_ids) == 1:
        per = ((d.channel_ids[0], d.messages),)
    return replace(d, per_channel=per, span_ns=span)


def scan(
    path: str | Path,
    *,
    validate_crcs: bool = True,
    progress: bool = False,
    topics: Any = None,
    mode: Literal["auto", "stream", "indexed"] = "auto",
    fast: bool = True,
    workers: int | None = None,
    fields: Any = None,
    max_memory: int | None = None,
) -> ScanResult:
    """Scan an MCAP file record by record, recovering after damage.

    Parameters
    ----------
    path : str or Path
        The MCAP file.
    validate_crcs : bool, optional
        Check every chunk's CRC-32 of its uncompressed data (and the data section CRC).
    progress : bool, optional
        Show a tqdm bar over the bytes of the file.
    topics : set of str, optional
        Only these topics are wanted: when the summary section validates, a chunk whose
        message indexes list only channels known from the summary, none of them on a wanted
        topic, is passed over undecompressed (``ScanResult.chunks_skipped_by_index``). A
        damaged or missing summary falls back to decoding every chunk. Not used with
        ``mode="stream"``.
    mode : {"auto", "stream", "indexed"}, optional
        The reading path. ``"stream"``: one linear pass over the records, never looking at
        the summary; resynchronisation after damage by searching for the next valid chunk
        record. ``"indexed"``: chunks located through the summary's chunk indexes (each read
        at its offset, its message indexes passed over by their stated length), the records
        between chunks still read; when the summary is missing or does not validate, the
        linear pass with a note in ``ScanResult.warnings``. ``"auto"`` (default): the linear
        pass, using a valid summary for its channels, the `topics` filter and recovery
        (resuming at its next chunk offset, reading a chunk with a damaged record header
        through its index), and searching for the next valid chunk record as well.
    fast : bool, optional
        Index runs of equal-length message records with numpy (default); False indexes every
        record one by one (the same result, slower: for tests).
    workers : int, optional
        Threads that open (decompress, CRC-check, index) the chunks ahead of the walk; default
        the machine's cores (at most 8); 1 opens each chunk in turn (the same result).
    fields : mapping of str to sequence of str, optional
        Topic -> field names (``"linear_acceleration.x"``, ``"header.stamp.sec"``) that the
        threads decode right after decompressing each chunk, for channels the valid summary
        knows whose messages are CDR of a fixed-layout type
        (:data:`vibroscope.io._ros2.FLOAT_FIELDS`): ``Block.decoded``. Default: the entries of
        `topics` that extend a topic by such a field path (``"/imu.linear_acceleration.x"``,
        as :func:`~vibroscope.io.read_mcap` passes them). When every message of a chunk that
        may be wanted later (of a `topics` topic) was decoded, the chunk is decompressed into
        a buffer reused from chunk to chunk and its bytes are not kept (``Block.buf``
        decompresses it again on use); the result is otherwise the same.
    max_memory : int, optional
        Memory budget in bytes (default :func:`memory_budget`): a chunk whose stated
        uncompressed size exceeds the share of one thread (``max_memory / (workers + 1)``),
        or :data:`MAX_RATIO` times its compressed size, is skipped and reported before anything
        is allocated for it (:func:`check_chunk_size`); decompression never produces more than
        the stated size.

    Returns
    -------
    ScanResult
        Schemas, channels, indexed message blocks (chunks in file order, then the messages
        outside chunks), and the damage: ``damage`` (:class:`Damage` entries) and
        ``skipped`` (byte offset, reason with topics and ``"(N messages lost)"`` when known).

    Raises
    ------
    LogFormatError
        If the file cannot be opened, is empty, does not start with the MCAP magic, or
        holds no readable message and no intact header record (names the byte offset).
    ValueError
        If `mode` is not one of the three.
    """
    if mode not in MODES:
        raise ValueError(f"{mode=} must be one of {MODES}")
    path = Path(path)
    data = _open(path)
    n = len(data)
    res = ScanResult(path=path, file_size=n, mode=mode)
    if n == 0:
        raise LogFormatError(f"{path}: empty file (0 bytes; no MCAP magic at byte offset 0)")
    if bytes(data[:8]) != MAGIC:
        raise LogFormatError(f"{path}: not an MCAP file (bad magic at byte offset 0)")
    if n == 8:
        raise LogFormatError(f"{path}: only the MCAP magic: the file ends at byte offset 8, before the header record")
    summary, why = (None, None) if mode == "stream" else _read_summary(data, n)
    if why is not None:
        res.warnings.append(f"{path}: {why}; the summary is not used")
    if summary is not None and summary.note is not None:
        res.warnings.append(f"{path}: {summary.note}")
    if mode == "indexed" and summary is None:
        res.warnings.append(f"{path}: no valid summary section to read by its chunk indexes; read by a linear pass")
    skip: set[int] = set()
    unwanted: set[int] = set()  # channels of the summary on no wanted topic
    if summary is not None:
        res.indexed = True
        res.schemas.update(summary.schemas)
        res.channels.update(summary.channels)
        if topics is not None:
            wanted = {cid for cid, ch in summary.channels.items() if ch.topic in topics}
            unwanted = set(summary.channels) - wanted
            for off, ci in summary.chunks.items():
                ids = set(ci.message_index_offsets)
                if ids and ids <= summary.channels.keys() and not ids & wanted:
                    skip.add(off)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, unit="B", unit_scale=True, desc=path.name)
    stop = summary.start if summary is not None else n
    sc = _Scanner(res, data, validate_crcs=validate_crcs, fast=fast, summary=summary, skip_chunks=skip,
                  search=mode != "indexed" or summary is None or not summary.chunks, seek=mode == "indexed", bar=bar,
                  plan=_decode_plan(summary, topics, fields), unwanted=unwanted)
    sc.start_pool(min(os.cpu_count() or 1, _MAX_WORKERS) if workers is None else workers, max_memory)
    try:
        sc.crc_ahead()
        if n >= 8 + 9:
            op = data[8]
            if op != Opcode.HEADER:
                res.warnings.append(f"{path}: header record damaged at byte offset 8 (found {_opname(op)}); "
                                    f"the rest of the file is read")
        sc.walk(8, stop)
    finally:
        sc.close_pool()
        for k in ("buf", "walk"):  # this thread's reused buffers (the pool's went with its threads)
            _LOCAL.__dict__.pop(k, None)
        if bar is not None:
            bar.update(max(0, n - bar.n))  # the summary and anything passed over
            bar.close()
    loose = sc.loose_block()
    if loose is not None:
        res.blocks.append(loose)
    res.complete = n >= 8 + _FOOTER_LEN + 8 and bytes(data[n - 8 :]) == MAGIC and data[n - 8 - _FOOTER_LEN] == Opcode.FOOTER
    reported = {d.offset for d in res.damage}
    for ci in summary.lost if summary is not None else ():
        if ci.chunk_start_offset in reported or ci.chunk_start_offset - summary.shift in reported:
            continue  # its place was reported damaged by the walk (with the loss its message indexes list)
        counts = index_counts(ci)
        res.damage.append(Damage(
            ci.chunk_start_offset, f"chunk of {ci.chunk_length} bytes listed by the summary's chunk index (at this "
            f"stated byte offset) is not in the file (deleted?)", sum(counts.values()) if counts is not None else None,
            tuple(sorted(ci.message_index_offsets)), tuple(sorted(counts.items())) if counts is not None else (),
            (int(ci.message_start_time), int(ci.message_end_time))))
    if summary is not None and summary.message_count is not None and topics is None and not res.damage:
        got = sum(b.n for b in res.blocks)
        if got < summary.message_count:  # a loss no damaged place explains: reported all the same
            res.damage.append(Damage(summary.start, f"the summary's statistics (section at this byte offset) count "
                                                    f"{summary.message_count} messages, {got} were found",
                                     summary.message_count - got))
    res.damage = [_with_loss(d, sc) for d in res.damage]
    res.damage.sort(key=lambda d: d.offset)
    res.skipped.extend((d.offset, d.describe(res.channels)) for d in res.damage)
    if res.header is None and not any("header record damaged" in w for w in res.warnings):
        res.warnings.append(f"{path}: no intact header record at byte offset 8")
    if not res.blocks and not res.chunks_skipped_by_index and (res.header is None or res.skipped):
        off = res.skipped[0][0] if res.skipped else 8
        raise LogFormatError(f"{path}: nothing readable (damaged at byte offset {off})")
    if not res.complete and not res.skipped:
        res.skipped.append((n, "file ends without a footer (log not closed?)"))
    return res
