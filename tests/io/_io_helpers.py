"""Helpers for the io tests: logs with known content written through mcap_ros2's own writer."""

from __future__ import annotations

import numpy as np
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
