"""Message records of a decompressed chunk indexed as arrays (channel id, log time, payload offset
and length), so that the decoders can work on whole blocks with numpy: equal-length records laid
end to end in one numpy step, any other layout by a record walk compiled with numba (``cache=True``,
``nogil``; compiled on first use, so importing this module does not import numba), and record by
record in Python where that walk must decide."""

from __future__ import annotations

import functools
import threading
from typing import Any

import numpy as np
from mcap.opcode import Opcode
from mcap.records import Channel, Schema

from vibroscope.io._records import MSG_HDR, REC_HDR, opname, parse_record

_LOCAL = threading.local()
_OP_MESSAGE, _OP_SCHEMA, _OP_CHANNEL = int(Opcode.MESSAGE), int(Opcode.SCHEMA), int(Opcode.CHANNEL)  # plain ints: fast


@functools.lru_cache(maxsize=64)
def periodic_dtype(stride: int) -> np.dtype:
    """Message records of `stride` bytes laid end to end: opcode, record length, channel id, log time."""
    return np.dtype({"names": ["op", "len", "cid", "log_time"], "formats": ["u1", "<u8", "<u2", "<u8"],
                     "offsets": [0, 1, 9, 15], "itemsize": stride})


def index_messages(buf: bytes, pos: int, end: int, out_records: list, fast: bool = True) -> tuple[np.ndarray, ...]:
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

    unpack_rec = REC_HDR.unpack_from
    unpack_msg = MSG_HDR.unpack_from
    tried_periodic = not fast
    while pos < end:
        if pos + 9 > end:
            raise ValueError(f"record header cut off at {pos} of {end} bytes")
        op, length = unpack_rec(buf, pos)
        if pos + 9 + length > end:
            raise ValueError(f"{opname(op)} record at {pos} needs {length} bytes, {end - pos - 9} left")
        if op == Opcode.MESSAGE:
            if not tried_periodic:
                tried_periodic = True
                stride = 9 + length
                rest = end - pos
                if length >= 22 and rest % stride == 0 and rest // stride > 8:
                    m = rest // stride
                    a = np.ndarray((m,), periodic_dtype(stride), buf, pos)
                    if (a["op"] == _OP_MESSAGE).all() and (a["len"] == length).all():
                        flush_py()
                        cids.append(a["cid"].astype(np.uint16))
                        logs.append(a["log_time"].astype(np.uint64))
                        starts.append(pos + 31 + stride * np.arange(m, dtype=np.int64))
                        lens.append(np.full(m, length - 22, np.int64))
                        pos = end
                        break
                if fast:  # any other layout: the record walk compiled (numba), else record by record below
                    got = index_compiled(buf, pos, end, out_records)
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
            out_records.append(parse_record(Schema, buf[pos + 9 : pos + 9 + length]))
        elif op == Opcode.CHANNEL:
            out_records.append(parse_record(Channel, buf[pos + 9 : pos + 9 + length]))
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
_COMPILE_LOCK = threading.Lock()


def index_compiled(buf: Any, pos: int, end: int, out_records: list) -> tuple[np.ndarray, ...] | None:
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
        out_records.append(parse_record(Schema if op[i] == _OP_SCHEMA else Channel, buf[s + 9 : s + 9 + ln]))
    return cid[:m][msg], logt[:m][msg], start[:m][msg], length[:m][msg]  # copies (boolean indexing)


def release_work() -> None:
    """Drop this thread's reused work arrays of the compiled walk (:func:`index_compiled`)."""
    _LOCAL.__dict__.pop("walk", None)
