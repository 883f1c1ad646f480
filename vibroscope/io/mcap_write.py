"""Writing :class:`~vibroscope.signals.Signals` as MCAP logs that read like real recordings."""

from __future__ import annotations

import json
import re
from collections import defaultdict
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from vibroscope.errors import ChannelError
from vibroscope._checks import atomic_file
from vibroscope.io import _ros2
from vibroscope.io.paths import MessagePath, format_path, parse_path
from vibroscope.signals import Signals

__all__ = ["write_ros2_mcap", "write_json_mcap", "stamps_ns", "UNITS_KEY", "channel_units"]

IMU = "sensor_msgs/msg/Imu"
WRENCH = "geometry_msgs/msg/WrenchStamped"

#: key of the MCAP Channel record's ``metadata`` entry that holds the units of its fields:
#: a JSON object ``{"linear_acceleration.x": "m/s^2", ...}`` (field path after the topic)
UNITS_KEY = "vibroscope.units"

#: units the ROS 2 message definitions fix for their fields (REP 103), by field-path prefix
_ROS_UNITS = (
    ("linear_acceleration.", "m/s^2"),
    ("angular_velocity.", "rad/s"),
    ("wrench.force.", "N"),
    ("wrench.torque.", "N m"),
)


def stamps_ns(signals: Signals) -> np.ndarray:
    """Sample stamps of `signals` as written to MCAP.

    Parameters
    ----------
    signals : Signals
        Uses `t0` (s) and `fs` (Hz).

    Returns
    -------
    ndarray of int64, shape (n_samples,)
        ``round(t0 * 1e9) + round(k * 1e9 / fs)`` in ns.
    """
    t0 = int(round(signals.t0 * 1e9))
    return t0 + np.round(np.arange(signals.n_samples) * (1e9 / signals.fs)).astype(np.int64)


def sanitize_name(name: str) -> str:
    """A channel name as a topic or field name: characters other than letters, digits and ``_``
    become ``_`` (leading and trailing ``/`` dropped), prefixed ``c_`` where it would not start with
    a letter or ``_``."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", name.strip().strip("/"))
    if not s or not (s[0].isalpha() or s[0] == "_"):
        s = "c_" + s
    return s


def _as_path(name: str) -> MessagePath | None:
    if not name.startswith("/") or "." not in name:
        return None
    try:
        mp = parse_path(name)
    except ChannelError:
        return None
    return mp if mp.fields else None


def _plan(
    signals: Signals,
    *,
    force_channels: Iterable[str] = (),
    accel_channels: Iterable[str] = (),
    json_topic: str = "/signals",
    ros: bool = True,
) -> dict[str, tuple[str, list[tuple[int, str | tuple]]]]:
    """{topic: (kind, [(row, field path)])} with kind IMU, WRENCH or "json"."""
    force_channels, accel_channels = set(force_channels), set(accel_channels)
    unknown = (force_channels | accel_channels) - set(signals.channels)
    if unknown:
        raise ChannelError(f"no channels {sorted(unknown)} in the signals; channels are {list(signals.channels)}")
    groups: dict[str, list[tuple[int, tuple]]] = defaultdict(list)
    for i, name in enumerate(signals.channels):
        if name in force_channels:
            groups["/" + sanitize_name(name)].append((i, ("wrench", "force", "x")))
        elif name in accel_channels:
            groups["/" + sanitize_name(name)].append((i, ("linear_acceleration", "x")))
        else:
            mp = _as_path(name)
            if mp is None:
                groups[json_topic].append((i, (sanitize_name(name),)))
            else:
                groups[mp.topic].append((i, mp.fields))
    plan = {}
    for topic, items in groups.items():
        kind = "json"
        if ros:
            for t in (IMU, WRENCH):
                names = {format_path("", f).lstrip(".") for _, f in items}
                if names <= set(_ros2.FLOAT_FIELDS[t]):
                    kind = t
                    break
        seen = set()
        for _, f in items:
            if f in seen:
                raise ChannelError(f"topic {topic!r}: field {format_path(topic, f)!r} given twice")
            seen.add(f)
        plan[topic] = (kind, items)
    return plan


def _json_schema(items: Sequence[tuple[int, tuple]]) -> dict[str, Any]:
    root: dict[str, Any] = {"type": "object", "properties": {}}

    def add(node: dict, fields: tuple) -> None:
        f = fields[0]
        if isinstance(f, int):
            raise ChannelError(f"JSON channels cannot use array indices ({fields})")
        if len(fields) == 1:
            node["properties"][f] = {"type": "number"}
        else:
            child = node["properties"].setdefault(f, {"type": "object", "properties": {}})
            add(child, fields[1:])

    for _, f in items:
        add(root, f)
    root["properties"]["header"] = {
        "type": "object",
        "properties": {
            "stamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nanosec": {"type": "integer"}}}
        },
    }
    return root


def _json_payloads(signals: Signals, items, sec, nsec) -> list[bytes]:
    rows = [(f, signals.data[i].tolist()) for i, f in items]
    out = []
    for k in range(signals.n_samples):
        msg: dict[str, Any] = {"header": {"stamp": {"sec": int(sec[k]), "nanosec": int(nsec[k])}}}
        for f, vals in rows:
            node = msg
            for name in f[:-1]:
                node = node.setdefault(name, {})
            node[f[-1]] = vals[k]
        out.append(json.dumps(msg, separators=(",", ":")).encode())
    return out


def channel_units(signals: Signals, kind: str, items: Sequence[tuple[int, tuple]]) -> dict[str, str]:
    """The units a topic's Channel record stores under :data:`UNITS_KEY`.

    Parameters
    ----------
    signals : Signals
        The signals written; ``signals.units[i]`` is the unit of row ``i``.
    kind : str
        The topic's message type (``sensor_msgs/msg/Imu``, ``geometry_msgs/msg/WrenchStamped``)
        or ``"json"``.
    items : sequence of (int, tuple)
        ``(row, fields)`` of the channels written to the topic.

    Returns
    -------
    dict of str to str
        ``{field path after the topic: unit}`` (``format_path("", fields).lstrip(".")``, e.g.
        ``"wrench.force.x": "N"``) for every written channel whose unit is known: the
        channel's own unit, else (ROS 2 types only) the unit the message definition fixes
        (``linear_acceleration.*`` m/s^2, ``angular_velocity.*`` rad/s, ``wrench.force.*`` N,
        ``wrench.torque.*`` N m). A channel of unknown unit has no entry (readers then fall
        back to their own heuristic); nothing is guessed from a channel name.
    """
    out: dict[str, str] = {}
    for i, f in items:
        key = format_path("", f).lstrip(".")
        unit = str(signals.units[i] or "").strip()
        if not unit and kind != "json":
            unit = next((u for prefix, u in _ROS_UNITS if key.startswith(prefix)), "")
        if unit:
            out[key] = unit
    return out


def _write(path, signals: Signals, plan, *, frame_id: str, chunk_size: int, compression: str, progress: bool) -> Path:
    """Write to a temporary file beside `path`, renamed to `path` only when complete."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"output {str(path)!r} is a directory; name an output file")
    if not path.parent.is_dir():
        raise ValueError(f"output {str(path)!r}: the directory {str(path.parent)!r} does not exist")
    with atomic_file(path) as tmp:
        _write_to(tmp, path.name, signals, plan, frame_id=frame_id, chunk_size=chunk_size,
                  compression=compression, progress=progress)
    return path


def _write_to(tmp: Path, label: str, signals: Signals, plan, *, frame_id: str, chunk_size: int, compression: str,
              progress: bool) -> None:
    from mcap.writer import CompressionType, Writer

    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE, "": CompressionType.NONE}
    if compression not in comp:
        raise ValueError(f"{compression=} must be one of {sorted(comp)}")
    st = stamps_ns(signals)
    if st.size and st[0] < 0:
        raise ValueError(f"{signals.t0=} must be >= 0 s (MCAP times are unsigned ns)")
    sec, nsec = st // 1_000_000_000, st % 1_000_000_000
    if st.size and sec[-1] > 2**31 - 1:
        raise ValueError("stamps beyond 2038 do not fit builtin_interfaces/Time.sec (int32)")
    n = signals.n_samples
    with open(tmp, "xb") as fh:  # "x": a fresh file with the umask's permissions
        w = Writer(fh, chunk_size=chunk_size, compression=comp[compression], enable_crcs=True, enable_data_crcs=True)
        ros = any(k != "json" for k, _ in plan.values())
        w.start(profile="ros2" if ros else "", library="vibroscope")
        schema_ids: dict[str, int] = {}
        chans = []
        for topic, (kind, items) in plan.items():
            units = channel_units(signals, kind, items)
            meta = {UNITS_KEY: json.dumps(units, separators=(",", ":"))}
            if kind == "json":
                sid = w.register_schema(topic.strip("/").replace("/", ".") or "signals", "jsonschema",
                                        json.dumps(_json_schema(items)).encode())
                cid = w.register_channel(topic, "json", sid, metadata=meta)
                payloads: Any = _json_payloads(signals, items, sec, nsec)
            else:
                if kind not in schema_ids:
                    schema_ids[kind] = w.register_schema(kind, "ros2msg", _ros2.MSGDEFS[kind].encode())
                cid = w.register_channel(topic, "cdr", schema_ids[kind], metadata=meta)
                values = {format_path("", f).lstrip("."): signals.data[i] for i, f in items}
                payloads = _ros2.encode_fixed(kind, sec, nsec, values, frame_id=frame_id)
            chans.append((cid, payloads))
        stl = st.tolist()
        it = range(n)
        if progress:
            from tqdm.auto import tqdm

            it = tqdm(it, desc=label, unit="sample")
        add = w.add_message
        for k in it:
            t = stl[k]
            for cid, pl in chans:
                add(channel_id=cid, log_time=t, data=bytes(pl[k]), publish_time=t, sequence=k)
        w.add_metadata("vibroscope", {"fs": repr(signals.fs), "t0": repr(signals.t0), "n_samples": str(n)})
        w.finish()


def write_ros2_mcap(
    path: str | Path,
    signals: Signals,
    *,
    force_channels: Iterable[str] = (),
    accel_channels: Iterable[str] = (),
    json_topic: str = "/signals",
    frame_id: str = "",
    chunk_size: int = 1 << 20,
    compression: str = "zstd",
    progress: bool = False,
) -> Path:
    """Write `signals` as a ROS 2 MCAP log, one message per sample and topic.

    Parameters
    ----------
    path : str or Path
        Output file.
    signals : Signals
        Channels named by message paths pick their topic and field:
        ``/imu/m1.linear_acceleration.x`` (also ``angular_velocity.*``, ``orientation.*``)
        becomes ``sensor_msgs/msg/Imu``, ``/ft.wrench.force.x`` (``wrench.torque.*``)
        ``geometry_msgs/msg/WrenchStamped``. Fields not given are 0, except the Imu's
        ``orientation_covariance[0] = -1`` (orientation unknown). Channels of any other
        form are written as JSON messages (schema ``jsonschema``): ``/topic.a.b`` as field
        ``a.b`` of topic ``/topic``; a plain name as a field of `json_topic`.
    force_channels, accel_channels : iterable of str, optional
        Plain channel names to write as ``wrench.force.x`` of a WrenchStamped topic /
        ``linear_acceleration.x`` of an Imu topic named ``/<name>``.
    json_topic : str, optional
        Topic of the plain-named channels written as JSON.
    frame_id : str, optional
        ``header.frame_id`` of every ROS message.
    chunk_size : int, optional
        Chunk size in bytes.
    compression : {"zstd", "lz4", "none"}, optional
    progress : bool, optional
        Show a tqdm bar.

    Returns
    -------
    Path

    Raises
    ------
    ChannelError
        If a field repeats within a topic or a named channel does not exist.
    ValueError
        If `t0` is negative, or `path` is a directory or in a directory that does not exist.

    See Also
    --------
    write_json_mcap : The same signals as JSON-encoded messages.
    vibroscope.io.read_mcap : Read the log back as Signals.

    Notes
    -----
    Header stamps are ``t0 + k / fs`` rounded to int ns; the log time and publish time
    equal the stamp. The ROS 2 message definitions are stored as ROS 2 bags store them (the
    dependent types after ``====...`` / ``MSG: pkg/Type`` lines), so any ROS 2 tool decodes
    them; the payloads are serialised with numpy and equal ``mcap_ros2``'s byte for byte.

    Each Channel record's ``metadata`` holds the units of the fields written on it under
    the key ``"vibroscope.units"`` (:data:`UNITS_KEY`): a JSON object mapping the field path
    after the topic to its unit, ``{"linear_acceleration.x": "m/s^2"}`` (see
    :func:`channel_units`).

    The file is written under a temporary name in the same directory
    (``.NAME.PID-XXXXXXXX.part``) and renamed to `path` only when complete, so an
    interrupted or failed write leaves no truncated `path` (and an existing `path` intact).
    """
    plan = _plan(signals, force_channels=force_channels, accel_channels=accel_channels, json_topic=json_topic)
    return _write(path, signals, plan, frame_id=frame_id, chunk_size=chunk_size, compression=compression, progress=progress)


def write_json_mcap(
    path: str | Path,
    signals: Signals,
    *,
    json_topic: str = "/signals",
    chunk_size: int = 1 << 20,
    compression: str = "zstd",
    progress: bool = False,
) -> Path:
    """Write `signals` as JSON-encoded MCAP messages (``/topic.field`` layout, see
    :func:`write_ros2_mcap`), with ``header.stamp`` in every message.

    Parameters
    ----------
    path : str or Path
        Output file.
    signals : Signals
        Channels; plain names become fields of `json_topic`.
    json_topic : str, optional
    chunk_size : int, optional
    compression : {"zstd", "lz4", "none"}, optional
    progress : bool, optional

    Returns
    -------
    Path

    See Also
    --------
    write_ros2_mcap : The same signals as ROS 2 (CDR) messages.
    vibroscope.io.read_mcap : Read the log back as Signals.

    Notes
    -----
    Units and the temporary-name write as in :func:`write_ros2_mcap`.
    """
    plan = _plan(signals, json_topic=json_topic, ros=False)
    return _write(path, signals, plan, frame_id="", chunk_size=chunk_size, compression=compression, progress=progress)
