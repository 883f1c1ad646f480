"""MCAP ingestion speed (issue 9, target 1): ROS 2 ``sensor_msgs/msg/Imu`` log to an (3, N) array.

For zstd and lz4 chunks, ``read_mcap(path, [".x", ".y", ".z"])`` (median and best of
`repeat`) against, in the same run:

* the same call without the scan's speed paths (``read_mcap(LogIndex.open(path), ...)``: the
  scan is not told the wanted fields, so every chunk is decompressed into fresh memory and
  kept, and the fields are gathered afterwards on one thread);
* the decoded-message path of ``mcap_ros2`` (``iter_decoded_messages``), timed on the first
  `baseline_msgs` messages and scaled linearly to the whole log (it is O(n) and ~30 k msg/s);
* rerun's own MCAP reader, ``rerun.chunk.McapReader`` (``ros2msg`` decoder) streamed to
  arrow chunks and the accelerometer columns gathered into one array (when rerun is
  installed).

With ``--mixed``, the same for Imu logs with frame ids of every length 0..40 (random per
message) and jittered stamps (written through ``mcap``'s writer; slow to write).

JSON and protobuf logs of the same three accelerations (one message per sample, zstd
chunks, `slow_msgs` messages: they are decoded message by message) are read too, against
the ``mcap`` reader's own loop over the messages with ``json.loads`` / ``mcap_protobuf``'s
decoder. Every path's values are checked equal to ours; the load average of the machine is
printed with the rows. Run: ``python benchmarks/mcap_ingest.py`` (``--msgs 1e6``);
``benchmarks/run.py`` calls :func:`bench_mcap`.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import times  # noqa: E402


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


def _accel_pb_class():
    """A protobuf message class ``Accel {double x, y, z}`` built at run time."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fdp = descriptor_pb2.FileDescriptorProto(name="vibroscope_bench_accel.proto", package="vibroscope_bench",
                                             syntax="proto3")
    m = fdp.message_type.add(name="Accel")
    for i, c in enumerate("xyz"):
        m.field.add(name=c, number=i + 1, type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE,
                    label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("vibroscope_bench.Accel"))


def _write_protobuf(path: Path, topic: str, data: np.ndarray, t0_ns: int, period_ns: int) -> None:
    from mcap_protobuf.writer import Writer

    cls = _accel_pb_class()
    with open(path, "wb") as fh, Writer(fh) as w:
        for k, (x, y, z) in enumerate(data.T.tolist()):
            t = t0_ns + k * period_ns
            w.write_message(topic, cls(x=x, y=y, z=z), log_time=t, publish_time=t)


def _json_loop(path: Path, topic: str) -> np.ndarray:
    import json

    from mcap.reader import make_reader

    vals = []
    with open(path, "rb") as f:
        for _, _, m in make_reader(f).iter_messages(topics=[topic]):
            a = json.loads(m.data)["linear_acceleration"]
            vals.append((a["x"], a["y"], a["z"]))
    return np.array(vals).T


def _protobuf_loop(path: Path, topic: str) -> np.ndarray:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    vals = []
    with open(path, "rb") as f:
        for _, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=[topic]):
            vals.append((m.x, m.y, m.z))
    return np.array(vals).T


def _write_mixed(path: Path, data: np.ndarray, compression: str, t0_ns: int, period_ns: int, seed: int = 3) -> None:
    """An Imu log with frame ids of every length 0..40 (random per message) and stamps jittered
    by up to 0.4 % of a period (on the grid: placed by index), through ``mcap``'s own writer."""
    from mcap.writer import CompressionType, Writer

    from vibroscope.io._ros2 import MSGDEFS, encode_fixed

    rng = np.random.default_rng(seed)
    n = data.shape[1]
    st = t0_ns + np.arange(n, dtype=np.int64) * period_ns + rng.integers(-period_ns // 250, period_ns // 250, n)
    lens = rng.integers(0, 41, n)
    sec, nsec = st // 1_000_000_000, st % 1_000_000_000
    payloads = [None] * n
    for m in range(41):  # one batch per frame id length
        idx = np.flatnonzero(lens == m)
        vals = {f"linear_acceleration.{c}": data[i, idx] for i, c in enumerate("xyz")}
        enc = encode_fixed("sensor_msgs/msg/Imu", sec[idx], nsec[idx], vals, frame_id="f" * m)
        for j, k in enumerate(idx.tolist()):
            payloads[k] = enc[j].tobytes()
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}[compression]
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=1 << 20, compression=comp)
        w.start("ros2", "bench")
        sid = w.register_schema("sensor_msgs/msg/Imu", "ros2msg", MSGDEFS["sensor_msgs/msg/Imu"].encode())
        cid = w.register_channel("/imu", "cdr", sid)
        add = w.add_message
        for k, t in enumerate(st.tolist()):
            add(channel_id=cid, log_time=t, data=payloads[k], publish_time=t, sequence=k)
        w.finish()


def _plain(path: Path, chans: list[str]):
    """read_mcap without the scan's speed paths: the scan is not told the wanted fields."""
    from vibroscope.io import read_mcap
    from vibroscope.io.log_index import LogIndex

    return read_mcap(LogIndex.open(path), chans)


def bench_formats(n_msgs: int, formats=("json", "protobuf"), repeat: int = 3) -> list[dict]:
    """JSON and protobuf logs of `n_msgs` messages (three accelerations each): ``read_mcap``
    against the ``mcap`` reader's loop decoding every message (values checked equal)."""
    from vibroscope import Signals
    from vibroscope.io import read_mcap, write_json_mcap

    rng = np.random.default_rng(2)
    topic = "/imu"
    data = rng.standard_normal((3, n_msgs))
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for fmt in formats:
            path = Path(d) / f"accel-{fmt}.mcap"
            if fmt == "json":
                chans = [f"{topic}.linear_acceleration.{c}" for c in "xyz"]
                write_json_mcap(path, Signals(data=data, fs=1000.0, channels=chans, units=["m/s^2"] * 3, t0=1.7e9))
                base, what = _json_loop, "mcap iter_messages + json.loads"
            else:
                chans = [f"{topic}.{c}" for c in "xyz"]
                _write_protobuf(path, topic, data, 1_700_000_000_000_000_000, 1_000_000)
                base, what = _protobuf_loop, "mcap_protobuf iter_decoded_messages"
            got = read_mcap(path, chans)
            assert np.array_equal(got.data, data), f"{fmt}: read_mcap differs from the values written"
            assert np.array_equal(base(path, topic), data), f"{fmt}: the baseline differs"
            t_ours = times(lambda: read_mcap(path, chans), repeat)
            t_base = min(times(lambda: base(path, topic), 2))
            best, med = min(t_ours), statistics.median(t_ours)
            rows.append(dict(case="mcap_read", size=f"{n_msgs} messages, {fmt}, zstd", ours_s=best, ours_median_s=med,
                             ours_msgs_per_s=n_msgs / best, baseline_s=t_base, baseline_msgs_per_s=n_msgs / t_base,
                             speedup=t_base / best, baseline=what))
    return rows


def bench_mcap(n_msgs: int, compressions=("zstd", "lz4"), repeat: int = 5, baseline_msgs: int = 100_000,
               frame_id: str = "imu_link", formats=("json", "protobuf"), slow_msgs: int = 100_000) -> list[dict]:
    """The Imu cases (`compressions`: ``"zstd"``, ``"lz4"``, and with ``"-mixed"`` appended the
    same with frame ids of mixed lengths and jittered stamps), then :func:`bench_formats` on
    ``min(n_msgs, slow_msgs)`` messages (none when `formats` is empty)."""
    from vibroscope import Signals
    from vibroscope.io import read_mcap, write_ros2_mcap

    rng = np.random.default_rng(1)
    topic = "/imu"
    chans = [f"{topic}.linear_acceleration.{c}" for c in "xyz"]
    sig = Signals(data=rng.standard_normal((3, n_msgs)), fs=1000.0, channels=chans, units=["m/s^2"] * 3, t0=1.7e9)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for comp in compressions:
            mixed = comp.endswith("-mixed")
            comp = comp.removesuffix("-mixed")
            path = Path(d) / f"imu-{comp}{'-mixed' if mixed else ''}.mcap"
            if mixed:
                _write_mixed(path, sig.data, comp, int(sig.t0 * 1e9), 1_000_000)
            else:
                write_ros2_mcap(path, sig, compression=comp, frame_id=frame_id)
            os.sync()  # the kernel's write-back of the new file would otherwise run during the timed reads
            got = read_mcap(path, chans)
            assert got.meta["fast_path"][topic] and np.array_equal(got.data, sig.data)
            assert np.array_equal(_plain(path, chans).data, sig.data)
            t_ours = times(lambda: read_mcap(path, chans), repeat)
            t_plain = min(times(lambda: _plain(path, chans), max(1, repeat // 2)))
            k = min(baseline_msgs, n_msgs)
            ref = _mcap_ros2(path, topic, k)
            assert np.array_equal(ref, got.data[:, :k]), "fast path differs from the mcap_ros2 decoder"
            t_lib = times(lambda: _mcap_ros2(path, topic, k), 1)[0] * n_msgs / k
            rr = _rerun(path, topic)
            t_rr = None
            if rr is not None:
                assert np.array_equal(rr, got.data), "rerun's McapReader differs"
                t_rr = min(times(lambda: _rerun(path, topic), 3))
            best, med = min(t_ours), statistics.median(t_ours)
            what = f"{comp}, frame ids of 0..40 bytes, jittered stamps" if mixed else comp
            row = dict(case="mcap_read", size=f"{n_msgs} Imu messages, {what}", ours_s=best, ours_median_s=med,
                       ours_msgs_per_s=n_msgs / best, ours_median_msgs_per_s=n_msgs / med,
                       plain_s=t_plain, speedup_vs_plain=t_plain / best,
                       baseline_s=t_lib, speedup=t_lib / best, baseline_msgs_per_s=n_msgs / t_lib,
                       baseline=f"mcap_ros2 iter_decoded_messages ({k} messages, scaled to {n_msgs})")
            if t_rr is not None:
                row.update(rerun_s=t_rr, rerun_msgs_per_s=n_msgs / t_rr, speedup_vs_rerun=t_rr / best)
            rows.append(row)
    if formats:
        rows += bench_formats(min(n_msgs, slow_msgs), formats, repeat=min(repeat, 3))
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--msgs", type=float, default=1e6, help="messages in the log (default 1e6)")
    p.add_argument("--repeat", type=int, default=5, help="timed reads of ours (default 5)")
    p.add_argument("--slow-msgs", type=float, default=1e5, help="messages of the JSON and protobuf logs (default 1e5)")
    p.add_argument("--only", choices=["imu", "formats"], help="only the Imu cases, or only JSON and protobuf")
    p.add_argument("--mixed", action="store_true", help="also Imu logs with frame ids of mixed lengths and jittered "
                                                        "stamps (zstd, lz4; slow to write)")
    a = p.parse_args(argv)
    load = os.getloadavg()
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} cores)")
    if a.only == "formats":
        rows = bench_formats(int(a.slow_msgs), repeat=min(a.repeat, 3))
    else:
        comps = ("zstd", "lz4", "zstd-mixed", "lz4-mixed") if a.mixed else ("zstd", "lz4")
        rows = bench_mcap(int(a.msgs), comps, repeat=a.repeat, slow_msgs=int(a.slow_msgs),
                          formats=() if a.only == "imu" else ("json", "protobuf"))
    load = os.getloadavg()
    print(f"load average after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    for r in rows:
        print("  ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
