"""Automatic choice of the channels to analyse in a log."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from vibroscope.io.log_index import LogIndex, select_acceleration_channels

__all__ = ["AutoSelection", "auto_channels", "moving_channels", "is_bookkeeping", "MAX_AUTO_CHANNELS", "FORCE_TYPES", "ForceInput",
           "FieldInfo", "force_candidates", "find_force_input", "numeric_fields", "nearest_numeric_paths",
           "field_hint"]

#: most channels an automatic (non-IMU) selection analyses (the fields that move, in field order)
MAX_AUTO_CHANNELS = 32

#: fields that count messages, stamp them or name things: never vibration data
_BOOKKEEPING = re.compile(
    r"(^|\.)(header|stamp|goal_info)(\.|$)|(^|\.)(seq|sec|nanosec|index_id|id|level|line|status|type)(\[\d+\])?$"
    r"|_count(er)?$|(^|\.)id\[\d+\]$|severity$"
)


#: message types whose ``force`` (``wrench.force`` of the stamped one) is a force input
FORCE_TYPES = ("geometry_msgs/msg/WrenchStamped", "geometry_msgs/WrenchStamped", "geometry_msgs/msg/Wrench",
               "geometry_msgs/Wrench")

#: a topic or field named like an excitation: a word force, command or input (``/shaker/force``,
#: ``/actuator/command``, ``.input``), delimited by ``/ . _ [`` or the ends
_FORCE_NAME = re.compile(r"(^|[^A-Za-z])(force|forces|command|input)([^A-Za-z]|$)", re.I)

#: units of fields that are responses or moments, never a force input
_NOT_FORCE_UNITS = ("m/s^2", "m/s²", "rad/s", "N m", "N·m", "Nm", "rad", "m", "m/s")


def moving_channels(channels, rows) -> list:
    """The channels of an automatic fallback choice that are kept: those whose values move.

    The second half of the automatic choice of :func:`auto_channels` (its third case returns
    every field of a topic); the callers then keep at most :data:`MAX_AUTO_CHANNELS` of them.

    Parameters
    ----------
    channels : sequence of str
        Message paths.
    rows : sequence of array_like
        Their values, one row per channel (NaN marks a missing sample, not a value).

    Returns
    -------
    list of str
        The channels, in order, whose finite values are not all equal (a channel with no
        finite value is dropped too).
    """
    import numpy as np

    out = []
    for c, v in zip(channels, rows):
        v = np.asarray(v, dtype=float)
        v = v[np.isfinite(v)]
        if v.size and v.max() > v.min():
            out.append(c)
    return out


def is_bookkeeping(path: str) -> bool:
    """True for a message path whose field is bookkeeping (header, stamps, sequence, ids, counters).

    Parameters
    ----------
    path : str
        A message path ``topic.field...``; the part after the first ``.`` is tested (a path
        without a field is not bookkeeping).

    Returns
    -------
    bool
    """
    fields = path.split(".", 1)[1] if "." in path else ""
    return bool(_BOOKKEEPING.search(fields))


@dataclass(frozen=True)
class AutoSelection:
    """Channels chosen for analysis, and why.

    Attributes
    ----------
    channels : tuple of str
        Message paths to read.
    reason : str
        How they were chosen.
    skipped : tuple of (str, str)
        (topic or path, reason) of what was left out and could matter (undecodable channels).
    fallback : bool
        True when the log had no Imu acceleration and a topic's measurement fields were taken.
    """

    channels: tuple[str, ...]
    reason: str
    skipped: tuple[tuple[str, str], ...] = field(default_factory=tuple)
    fallback: bool = False


def auto_channels(path: str | Path | LogIndex, *, min_messages: int = 64, max_channels: int = 32,
                  exclude_topics: tuple = (), message_counts: dict | None = None) -> AutoSelection:
    """Choose what to analyse in a log with no channel given.

    1. Every ``linear_acceleration.{x,y,z}`` of the ``sensor_msgs/msg/Imu`` topics.
    2. Else the acceleration fields of every decodable topic of another schema (a JSON or
       protobuf log of accelerometers): fields whose unit is m/s² (stored by the writer, or
       :func:`~vibroscope.io.log_index.unit_for` their name: ``linear_acceleration.*``), of
       topics with at least `min_messages` messages.
    3. Else (no acceleration, e.g. a robot's joint-state log): the numeric measurement fields of
       the decodable topic with the largest ``messages × min(fields, max_channels)`` (at least
       `min_messages` messages), leaving out bookkeeping (:func:`is_bookkeeping`). All its
       fields are returned; the caller drops constant ones and keeps at most `max_channels`.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP log, or its index (:meth:`LogIndex.open`: then the log is not scanned again).
    min_messages : int, optional
        Fewest messages a fallback topic needs (default 64).
    max_channels : int, optional
        Field count beyond which a topic scores no higher (default 32).
    exclude_topics : tuple of str, optional
        Topics never chosen as responses (e.g. the input's: a force is not a response).
    message_counts : dict of str to int, optional
        Messages per topic in the whole log, for an index that holds only some of its chunks
        (:func:`vibroscope.io.blocks.open_grid` samples the first and last chunks); default the
        index's own counts.

    Returns
    -------
    AutoSelection

    Raises
    ------
    vibroscope.errors.ChannelError
        If no topic qualifies (names the file).
    """
    from vibroscope.errors import ChannelError

    # one scan serves the topic table and, for the fallback, the field discovery
    log = path if isinstance(path, LogIndex) else LogIndex.open(path)
    info = log.info()
    undecodable = tuple((t.topic, f"{t.schema_name}: {t.reason}") for t in info.topics
                        if not t.decodable and t.message_count > 0)
    acc, _ = select_acceleration_channels(info)
    if acc:
        return AutoSelection(tuple(acc), "linear_acceleration of every sensor_msgs/msg/Imu topic", undecodable)
    counts = {t.topic: (t.message_count if message_counts is None else int(message_counts.get(t.topic, 0)))
              for t in info.topics if t.decodable}
    fields = log.discover_fields()
    accel = [p for topic, paths in fields.items() if topic not in exclude_topics and counts.get(topic, 0) >= min_messages
             for p in paths if log.unit(log.topic_of(p)) in ("m/s^2", "m/s²")]
    if accel:
        topics = list(dict.fromkeys(log.topic_of(p).topic for p in accel))
        return AutoSelection(tuple(accel), f"no Imu topic: the {len(accel)} acceleration fields (unit m/s^2) of "
                                           f"{len(topics)} topics ({', '.join(topics[:4])}{' ...' if len(topics) > 4 else ''})",
                             undecodable, fallback=True)
    best, best_key = None, None
    for topic, paths in fields.items():
        if topic in exclude_topics:
            continue
        meas = [p for p in paths if not is_bookkeeping(p)]
        n = counts.get(topic, 0)
        score = n * min(len(meas), max_channels)
        if meas and n >= min_messages and (best_key is None or score > best_key):
            best, best_key = (topic, meas), score
    if best is None:
        raise ChannelError(f"{log.path}: no acceleration field and no decodable topic with {min_messages}+ messages "
                           "and numeric measurement fields; name channels with --outputs")
    topic, meas = best
    return AutoSelection(tuple(meas),
                         f"no Imu acceleration in the log: the {len(meas)} measurement fields of {topic} "
                         f"({counts[topic]} messages)", undecodable, fallback=True)


@dataclass(frozen=True)
class FieldInfo:
    """One numeric message path of a log.

    Attributes
    ----------
    path : str
        The message path (``/shaker/force.wrench.force.x``).
    topic : str
        Its topic.
    unit : str
        Its unit (:meth:`~vibroscope.io.log_index.LogIndex.unit`: stored by the writer, else from
        the field's name), ``""`` when unknown.
    sample : float
        Its value in the topic's first decodable message.
    schema : str
        The topic's message type.
    """

    path: str
    topic: str
    unit: str
    sample: float
    schema: str


def _index(path) -> LogIndex:
    return path if isinstance(path, LogIndex) else LogIndex.open(path)


def _schemas(log: LogIndex) -> dict[str, str]:
    return {t.topic: t.schema_name for t in log.info().topics}


def numeric_fields(path: str | Path | LogIndex, topics=None) -> tuple[FieldInfo, ...]:
    """Every numeric message path of a log, with its unit and a sample value.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP log, or its index.
    topics : iterable of str, optional
        Only these topics; default every decodable topic.

    Returns
    -------
    tuple of FieldInfo
        In topic order, then message order (the fields of the first decodable message of each
        topic, :func:`~vibroscope.io.log_index.discover_fields`; arrays list at most 64 elements).

    Raises
    ------
    vibroscope.errors.ChannelError
        If a topic of `topics` is not in the log, or does not decode (names the file, the
        topic and why).
    """
    import numbers

    from vibroscope.errors import ChannelError
    from vibroscope.io.paths import get_field

    log = _index(path)
    found = log.discover_fields()
    schemas = _schemas(log)
    if topics is not None:
        topics = list(topics)
        for t in topics:
            if t not in log.by_topic:
                raise ChannelError(f"{log.path}: no topic {t!r}; topics are {sorted(log.by_topic)}")
            if t not in found:
                _msg, why = log.first_decoded(log.by_topic[t][0])
                raise ChannelError(f"{log.path}: topic {t!r} ({schemas.get(t) or 'no schema'}) has no numeric field "
                                   f"to list: {why or 'its first message holds no number'}")
    out = []
    for topic, paths in found.items():
        if topics is not None and topic not in topics:
            continue
        msg, _why = log.first_decoded(log.by_topic[topic][0])
        for p in paths:
            mp = log.topic_of(p)
            try:
                v = get_field(msg, mp.fields, topic=topic)
                v = float(v) if isinstance(v, numbers.Real) else float("nan")
            except ChannelError:
                v = float("nan")
            out.append(FieldInfo(p, topic, log.unit(mp), v, schemas.get(topic, "")))
    return tuple(out)


def nearest_numeric_paths(path: str | Path | LogIndex, channel: str, n: int = 8) -> list[str]:
    """The numeric message paths of a log nearest to `channel` (a path that is not one).

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP log, or its index.
    channel : str
        The message path given (``/shaker/force``, ``/imu.linear_acceleration.q``).
    n : int, optional
        Most paths returned; default 8.

    Returns
    -------
    list of str
        The numeric fields of `channel`'s topic (bookkeeping fields, :func:`is_bookkeeping`,
        only when it has no other) ranked by :func:`vibroscope.io.paths.nearest_paths`; of every
        topic when `channel` names none of the log's; empty when nothing is near.
    """
    from vibroscope.errors import ChannelError
    from vibroscope.io.paths import nearest_paths

    log = _index(path)
    found = log.discover_fields()
    try:
        topic = log.topic_of(channel).topic
        cands = list(found.get(topic, []))
    except ChannelError:
        cands = [p for ps in found.values() for p in ps]
    meas = [p for p in cands if not is_bookkeeping(p)]
    return nearest_paths(channel, meas or cands, n=n)


def field_hint(path: str | Path | LogIndex, channel: str, n: int = 8) -> str:
    """The end of an error about `channel`: ``"; numeric paths near it: a, b, ..."`` (``""`` if none).

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP log, or its index.
    channel : str
        The message path that is not a numeric field.
    n : int, optional
        Most paths named; default 8.

    Returns
    -------
    str
    """
    try:
        near = nearest_numeric_paths(path, channel, n=n)
    except Exception:  # noqa: BLE001 - a hint never hides the error it completes
        return ""
    return f"; numeric paths near it: {', '.join(near)} (all of them: vibroscope info --fields LOG)" if near else ""


def force_candidates(path: str | Path | LogIndex, *, exclude_topics=(), min_messages: int = 64,
                     message_counts: dict | None = None) -> tuple[tuple[str, str], ...]:
    """The force-like numeric fields of a log: what could be an FRF's input.

    A field is force-like when its topic has at least `min_messages` messages, is not an Imu
    topic, the field is not bookkeeping (:func:`is_bookkeeping`) nor of a response's or a
    moment's unit (m/s², rad/s, N m, m, ...), and

    1. it is the ``force`` (``wrench.force``) of a ``geometry_msgs`` Wrench/WrenchStamped
       topic (:data:`FORCE_TYPES`; the torque is not), or
    2. its unit is N (stored by the writer, or from its name), or
    3. its topic or field is named like an excitation: a word ``force``, ``command`` or
       ``input`` (``/shaker/force``, ``/actuator/command.data``).

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP log, or its index.
    exclude_topics : iterable of str, optional
        Topics never taken (e.g. the responses' topics).
    min_messages : int, optional
        Fewest messages of a candidate topic; default 64.
    message_counts : dict of str to int, optional
        Messages per topic in the whole log, for an index that holds only some of its chunks
        (:meth:`vibroscope.io.blocks.LogGrid.force_input`); default the index's own counts.

    Returns
    -------
    tuple of (str, str)
        (message path, why: ``"WrenchStamped"``, ``"unit N"`` or ``"named like a force"``), in
        topic and field order.
    """
    from vibroscope.io.log_index import ACCELERATION_TYPES

    log = _index(path)
    info = log.info()
    exclude_topics = set(exclude_topics)
    out = []
    fields = log.discover_fields()
    for t in info.topics:
        n = t.message_count if message_counts is None else int(message_counts.get(t.topic, 0))
        if (t.topic in exclude_topics or t.schema_name in ACCELERATION_TYPES or n < min_messages
                or t.topic not in fields):
            continue
        short = t.schema_name.rsplit("/", 1)[-1]
        for p in fields[t.topic]:
            if is_bookkeeping(p):
                continue
            mp = log.topic_of(p)
            unit = log.unit(mp)
            if unit in _NOT_FORCE_UNITS:
                continue
            names = [f for f in mp.fields if isinstance(f, str)]
            if t.schema_name in FORCE_TYPES:
                if "force" in names:
                    out.append((p, short))
            elif unit == "N":
                out.append((p, "unit N"))
            elif _FORCE_NAME.search(t.topic) or any(_FORCE_NAME.search(f) for f in names):
                out.append((p, "named like a force"))
    return tuple(out)


def _look(log: LogIndex, topic: str, paths: list[str], n: int):
    """Values (len(paths), <= n) of `paths` in every k-th message of `topic` (NaN where absent)."""
    import numbers

    import numpy as np

    from vibroscope.io.paths import get_field

    cid = log.by_topic[topic][0]
    dec, _why = log.decoders.get(log.scan.channels[cid], log.schema(cid))
    if dec is None:
        return np.full((len(paths), 0), np.nan)
    step = max(1, -(-log.count(cid) // n))
    fields = [log.topic_of(p).fields for p in paths]
    cols = []
    for i, (_off, p) in enumerate(log.payloads(cid)):
        if i % step:
            continue
        col = np.full(len(paths), np.nan)
        try:
            msg = dec(bytes(p))
        except Exception:  # noqa: BLE001 - a message that does not decode says nothing
            continue
        for k, f in enumerate(fields):
            try:
                v = get_field(msg, f)
            except Exception:  # noqa: BLE001
                continue
            if isinstance(v, numbers.Real) and not isinstance(v, bool):
                col[k] = float(v)
        cols.append(col)
    return np.array(cols).T if cols else np.full((len(paths), 0), np.nan)


@dataclass(frozen=True)
class ForceInput:
    """The force input found in a log, or why none was taken.

    Attributes
    ----------
    channel : str or None
        The message path taken as the input; None when there is none, or several.
    why : str
        Why it is force-like (``"WrenchStamped"``, ``"unit N"``, ``"named like a force"``,
        with ``"; dominant axis"`` when its topic's other force axes move 10x less).
    candidates : tuple of str
        The force-like fields that move (more than one: none was taken).
    """

    channel: str | None
    why: str
    candidates: tuple[str, ...] = ()

    def line(self) -> str:
        """The report's line: ``input: PATH (force-like: WHY); --output-only to ignore it``, or
        why no input was taken, or ``""`` when the log holds no force-like field."""
        if self.channel:
            return f"input: {self.channel} (force-like: {self.why}); --output-only to ignore it"
        if self.candidates:
            c = self.candidates
            return (f"no input taken: {len(c)} force-like channels move ({', '.join(c[:4])}"
                    f"{' ...' if len(c) > 4 else ''}); name one with --input")
        return ""


def find_force_input(path: str | Path | LogIndex, *, exclude_topics=(), min_messages: int = 64,
                     n_look: int = 512, message_counts: dict | None = None) -> ForceInput:
    """The one force-like channel of a log that moves, to take as the FRF input.

    The candidates of :func:`force_candidates` are looked at in at most `n_look` messages of
    their topic, spread evenly over the log, and those that vary there are kept. One left: it is the input. Several on one topic, all in N, one of
    them with a standard deviation at least 10 times every other's (a one-axis shaker on a
    three-axis load cell): that one. Otherwise none is taken.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP log, or its index.
    exclude_topics : iterable of str, optional
        Topics never taken (the responses').
    min_messages : int, optional
        Fewest messages of a candidate topic; default 64.
    n_look : int, optional
        Most messages decoded per candidate topic; default 512.
    message_counts : dict of str to int, optional
        Messages per topic in the whole log, for an index of some of its chunks (see
        :func:`force_candidates`).

    Returns
    -------
    ForceInput
    """
    import numpy as np

    log = _index(path)
    cands = force_candidates(log, exclude_topics=exclude_topics, min_messages=min_messages,
                             message_counts=message_counts)
    if not cands:
        return ForceInput(None, "")
    why = dict(cands)
    by_topic: dict[str, list[str]] = {}
    for p, _ in cands:
        by_topic.setdefault(log.topic_of(p).topic, []).append(p)
    moving, spread = [], {}
    for topic, paths in by_topic.items():
        vals = _look(log, topic, paths, n_look)
        for c, row in zip(paths, vals):
            x = row[np.isfinite(row)]
            if x.size > 1 and x.max() > x.min():
                moving.append(c)
                spread[c] = float(np.std(x))
    if len(moving) == 1:
        return ForceInput(moving[0], why[moving[0]], tuple(moving))
    if len(moving) > 1 and len({log.topic_of(c).topic for c in moving}) == 1 \
            and all(log.unit(log.topic_of(c)) == "N" for c in moving):
        order = sorted(moving, key=lambda c: -spread[c])
        if spread[order[0]] >= 10 * spread[order[1]]:
            return ForceInput(order[0], f"{why[order[0]]}; dominant axis", tuple(moving))
    return ForceInput(None, "", tuple(moving))
