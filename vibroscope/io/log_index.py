"""The index of a scanned MCAP log: topics, channels and schemas, per-topic message access,
decoders, the topic table (:class:`LogInfo`) and field discovery.

:meth:`LogIndex.open` scans a file once (:func:`vibroscope.io._scan.scan`: chunk CRCs
checked, damage skipped and reported); everything a command needs from the log afterwards
(the topic table, the automatic channel choice, the samples of :func:`~vibroscope.io.read_mcap`)
comes from that one index.
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
from vibroscope.io import _scan
from vibroscope.io.paths import MessagePath, format_path, parse_path
from vibroscope.io.timebase import fit_stamps, outlier_stamps

__all__ = [
    "LogIndex",
    "LogInfo",
    "TopicInfo",
    "mcap_info",
    "discover_fields",
    "iter_raw_messages",
    "select_acceleration_channels",
    "acceleration_paths",
    "unit_for",
    "ACCELERATION_TYPES",
    "UNITS_KEY",
]

#: message types whose ``linear_acceleration.{x,y,z}`` the automatic selection takes
ACCELERATION_TYPES = ("sensor_msgs/msg/Imu", "sensor_msgs/Imu")

#: key of a Channel record's metadata holding the units of its fields: a JSON object mapping
#: the field path after the topic (``format_path("", fields).lstrip(".")``) to a unit string
UNITS_KEY = "vibroscope.units"


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


# -- info ----------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class TopicInfo:
    """One topic of a log.

    Attributes
    ----------
    topic, schema_name, schema_encoding, message_encoding : str
    message_count : int
    rate_hz : float
        ``(n - 1) / (last - first log time)`` (nan with fewer than 2 messages), outlier log
        times left out.
    start_ns, end_ns : int
        First and last log time in ns (0 when there are no messages), outliers left out.
    decodable : bool
    reason : str
        Why not, when not decodable.
    gaps : int
        Increments of the log times longer than 1.5 median periods; default 0.
    gap_time_s : float
        Time missing in those gaps, ``sum(dt - median)``, in s; default 0.
    outliers : int
        Log times far off their neighbours (:func:`~vibroscope.io.timebase.outlier_stamps`),
        left out of the span, rate and gap count; default 0. Header stamps are checked on reading
        (``read_mcap(...).meta["outliers"]``).
    lost_messages : int or None
        Messages of the topic in damaged or missing chunks (from their message indexes or the
        summary's chunk indexes); None when a damaged place lists the topic without a count;
        default 0.
    lost_s : float
        Seconds covered by the log time ranges of the lost chunks that held the topic (an
        upper bound of its time lost), when known; default 0.
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
    gaps: int = 0
    gap_time_s: float = 0.0
    outliers: int = 0
    lost_messages: int | None = 0
    lost_s: float = 0.0


@dataclass(frozen=True, kw_only=True)
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


class LogIndex:
    """A scanned MCAP log: its topics, channels and schemas, and access to each channel's
    messages (undecoded, as views into the chunks' bytes).

    Build it with :meth:`LogIndex.open`; pass it to :func:`~vibroscope.io.read_mcap` and
    :func:`vibroscope.io.select.auto_channels` so that a command scans its log once.

    Parameters
    ----------
    scan : vibroscope.io._scan.ScanResult
        The scanned records.
    topics : set of str, optional
        The topics the scan was limited to (None: all); chunks of other topics may have
        been passed over, so only these topics can be read from this index.

    Attributes
    ----------
    path : Path
        The file.
    scan : ScanResult
        Schemas, channels, message blocks, damage skipped.
    by_topic : dict of str to list of int
        Channel ids of each topic, in id order.
    topics : set of str or None
        As given.
    decoders : object
        The decoder factories (ROS 2 ``ros2msg`` CDR, protobuf, JSON), one decoder per channel.
    """

    def __init__(self, scan: Any, topics: Any = None) -> None:
        self.path = Path(scan.path)
        self.scan = scan
        self.topics = None if topics is None else set(topics)
        self.decoders = _Decoders()
        self.by_topic: dict[str, list[int]] = defaultdict(list)
        for cid, ch in sorted(scan.channels.items()):
            self.by_topic[ch.topic].append(cid)
        self._where: dict[int, list[tuple[int, np.ndarray]]] = {}
        self._info: LogInfo | None = None
        self._fields: dict[str, list[str]] | None = None

    @classmethod
    def open(cls, path: str | Path, *, progress: bool = False, topics: Any = None,
             max_memory: int | None = None) -> "LogIndex":
        """Scan `path` once and index it.

        Parameters
        ----------
        path : str or Path
            The MCAP file.
        progress : bool, optional
            Show a tqdm bar over the bytes of the file; default False.
        topics : set of str, optional
            Only these topics are wanted: with an intact summary, chunks holding none of
            them are not decompressed (:func:`vibroscope.io._scan.scan`). Default: all.
        max_memory : int, optional
            Memory budget in bytes for decompressing chunks (:func:`vibroscope.io._scan.scan`);
            default half the available memory.

        Returns
        -------
        LogIndex

        Raises
        ------
        LogFormatError
            If nothing of the file can be read (names file and byte offset).
        """
        return cls(_scan.scan(Path(path), progress=progress, topics=topics, max_memory=max_memory), topics)

    # -- channels and messages ------------------------------------------------------------
    def schema(self, cid: int) -> Any:
        """The Schema record of channel `cid` (None without one).

        Parameters
        ----------
        cid : int
            Channel id.

        Returns
        -------
        mcap.records.Schema or None
        """
        ch = self.scan.channels[cid]
        return self.scan.schemas.get(ch.schema_id) if ch.schema_id else None

    def schema_name(self, cid: int) -> str:
        """The schema name of channel `cid` (``""`` without a schema).

        Parameters
        ----------
        cid : int
            Channel id.

        Returns
        -------
        str
        """
        s = self.schema(cid)
        return s.name if s is not None else ""

    def where(self, cid: int) -> list[tuple[int, np.ndarray]]:
        """(block index, message indices) of channel `cid`, in file order.

        Parameters
        ----------
        cid : int
            Channel id.

        Returns
        -------
        list of (int, ndarray of int)
        """
        if cid not in self._where:
            out = []
            for bi, b in enumerate(self.scan.blocks):
                idx = np.flatnonzero(b.channel_id == cid)
                if idx.size:
                    out.append((bi, idx))
            self._where[cid] = out
        return self._where[cid]

    def count(self, cid: int) -> int:
        """Messages of channel `cid` read.

        Parameters
        ----------
        cid : int
            Channel id.

        Returns
        -------
        int
        """
        return sum(i.size for _, i in self.where(cid))

    def payloads(self, cid: int) -> Iterable[tuple[int, memoryview]]:
        """(file offset of the containing chunk, payload) for every message of `cid`.

        Parameters
        ----------
        cid : int
            Channel id.

        Yields
        ------
        (int, memoryview)
            In file order; the offset is -1 for messages outside chunks.
        """
        for bi, idx in self.where(cid):
            b = self.scan.blocks[bi]
            mv = memoryview(b.buf)
            for s, n in zip(b.start[idx].tolist(), b.length[idx].tolist()):
                yield b.file_offset, mv[s : s + n]

    def log_times(self, cid: int) -> np.ndarray:
        """Log times of channel `cid` in ns, int64 shape (n,), in file order.

        Parameters
        ----------
        cid : int
            Channel id.

        Returns
        -------
        ndarray of int64
        """
        parts = []
        for bi, idx in self.where(cid):
            lt = self.scan.blocks[bi].log_time
            parts.append(lt if idx.size == lt.size else lt[idx])  # a block of this channel only: as it is
        return np.concatenate(parts, dtype=np.int64, casting="unsafe") if parts else np.empty(0, np.int64)

    def first_decoded(self, cid: int) -> tuple[Any, str]:
        """(first message of `cid` decoded, "") or (None, why not).

        Parameters
        ----------
        cid : int
            Channel id.

        Returns
        -------
        (object or None, str)
        """
        dec, reason = self.decoders.get(self.scan.channels[cid], self.schema(cid))
        if dec is None:
            return None, reason
        for off, p in self.payloads(cid):
            try:
                return dec(bytes(p)), ""
            except Exception as exc:  # noqa: BLE001
                return None, f"first message (chunk at byte offset {off}) does not decode: {type(exc).__name__}: {exc}"
        return None, "no messages"

    def units(self, topic: str) -> dict[str, str]:
        """Units stored by the writer in the metadata of `topic`'s channel (key :data:`UNITS_KEY`).

        Parameters
        ----------
        topic : str
            Topic name.

        Returns
        -------
        dict of str to str
            Field path after the topic (e.g. ``"wrench.force.x"``) to unit; empty when the
            channel stores none or the value is not a JSON object of strings.
        """
        for cid in self.by_topic.get(topic, []):
            raw = (self.scan.channels[cid].metadata or {}).get(UNITS_KEY)
            if raw is None:
                continue
            try:
                d = json.loads(raw)
            except ValueError:
                return {}
            if isinstance(d, dict):
                return {str(k): v for k, v in d.items() if isinstance(v, str)}
        return {}

    def unit(self, mp: MessagePath) -> str:
        """The unit of a channel: the log's own (:meth:`units`) else :func:`unit_for` its name.

        Parameters
        ----------
        mp : MessagePath
            The channel.

        Returns
        -------
        str
        """
        stored = self.units(mp.topic).get(format_path("", mp.fields).lstrip("."))
        return stored if stored is not None else unit_for(mp.fields)

    def topic_of(self, path: str) -> MessagePath:
        """Parse a message path against the log's topics.

        Parameters
        ----------
        path : str
            ``/topic.field...``.

        Returns
        -------
        MessagePath

        Raises
        ------
        ChannelError
            If no topic of the log is a prefix of `path`, or the index was opened for
            other topics.
        """
        try:
            mp = parse_path(path, self.by_topic.keys())
        except ChannelError:
            raise ChannelError(
                f"{self.path}: channel {path!r}: no such topic; topics are {sorted(self.by_topic)}"
            ) from None
        if self.topics is not None and mp.topic not in self.topics:
            raise ChannelError(
                f"{self.path}: channel {path!r}: this index was opened for the topics {sorted(self.topics)} "
                "only; open the log again (LogIndex.open without topics)"
            )
        return mp

    # -- summaries ------------------------------------------------------------------------
    def info(self) -> "LogInfo":
        """The topic table (computed once).

        Returns
        -------
        LogInfo
            See :func:`mcap_info`.
        """
        if self._info is None:
            self._info = _info(self)
        return self._info

    def discover_fields(self) -> dict[str, list[str]]:
        """All numeric scalar leaf paths of every decodable topic, from its first message
        (computed once).

        Returns
        -------
        dict of str to list of str
            See :func:`discover_fields`.
        """
        if self._fields is None:
            self._fields = _discover(self)
        return self._fields

    def raw_messages(self) -> Iterator[tuple[str, int, int, bytes]]:
        """Every intact message, undecoded: (topic, channel id, log time ns, payload).

        Yields
        ------
        (str, int, int, bytes)
            In file order; see :func:`iter_raw_messages`.
        """
        for b in self.scan.blocks:
            mv = memoryview(b.buf)
            for c, t, s, n in zip(b.channel_id.tolist(), b.log_time.tolist(), b.start.tolist(), b.length.tolist()):
                yield self.scan.channels[c].topic if c in self.scan.channels else "", c, t, bytes(mv[s : s + n])


def _gap_counts(lt: np.ndarray) -> tuple[int, float]:
    """(gaps, time missing in s) of log times, as :func:`~vibroscope.io.timebase.fit_stamps` finds
    them (increments over 1.5 periods, and for stamps with jitter only those holding a whole
    missing period), after sorting and dropping repeated log times."""
    if lt.size < 3:
        return 0, 0.0
    ts = np.sort(lt)  # np.unique of numpy 2.4 takes ~1 s on 1e6 stamps, sorting and comparing ~15 ms
    ts = ts[np.r_[True, ts[1:] != ts[:-1]]]
    if ts.size < 3:
        return 0, 0.0
    fit = fit_stamps(ts)
    dt = np.diff(ts).astype(np.float64) * 1e-9
    g = fit.gap
    return int(g.sum()), float(np.sum(dt[g] - fit.period_s))


def _info(log: LogIndex) -> LogInfo:
    topics = []
    lost = log.scan.lost_by_topic()
    for topic, cids in sorted(log.by_topic.items()):
        cid = cids[0]
        ch = log.scan.channels[cid]
        sch = log.schema(cid)
        lt = np.concatenate([log.log_times(c) for c in cids])
        n = int(lt.size)
        bad = outlier_stamps(lt)  # a log time far off the others: not counted in span, rate and gaps
        outliers = int(bad.sum())
        lt = lt[~bad]
        gaps, missing = _gap_counts(lt)
        if lt.size:
            t0, t1 = int(lt.min()), int(lt.max())
            rate = (lt.size - 1) / ((t1 - t0) * 1e-9) if lt.size > 1 and t1 > t0 else float("nan")
            _msg, reason = log.first_decoded(cid)
            ok = _msg is not None
        else:
            t0 = t1 = 0
            rate = float("nan")
            dec, reason = log.decoders.get(ch, sch)
            ok = dec is not None
        lost_messages, lost_s = lost.get(topic, (0, 0.0))
        topics.append(
            TopicInfo(
                topic=topic,
                schema_name=sch.name if sch is not None else "",
                schema_encoding=sch.encoding if sch is not None else "",
                message_encoding=ch.message_encoding,
                message_count=n,
                rate_hz=rate,
                start_ns=t0,
                end_ns=t1,
                decodable=ok,
                reason="" if ok else reason,
                gaps=gaps,
                gap_time_s=missing,
                outliers=outliers,
                lost_messages=lost_messages,
                lost_s=lost_s,
            )
        )
    withmsg = [t for t in topics if t.message_count]
    hdr = log.scan.header
    return LogInfo(
        path=str(log.path),
        profile=hdr.profile if hdr else "",
        library=hdr.library if hdr else "",
        message_count=sum(t.message_count for t in topics),
        start_ns=min((t.start_ns for t in withmsg), default=0),
        end_ns=max((t.end_ns for t in withmsg), default=0),
        topics=tuple(topics),
        skipped=tuple(log.scan.skipped),
        warnings=tuple(log.scan.warnings),
    )


def _as_index(path_or_index: Any, **kw: Any) -> LogIndex:
    return path_or_index if isinstance(path_or_index, LogIndex) else LogIndex.open(path_or_index, **kw)


def mcap_info(path: str | Path | LogIndex) -> LogInfo:
    """Topics, schemas, message counts, rates and time span of an MCAP log.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP file, or its index.

    Returns
    -------
    LogInfo
        One :class:`TopicInfo` per topic (schema name and encoding, message encoding,
        count, rate in Hz from the log times, first/last log time in ns, whether its
        messages decode and why not, gaps in the log times), plus any damage skipped (byte
        offset, reason).

    Raises
    ------
    LogFormatError
        If nothing of the file can be read (names the byte offset).
    """
    return _as_index(path).info()


def iter_raw_messages(path: str | Path | LogIndex) -> Iterator[tuple[str, int, int, bytes]]:
    """Every intact message, undecoded.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP file, or its index.

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
    return _as_index(path).raw_messages()


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


def _discover(log: LogIndex) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for topic, cids in sorted(log.by_topic.items()):
        msg, _reason = log.first_decoded(cids[0])
        if msg is None:
            continue
        leaves: list = []
        _leaves(msg, (), leaves)
        out[topic] = [format_path(topic, f) for f in leaves]
    return out


def discover_fields(path: str | Path | LogIndex) -> dict[str, list[str]]:
    """All numeric scalar leaf paths of every decodable topic, from its first message.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP file, or its index.

    Returns
    -------
    dict of str to list of str
        ``{topic: ["/topic.a.b", "/topic.arr[0]", ...]}``; topics that do not decode are
        absent (see :func:`mcap_info` for why). Arrays list at most 64 elements.
    """
    return _as_index(path).discover_fields()


def acceleration_paths(topic: str) -> list[str]:
    """The acceleration channels of one ``sensor_msgs/msg/Imu`` topic: ``linear_acceleration.{x,y,z}``.

    The one place that names them, for the automatic choice of a whole read
    (:func:`select_acceleration_channels`) and of a block-by-block read
    (:func:`vibroscope.io.blocks.open_grid`).

    Parameters
    ----------
    topic : str
        The Imu topic.

    Returns
    -------
    list of str
        Three message paths.

    Examples
    --------
    >>> acceleration_paths("/imu")
    ['/imu.linear_acceleration.x', '/imu.linear_acceleration.y', '/imu.linear_acceleration.z']
    """
    return [f"{topic}.linear_acceleration.{c}" for c in "xyz"]


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
            paths = acceleration_paths(t.topic)
            if not t.decodable:
                skipped.extend((p, t.reason) for p in paths)
            elif t.message_count == 0:
                skipped.extend((p, "no messages") for p in paths)
            else:
                selected.extend(paths)
        else:
            skipped.append((t.topic, f"not an IMU topic ({t.schema_name or 'no schema'})"))
    return selected, skipped
