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

The parts, one module each: the record framing (:mod:`vibroscope.io._records`), the summary
section (:mod:`vibroscope.io._summary`), chunks opened (:mod:`vibroscope.io._chunks`), message
records indexed as arrays (:mod:`vibroscope.io._index_kernels`), the walk that resynchronises
after damage (:mod:`vibroscope.io._walk`) and the result types (:mod:`vibroscope.io._scan_result`);
this module opens the file and drives them.
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path
from typing import Any, Literal

from mcap.opcode import Opcode

from vibroscope.errors import LogFormatError
from vibroscope.io import _ros2
from vibroscope.io._chunks import (  # noqa: F401 - re-exported: the names callers import from here
    MAX_RATIO,
    RATIO_SLACK,
    check_chunk_size,
    memory_budget,
    release_scratch,
)
from vibroscope.io._index_kernels import release_work
from vibroscope.io._records import FOOTER_LEN, MAGIC, opname
from vibroscope.io._scan_result import Block, Damage, ScanResult  # noqa: F401 - re-exported
from vibroscope.io._summary import Summary, index_counts, read_summary
from vibroscope.io._walk import Scanner, with_loss

from mcap.records import Schema  # noqa: E402,F401 - io/blocks.py builds a ScanResult of these

MODES = ("auto", "stream", "indexed")
_MAX_WORKERS = 8


def _open(path: Path) -> Any:
    """The file's bytes: a read-only map (chunk data and loose payloads are sliced without copying)."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
    except (OSError, ValueError) as exc:
        raise LogFormatError(f"{path}: cannot read ({exc})") from exc


def _decode_plan(summary: Summary | None, topics: Any, fields: Any) -> dict[int, tuple[str, tuple[str, ...]]]:
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
    summary, why = (None, None) if mode == "stream" else read_summary(data, n)
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
    sc = Scanner(res, data, validate_crcs=validate_crcs, fast=fast, summary=summary, skip_chunks=skip,
                  search=mode != "indexed" or summary is None or not summary.chunks, seek=mode == "indexed", bar=bar,
                  plan=_decode_plan(summary, topics, fields), unwanted=unwanted)
    sc.start_pool(min(os.cpu_count() or 1, _MAX_WORKERS) if workers is None else workers, max_memory)
    try:
        sc.crc_ahead()
        if n >= 8 + 9:
            op = data[8]
            if op != Opcode.HEADER:
                res.warnings.append(f"{path}: header record damaged at byte offset 8 (found {opname(op)}); "
                                    f"the rest of the file is read")
        sc.walk(8, stop)
    finally:
        sc.close_pool()
        release_scratch()  # this thread's reused buffers (the pool's went with its threads)
        release_work()
        if bar is not None:
            bar.update(max(0, n - bar.n))  # the summary and anything passed over
            bar.close()
    loose = sc.loose_block()
    if loose is not None:
        res.blocks.append(loose)
    res.complete = n >= 8 + FOOTER_LEN + 8 and bytes(data[n - 8 :]) == MAGIC and data[n - 8 - FOOTER_LEN] == Opcode.FOOTER
    reported = {d.offset for d in res.damage}
    for ci in summary.lost if summary is not None else ():
        if ci.chunk_start_offset in reported or ci.chunk_start_offset - summary.shift in reported:
            continue  # its place was reported damaged by the walk (with the loss its message indexes list)
        counts = index_counts(ci)
        res.damage.append(Damage(
            offset=ci.chunk_start_offset,
            reason=f"chunk of {ci.chunk_length} bytes listed by the summary's chunk index (at this "
            f"stated byte offset) is not in the file (deleted?)",
            messages=sum(counts.values()) if counts is not None else None,
            channel_ids=tuple(sorted(ci.message_index_offsets)),
            per_channel=tuple(sorted(counts.items())) if counts is not None else (),
            span_ns=(int(ci.message_start_time), int(ci.message_end_time))))
    if summary is not None and summary.message_count is not None and topics is None and not res.damage:
        got = sum(b.n for b in res.blocks)
        if got < summary.message_count:  # a loss no damaged place explains: reported all the same
            res.damage.append(Damage(offset=summary.start,
                                     reason=f"the summary's statistics (section at this byte offset) count "
                                     f"{summary.message_count} messages, {got} were found",
                                     messages=summary.message_count - got))
    res.damage = [with_loss(d, sc) for d in res.damage]
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
