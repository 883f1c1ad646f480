"""The MCAP summary section, read defensively: located and validated through the footer
(:func:`locate_summary`, the one check every reader of the package uses), parsed record by record
(:func:`parse_summary`; chunk indexes with ``struct``, :func:`chunk_index`), found again when bytes
before it were deleted (:func:`relocated_summary`), and the message counts its chunk indexes imply
(:func:`index_counts`)."""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, Callable

from mcap.opcode import Opcode
from mcap.records import Channel, ChunkIndex, Schema, Statistics

from vibroscope.io._records import FOOTER_LEN, MAGIC, REC_HDR, opname, parse_record, valid_opcode


@dataclass(kw_only=True)
class Summary:
    """A summary section that validated: its start offset, schemas, channels, chunk indexes by
    chunk offset, the statistics' message count (None without one), and, when it was found again
    after deleted bytes (:func:`relocated_summary`), the chunk indexes of chunks not in the file,
    a note and the shift."""

    start: int
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    chunks: dict[int, ChunkIndex]
    message_count: int | None
    lost: list[ChunkIndex] = field(default_factory=list)  # chunk indexes of chunks not in the file
    note: str | None = None  # how the summary was found, when not where the footer says
    shift: int = 0  # bytes the footer's summary start (and chunk offsets after a deletion) point too far


def locate_summary(read: Callable[[int, int], Any], size: int) -> tuple[tuple[int, int, int] | None, str | None]:
    """Where the footer says the summary section lies, and whether it validates there.

    The one summary check of the package: :func:`read_summary` (the scan, on a mapped file) and
    :mod:`vibroscope.io.blocks` (the block reader, with ``pread``) both use it. The section
    validates when the file ends in the MCAP magic after a footer record, the footer's summary
    start lies in ``[8, footer offset]``, and the bytes from it to the footer's CRC field match
    the footer's CRC-32 (when one is stored, i.e. not 0).

    Parameters
    ----------
    read : callable
        ``read(offset, n)`` gives the `n` bytes of the file at byte `offset` (bytes-like; called
        only with ranges inside the file).
    size : int
        Size of the file in bytes.

    Returns
    -------
    place : (int, int, int) or None
        (summary start, footer record offset, stored CRC-32) as the footer states them; None
        when the file has no summary (no closing magic, or a summary start of 0) or no footer
        record before its closing magic.
    why : str or None
        Why the summary is not used (no footer record, a start outside the file, a CRC-32
        mismatch, naming the byte offset); None when it validates or the file has none.
    """
    if size < 8 + FOOTER_LEN + 8 or bytes(read(size - 8, 8)) != MAGIC:
        return None, None
    fpos = size - 8 - FOOTER_LEN
    foot = read(fpos, FOOTER_LEN)
    op, length = REC_HDR.unpack_from(foot, 0)
    if op != Opcode.FOOTER or length != 20:
        return None, f"no footer record at byte offset {fpos} (found {opname(op)}, length {length})"
    summary_start, _sos, summary_crc = struct.unpack_from("<QQI", foot, 9)
    if summary_start == 0:
        return None, None
    place = (summary_start, fpos, summary_crc)
    if not 8 <= summary_start <= fpos:
        return place, f"the footer's summary start {summary_start} lies outside the file"
    if summary_crc != 0:
        crc = zlib.crc32(read(summary_start, fpos + 9 + 16 - summary_start))
        if crc != summary_crc:
            return place, (f"summary section at byte offset {summary_start} fails its CRC-32 "
                           f"(stored {summary_crc:#010x}, computed {crc:#010x})")
    return place, None


def read_summary(data: Any, n: int) -> tuple[Summary | None, str | None]:
    """The summary section, or None and why not (None, None: the file has none).

    Every record is parsed defensively: a summary that does not parse, lies outside the file,
    fails its CRC-32, or (without a CRC) has a chunk index not pointing at a chunk opcode is
    not used. A summary whose stated start is wrong because bytes before it were deleted
    (a lost chunk) is found again (:func:`relocated_summary`).
    """
    mv = memoryview(data)
    place, why = locate_summary(lambda off, k: mv[off : off + k], n)
    if place is None:
        return None, why
    summary_start, fpos, summary_crc = place
    if why is not None:
        moved = relocated_summary(data, fpos, summary_start, summary_crc)
        return (moved, None) if moved is not None else (None, why)
    return parse_summary(data, summary_start, fpos, summary_crc)


_DATA_END_HEAD = bytes([Opcode.DATA_END]) + struct.pack("<Q", 4)
_MAX_CHUNK_SEARCHES = 256  # chunk indexes looked for byte by byte when neither offset holds their chunk


def relocated_summary(data: Any, fpos: int, stated: int, crc: int) -> Summary | None:
    """The summary section found where it lies when bytes before it were deleted, or None.

    The footer's summary start then points `shift` bytes too far. The section is looked for
    right after a Data End record (where writers put it) and proven by the footer's CRC-32,
    or without one by parsing to the footer with more than half of its chunk indexes matching
    chunk records. Its chunk indexes are then matched to the chunk
    records of the file (:func:`place_chunks`): at their stated offset (before the deleted
    bytes), `shift` bytes earlier (after them), or where a chunk record with the same length,
    log time range and uncompressed size lies; a chunk index matching no chunk record lists
    a chunk that is not in the file (``Summary.lost``).
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
        summary, _why = parse_summary(data, start, fpos, crc, placed=False)
        if summary is None:
            continue
        shift = stated - start
        chunks, lost, moved = place_chunks(data, summary.chunks, shift, start)
        if crc == 0 and len(chunks) <= len(lost):  # no CRC to prove it: most chunk indexes must match
            continue
        summary.chunks, summary.lost, summary.shift = chunks, lost, shift
        summary.note = (f"the footer's summary start {stated} is wrong by {shift:+d} bytes (bytes deleted before "
                        f"it?); the summary section found at byte offset {start} ({'its CRC-32 checked' if crc else 'no CRC-32'}) is used: "
                        f"{len(chunks)} of its {len(chunks) + len(lost)} chunk indexes match chunk records "
                        f"({moved} shifted); {len(lost)} list{'s a chunk' if len(lost) == 1 else ' chunks'} no longer in the file")
        return summary
    return None


def chunk_signature(ci: ChunkIndex) -> bytes:
    """The first 33 bytes of the chunk record a chunk index lists: opcode, record length, log
    time range and uncompressed size."""
    return bytes([Opcode.CHUNK]) + struct.pack("<QQQQ", ci.chunk_length - 9, ci.message_start_time,
                                               ci.message_end_time, ci.uncompressed_size)


def place_chunks(data: Any, stated: dict[int, ChunkIndex], shift: int,
                  stop: int) -> tuple[dict[int, ChunkIndex], list[ChunkIndex], int]:
    """(chunk indexes by the offset where their chunk record lies, chunk indexes whose chunk is
    not in ``data[8:stop]``, how many were moved); see :func:`relocated_summary`."""
    placed: dict[int, ChunkIndex] = {}
    lost: list[ChunkIndex] = []
    moved = searches = 0
    for o, ci in sorted(stated.items()):
        sig = chunk_signature(ci)
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


def parse_summary(data: Any, summary_start: int, fpos: int, summary_crc: int,
                   placed: bool = True) -> tuple[Summary | None, str | None]:
    """The summary records in ``data[summary_start:fpos]``; `placed`: its chunk indexes must
    point into the data section (else they are matched to chunk records by the caller)."""
    schemas, channels, chunks, count = {}, {}, {}, None
    pos = summary_start
    while pos < fpos:
        if pos + 9 > fpos:
            return None, f"summary record header cut off at byte offset {pos}"
        op, length = REC_HDR.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        if end > fpos or not valid_opcode(op):
            return None, f"summary record at byte offset {pos} is damaged ({opname(op)}, length {length})"
        try:
            if op == Opcode.SCHEMA:
                sc = parse_record(Schema, data[body:end])
                schemas[sc.id] = sc
            elif op == Opcode.CHANNEL:
                ch = parse_record(Channel, data[body:end])
                channels[ch.id] = ch
            elif op == Opcode.CHUNK_INDEX:
                ci = chunk_index(data, body, end)
                o = ci.chunk_start_offset
                if placed and not (8 <= o and ci.chunk_length >= 9 and o + ci.chunk_length <= summary_start):
                    return None, f"chunk index at byte offset {pos} points outside the data section ({o})"
                if placed and summary_crc == 0 and data[o] != Opcode.CHUNK:
                    return None, f"chunk index at byte offset {pos} points at {opname(data[o])}, not a chunk ({o})"
                if not placed and ci.chunk_length < 9 + 40:
                    return None, f"chunk index at byte offset {pos} states a chunk length of {ci.chunk_length}"
                chunks[o] = ci
            elif op == Opcode.STATISTICS:
                count = parse_record(Statistics, data[body:end]).message_count
        except Exception as exc:  # noqa: BLE001 - any parse failure invalidates the summary
            return None, f"summary {opname(op)} record at byte offset {pos} does not parse ({type(exc).__name__}: {exc})"
        pos = end
    return Summary(start=summary_start, schemas=schemas, channels=channels, chunks=chunks, message_count=count), None


_CI_HEAD = struct.Struct("<QQQQI")
_CI_ENTRY = struct.Struct("<HQ")


def chunk_index(data: Any, body: int, end: int) -> ChunkIndex:
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
        return parse_record(ChunkIndex, data[body:end])
    return ChunkIndex(message_start_time=t0, message_end_time=t1, chunk_start_offset=off, chunk_length=length,
                      message_index_offsets=offsets, message_index_length=milen, compression=comp,
                      compressed_size=csize, uncompressed_size=usize)

