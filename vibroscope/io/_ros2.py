"""ROS 2 message definitions and the fixed-layout CDR fast path (decode and encode with numpy).

``sensor_msgs/msg/Imu`` and ``geometry_msgs/msg/WrenchStamped`` serialised as little-endian
CDR (XCDR1) have a fixed layout once the length of ``header.frame_id`` is fixed:

    encapsulation header (4 bytes) | int32 sec | uint32 nanosec | uint32 n | n bytes frame_id
    (NUL included) | padding to 8 (relative to the end of the encapsulation header) | float64...

so a block of equally long payloads is one numpy structured array.
"""

from __future__ import annotations

import threading

import numpy as np

from vibroscope.io.timebase import stamps_ns

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


def _gather_fixed(buf, st, ln, nfloats, cols, sec, nsec, out):  # pragma: no cover - compiled by numba
    """Check and gather fixed-layout payloads in one pass (numba kernel, the GIL released).

    Payload i is ``buf[st[i] : st[i] + ln[i]]``: it must be CDR little-endian with exactly
    `nfloats` float64 after the place its frame_id length puts the first. Fills `sec`, `nsec`
    and ``out[k, i]`` with the 8 bytes of float ``cols[k]`` (``out`` is uint64: the bytes are
    moved, not converted). Returns 0, or 1 at the first payload that does not fit.
    """
    nb = buf.size
    for i in range(st.size):
        s = st[i]
        n = ln[i]
        if s < 0 or n < 16 or s + n > nb or buf[s] != 0 or buf[s + 1] != 1:
            return 1
        flen = np.int64(buf[s + 12]) | (np.int64(buf[s + 13]) << 8) | (np.int64(buf[s + 14]) << 16) \
            | (np.int64(buf[s + 15]) << 24)
        first = 4 + (12 + flen + 7) // 8 * 8
        if first + 8 * nfloats != n:
            return 1
        sv = np.int64(buf[s + 4]) | (np.int64(buf[s + 5]) << 8) | (np.int64(buf[s + 6]) << 16) \
            | (np.int64(buf[s + 7]) << 24)
        sec[i] = sv - ((sv >> 31) << 32)  # int32, two's complement
        nsec[i] = np.int64(buf[s + 8]) | (np.int64(buf[s + 9]) << 8) | (np.int64(buf[s + 10]) << 16) \
            | (np.int64(buf[s + 11]) << 24)
        for k in range(cols.size):
            a = s + first + 8 * cols[k]
            v = np.uint64(0)
            for b in range(8):
                v |= np.uint64(buf[a + b]) << np.uint64(8 * b)
            out[k, i] = v
    return 0


_KERNEL: list = []
_KERNEL_LOCK = threading.Lock()


def _gather_kernel():
    """The compiled :func:`_gather_fixed`, or None without numba."""
    with _KERNEL_LOCK:
        if not _KERNEL:
            try:
                import numba
            except ImportError:  # pragma: no cover - numba is a dependency
                _KERNEL.append(None)
            else:
                _KERNEL.append(numba.njit(cache=True, nogil=True)(_gather_fixed))
        return _KERNEL[0]


def decode_block(buf, st: np.ndarray, ln: np.ndarray, tname: str, names: list[str] | tuple[str, ...],
                 compiled: bool = True):
    """Stamps and fields of fixed-layout payloads of one block (a chunk's bytes), or None.

    Parameters
    ----------
    buf : bytes-like
        The block's bytes (a decompressed chunk); only ``buf[st[i] : st[i] + ln[i]]`` is read.
    st : ndarray of int, shape (m,)
        Byte offset of each payload in `buf` (m >= 1).
    ln : ndarray of int, shape (m,)
        Byte length of each payload.
    tname : str
        The message type, a key of :data:`FLOAT_FIELDS`.
    names : sequence of str
        Fields wanted: :data:`FLOAT_FIELDS` of `tname` or :data:`STAMP_FIELDS`.

    compiled : bool, optional
        Payloads that are not one strided view (frame ids of mixed lengths, irregular
        interleaving) are checked and gathered in one pass of a compiled kernel (numba, the GIL
        released; default); False, or without numba, by numpy gathers (the same result).

    Returns
    -------
    (ndarray of int64 shape (m,), list of ndarray shape (m,)) or None
        ``header.stamp`` in ns and one array per name (float64; int32 / uint32 for the stamp
        fields), or None when one payload does not fit the fixed layout (CDR little-endian,
        a frame_id of any length, no byte more or less than the layout). The arrays may be
        views of `buf`.

    Notes
    -----
    Payloads of one length evenly spaced (one topic, or topics interleaved in a fixed
    pattern) are one strided numpy view; in any other block (frame ids of mixed lengths,
    irregular interleaving) each field is gathered at its byte offsets.
    """
    m = st.size
    L = int(ln[0])
    if m == 1 or (ln.min() == ln.max() and (d := np.diff(st)).min() == d.max() and d[0] >= L):
        lay = layout_of_length(tname, L)
        if lay is None:
            return None
        first, dt = lay
        step = int(st[1] - st[0]) if m > 1 else L
        p = np.ndarray((m,), dtype=dt, buffer=buf, offset=int(st[0]), strides=(step,))
        if not (p["_cdr"] == 0x0100).all() or not flen_fits(p["_flen"], first):
            return None
        stamps = stamps_ns(p["header.stamp.sec"], p["header.stamp.nanosec"])  # nanosec >= 1e9: invalid
        return stamps, [p[n] for n in names]
    floats = FLOAT_FIELDS[tname]
    kernel = _gather_kernel() if compiled else None
    if kernel is not None:
        cols = np.array([floats.index(n) for n in names if n not in STAMP_FIELDS], np.int64)
        sec, nsec = np.empty(m, np.int32), np.empty(m, np.uint32)
        out = np.empty((cols.size, m), np.uint64)
        if kernel(np.frombuffer(buf, np.uint8), st.astype(np.int64, copy=False), ln.astype(np.int64, copy=False),
                  len(floats), cols, sec, nsec, out):
            return None
        f64 = iter(out.view("<f8"))
        vals = [sec if n == STAMP_FIELDS[0] else nsec if n == STAMP_FIELDS[1] else next(f64) for n in names]
        return stamps_ns(sec, nsec), vals
    nb = len(buf)
    st, ln = st.astype(np.int64), ln.astype(np.int64)
    if int(st.min()) < 0 or int(ln.min()) < 16 or int((st + ln).max()) > nb:
        return None

    def at(dtype: str, offs: np.ndarray) -> np.ndarray:  # values of `dtype` at any byte offsets
        size = np.dtype(dtype).itemsize
        return np.ndarray((nb - size + 1,), dtype, buf, 0, (1,))[offs]

    if not (at("<u2", st) == 0x0100).all():
        return None
    first = 4 + (12 + at("<u4", st + 12).astype(np.int64) + 7) // 8 * 8
    if not (first + 8 * len(floats) == ln).all():
        return None
    sec, nsec = at("<i4", st + 4), at("<u4", st + 8)
    first += st
    cols = {"header.stamp.sec": sec, "header.stamp.nanosec": nsec}
    vals = [cols[n] if n in cols else at("<f8", first + 8 * floats.index(n)) for n in names]
    return stamps_ns(sec, nsec), vals


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
