"""The resynchronising walk over the records of an MCAP data section (:class:`Scanner`): chunks
opened ahead of it on a pool of threads and taken in file order, damaged records reported with
their byte offset, the walk resumed at the next valid chunk (or the next chunk offset of a valid
summary), and the messages lost counted (:func:`with_loss`). :func:`vibroscope.io._scan.scan`
drives it; its module docstring states the rules."""

from __future__ import annotations

import bisect
import struct
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Header, Metadata, Schema

from vibroscope.io import _ros2
from vibroscope.io._chunks import (
    COMPRESSIONS,
    MAX_CHUNK_USIZE,
    check_chunk_size,
    checked,
    crc32,
    decompress_into,
    memory_budget,
    read_chunk,
    reopen_chunk,
)
from vibroscope.io._index_kernels import index_messages
from vibroscope.io._records import MSG_HDR, REC_HDR, opname, parse_record, valid_opcode
from vibroscope.io._scan_result import Block, Damage, ScanResult
from vibroscope.io._summary import Summary, index_counts

SUMMARY_ONLY_OPS = {Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX, Opcode.METADATA_INDEX, Opcode.STATISTICS,
                     Opcode.SUMMARY_OFFSET}
DATA_OPS = {Opcode.CHUNK, Opcode.MESSAGE, Opcode.MESSAGE_INDEX, Opcode.ATTACHMENT, Opcode.METADATA, Opcode.HEADER}


def fields_end(data: Any, op: int, body: int, end: int) -> int | None:
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


class Scanner:
    """Walks the records of the data section, filling a :class:`ScanResult`."""

    def __init__(self, res: ScanResult, data: Any, *, validate_crcs: bool, fast: bool, summary: Summary | None,
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
        self.max_chunk = MAX_CHUNK_USIZE  # bytes one chunk may take decompressed (start_pool sets the budget's share)

    # -- chunks opened ahead of the walk -----------------------------------------------------
    def start_pool(self, workers: int, max_memory: int | None = None) -> None:
        """Open chunks ahead of the walk on `workers` threads (decompression and CRC-32 release the GIL);
        each chunk may take decompressed at most the share of `max_memory` (bytes, default
        :func:`memory_budget`) of one of the ``workers + 1`` threads."""
        budget = memory_budget() if max_memory is None else int(max_memory)
        self.max_chunk = min(MAX_CHUNK_USIZE, budget // (max(workers, 1) + 1))
        if workers > 1:
            self.pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="vibroscope-mcap")
            self.window = 2 * workers + 2

    def crc_ahead(self) -> None:
        """Start the data section CRC-32 on a thread, for a data end record just before the summary
        (where writers put it); used only when the walk finds the data end record there."""
        s = self.summary
        if self.pool is not None and self.validate_crcs and s is not None and s.start >= 8 + 13:
            op, length = REC_HDR.unpack_from(self.data, s.start - 13)
            if op == Opcode.DATA_END and length == 4:
                self.data_crc[s.start - 13] = self.pool.submit(crc32, self.mview[: s.start - 13])

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
            op, length = REC_HDR.unpack_from(data, p)
            e = p + 9 + length
            if not valid_opcode(op) or e > stop:
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
                        self.res.damage.append(Damage(
                            offset=pos, reason=f"chunk record damaged (found {opname(data[pos])} where the summary's "
                            "chunk index lists a chunk)", messages=msgs, channel_ids=cids))
                        self.done.add(pos)
                        pos = end
                        continue
                    pos = self.damaged(pos, f"{opname(data[pos])} where the summary's chunk index lists a chunk", stop)
                    continue
            if pos + 9 > stop:
                pos = self.damaged(pos, f"{stop - pos} bytes left where a record header needs 9"
                                   + (" (file cut off?)" if stop == self.n else ""), stop)
                continue
            op, length = REC_HDR.unpack_from(data, pos)
            body, end = pos + 9, pos + 9 + length
            if not valid_opcode(op):
                if length >= 40 and end <= stop and self.disguised_chunk(pos, op, body, end):
                    self._progress(pos, end)
                    pos = end
                    continue
                pos = self.damaged(pos, f"invalid opcode 0x{op:02x} (record length {length})", stop)
                continue
            if end > stop:
                where = "cut off by the end of the file" if stop == self.n else f"running past byte offset {stop}"
                pos = self.damaged(pos, f"{opname(op)} record {where}: needs {length} bytes, {stop - body} left", stop)
                continue
            over = self.jumps_over_chunk(pos, end)
            if over is not None:
                pos = self.damaged(pos, f"{opname(op)} record of {length} bytes runs over the chunk the summary "
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
        fit = fields_end(data, op, body, end)
        if fit is not None and fit < end and self._plausible(fit, stop):
            # a record length longer than the record's own fields, and well-framed records where
            # they end: the length is damaged (padding is not followed by records that way)
            res.warnings.append(f"{res.path}: {opname(op)} record at byte offset {pos}: record length {end - body} "
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
        if op in SUMMARY_ONLY_OPS:
            return self.bad_record(pos, end, stop, f"{opname(op)} record inside the data section")
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
            cid, _s, lt, _p = MSG_HDR.unpack_from(data, body)
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
                rec = parse_record(cls, data[body:end])
            except Exception as exc:  # noqa: BLE001 - a record that does not parse is skipped and reported
                return self.bad_record(pos, end, stop, f"{opname(op)} record does not parse ({type(exc).__name__}: {exc})")
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
            self.res.damage.append(Damage(offset=pos, reason=reason, messages=msgs, channel_ids=cids))
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
        op, length = REC_HDR.unpack_from(self.data, p)
        return op not in DATA_OPS or p + 9 + length > self.n

    def disguised_chunk(self, pos: int, op: int, body: int, end: int) -> bool:
        """A record whose opcode is damaged but whose body is exactly a valid chunk (framing that
        fits its length, decompression to the stated size, a matching CRC-32): read as the chunk."""
        data = self.data
        (clen,) = struct.unpack_from("<I", data, body + 28)
        if clen > 4 or body + 40 + clen > end or bytes(data[body + 32 : body + 32 + clen]) not in COMPRESSIONS:
            return False
        (dlen,) = struct.unpack_from("<Q", data, body + 32 + clen)
        (crc,) = struct.unpack_from("<I", data, body + 24)
        if body + 40 + clen + dlen != end or (crc == 0 and clen == 0) or not self.validate_crcs:
            return False
        try:
            opened = self.open_chunk(body, end)
        except Exception as exc:  # noqa: BLE001 - framed like a chunk, but damaged
            msgs, cids = self.loss_of_chunk(pos, end, self.n)
            self.res.damage.append(Damage(offset=pos,
                                          reason=f"record with a damaged opcode ({opname(op)}) framed like a chunk, "
                                          f"chunk skipped: {type(exc).__name__}: {exc}", messages=msgs,
                                          channel_ids=cids))
            self.done.add(pos)
            return True
        self.take(pos, opened, end)
        self.res.warnings.append(f"{self.res.path}: record at byte offset {pos} has a damaged opcode ({opname(op)}) "
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
        op, length = REC_HDR.unpack_from(self.data, p)
        return valid_opcode(op) and p + 9 + length <= stop and self._plausible(p + 9 + length, stop, depth - 1)

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
        chunk = read_chunk(self.mview, body, end)
        check_chunk_size(chunk, self.max_chunk)
        raw = decompress_into(chunk) if self.plan else None
        scratch = raw is not None
        if scratch and self.validate_crcs and chunk.uncompressed_crc != 0 and crc32(raw) != chunk.uncompressed_crc:
            scratch, raw = False, None  # damaged: the usual path below names the fault
        if raw is None:
            raw = checked(chunk, self.validate_crcs)
        recs: list = []
        idx = index_messages(raw, 0, len(raw), recs, self.fast)
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
            reopen = None if raw is not None else partial(reopen_chunk, self.mview, self.res.path, pos, end,
                                                          self.validate_crcs)
            self.res.blocks.append(Block(raw, pos, cid, lt, st, ln, decoded, reopen))
        listed, cids = self.loss_of_chunk(pos, end, self.n)
        if listed is not None and listed > cid.size:
            self.res.damage.append(Damage(offset=pos, reason=f"chunk holds {cid.size} messages where its message "
                                          f"indexes list {listed}: damaged", messages=listed - int(cid.size),
                                          channel_ids=cids))

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
        op, length = REC_HDR.unpack_from(self.data, pos)
        if op == Opcode.CHUNK and length == ci.chunk_length - 9:
            return None
        try:
            chunk = read_chunk(self.mview, pos + 9, end)
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
            f"{self.res.path}: chunk record header at byte offset {pos} damaged ({opname(op)}, length {length}); "
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
            self.res.damage.append(Damage(offset=pos, reason=f"damaged record: {problem}; resumed back at byte offset "
                                          f"{back} (a valid chunk that a damaged record length had passed over)"))
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
        self.res.damage.append(Damage(offset=pos, reason=f"damaged record: {problem}; {tail}", messages=msgs,
                                      channel_ids=cids))
        for o in lost:
            self.done.add(o)
            if o != pos:
                m, c = self.loss_of_chunk(o, None, stop)
                self.res.damage.append(Damage(offset=o, reason="chunk lost in the damaged bytes", messages=m,
                                              channel_ids=c))
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
            if bytes(data[q + 41 : q + 41 + clen]) not in COMPRESSIONS:
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
            crc = ahead.result() if ahead is not None else crc32(memoryview(self.data)[:pos])
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


def with_loss(d: Damage, sc: "Scanner") -> Damage:
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

