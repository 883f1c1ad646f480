"""MCAP ingestion speed (issue 9, target 1): ROS 2 ``sensor_msgs/msg/Imu`` log to an (3, N) array.

For zstd and lz4 chunks, ``read_mcap(path, [".x", ".y", ".z"])`` (median and best of
`repeat`) against, in the same run:

* the decoded-message path of ``mcap_ros2`` (``iter_decoded_messages``), timed on the first
  `baseline_msgs` messages and scaled linearly to the whole log (it is O(n) and ~30 k msg/s);
* rerun's own MCAP reader, ``rerun.chunk.McapReader`` (``ros2msg`` decoder) streamed to
  arrow chunks and the accelerometer columns gathered into one array (when rerun is
  installed).

Every path's values are checked equal to ours. Run: ``python -m benchmarks.mcap_ingest``
(``--msgs 1e6``); ``benchmarks/run.py`` calls :func:`bench_mcap`.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _times(fn, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        gc.collect()
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def _mcap_ros2(path: Path, topic: str, limit: int) -> np.ndarray:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    vals = []
    with open(path, "rb") as f:
        r = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, _, m in r.iter_decoded_messages(topics=[topic]):
            a = m.linear_acceleration
            vals.append((a.x, a.y, a.z))
            if len(vals) >= limit:
                break
    return np.array(vals).T


def _rerun(path: Path, topic: str) -> np.ndarray | None:
    try:
        from rerun.chunk import McapReader
    except ImportError:
        return None
    parts = []
    for c in McapReader(path, decoders=["ros2msg"], include_topic_regex=[f"^{topic}$"]).stream():
        rb = c.to_record_batch()
        if c.entity_path != topic or "Scalars:scalars" not in rb.schema.names:
            continue
        flat = rb.column("Scalars:scalars").flatten().to_numpy(zero_copy_only=False)
        parts.append(flat.reshape(-1, 6)[:, 3:])  # gyroscope x, y, z then accelerometer x, y, z
    return np.concatenate(parts).T


def bench_mcap(n_msgs: int, compressions=("zstd", "lz4"), repeat: int = 5, baseline_msgs: int = 100_000,
               frame_id: str = "imu_link") -> list[dict]:
    from vibroscope import Signals
    from vibroscope.io import read_mcap, write_ros2_mcap

    rng = np.random.default_rng(1)
    topic = "/imu"
    chans = [f"{topic}.linear_acceleration.{c}" for c in "xyz"]
    sig = Signals(rng.standard_normal((3, n_msgs)), 1000.0, chans, ["m/s^2"] * 3, t0=1.7e9)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for comp in compressions:
            path = Path(d) / f"imu-{comp}.mcap"
            write_ros2_mcap(path, sig, compression=comp, frame_id=frame_id)
            got = read_mcap(path, chans)
            assert got.meta["fast_path"][topic] and np.array_equal(got.data, sig.data)
            t_ours = _times(lambda: read_mcap(path, chans), repeat)
            k = min(baseline_msgs, n_msgs)
            ref = _mcap_ros2(path, topic, k)
            assert np.array_equal(ref, got.data[:, :k]), "fast path differs from the mcap_ros2 decoder"
            t_lib = _times(lambda: _mcap_ros2(path, topic, k), 1)[0] * n_msgs / k
            rr = _rerun(path, topic)
            t_rr = None
            if rr is not None:
                assert np.array_equal(rr, got.data), "rerun's McapReader differs"
                t_rr = min(_times(lambda: _rerun(path, topic), 3))
            best, med = min(t_ours), statistics.median(t_ours)
            row = dict(case="mcap_read", size=f"{n_msgs} Imu messages, {comp}", ours_s=best, ours_median_s=med,
                       ours_msgs_per_s=n_msgs / best, ours_median_msgs_per_s=n_msgs / med,
                       baseline_s=t_lib, speedup=t_lib / best, baseline_msgs_per_s=n_msgs / t_lib,
                       baseline=f"mcap_ros2 iter_decoded_messages ({k} messages, scaled to {n_msgs})")
            if t_rr is not None:
                row.update(rerun_s=t_rr, rerun_msgs_per_s=n_msgs / t_rr, speedup_vs_rerun=t_rr / best)
            rows.append(row)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--msgs", type=float, default=1e6, help="messages in the log (default 1e6)")
    p.add_argument("--repeat", type=int, default=5, help="timed reads of ours (default 5)")
    a = p.parse_args(argv)
    for r in bench_mcap(int(a.msgs), repeat=a.repeat):
        print("  ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
