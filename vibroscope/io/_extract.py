"""Samples of one channel's fields out of a :class:`~vibroscope.io.log_index.LogIndex`: the
numpy fast path over whole chunks (fixed-layout CDR ``sensor_msgs/msg/Imu`` and
``geometry_msgs/msg/WrenchStamped``), else every message decoded by the mcap decoders.

In the decoded path one bad message does not sink a channel: a message that does not decode
is dropped (it has no stamp) and a field that is absent or not a number in one message gives
NaN at that message's stamp; both are reported with the topic, the chunk's byte offset and
the field. A field absent from (or not a number in) the first decodable message raises.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibroscope.errors import ChannelError
from vibroscope.io import _ros2
from vibroscope.io.paths import format_path, get_field
from vibroscope.io.timebase import INVALID_STAMP_NS

#: reports per kind of fault kept in ``skipped`` per topic (the counts are always complete)
MAX_REPORTS = 5


@dataclass
class Extracted:
    """Samples of one channel, in file order.

    Attributes
    ----------
    stamps : ndarray of int64, shape (n,)
        Time stamps in ns.
    values : ndarray of float, shape (k, n)
        One row per requested field (NaN where a message lacked it).
    source : str
        ``"header.stamp"`` or ``"log_time"``.
    log_times : ndarray of int64, shape (n,)
        The messages' log times in ns.
    fast : bool
        Whether the numpy fast path decoded them.
    """

    stamps: np.ndarray
    values: np.ndarray
    source: str
    log_times: np.ndarray
    fast: bool


def _stamp_of(msg: Any) -> int | None:
    try:
        st = get_field(msg, ("header", "stamp"))
        sec, nsec = (st["sec"], st["nanosec"]) if isinstance(st, dict) else (st.sec, st.nanosec)
        if not 0 <= int(nsec) < 1_000_000_000:  # an invalid time: dropped as an outlier stamp, counted
            return INVALID_STAMP_NS
        return int(sec) * 1_000_000_000 + int(nsec)
    except Exception:  # noqa: BLE001 - no header: log_time is used
        return None


def fast_extract(log: Any, cid: int, names: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """(stamps ns, values (k, n)) by the numpy fast path, or None when it does not apply.

    It applies to a CDR channel of a fixed-layout type (:data:`~vibroscope.io._ros2.FLOAT_FIELDS`)
    whose every message is one such payload (CDR little-endian, a frame_id of any length, no
    bytes more or less than the layout): block by block (a chunk's bytes, hot in the cache),
    each block one strided view or one gather per field. Blocks whose fields the scan
    decoded already (``Block.decoded``, :func:`vibroscope.io._scan.scan` with `fields`) are
    taken as they are.
    """
    ch = log.scan.channels[cid]
    tname = log.schema_name(cid)
    if ch.message_encoding != "cdr" or tname not in _ros2.FLOAT_FIELDS:
        return None
    if any(n not in _ros2.FLOAT_FIELDS[tname] and n not in _ros2.STAMP_FIELDS for n in names):
        return None
    where = log.where(cid)
    if not where:
        return None
    blocks = log.scan.blocks
    total = sum(int(idx.size) for _, idx in where)
    stamps = np.empty(total, np.int64)
    vals = np.empty((len(names), total))
    o = 0
    for bi, idx in where:
        b = blocks[bi]
        pre = b.decoded.get(cid)  # decoded by the scan's threads right after decompression
        if pre is not None and pre[0] == tname and pre[1].size == idx.size and all(n in pre[2] for n in names):
            got = pre[1], [pre[2][n] for n in names]
        else:
            got = _ros2.decode_block(b.buf, b.start[idx], b.length[idx], tname, names)
        if got is None:
            return None
        m = idx.size
        stamps[o : o + m] = got[0]
        for k, v in enumerate(got[1]):
            vals[k, o : o + m] = v
        o += m
    return stamps, vals


class _Faults:
    """Per-topic fault counts of the decoded path, reported as ``skipped`` entries and warnings."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.kinds: dict[str, list] = {}  # kind -> [count, first offset, first detail]

    def add(self, kind: str, off: int, detail: str, skipped: list[dict], entry: dict) -> None:
        rec = self.kinds.setdefault(kind, [0, off, detail])
        rec[0] += 1
        if rec[0] <= MAX_REPORTS:
            skipped.append({"topic": self.topic, "offset": off, **entry})

    def warnings(self) -> list[str]:
        out = []
        for kind, (n, off, detail) in self.kinds.items():
            out.append(f"topic {self.topic!r}: {n} messages {kind} (first in the chunk at byte offset {off}: {detail})")
        return out


def _hint(log: Any, channel: str) -> str:
    """The numeric paths near `channel` (:func:`vibroscope.io.select.field_hint`), for an error."""
    from vibroscope.io.select import field_hint

    return field_hint(log, channel)


def generic_extract(
    log: Any, cid: int, fields: list[tuple[str | int, ...]], skipped: list[dict], warnings: list[str],
    progress: bool = False,
) -> Extracted:
    """Samples of `fields` of channel `cid` by decoding every message (see the module notes).

    Raises
    ------
    ChannelError
        If the channel has no decoder, or a field is absent from or not a number in the
        first decodable message (names file, topic and field).
    """
    ch = log.scan.channels[cid]
    dec, reason = log.decoders.get(ch, log.schema(cid))
    if dec is None:
        raise ChannelError(f"{log.path}: topic {ch.topic!r} ({log.schema_name(cid)}): {reason}")
    logt = log.log_times(cid)
    n = logt.size
    vals = np.full((len(fields), n), np.nan)
    stamps = np.empty(n, np.int64)
    keep = np.ones(n, bool)
    use_header: bool | None = None
    faults = _Faults(ch.topic)
    names = [format_path(ch.topic, f) for f in fields]
    it = log.payloads(cid)
    if progress and n > 10_000:
        from tqdm.auto import tqdm

        it = tqdm(it, total=n, unit="msg", desc=f"decoding {ch.topic}")
    for i, (off, p) in enumerate(it):
        try:
            msg = dec(bytes(p))
        except Exception as exc:  # noqa: BLE001 - one bad message does not stop the read
            keep[i] = False
            why = f"{type(exc).__name__}: {exc}"
            faults.add("do not decode (dropped)", off, why, skipped,
                       {"reason": f"message {i} does not decode: {why}"})
            continue
        first = use_header is None
        st = _stamp_of(msg)
        if first:
            use_header = st is not None
        if use_header and st is None:
            keep[i] = False
            faults.add("have no header.stamp (dropped)", off, f"message {i}", skipped,
                       {"reason": f"message {i} has no header.stamp"})
            continue
        stamps[i] = st if use_header else logt[i]
        for k, f in enumerate(fields):
            try:
                v = get_field(msg, f, topic=ch.topic)
            except ChannelError as exc:
                if first:  # the numeric paths near the one given, to copy
                    raise ChannelError(f"{log.path}: {exc}{_hint(log, names[k])}") from None
                v = None
            if v is None or isinstance(v, bool) or not isinstance(v, numbers.Real):
                if first:
                    raise ChannelError(
                        f"{log.path}: topic {ch.topic!r}: field {names[k]!r} is not a number ({type(v).__name__})"
                        + _hint(log, names[k])
                    )
                faults.add(f"lack field {names[k]!r} or hold no number there (NaN at their stamps)", off,
                           f"message {i}", skipped,
                           {"field": names[k], "reason": f"message {i}: field {names[k]!r} missing or not a number"})
                continue
            vals[k, i] = float(v)
    warnings.extend(faults.warnings())
    return Extracted(stamps[keep], vals[:, keep], "header.stamp" if use_header else "log_time", logt[keep], False)


def extract(log: Any, cid: int, fields: list[tuple[str | int, ...]], skipped: list[dict], warnings: list[str],
            progress: bool = False) -> Extracted:
    """The samples of `fields` of channel `cid`: the fast path where it applies, else decoded."""
    names = [format_path("", f).lstrip(".") for f in fields]
    res = fast_extract(log, cid, names)
    if res is not None:
        stamps, vals = res
        return Extracted(stamps, vals, "header.stamp", log.log_times(cid), True)
    return generic_extract(log, cid, fields, skipped, warnings, progress)
