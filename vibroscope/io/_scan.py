"""Record-level MCAP scanning that survives damage.

The summary section is used when it is intact (its CRC checks out and its chunk indexes
point at chunk records): its channels are known up front and chunks holding none of the
wanted topics are passed over. The data section is then read in one linear pass, record by
record, with every chunk's CRC-32 checked (``mcap.reader``/``mcap.stream_reader`` check
CRCs only with ``validate_crcs=True``; here always), and the data section CRC when the
writer stored one. A damaged summary, or none, just means every chunk is read. A chunk that fails to
decompress or whose CRC does not match is skipped whole and reported with its byte offset;
a record cut off by the end of the file stops the scan and is reported. Everything before
the damage is kept. Message records are not decoded here: they are indexed as arrays
(channel id, log time, payload offset and length) into their chunk's bytes, so that the
decoders can work on whole blocks with numpy.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, Header, Schema

from vibroscope.errors import LogFormatError

MAGIC = b"\x89MCAP0\r\n"
_MSG_HDR = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time
_REC_HDR = struct.Struct("<BQ")

try:  # optional codecs of mcap
    import zstandard as _zstd
except ImportError:  # pragma: no cover
    _zstd = None
try:
    import lz4.frame as _lz4
except ImportError:  # pragma: no cover
    _lz4 = None


def _opname(op: int) -> str:
    try:
        return Opcode(op).name
    except ValueError:
        return f"opcode 0x{op:02x}"


@dataclass
class Block:
    """Messages found in one container (a chunk, or the loose messages of the data section)."""

    buf: bytes
    file_offset: int  # byte offset of the chunk record (or -1 for loose messages)
    channel_id: np.ndarray  # uint16 (n,)
    log_time: np.ndarray  # uint64 (n,)
    start: np.ndarray  # int64 (n,), payload offset in buf
    length: np.ndarray  # int64 (n,)

    @property
    def n(self) -> int:
        return int(self.channel_id.size)


@dataclass
class ScanResult:
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


def _read_summary(data: Any, n: int) -> tuple[dict, dict, dict[int, set[int]]] | None:
    """Schemas, channels and {chunk offset: channel ids} from the summary section, or None
    when there is none or it fails any check (the caller then scans everything)."""
    fsize = 1 + 8 + 20
    if n < 8 + fsize + 8 or bytes(data[n - 8 : n]) != MAGIC:
        return None
    fpos = n - 8 - fsize
    op, length = _REC_HDR.unpack_from(data, fpos)
    if op != Opcode.FOOTER or length != 20:
        return None
    summary_start, _sos, summary_crc = struct.unpack_from("<QQI", data, fpos + 9)
    if summary_start == 0 or not 8 <= summary_start <= fpos:
        return None
    if summary_crc != 0 and zlib.crc32(memoryview(data)[summary_start : fpos + 9 + 16]) != summary_crc:
        return None
    schemas, channels, chunks = {}, {}, {}
    pos = summary_start
    while pos < fpos:
        op, length = _REC_HDR.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        if end > fpos:
            return None
        if op == Opcode.SCHEMA:
            sc = _parse(Schema, data[body:end])
            schemas[sc.id] = sc
        elif op == Opcode.CHANNEL:
            ch = _parse(Channel, data[body:end])
            channels[ch.id] = ch
        elif op == Opcode.CHUNK_INDEX:
            ci = _parse(ChunkIndex, data[body:end])
            if ci.chunk_start_offset >= summary_start or data[ci.chunk_start_offset] != Opcode.CHUNK:
                return None
            chunks[ci.chunk_start_offset] = set(ci.message_index_offsets)
        pos = end
    return schemas, channels, chunks


def _parse(cls: Any, body: bytes) -> Any:
    return cls.read(ReadDataStream(BytesIO(body)))


def _read_chunk(mv: memoryview, body: int, end: int) -> Chunk:
    """Parse a Chunk record without copying its (possibly large) data."""
    start_t, end_t, usize, crc, clen = struct.unpack_from("<QQQII", mv, body)
    p = body + 32
    comp = bytes(mv[p : p + clen]).decode()
    p += clen
    (dlen,) = struct.unpack_from("<Q", mv, p)
    p += 8
    if p + dlen > end:
        raise ValueError(f"chunk data length {dlen} runs past the record end")
    return Chunk(compression=comp, data=mv[p : p + dlen], message_end_time=end_t, message_start_time=start_t,
                 uncompressed_crc=crc, uncompressed_size=usize)


def _decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "":
        return chunk.data
    if chunk.compression == "zstd":
        if _zstd is None:
            raise ValueError("zstd compression but the zstandard module is not installed")
        return _zstd.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        if _lz4 is None:
            raise ValueError("lz4 compression but the lz4 module is not installed")
        return _lz4.decompress(chunk.data)
    raise ValueError(f"unsupported chunk compression {chunk.compression!r}")


def _index_messages(buf: bytes, pos: int, end: int, out_records: list) -> tuple[np.ndarray, ...]:
    """Index the records of `buf[pos:end]`; Schema/Channel records go to `out_records`.

    Message records of one equal length laid end to end (the usual case for a sensor
    topic) are indexed with numpy in one step; anything else record by record.
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
    tried_periodic = False
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
                    a = np.frombuffer(buf, np.uint8, count=rest, offset=pos).reshape(-1, stride)
                    if (a[:, 0] == Opcode.MESSAGE).all() and (a[:, 1:9] == a[0, 1:9]).all():
                        flush_py()
                        m = a.shape[0]
                        cids.append(a[:, 9:11].copy().view("<u2").ravel().astype(np.uint16))
                        logs.append(a[:, 15:23].copy().view("<u8").ravel().astype(np.uint64))
                        starts.append(pos + 31 + stride * np.arange(m, dtype=np.int64))
                        lens.append(np.full(m, length - 22, np.int64))
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


def _open(path: Path) -> Any:
    """The file's bytes: a read-only map (chunk data and loose payloads are sliced without copying)."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
    except (OSError, ValueError) as exc:
        raise LogFormatError(f"{path}: cannot read ({exc})") from exc


def _use_summary(res: ScanResult, data: Any, topics: Any) -> dict[int, set[int]]:
    """Take schemas and channels from an intact summary section; returns the chunks (offset:
    channel ids) that hold none of the wanted `topics` and need not be decompressed."""
    summ = _read_summary(data, len(data))
    if summ is None:
        return {}
    schemas, channels, chunks = summ
    res.indexed = True
    res.schemas.update(schemas)
    res.channels.update(channels)
    if topics is None:
        return {}
    wanted = {cid for cid, ch in channels.items() if ch.topic in topics}
    return {off: ids for off, ids in chunks.items() if ids and not ids & wanted}


class _DataSection:
    """One linear pass over the records of the data section, filling a :class:`ScanResult`."""

    def __init__(self, res: ScanResult, data: Any, validate_crcs: bool, skip_chunks: dict[int, set[int]]) -> None:
        self.res = res
        self.data = data
        self.mview = memoryview(data)
        self.validate_crcs = validate_crcs
        self.skip_chunks = skip_chunks
        self.loose: tuple[list, list, list, list] = ([], [], [], [])  # channel id, log time, start, length
        self.pending_loss: list[int] = []  # indexes into res.skipped of the skipped chunks
        self.last_skipped_chunk = False  # message indexes that follow count messages lost in it

    def run(self, bar: Any = None) -> int:
        """Read records from byte 8 up to the footer, the end of the file or the first cut-off
        record; returns the byte offset where the scan stopped."""
        res, data = self.res, self.data
        n = len(data)
        pos = 8
        while pos < n:
            if pos + 9 > n:
                res.skipped.append((pos, f"file ends inside a record header ({n - pos} of 9 bytes)"))
                break
            op, length = _REC_HDR.unpack_from(data, pos)
            body, end = pos + 9, pos + 9 + length
            if end > n:
                res.skipped.append(
                    (pos, f"{_opname(op)} record cut off by the end of the file: needs {length} bytes, {n - body} left")
                )
                break
            if op == Opcode.FOOTER:
                self.footer(end)
                return end
            self.record(op, pos, body, end, length)
            if op != Opcode.MESSAGE_INDEX:
                self.last_skipped_chunk = self.last_skipped_chunk and op == Opcode.CHUNK
            if bar is not None:
                bar.update(end - pos)
            pos = end
        return pos

    def record(self, op: int, pos: int, body: int, end: int, length: int) -> None:
        res, data = self.res, self.data
        if op == Opcode.CHUNK and pos in self.skip_chunks:
            res.chunks_skipped_by_index += 1
            self.last_skipped_chunk = False  # its message indexes are no loss
        elif op == Opcode.CHUNK:
            self.chunk(pos, body, end)
        elif op == Opcode.MESSAGE_INDEX:
            if self.last_skipped_chunk and length >= 6:
                self.count_lost(body)
        elif op == Opcode.MESSAGE:
            self.message(pos, body, length)
        elif op == Opcode.SCHEMA:
            s = _parse(Schema, data[body:end])
            res.schemas.setdefault(s.id, s)
        elif op == Opcode.CHANNEL:
            c = _parse(Channel, data[body:end])
            res.channels.setdefault(c.id, c)
        elif op == Opcode.HEADER:
            res.header = _parse(Header, data[body:end])
        elif op == Opcode.DATA_END:
            self.data_end(pos, body, length)

    def chunk(self, pos: int, body: int, end: int) -> None:
        """Decompress, check and index one chunk; any failure skips this chunk only."""
        res = self.res
        try:
            raw, recs, (cid, lt, st, ln) = self._open_chunk(body, end)
        except Exception as exc:  # noqa: BLE001 - any failure skips this chunk only
            res.skipped.append((pos, f"chunk skipped: {type(exc).__name__}: {exc}"))
            self.last_skipped_chunk = True
            self.pending_loss.append(len(res.skipped) - 1)
            return
        self.last_skipped_chunk = False
        for r in recs:
            (res.schemas if isinstance(r, Schema) else res.channels)[r.id] = r
        if cid.size:
            res.blocks.append(Block(raw, pos, cid, lt, st, ln))

    def _open_chunk(self, body: int, end: int) -> tuple[bytes, list, tuple[np.ndarray, ...]]:
        chunk = _read_chunk(self.mview, body, end)
        raw = _decompress(chunk)
        if len(raw) != chunk.uncompressed_size:
            raise ValueError(f"uncompressed size {len(raw)} != {chunk.uncompressed_size} stated")
        if self.validate_crcs and chunk.uncompressed_crc != 0:
            crc = zlib.crc32(raw)
            if crc != chunk.uncompressed_crc:
                raise ValueError(f"CRC-32 mismatch: stored {chunk.uncompressed_crc:#010x}, computed {crc:#010x}")
        recs: list = []
        return raw, recs, _index_messages(raw, 0, len(raw), recs)

    def count_lost(self, body: int) -> None:
        """Add the messages a message index lists to the loss reported for the last skipped chunk."""
        # channel_id u16, records length u32, then (u64 log_time, u64 offset) pairs
        nrec = struct.unpack_from("<I", self.data, body + 2)[0] // 16
        i = self.pending_loss[-1]
        off, reason = self.res.skipped[i]
        lost = int(reason.rsplit("(", 1)[1].split()[0]) if reason.endswith("messages lost)") else 0
        base = reason.rsplit(" (", 1)[0] if reason.endswith("messages lost)") else reason
        self.res.skipped[i] = (off, f"{base} ({lost + nrec} messages lost)")

    def message(self, pos: int, body: int, length: int) -> None:
        """Index a message outside any chunk."""
        if length < 22:
            self.res.skipped.append((pos, f"message record too short ({length} bytes)"))
            return
        cid, _s, lt, _p = _MSG_HDR.unpack_from(self.data, body)
        for col, v in zip(self.loose, (cid, lt, body + 22, length - 22)):
            col.append(v)

    def data_end(self, pos: int, body: int, length: int) -> None:
        """Check the data section CRC, when the writer stored one."""
        stored = struct.unpack_from("<I", self.data, body)[0] if length >= 4 else 0
        if self.validate_crcs and stored != 0:
            crc = zlib.crc32(memoryview(self.data)[:pos])
            if crc != stored:
                self.res.warnings.append(
                    f"{self.res.path}: data section CRC-32 mismatch (stored {stored:#010x}, computed {crc:#010x}; "
                    f"data section ends at byte offset {pos})"
                )

    def footer(self, end: int) -> None:
        if bytes(self.data[end : end + 8]) != MAGIC:
            self.res.skipped.append((end, "closing magic missing after the footer"))
        else:
            self.res.complete = True

    def loose_block(self) -> Block | None:
        """The messages found outside chunks, as one block over the whole file."""
        if not self.loose[0]:
            return None
        c, lt, st, ln = self.loose
        return Block(self.data, -1, np.array(c, np.uint16), np.array(lt, np.uint64), np.array(st, np.int64),
                     np.array(ln, np.int64))


def scan(
    path: str | Path, *, validate_crcs: bool = True, progress: bool = False, topics: Any = None
) -> ScanResult:
    """Scan an MCAP file record by record.

    Parameters
    ----------
    path : str or Path
        The MCAP file.
    validate_crcs : bool, optional
        Check every chunk's CRC-32 of its uncompressed data (and the data section CRC).
    progress : bool, optional
        Show a tqdm bar over the bytes of the file.
    topics : set of str, optional
        Only these topics are wanted: when the summary section is intact (its CRC checks
        out and its chunk indexes point at chunks), chunks whose message indexes list none
        of their channels are passed over undecompressed. A damaged or missing summary
        falls back to decoding every chunk.

    Returns
    -------
    ScanResult
        Schemas, channels, indexed message blocks, and the damage skipped (byte offsets).

    Raises
    ------
    LogFormatError
        If the file cannot be opened, does not start with the MCAP magic, or ends before
        the header record.
    """
    path = Path(path)
    data = _open(path)
    res = ScanResult(path=path, file_size=len(data))
    if bytes(data[:8]) != MAGIC:
        raise LogFormatError(f"{path}: not an MCAP file (bad magic at byte offset 0)")
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(data), unit="B", unit_scale=True, desc=path.name)
    section = _DataSection(res, data, validate_crcs, _use_summary(res, data, topics))
    try:
        pos = section.run(bar)
    finally:
        if bar is not None:
            bar.close()
    loose = section.loose_block()
    if loose is not None:
        res.blocks.append(loose)
    if not res.blocks and (res.header is None or res.skipped):
        off = res.skipped[0][0] if res.skipped else 8
        raise LogFormatError(f"{path}: nothing readable (damaged at byte offset {off})")
    if not res.complete and not res.skipped:
        res.skipped.append((pos, "file ends without a footer (log not closed?)"))
    return res
