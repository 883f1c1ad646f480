"""ROS 2 message definitions and the fixed-layout CDR fast path (decode and encode with numpy).

``sensor_msgs/msg/Imu`` and ``geometry_msgs/msg/WrenchStamped`` serialised as little-endian
CDR (XCDR1) have a fixed layout once the length of ``header.frame_id`` is fixed:

    encapsulation header (4 bytes) | int32 sec | uint32 nanosec | uint32 n | n bytes frame_id
    (NUL included) | padding to 8 (relative to the end of the encapsulation header) | float64...

so a block of equally long payloads is one numpy structured array.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SEP = "=" * 80 + "\n"

_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_VEC3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_WRENCH = "MSG: geometry_msgs/Wrench\nVector3  force\nVector3  torque\n"

#: message definitions as ROS 2 bag files store them (dependent types after separator lines)
MSGDEFS: dict[str, str] = {
    "sensor_msgs/msg/Imu": (
        "std_msgs/Header header\n"
        "geometry_msgs/Quaternion orientation\n"
        "float64[9] orientation_covariance\n"
        "geometry_msgs/Vector3 angular_velocity\n"
        "float64[9] angular_velocity_covariance\n"
        "geometry_msgs/Vector3 linear_acceleration\n"
        "float64[9] linear_acceleration_covariance\n"
        + SEP + _HEADER + SEP + _TIME + SEP + _QUAT + SEP + _VEC3
    ),
    "geometry_msgs/msg/WrenchStamped": (
        "std_msgs/Header header\nWrench wrench\n"
        + SEP + _HEADER + SEP + _TIME + SEP + _WRENCH + SEP + _VEC3
    ),
}


def _vec(prefix: str, names: str = "xyz") -> list[str]:
    return [f"{prefix}.{c}" for c in names]


def _cov(prefix: str) -> list[str]:
    return [f"{prefix}[{i}]" for i in range(9)]


#: float64 leaf paths in serialisation order
FLOAT_FIELDS: dict[str, tuple[str, ...]] = {
    "sensor_msgs/msg/Imu": tuple(
        _vec("orientation", "xyzw")
        + _cov("orientation_covariance")
        + _vec("angular_velocity")
        + _cov("angular_velocity_covariance")
        + _vec("linear_acceleration")
        + _cov("linear_acceleration_covariance")
    ),
    "geometry_msgs/msg/WrenchStamped": tuple(_vec("wrench.force") + _vec("wrench.torque")),
}

STAMP_FIELDS = ("header.stamp.sec", "header.stamp.nanosec")


def _layout(frame_len: int) -> int:
    """Offset (in the payload) of the first float64 for a frame_id of `frame_len` bytes incl. NUL."""
    p = 12 + frame_len  # relative to the end of the 4-byte encapsulation header
    p = (p + 7) // 8 * 8
    return 4 + p


@dataclass(frozen=True)
class FastLayout:
    """The structured dtype of one fixed-layout payload."""

    type_name: str
    payload_len: int
    frame_len: int
    dtype: np.dtype


def layout_for(type_name: str, payload: bytes) -> FastLayout | None:
    """The fixed layout of `type_name` given one sample payload, or None if it does not fit."""
    floats = FLOAT_FIELDS.get(type_name)
    if floats is None or len(payload) < 16 or payload[:2] != b"\x00\x01":
        return None
    frame_len = int.from_bytes(payload[12:16], "little")
    first = _layout(frame_len)
    if first + 8 * len(floats) != len(payload):
        return None
    names = ["_cdr", "_flen", "header.stamp.sec", "header.stamp.nanosec", *floats]
    formats = ["<u2", "<u4", "<i4", "<u4", *(["<f8"] * len(floats))]
    offsets = [0, 12, 4, 8, *(first + 8 * i for i in range(len(floats)))]
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": len(payload)})
    return FastLayout(type_name, len(payload), frame_len, dt)


def layout_of_length(type_name: str, length: int) -> tuple[int, np.dtype] | None:
    """(offset of the first float64, structured dtype) of a `type_name` payload of `length` bytes,
    or None when no frame_id length gives that payload length.

    The frame_id length (``_flen``, NUL included) of a payload of this layout lies in
    ``[first - 23, first - 16]`` (see :func:`flen_fits`); the dtype reads it with the CDR
    encapsulation (``_cdr``) so that the caller checks both.
    """
    key = (type_name, length)
    got = _LAYOUTS.get(key)
    if got is None and key not in _LAYOUTS:
        floats = FLOAT_FIELDS.get(type_name)
        first = length - 8 * len(floats) if floats else -1
        if floats is None or first < 20 or (first - 4) % 8:
            got = None
        else:
            names = ["_cdr", "_flen", "header.stamp.sec", "header.stamp.nanosec", *floats]
            formats = ["<u2", "<u4", "<i4", "<u4", *(["<f8"] * len(floats))]
            offsets = [0, 12, 4, 8, *(first + 8 * i for i in range(len(floats)))]
            got = first, np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": length})
        _LAYOUTS[key] = got
    return got


_LAYOUTS: dict[tuple[str, int], tuple[int, np.dtype] | None] = {}


def flen_fits(flen: np.ndarray, first: int) -> bool:
    """Whether every frame_id length `flen` (NUL included) puts the first float64 at `first`."""
    lo, hi = int(flen.min()), int(flen.max())
    return _layout(lo) == first and _layout(hi) == first


def encode_fixed(
    type_name: str,
    sec: np.ndarray,
    nanosec: np.ndarray,
    values: dict[str, np.ndarray],
    frame_id: str = "",
) -> np.ndarray:
    """Serialise n messages at once; returns an (n, payload_len) uint8 array.

    Fields absent from `values` are 0, except ``sensor_msgs/msg/Imu``'s
    ``orientation_covariance[0]`` = -1 (orientation unknown, REP 145).
    """
    fid = frame_id.encode() + b"\x00"
    floats = FLOAT_FIELDS[type_name]
    first = _layout(len(fid))
    L = first + 8 * len(floats)
    n = len(sec)
    out = np.zeros((n, L), np.uint8)
    out[:, 1] = 1  # CDR_LE
    out[:, 4:8] = np.asarray(sec, "<i4").reshape(-1, 1).view(np.uint8)
    out[:, 8:12] = np.asarray(nanosec, "<u4").reshape(-1, 1).view(np.uint8)
    out[:, 12:16] = np.frombuffer(np.uint32(len(fid)).astype("<u4").tobytes(), np.uint8)
    out[:, 16 : 16 + len(fid)] = np.frombuffer(fid, np.uint8)
    f = np.zeros((n, len(floats)), "<f8")
    if type_name == "sensor_msgs/msg/Imu":
        f[:, floats.index("orientation_covariance[0]")] = -1.0
    for name, v in values.items():
        f[:, floats.index(name)] = v
    out[:, first:] = f.view(np.uint8)
    return out
