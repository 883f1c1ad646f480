"""Automatic choice of the channels to analyse in a log."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from vibroscope.io.log_index import LogIndex, select_acceleration_channels

__all__ = ["AutoSelection", "auto_channels", "is_bookkeeping", "MAX_AUTO_CHANNELS"]

#: most channels an automatic (non-IMU) selection analyses (the fields that move, in field order)
MAX_AUTO_CHANNELS = 32

#: fields that count messages, stamp them or name things: never vibration data
_BOOKKEEPING = re.compile(
    r"(^|\.)(header|stamp|goal_info)(\.|$)|(^|\.)(seq|sec|nanosec|index_id|id|level|line|status|type)(\[\d+\])?$"
    r"|_count(er)?$|(^|\.)id\[\d+\]$|severity$"
)


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
