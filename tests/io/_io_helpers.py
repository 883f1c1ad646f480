"""Helpers for the io tests: logs with known content written through mcap_ros2's own writer."""

from __future__ import annotations

import struct
from pathlib import Path

from mcap_ros2.writer import Writer as Ros2Writer

from vibroscope.io._ros2 import MSGDEFS

IMU = "sensor_msgs/msg/Imu"


def imu_msg(stamp_ns: int, ax: float, ay: float = 0.0, az: float = 0.0, frame_id: str = "imu") -> dict:
    return {
        "header": {"stamp": {"sec": int(stamp_ns // 1_000_000_000), "nanosec": int(stamp_ns % 1_000_000_000)},
                   "frame_id": frame_id},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        "orientation_covariance": [-1.0] + [0.0] * 8,
        "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular_velocity_covariance": [0.0] * 9,
        "linear_acceleration": {"x": float(ax), "y": float(ay), "z": float(az)},
        "linear_acceleration_covariance": [0.0] * 9,
    }


def write_imu_log(path, topics: dict, *, chunk_size: int = 1 << 20, frame_ids=None, log_times=None) -> None:
    """topics: {topic: (stamps_ns (n,), ax (n,))}; messages interleaved by log time = stamp
    (or `log_times[topic]`), written through ``mcap_ros2.writer.Writer``."""
    with open(path, "wb") as fh:
        w = Ros2Writer(fh, chunk_size=chunk_size)
        schema = w.register_msgdef(IMU, MSGDEFS[IMU])
        events = []
        for topic, (st, ax) in topics.items():
            lt = log_times[topic] if log_times and topic in log_times else st
            for k in range(len(st)):
                events.append((int(lt[k]), topic, k))
        events.sort(key=lambda e: e[0])
        for lt, topic, k in events:
            st, ax = topics[topic]
            fid = frame_ids[k % len(frame_ids)] if frame_ids else "imu"
            w.write_message(topic, schema, imu_msg(int(st[k]), ax[k], 2 * ax[k], -ax[k], fid), log_time=lt)
        w.finish()


_FOOTER = 1 + 8 + 20  # opcode, record length, (summary_start u64, summary_offset_start u64, summary_crc u32)


def _footer_fields(data) -> tuple[int, int, int, int]:
    """(footer offset, summary_start, summary_offset_start, summary_crc) of an MCAP file's bytes."""
    fpos = len(data) - 8 - _FOOTER
    assert data[fpos] == 0x02, "no footer record before the closing magic"
    return (fpos, *struct.unpack_from("<QQI", data, fpos + 9))


def copy_with_damaged_summary(src, dst):
    """`src` copied to `dst` with one byte of its summary section flipped, so that the summary
    fails its CRC-32 (the data section is untouched). Returns `dst`."""
    data = bytearray(Path(src).read_bytes())
    _, start, _, crc = _footer_fields(data)
    assert start and crc, "the file has no summary CRC to break"
    data[start + 9] ^= 0xFF  # inside the first summary record's body
    Path(dst).write_bytes(bytes(data))
    return Path(dst)


def copy_without_summary(src, dst):
    """`src` copied to `dst` with its footer saying there is no summary section
    (``summary_start = 0``, as from a writer that wrote none). Returns `dst`."""
    data = bytearray(Path(src).read_bytes())
    fpos, start, _, _ = _footer_fields(data)
    assert start, "the file has no summary section"
    struct.pack_into("<QQI", data, fpos + 9, 0, 0, 0)
    Path(dst).write_bytes(bytes(data))
    return Path(dst)
