"""Foxglove-style message paths: ``/topic.field.subfield`` and ``/topic.array[2]``.

A message path names one scalar inside the messages of one topic. The topic is everything
before the first ``.`` that follows it; when the file's topics are known the longest known
topic that prefixes the string wins (topics may contain dots in principle).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

from vibroscope.errors import ChannelError

__all__ = ["MessagePath", "parse_path", "get_field", "format_path", "nearest_paths"]

# ASCII only: "\d" would take other scripts' digits ("[٣]") that format_path writes back differently
_FIELD = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[-?[0-9]+\])*)")
_INDEX = re.compile(r"\[(-?[0-9]+)\]")
_TOPIC = re.compile(r"([^.\[]+)(.*)", re.DOTALL)


@dataclass(frozen=True)
class MessagePath:
    """A parsed message path.

    Attributes
    ----------
    topic : str
        The topic name (``/imu/m1``).
    fields : tuple of (str or int)
        Field names and integer array indices, in order
        (``("linear_acceleration", "x")`` or ``("data", 2)``).
    """

    topic: str
    fields: tuple[str | int, ...]

    def __str__(self) -> str:
        return format_path(self.topic, self.fields)


def format_path(topic: str, fields: Sequence[str | int]) -> str:
    """The string form of a message path (inverse of :func:`parse_path`).

    Parameters
    ----------
    topic : str
        Topic name; ``""`` gives the bare field path with a leading ``.``.
    fields : sequence of (str or int)
        Field names and array indices.

    Returns
    -------
    str
        ``topic.a.b[2]``.
    """
    out = topic
    for f in fields:
        out += f"[{f}]" if isinstance(f, int) else f".{f}"
    return out


def _parse_fields(s: str, whole: str) -> tuple[str | int, ...]:
    if s == "":
        return ()
    fields: list[str | int] = []
    for part in s.split("."):
        m = _FIELD.fullmatch(part)
        if not m:
            raise ChannelError(f"message path {whole!r}: cannot parse field {part!r} (a name [A-Za-z_][A-Za-z0-9_]* "
                               "with optional [index] suffixes)")
        fields.append(m.group(1))
        fields.extend(int(i) for i in _INDEX.findall(m.group(2)))
    return tuple(fields)


def parse_path(s: str, topics: Iterable[str] | None = None) -> MessagePath:
    """Parse a message path.

    Parameters
    ----------
    s : str
        ``/topic.field.subfield`` or ``/topic.array[2].x``.
    topics : iterable of str, optional
        The topics known to exist (a file's topics). When given, the longest topic that is
        followed by ``.``, ``[`` or the end of `s` is taken; otherwise the topic ends at the
        first ``.`` or ``[``.

    Returns
    -------
    MessagePath

    Raises
    ------
    ChannelError
        If `s` is empty, names no topic, or a field does not parse (field names are ASCII
        identifiers, indices ASCII integers), or `topics` is given and none of them (an
        empty topic never matches) prefixes `s`. Nothing else is raised, whatever the text.

    Examples
    --------
    >>> parse_path("/imu/m1.linear_acceleration.x")
    MessagePath(topic='/imu/m1', fields=('linear_acceleration', 'x'))
    >>> parse_path("/joints.position[2]")
    MessagePath(topic='/joints', fields=('position', 2))
    """
    s = str(s).strip()
    if not s:
        raise ChannelError("empty message path")
    if topics is not None:
        best = None
        for t in topics:
            if t and s.startswith(t) and (len(s) == len(t) or s[len(t)] in ".["):
                if best is None or len(t) > len(best):
                    best = t
        if best is None:
            raise ChannelError(f"message path {s!r}: no topic of the file prefixes it")
        topic, rest = best, s[len(best):]
    else:
        m = _TOPIC.fullmatch(s)
        if not m:
            raise ChannelError(f"message path {s!r}: no topic")
        topic, rest = m.group(1), m.group(2)
    if rest.startswith("["):  # /topic[3].x: an index right after the topic is not allowed
        raise ChannelError(f"message path {s!r}: an array index needs a field before it")
    if topic != topic.strip():
        raise ChannelError(f"message path {s!r}: topic {topic!r} begins or ends with white space")
    if rest.startswith("."):
        rest = rest[1:]
        if not rest:
            raise ChannelError(f"message path {s!r}: a field name must follow the '.'")
    elif rest:
        raise ChannelError(f"message path {s!r}: expected '.' after topic {topic!r}")
    return MessagePath(topic, _parse_fields(rest, s))


def get_field(msg: Any, fields: Sequence[str | int], *, topic: str = "") -> Any:
    """Walk `fields` into a decoded message.

    Works on ROS 2 dynamic messages and protobuf messages (attributes), JSON messages
    (dicts) and sequences (integer indices).

    Parameters
    ----------
    msg : object
        A decoded message.
    fields : sequence of (str or int)
        As in :attr:`MessagePath.fields`.
    topic : str, optional
        The topic, used only in error messages.

    Returns
    -------
    object
        The value found.

    Raises
    ------
    ChannelError
        Naming the topic and the field path up to the failing element.
    """
    cur = msg
    for i, f in enumerate(fields):
        try:
            if isinstance(f, int):
                cur = cur[f]
            elif isinstance(cur, dict):
                cur = cur[f]
            else:
                if not hasattr(cur, f):
                    raise AttributeError(f)
                cur = getattr(cur, f)
        except (KeyError, IndexError, AttributeError, TypeError) as exc:
            where = format_path(topic or "<topic>", fields[: i + 1])
            raise ChannelError(
                f"topic {topic!r}: field {where!r} not found in the message ({type(exc).__name__}: {exc})"
            ) from None
    return cur


def nearest_paths(path: str, candidates: Sequence[str], n: int = 8) -> list[str]:
    """The message paths of `candidates` nearest to `path`, nearest first.

    The paths that extend `path` (``/shaker/force`` -> ``/shaker/force.wrench.force.x``, in the
    order given) come first, then those whose every step but the last matches (the siblings of a
    misspelt field), then the closest by :class:`difflib.SequenceMatcher` ratio (at least 0.5).

    Parameters
    ----------
    path : str
        A message path that names no numeric field.
    candidates : sequence of str
        The valid paths, in a meaningful order (message order).
    n : int, optional
        Most paths returned; default 8.

    Returns
    -------
    list of str
        At most `n` paths of `candidates`, none repeated.

    Examples
    --------
    >>> nearest_paths("/ft", ["/ft.wrench.force.x", "/ft.wrench.force.y", "/imu.x"], n=2)
    ['/ft.wrench.force.x', '/ft.wrench.force.y']
    >>> nearest_paths("/imu.linear_acceleration.q", ["/imu.angular_velocity.x", "/imu.linear_acceleration.x"])
    ['/imu.linear_acceleration.x', '/imu.angular_velocity.x']
    """
    import difflib

    path = str(path).strip()
    out: list[str] = []
    ext = [c for c in candidates if c.startswith(path) and c[len(path):len(path) + 1] in (".", "[")]
    out += ext
    parent = path.rsplit(".", 1)[0] if "." in path else None
    if parent:
        out += [c for c in candidates if c.startswith(parent + ".") and c not in out]
    if len(out) < n:
        scored = sorted(((difflib.SequenceMatcher(None, path, c).ratio(), -k, c) for k, c in enumerate(candidates)
                         if c not in out), reverse=True)
        out += [c for r, _, c in scored if r >= 0.5]
    return out[:n]
