"""Reading MCAP logs into :class:`~vibroscope.signals.Signals`.

Decoding goes through the decoder factories of the ``mcap`` library (ROS 2 CDR via
``mcap_ros2``, protobuf via ``mcap_protobuf``) plus JSON; ``sensor_msgs/msg/Imu`` and
``geometry_msgs/msg/WrenchStamped`` in fixed-layout CDR take a numpy fast path over whole
chunks. Records are scanned by :mod:`vibroscope.io._scan`, which checks chunk CRCs and keeps
everything before (and around) damage.
"""

from __future__ import annotations

import json
import numbers
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from vibroscope.errors import ChannelError
from vibroscope.io import _ros2
from vibroscope.io._scan import ScanResult, scan
from vibroscope.io.paths import MessagePath, format_path, get_field, parse_path
from vibroscope.io.timebase import TimebaseReport, analyse_stamps, grid_for, on_grid, resample_to_grid
from vibroscope.signals import Signals

__all__ = [
    "read_mcap",
    "mcap_info",
    "discover_fields",
    "select_acceleration_channels",
    "iter_raw_messages",
    "LogInfo",
    "TopicInfo",
    "unit_for",
    "ACCELERATION_TYPES",
]

#: message types whose ``linear_acceleration.{x,y,z}`` the automatic selection takes
ACCELERATION_TYPES = ("sensor_msgs/msg/Imu", "sensor_msgs/Imu")


def unit_for(fields: Sequence[str | int]) -> str:
    """SI unit of a message field by its name.

    Parameters
    ----------
    fields : sequence of (str or int)
        A field path, as in :attr:`MessagePath.fields`.

    Returns
    -------
    str
        ``linear_acceleration`` -> ``m/s^2``, ``angular_velocity`` -> ``rad/s``,
        ``wrench.force``/``force`` -> ``N``, ``wrench.torque``/``torque`` -> ``N m``,
        otherwise ``""``.
    """
    names = [f for f in fields if isinstance(f, str)]
    if "linear_acceleration" in names:
        return "m/s^2"
    if "angular_velocity" in names:
        return "rad/s"
    if "force" in names:
        return "N"
    if "torque" in names:
        return "N m"
    return ""


# -- decoding ------------------------------------------------------------------------------
class _JSONDecoderFactory:
    def decoder_for(self, message_encoding: str, schema: Any) -> Callable[[bytes], Any] | None:
        if message_encoding != "json":
            return None
        return lambda data: json.loads(bytes(data))


class _Decoders:
    """Decoder factories of the mcap libraries; remembers why a channel cannot be decoded."""

    def __init__(self) -> None:
        from mcap_protobuf.decoder import DecoderFactory as PbFactory
        from mcap_ros2.decoder import DecoderFactory as Ros2Factory

        self.factories = [Ros2Factory(), PbFactory(), _JSONDecoderFactory()]
        self.cache: dict[int, tuple[Callable | None, str]] = {}

    def get(self, channel: Any, schema: Any) -> tuple[Callable | None, str]:
        if channel.id in self.cache:
            return self.cache[channel.id]
        dec, reason = None, ""
        if schema is not None and schema.encoding == "ros2idl":
            reason = "schema encoding 'ros2idl' is not supported by the ROS 2 decoder (only 'ros2msg')"
        else:
            for f in self.factories:
                try:
                    dec = f.decoder_for(channel.message_encoding, schema)
                except Exception as exc:  # noqa: BLE001 - schema parse failures
                    reason = f"schema {getattr(schema, 'name', '')!r} does not parse: {type(exc).__name__}: {exc}"
                    dec = None
                    break
                if dec is not None:
                    break
            else:
                enc = schema.encoding if schema is not None else "(no schema)"
                reason = f"no decoder for message encoding {channel.message_encoding!r} with schema encoding {enc!r}"
        self.cache[channel.id] = (dec, reason)
        return dec, reason


class _Log:
    """A scanned log with per-channel message access."""

    def __init__(self, path: str | Path, *, progress: bool = False, topics: Any = None) -> None:
        self.path = Path(path)
        self.scan: ScanResult = scan(self.path, progress=progress, topics=topics)
        self.decoders = _Decoders()
        self.by_topic: dict[str, list[int]] = defaultdict(list)
        for cid, ch in sorted(self.scan.channels.items()):
            self.by_topic[ch.topic].append(cid)
        self._where: dict[int, list[tuple[int, np.ndarray]]] = {}

    def schema(self, cid: int) -> Any:
        ch = self.scan.channels[cid]
        return self.scan.schemas.get(ch.schema_id) if ch.schema_id else None

    def schema_name(self, cid: int) -> str:
        s = self.schema(cid)
        return s.name if s is not None else ""

    def where(self, cid: int) -> list[tuple[int, np.ndarray]]:
        """(block index, message indices) of channel `cid`, in file order."""
        if cid not in self._where:
            out = []
            for bi, b in enumerate(self.scan.blocks):
                idx = np.flatnonzero(b.channel_id == cid)
                if idx.size:
                    out.append((bi, idx))
            self._where[cid] = out
        return self._where[cid]

    def count(self, cid: int) -> int:
        return sum(i.size for _, i in self.where(cid))

    def payloads(self, cid: int) -> Iterable[tuple[int, memoryview]]:
        """(file offset of the containing chunk, payload) for every message of `cid`."""
        for bi, idx in self.where(cid):
            b = self.scan.blocks[bi]
            mv = memoryview(b.buf)
            for s, n in zip(b.start[idx].tolist(), b.length[idx].tolist()):
                yield b.file_offset, mv[s : s + n]

    def log_times(self, cid: int) -> np.ndarray:
        parts = [self.scan.blocks[bi].log_time[idx] for bi, idx in self.where(cid)]
        return np.concatenate(parts).astype(np.int64) if parts else np.empty(0, np.int64)

    def first_decoded(self, cid: int) -> tuple[Any, str]:
        dec, reason = self.decoders.get(self.scan.channels[cid], self.schema(cid))
        if dec is None:
            return None, reason
        for off, p in self.payloads(cid):
            try:
                return dec(bytes(p)), ""
            except Exception as exc:  # noqa: BLE001
                return None, f"first message (chunk at byte offset {off}) does not decode: {type(exc).__name__}: {exc}"
        return None, "no messages"

    def topic_of(self, path: str) -> MessagePath:
        try:
            return parse_path(path, self.by_topic.keys())
        except ChannelError:
            raise ChannelError(
                f"{self.path}: channel {path!r}: no such topic; topics are {sorted(self.by_topic)}"
            ) from None


# -- extraction ------------------------------------------------------------------------------
def _stamp_of(msg: Any) -> int | None:
    try:
        st = get_field(msg, ("header", "stamp"))
        if isinstance(st, dict):
            return int(st["sec"]) * 1_000_000_000 + int(st["nanosec"])
        return int(st.sec) * 1_000_000_000 + int(st.nanosec)
    except Exception:  # noqa: BLE001 - no header: log_time is used
        return None


def _fast_extract(log: _Log, cid: int, names: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """(stamps ns, values (k, n)) by the numpy fast path, or None when it does not apply."""
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
    lens = np.concatenate([blocks[bi].length[idx] for bi, idx in where])
    if lens.min() != lens.max():
        return None
    b0, i0 = where[0]
    s0 = int(blocks[b0].start[i0[0]])
    lay = _ros2.layout_for(tname, blocks[b0].buf[s0 : s0 + int(lens[0])])
    if lay is None:
        return None
    parts = []
    for bi, idx in where:
        b = blocks[bi]
        st = b.start[idx]
        d = np.diff(st)
        if st.size == 1 or (d.min() == d.max() and d[0] >= lay.payload_len):
            step = int(d[0]) if st.size > 1 else lay.payload_len
            a = np.ndarray((st.size,), dtype=lay.dtype, buffer=b.buf, offset=int(st[0]), strides=(step,))
        else:
            mv = memoryview(b.buf)
            L = lay.payload_len
            a = np.frombuffer(b"".join([mv[s : s + L] for s in st.tolist()]), dtype=lay.dtype)
        parts.append(a)
    ok = all(((p["_cdr"] == 0x0100) & (p["_flen"] == lay.frame_len)).all() for p in parts)
    if not ok:
        return None
    stamps = np.concatenate(
        [p["header.stamp.sec"].astype(np.int64) * 1_000_000_000 + p["header.stamp.nanosec"] for p in parts]
    )
    vals = np.empty((len(names), stamps.size))
    for k, n in enumerate(names):
        vals[k] = np.concatenate([p[n] for p in parts])
    return stamps, vals


def _generic_extract(
    log: _Log, cid: int, fields: list[tuple[str | int, ...]], skipped: list[dict], progress: bool = False
) -> tuple[np.ndarray, np.ndarray, str, np.ndarray]:
    """(stamps ns, values (k, n), time source, log times ns) by decoding every message."""
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
    bad = 0
    it = log.payloads(cid)
    if progress and n > 10_000:
        from tqdm.auto import tqdm

        it = tqdm(it, total=n, unit="msg", desc=f"decoding {ch.topic}")
    for i, (off, p) in enumerate(it):
        try:
            msg = dec(bytes(p))
        except Exception as exc:  # noqa: BLE001 - one bad message does not stop the read
            keep[i] = False
            bad += 1
            if bad <= 5:
                skipped.append(
                    {"topic": ch.topic, "offset": off, "reason": f"message {i} does not decode: {type(exc).__name__}: {exc}"}
                )
            continue
        if use_header is None:
            use_header = _stamp_of(msg) is not None
        st = _stamp_of(msg) if use_header else None
        stamps[i] = st if st is not None else logt[i]
        for k, f in enumerate(fields):
            v = get_field(msg, f, topic=ch.topic)
            if isinstance(v, bool) or not isinstance(v, numbers.Real):
                raise ChannelError(
                    f"{log.path}: topic {ch.topic!r}: field {format_path(ch.topic, f)!r} is not a number "
                    f"({type(v).__name__})"
                )
            vals[k, i] = float(v)
    if bad > 5:
        skipped.append({"topic": ch.topic, "offset": None, "reason": f"{bad} messages in all do not decode"})
    return stamps[keep], vals[:, keep], "header.stamp" if use_header else "log_time", logt[keep]


# -- info ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log.

    Attributes
    ----------
    topic, schema_name, schema_encoding, message_encoding : str
    message_count : int
    rate_hz : float
        ``(n - 1) / (last - first log time)`` (nan with fewer than 2 messages).
    start_ns, end_ns : int
        First and last log time in ns (0 when there are no messages).
    decodable : bool
    reason : str
        Why not, when not decodable.
    """

    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    message_count: int
    rate_hz: float
    start_ns: int
    end_ns: int
    decodable: bool
    reason: str = ""


@dataclass(frozen=True)
class LogInfo:
    """Summary of an MCAP log (see :func:`mcap_info`).

    Attributes
    ----------
    path : str
        The file.
    profile, library : str
        The MCAP header's profile (e.g. ``"ros2"``) and writing library; ``""`` without a
        header.
    message_count : int
        Messages in all topics.
    start_ns, end_ns : int
        Earliest and latest message log time over the topics with messages, int64 ns (0
        when there are none).
    topics : tuple of TopicInfo
        One per topic, sorted by topic name.
    skipped : tuple of (int, str)
        Damage the scan skipped: byte offset and reason; default none.
    warnings : tuple of str
        What the scan has to say about the file; default none.
    """

    path: str
    profile: str
    library: str
    message_count: int
    start_ns: int
    end_ns: int
    topics: tuple[TopicInfo, ...]
    skipped: tuple[tuple[int, str], ...] = ()
    warnings: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        """Time between the first and last message in s."""
        return (self.end_ns - self.start_ns) * 1e-9

    def topic(self, name: str) -> TopicInfo:
        """The :class:`TopicInfo` of topic `name` (raises ChannelError if absent).

        Parameters
        ----------
        name : str
            A topic name, e.g. ``"/imu/data"``.

        Returns
        -------
        TopicInfo

        Raises
        ------
        ChannelError
            If the log has no such topic.
        """
        for t in self.topics:
            if t.topic == name:
                return t
        raise ChannelError(f"{self.path}: no topic {name!r}")

    def as_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        from dataclasses import asdict

        d = asdict(self)
        d["duration_s"] = self.duration_s
        return d


def _info(log: _Log) -> LogInfo:
    topics = []
    for topic, cids in sorted(log.by_topic.items()):
        cid = cids[0]
        ch = log.scan.channels[cid]
        sch = log.schema(cid)
        lt = np.concatenate([log.log_times(c) for c in cids])
        n = int(lt.size)
        if n:
            t0, t1 = int(lt.min()), int(lt.max())
            rate = (n - 1) / ((t1 - t0) * 1e-9) if n > 1 and t1 > t0 else float("nan")
            _msg, reason = log.first_decoded(cid)
            ok = _msg is not None
        else:
            t0 = t1 = 0
            rate = float("nan")
            dec, reason = log.decoders.get(ch, sch)
            ok = dec is not None
        topics.append(
            TopicInfo(
                topic,
                sch.name if sch is not None else "",
                sch.encoding if sch is not None else "",
                ch.message_encoding,
                n,
                rate,
                t0,
                t1,
                ok,
                "" if ok else reason,
            )
        )
    withmsg = [t for t in topics if t.message_count]
    hdr = log.scan.header
    return LogInfo(
        str(log.path),
        hdr.profile if hdr else "",
        hdr.library if hdr else "",
        sum(t.message_count for t in topics),
        min((t.start_ns for t in withmsg), default=0),
        max((t.end_ns for t in withmsg), default=0),
        tuple(topics),
        tuple(log.scan.skipped),
        tuple(log.scan.warnings),
    )


def mcap_info(path: str | Path) -> LogInfo:
    """Topics, schemas, message counts, rates and time span of an MCAP log.

    Parameters
    ----------
    path : str or Path
        The MCAP file.

    Returns
    -------
    LogInfo
        One :class:`TopicInfo` per topic (schema name and encoding, message encoding,
        count, rate in Hz from the log times, first/last log time in ns, whether its
        messages decode and why not), plus any damage skipped (byte offset, reason).

    Raises
    ------
    LogFormatError
        If nothing of the file can be read (names the byte offset).
    """
    return _info(_Log(path))


def iter_raw_messages(path: str | Path) -> Iterator[tuple[str, int, int, bytes]]:
    """Every intact message, undecoded.

    Parameters
    ----------
    path : str or Path
        The MCAP file.

    Returns
    -------
    iterator of (str, int, int, bytes)
        (topic, channel id, log time in ns, payload) in file order; messages outside
        chunks come after the chunked ones. Damage is skipped as in :func:`read_mcap`. The
        file is scanned when this is called (so the error below is raised here, not on the
        first ``next``); the payloads are copied out one by one as the iterator advances.

    Raises
    ------
    LogFormatError
        If nothing of the file can be read.
    """
    log = _Log(path)
    return _raw_messages(log)


def _raw_messages(log: _Log) -> Iterator[tuple[str, int, int, bytes]]:
    for b in log.scan.blocks:
        mv = memoryview(b.buf)
        for c, t, s, n in zip(b.channel_id.tolist(), b.log_time.tolist(), b.start.tolist(), b.length.tolist()):
            yield log.scan.channels[c].topic if c in log.scan.channels else "", c, t, bytes(mv[s : s + n])


# -- field discovery and selection ---------------------------------------------------------
def _leaves(obj: Any, prefix: tuple, out: list, depth: int = 0) -> None:
    if depth > 12:
        return
    if isinstance(obj, bool) or obj is None or isinstance(obj, (str, bytes)):
        return
    if isinstance(obj, numbers.Real):
        out.append(prefix)
        return
    if isinstance(obj, dict):
        for k, v in obj.items():
            _leaves(v, prefix + (str(k),), out, depth + 1)
        return
    if isinstance(obj, (list, tuple, np.ndarray)):
        for i, v in enumerate(list(obj)[:64]):
            _leaves(v, prefix + (i,), out, depth + 1)
        return
    if hasattr(obj, "DESCRIPTOR") and hasattr(obj.DESCRIPTOR, "fields"):  # protobuf
        for fd in obj.DESCRIPTOR.fields:
            _leaves(getattr(obj, fd.name), prefix + (fd.name,), out, depth + 1)
        return
    slots = getattr(type(obj), "__slots__", None)
    if slots:
        for s in slots:
            _leaves(getattr(obj, s, None), prefix + (s,), out, depth + 1)
        return
    if hasattr(obj, "__dict__"):
        for k, v in vars(obj).items():
            _leaves(v, prefix + (k,), out, depth + 1)


def _discover(log: _Log) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for topic, cids in sorted(log.by_topic.items()):
        msg, _reason = log.first_decoded(cids[0])
        if msg is None:
            continue
        leaves: list = []
        _leaves(msg, (), leaves)
        out[topic] = [format_path(topic, f) for f in leaves]
    return out


def discover_fields(path: str | Path) -> dict[str, list[str]]:
    """All numeric scalar leaf paths of every decodable topic, from its first message.

    Parameters
    ----------
    path : str or Path
        The MCAP file.

    Returns
    -------
    dict of str to list of str
        ``{topic: ["/topic.a.b", "/topic.arr[0]", ...]}``; topics that do not decode are
        absent (see :func:`mcap_info` for why). Arrays list at most 64 elements.
    """
    return _discover(_Log(path))


def select_acceleration_channels(info: LogInfo) -> tuple[list[str], list[tuple[str, str]]]:
    """Acceleration channels of a log: ``linear_acceleration.{x,y,z}`` of every Imu topic.

    Parameters
    ----------
    info : LogInfo
        From :func:`mcap_info`.

    Returns
    -------
    selected : list of str
        Message paths.
    skipped : list of (str, str)
        (path or topic, reason) of Imu topics that cannot be read, and of topics that are
        not IMUs (reason names their type).
    """
    selected, skipped = [], []
    for t in info.topics:
        if t.schema_name in ACCELERATION_TYPES:
            paths = [f"{t.topic}.linear_acceleration.{c}" for c in "xyz"]
            if not t.decodable:
                skipped.extend((p, t.reason) for p in paths)
            elif t.message_count == 0:
                skipped.extend((p, "no messages") for p in paths)
            else:
                selected.extend(paths)
        else:
            skipped.append((t.topic, f"not an IMU topic ({t.schema_name or 'no schema'})"))
    return selected, skipped


# -- read_mcap -------------------------------------------------------------------------------
@dataclass
class _Notes:
    """What a read left out (``meta["skipped"]``) and what it has to say (``meta["warnings"]``)."""

    skipped: list[dict]
    warnings: list[str]

    @classmethod
    def of_scan(cls, log: _Log) -> "_Notes":
        """The damage the scan skipped, as skipped entries and warnings."""
        skipped = [{"offset": o, "reason": r} for o, r in log.scan.skipped]
        warnings = list(log.scan.warnings)
        warnings += [f"{log.path}: skipped at byte offset {o}: {r}" for o, r in log.scan.skipped]
        return cls(skipped, warnings)


@dataclass
class _TopicSamples:
    """The samples of one topic's requested fields, sorted by stamp and free of duplicates."""

    t_ns: np.ndarray  # (n,) int64
    values: np.ndarray  # (k, n): one row per requested field of the topic
    report: TimebaseReport


def _wanted_topics(channels: Sequence[str] | None) -> set[str] | None:
    """Every prefix of the channels that could be the topic (matched exactly after the scan)."""
    if channels is None:
        return None
    return {c[:i] for c in channels for i in range(1, len(c) + 1) if i == len(c) or c[i] in ".["}


def _automatic_channels(log: _Log, notes: _Notes) -> list[str]:
    """The acceleration channels of every readable Imu topic; unreadable Imu topics noted."""
    sel, skip = select_acceleration_channels(_info(log))
    for p, r in skip:
        if not r.startswith("not an IMU"):
            notes.skipped.append({"topic": p, "schema": "sensor_msgs/msg/Imu", "reason": r})
    if not sel:
        nums = _discover(log)
        hint = "; ".join(f"{t}: {len(v)} numeric fields, e.g. {v[:3]}" for t, v in list(nums.items())[:6])
        raise ChannelError(
            f"{log.path}: no acceleration field (no readable sensor_msgs/msg/Imu topic); choose channels "
            f"among the numeric fields (discover_fields): {hint}"
        )
    return sel


def _extract(log: _Log, cid: int, fields: list[tuple[str | int, ...]], notes: _Notes, progress: bool):
    """(stamps ns, values (k, n), time source, log times ns, fast path used) of channel `cid`."""
    names = [format_path("", f).lstrip(".") for f in fields]
    res = _fast_extract(log, cid, names)
    if res is not None:
        stamps, vals = res
        return stamps, vals, "header.stamp", log.log_times(cid), True
    stamps, vals, source, logt = _generic_extract(log, cid, fields, notes.skipped, progress)
    return stamps, vals, source, logt, False


def _usable_stamps(topic: str, stamps: np.ndarray, source: str, logt: np.ndarray, notes: _Notes):
    """(stamps, source): the log times instead of header stamps that are mostly equal."""
    if source == "header.stamp" and stamps.size > 1 and np.count_nonzero(np.diff(stamps) == 0) > 0.5 * (stamps.size - 1):
        notes.warnings.append(
            f"topic {topic!r}: header.stamp unusable (most consecutive stamps equal, e.g. {int(stamps[0])} ns, "
            f"in {stamps.size} messages); using log_time"
        )
        return logt, "log_time"
    return stamps, source


def _timebase_warnings(topic: str, rep: TimebaseReport) -> list[str]:
    """What was done to a topic's stamps: duplicates dropped, reordering, gaps."""
    out = []
    if rep.duplicates:
        out.append(f"topic {topic!r}: {rep.duplicates} messages with duplicate stamps dropped")
    if rep.out_of_order:
        out.append(f"topic {topic!r}: {rep.out_of_order} out-of-order stamps (sorted)")
    if rep.gaps:
        out.append(
            f"topic {topic!r}: {rep.gaps} gaps, {rep.gap_time_s:.6g} s missing in all "
            f"(first at {rep.gap_where_s[0][0]:.6g} s after the start); interpolated across"
        )
    return out


def _read_topic(
    log: _Log, topic: str, fields: list[tuple[str | int, ...]], notes: _Notes, progress: bool,
    fast_path: dict[str, bool],
) -> _TopicSamples | None:
    """The requested fields of one topic with their time base, or None (noted) when unreadable;
    ``fast_path[topic]`` says whether the numpy fast path decoded it."""
    cids = log.by_topic[topic]
    cid = cids[0]
    dec, reason = log.decoders.get(log.scan.channels[cid], log.schema(cid))
    if dec is None:
        notes.skipped.append({"topic": topic, "schema": log.schema_name(cid), "reason": reason})
        notes.warnings.append(f"{log.path}: topic {topic!r} ({log.schema_name(cid)}) skipped: {reason}")
        return None
    if len(cids) > 1:
        notes.warnings.append(f"topic {topic!r} has {len(cids)} channels; reading channel id {cid} only")
    stamps, vals, source, logt, fast_path[topic] = _extract(log, cid, fields, notes, progress)
    stamps, source = _usable_stamps(topic, stamps, source, logt, notes)
    # stamps are in file (logging) order: out-of-order counts refer to that order
    order, rep = analyse_stamps(topic, stamps, time_source=source)
    if stamps.size == 0:
        notes.skipped.append({"topic": topic, "schema": log.schema_name(cid), "reason": "no messages"})
        return None
    notes.warnings.extend(_timebase_warnings(topic, rep))
    return _TopicSamples(stamps[order], vals[:, order], rep)


def _drop_unmeasured_axes(by_topic: dict[str, list[int]], rows: dict[int, np.ndarray], parsed: list[MessagePath],
                          notes: _Notes) -> None:
    """Remove from `rows` an axis that is 0 in every message of a topic whose other axes move."""
    for topic, idxs in by_topic.items():
        zero = [i for i in idxs if i in rows and not np.any(rows[i])]
        if zero and len(zero) < len(idxs):
            for i in zero:
                del rows[i]
                notes.skipped.append({"topic": topic, "channel": str(parsed[i]),
                                      "reason": "identically zero in every message (axis not measured)"})


def _channels_read(log: _Log, parsed: list[MessagePath], rows: dict[int, np.ndarray], notes: _Notes) -> list[int]:
    """Indices of the channels read; the others noted as not read. Raises when none was."""
    keep = [i for i in range(len(parsed)) if i in rows]
    if not keep:
        raise ChannelError(
            f"{log.path}: none of the requested channels can be read: "
            + "; ".join(f"{s.get('topic')}: {s['reason']}" for s in notes.skipped if "topic" in s)
        )
    for i in range(len(parsed)):
        if i not in rows and parsed[i].topic not in {s.get("topic") for s in notes.skipped}:
            notes.skipped.append({"topic": parsed[i].topic, "reason": "not read"})
    return keep


def _output_rate(log: _Log, fs: float | None, topics: list[str], reports: dict[str, TimebaseReport],
                 resample: bool) -> float:
    """`fs`, by default the highest estimated topic rate (the first topic's without resampling)."""
    if fs is None:
        cand = [reports[t].fs_est for t in topics if np.isfinite(reports[t].fs_est)]
        if not cand:
            raise ChannelError(f"{log.path}: cannot estimate a sample rate (fewer than 2 messages per topic)")
        fs = max(cand) if resample else cand[0]
    return float(fs)


def _as_logged(topics: list[str], samples: dict[str, _TopicSamples], rows: dict[int, np.ndarray],
               keep: list[int]) -> tuple[int, list[np.ndarray], dict[str, bool]]:
    """(start ns, rows, resampled per topic) of topics taken sample for sample (``resample=False``)."""
    lens = {t: samples[t].t_ns.size for t in topics}
    if len(set(lens.values())) != 1:
        raise ValueError(f"resample=False needs equal sample counts per topic, got {lens=}")
    return int(samples[topics[0]].t_ns[0]), [rows[i] for i in keep], {t: False for t in topics}


def _onto_grid(log: _Log, topics: list[str], samples: dict[str, _TopicSamples], rows: dict[int, np.ndarray],
               keep: list[int], parsed: list[MessagePath], fs: float,
               notes: _Notes) -> tuple[int, list[np.ndarray], dict[str, bool]]:
    """(start ns, rows, resampled per topic) on the grid at `fs` over the topics' common span: a
    topic already on the grid is taken as it is, any other resampled (and said so)."""
    start, n = grid_for([(int(samples[t].t_ns[0]), int(samples[t].t_ns[-1])) for t in topics], fs)
    if n < 2:
        raise ChannelError(f"{log.path}: the topics {topics} do not overlap in time")
    grid_ns = start + np.round(np.arange(n) / fs * 1e9).astype(np.int64)
    topic_rows: dict[int, np.ndarray] = {}
    resampled: dict[str, bool] = {}
    for t in topics:
        tt, fs_src = samples[t].t_ns, samples[t].report.fs_est
        ii = [i for i in keep if parsed[i].topic == t]
        y = np.vstack([rows[i] for i in ii])
        i0 = int(np.searchsorted(tt, start))
        if tt.size - i0 >= n and on_grid(tt[i0 : i0 + n], start, fs):
            out = y[:, i0 : i0 + n]
            resampled[t] = False
        else:
            out = resample_to_grid((tt - start) * 1e-9, y, (grid_ns - start) * 1e-9, fs=fs, fs_src=fs_src)
            resampled[t] = True
            notes.warnings.append(
                f"topic {t!r} ({fs_src:.6g} Hz est.) resampled onto {fs:.6g} Hz"
                + (" with anti-alias low-pass" if fs_src > fs * 1.0001 else "")
            )
        for k, i in enumerate(ii):
            topic_rows[i] = out[k]
    return start, [topic_rows[i] for i in keep], resampled
def read_mcap(
    path: str | Path,
    channels: Sequence[str] | None = None,
    *,
    fs: float | None = None,
    progress: bool = False,
    resample: bool = True,
) -> Signals:
    """Read channels of an MCAP log onto one uniform time grid.

    Parameters
    ----------
    path : str or Path
        The MCAP file (ROS 2 CDR, protobuf or JSON messages).
    channels : sequence of str, optional
        Message paths, ``/topic.field.sub`` or ``/topic.array[i]``. Default: the
        ``linear_acceleration.{x,y,z}`` of every ``sensor_msgs/msg/Imu`` topic
        (:func:`select_acceleration_channels`); of these, an axis that is 0 in every
        message of a topic whose other axes are not is left out (a single-axis sensor
        published as an Imu) and listed in ``meta["skipped"]``.
    fs : float, optional
        Output rate in Hz. Default: the highest estimated rate among the selected topics.
    progress : bool, optional
        Show a tqdm progress bar while scanning the file.
    resample : bool, optional
        If False, no interpolation: every topic must have the same number of samples (after
        dropping duplicate stamps), which are returned as they are at `fs` (default the
        first topic's estimated rate).

    Returns
    -------
    Signals
        ``data`` shape (n_channels, n_samples) in the fields' units (``units``: m/s^2,
        rad/s, N, N m or ""), ``t0`` the first grid time in s (header stamps, else log
        time). ``meta`` holds ``source``, ``timebase`` (per topic a
        :meth:`TimebaseReport.as_dict`), ``timebase_reports`` (the
        :class:`~vibroscope.io.timebase.TimebaseReport` objects), ``warnings`` (list of str), ``skipped`` (list of
        dicts: damage with ``offset`` and ``reason``, undecodable channels with ``topic``,
        ``schema``, ``reason``), ``fast_path`` (per topic).

    Raises
    ------
    LogFormatError
        If nothing of the file can be read (names file and byte offset).
    ChannelError
        If a channel names an unknown topic or field, or no requested channel can be read,
        or (automatic selection) the log has no acceleration field.

    Notes
    -----
    Time base: ``header.stamp`` (sec + nanosec, int64 ns) where the message has a header,
    else the log time. Stamps are sorted; equal stamps are dropped (first kept). A topic
    whose stamps lie on the output grid within 1 % of a period is taken as it is; otherwise
    it is interpolated (cubic spline) within the common time span of all topics, after an
    anti-alias low-pass when its rate exceeds `fs` (:func:`~vibroscope.io.timebase.resample_to_grid`).
    """
    log = _Log(path, progress=progress, topics=_wanted_topics(channels))
    notes = _Notes.of_scan(log)
    auto = channels is None
    if auto:
        channels = _automatic_channels(log, notes)
    parsed = [log.topic_of(c) for c in channels]
    by_topic: dict[str, list[int]] = defaultdict(list)
    for i, mp in enumerate(parsed):
        by_topic[mp.topic].append(i)

    samples: dict[str, _TopicSamples] = {}
    fast_path: dict[str, bool] = {}
    rows: dict[int, np.ndarray] = {}  # index into `parsed` -> samples
    for topic, idxs in by_topic.items():
        got = _read_topic(log, topic, [parsed[i].fields for i in idxs], notes, progress, fast_path)
        if got is not None:
            samples[topic] = got
            rows.update({i: got.values[k] for k, i in enumerate(idxs)})
    if auto:  # an axis that is 0 in every message of a topic whose other axes move was not measured
        _drop_unmeasured_axes(by_topic, rows, parsed, notes)
    keep = _channels_read(log, parsed, rows, notes)

    topics = list(dict.fromkeys(parsed[i].topic for i in keep))
    reports = {t: samples[t].report for t in topics}
    fs = _output_rate(log, fs, topics, reports, resample)
    if resample:
        start, data, resampled = _onto_grid(log, topics, samples, rows, keep, parsed, fs, notes)
    else:
        start, data, resampled = _as_logged(topics, samples, rows, keep)
    from dataclasses import replace

    meta = {
        "source": str(log.path),
        "timebase": {t: {**reports[t].as_dict(), "resampled": resampled.get(t, False)} for t in topics},
        "timebase_reports": {t: replace(reports[t], resampled=resampled.get(t, False)) for t in topics},
        "warnings": notes.warnings,
        "skipped": notes.skipped,
        "fast_path": fast_path,
        "t0_ns": int(start),
        "indexed": log.scan.indexed,
        "chunks_skipped_by_index": log.scan.chunks_skipped_by_index,
    }
    names = [str(parsed[i]) for i in keep]
    units = [unit_for(parsed[i].fields) for i in keep]
    return Signals(np.vstack(data), fs, names, units, start * 1e-9, meta)
