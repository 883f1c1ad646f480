"""Write -> read round trips (ROS 2, JSON, protobuf), the CDR fast path against the generic
decoder, and the writer's payloads against mcap_ros2's serialiser."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.errors import ChannelError
from vibroscope.io import discover_fields, mcap_info, read_mcap
from vibroscope.io import _extract
from vibroscope.io._ros2 import FLOAT_FIELDS, MSGDEFS, encode_fixed
from vibroscope.io.mcap_write import stamps_ns, write_json_mcap, write_ros2_mcap
from vibroscope.signals import Signals

from _io_helpers import copy_with_damaged_summary, write_imu_log


@pytest.fixture
def mixed_signals():
    rng = np.random.default_rng(1)
    chans = [
        "/actuator/force_cmd.wrench.force.x",
        "/actuator/force_cmd.wrench.torque.z",
        "/imu/m1.linear_acceleration.x",
        "/imu/m1.linear_acceleration.z",
        "/imu/m1.angular_velocity.y",
        "/env.temperature",
        "/env.pressure.static",
    ]
    return Signals(data=rng.standard_normal((len(chans), 777)), fs=1651.0, channels=chans, t0=1_700_000_000.25)


def test_ros2_roundtrip_exact(tmp_path, mixed_signals):
    s = mixed_signals
    p = write_ros2_mcap(tmp_path / "a.mcap", s, frame_id="base")
    r = read_mcap(p, list(s.channels))
    assert r.channels == s.channels
    assert np.array_equal(r.data, s.data)
    assert r.fs == 1651.0 and r.n_samples == 777
    assert r.t0 == pytest.approx(s.t0, abs=1e-9)
    assert r.meta["t0_ns"] == stamps_ns(s)[0]
    assert r.units == ("N", "N m", "m/s^2", "m/s^2", "rad/s", "", "")
    assert r.meta["fast_path"] == {"/actuator/force_cmd": True, "/imu/m1": True, "/env": False}
    tb = r.meta["timebase"]["/imu/m1"]
    assert tb["n_messages"] == 777 and tb["gaps"] == 0 and tb["duplicates"] == 0 and not tb["resampled"]
    assert tb["time_source"] == "header.stamp"
    info = mcap_info(p)
    types = {t.topic: t.schema_name for t in info.topics}
    assert types == {"/actuator/force_cmd": "geometry_msgs/msg/WrenchStamped", "/imu/m1": "sensor_msgs/msg/Imu",
                     "/env": "env"}
    assert info.topic("/imu/m1").rate_hz == pytest.approx(1651.0, rel=1e-6)
    # automatic selection takes the Imu's accelerations; y was not written (zeros): left out
    auto = read_mcap(p)
    assert auto.channels == ("/imu/m1.linear_acceleration.x", "/imu/m1.linear_acceleration.z")
    assert any(s.get("channel") == "/imu/m1.linear_acceleration.y" for s in auto.meta["skipped"])
    assert np.array_equal(read_mcap(p, ["/imu/m1.linear_acceleration.y"]).data, np.zeros((1, 777)))
    # Imu orientation unknown
    o = read_mcap(p, ["/imu/m1.orientation_covariance[0]"])
    assert np.all(o.data == -1.0)


def test_json_roundtrip_exact(tmp_path, mixed_signals):
    s = mixed_signals
    p = write_json_mcap(tmp_path / "j.mcap", s)
    r = read_mcap(p, list(s.channels))
    assert np.array_equal(r.data, s.data) and r.fs == 1651.0
    assert r.meta["timebase"]["/env"]["time_source"] == "header.stamp"
    assert "/imu/m1.linear_acceleration.x" in discover_fields(p)["/imu/m1"]


def test_plain_names_and_force_channels(tmp_path):
    s = Signals(data=np.arange(20.0).reshape(2, 10), fs=100.0, channels=["F1", "temp"])
    p = write_ros2_mcap(tmp_path / "f.mcap", s, force_channels=["F1"])
    r = read_mcap(p, ["/F1.wrench.force.x", "/signals.temp"])
    assert np.array_equal(r.data, s.data) and r.units == ("N", "")
    assert mcap_info(p).topic("/F1").schema_name == "geometry_msgs/msg/WrenchStamped"


def test_writer_payload_equals_mcap_ros2_serialiser():
    from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

    rng = np.random.default_rng(2)
    for t, floats in FLOAT_FIELDS.items():
        enc = serialize_dynamic(t, MSGDEFS[t])[t]
        dec = generate_dynamic(t, MSGDEFS[t])[t]
        vals = {f: rng.standard_normal(3) for f in floats[::3]}
        for fid in ("", "a", "imu_link", "twelve_chars"):
            arr = encode_fixed(t, np.array([1, 2, 3]), np.array([4, 5, 999_999_999]), vals, frame_id=fid)
            for k in range(3):
                msg = dec(arr[k].tobytes())
                assert enc(msg) == arr[k].tobytes()
                assert msg.header.frame_id == fid


@pytest.mark.parametrize("frame_ids", [["imu"], ["a", "long_frame_id"]])
def test_fast_path_equals_generic_decoder(tmp_path, monkeypatch, frame_ids):
    rng = np.random.default_rng(3)
    n = 3000
    st = 5_000_000_000 + np.arange(n, dtype=np.int64) * 2_000_000
    ax = rng.standard_normal(n) * 1e3
    p = tmp_path / "imu.mcap"
    write_imu_log(p, {"/imu": (st, ax)}, chunk_size=20_000, frame_ids=frame_ids)
    chans = ["/imu.linear_acceleration.x", "/imu.linear_acceleration.y", "/imu.linear_acceleration.z",
             "/imu.orientation.w", "/imu.header.stamp.nanosec"]
    fast = read_mcap(p, chans)
    assert fast.meta["fast_path"]["/imu"] is True  # a varying frame_id too (issue 9: any frame id length)
    monkeypatch.setattr(_extract, "fast_extract", lambda *a, **k: None)
    gen = read_mcap(p, chans)
    assert gen.meta["fast_path"]["/imu"] is False
    assert fast.data.tobytes() == gen.data.tobytes()
    assert np.array_equal(fast.data[0], ax) and np.array_equal(fast.data[1], 2 * ax)
    assert fast.fs == 500.0 and fast.meta["t0_ns"] == st[0]


def test_protobuf_roundtrip(tmp_path):
    from google.protobuf.wrappers_pb2 import DoubleValue
    from mcap_protobuf.writer import Writer

    vals = np.random.default_rng(4).standard_normal(200)
    p = tmp_path / "pb.mcap"
    with open(p, "wb") as fh, Writer(fh) as w:
        for k, v in enumerate(vals):
            t = 1_000_000_000 + k * 10_000_000
            w.write_message("/pb/value", DoubleValue(value=float(v)), log_time=t, publish_time=t)
    r = read_mcap(p, ["/pb/value.value"])
    assert np.array_equal(r.data[0], vals) and r.fs == 100.0
    assert r.meta["timebase"]["/pb/value"]["time_source"] == "log_time"
    assert mcap_info(p).topic("/pb/value").schema_encoding == "protobuf"


def test_unknown_channel_errors_name_topic_and_field(tmp_path, mixed_signals):
    p = write_ros2_mcap(tmp_path / "a.mcap", mixed_signals)
    with pytest.raises(ChannelError, match="/nope"):
        read_mcap(p, ["/nope.x"])
    with pytest.raises(ChannelError, match=r"/imu/m1.*linear_acceleration\.q"):
        read_mcap(p, ["/imu/m1.linear_acceleration.q"])
    with pytest.raises(ChannelError, match="not a number"):
        read_mcap(p, ["/env.pressure"])


def test_progress_bar(tmp_path, mixed_signals, capfd):
    p = write_ros2_mcap(tmp_path / "a.mcap", mixed_signals)
    r = read_mcap(p, ["/imu/m1.linear_acceleration.x"], progress=True)
    assert r.n_samples == 777
    out, err = capfd.readouterr()
    # tqdm's bar over the file's bytes, on stderr, run to the end (100 %)
    assert out == "" and "a.mcap" in err and "100%" in err
    read_mcap(p, ["/imu/m1.linear_acceleration.x"])
    assert capfd.readouterr().err == ""  # no bar without progress=True


def _sequential_log(path, n=2000):
    """/a then /b, each in chunks of its own (/b logged entirely after /a); returns /a's x."""
    st = 1_000_000_000 + np.arange(n, dtype=np.int64) * 1_000_000
    ax = np.random.default_rng(8).standard_normal(n)
    write_imu_log(path, {"/a": (st, ax), "/b": (st, -ax)}, chunk_size=16_000,
                  log_times={"/b": st + n * 1_000_000})
    return ax


def test_chunk_index_skips_chunks_of_other_topics(tmp_path):
    p = tmp_path / "seq.mcap"
    ax = _sequential_log(p)
    r = read_mcap(p, ["/a.linear_acceleration.x"])
    assert r.meta["indexed"] and r.meta["chunks_skipped_by_index"] > 3
    assert np.array_equal(r.data[0], ax)
    # a damaged summary (its CRC fails) is not used: every chunk is read, with the same result
    q = copy_with_damaged_summary(p, tmp_path / "bad_summary.mcap")
    full = read_mcap(q, ["/a.linear_acceleration.x"])
    assert not full.meta["indexed"] and full.meta["chunks_skipped_by_index"] == 0
    assert np.array_equal(full.data, r.data) and full.meta["skipped"] == []


def test_messages_lost_in_a_damaged_chunk_count_only_its_own(tmp_path):
    """A damaged chunk followed by chunks passed over by the index: the loss reported for the
    damaged chunk counts its own messages, not theirs."""
    from vibroscope.io._scan import scan

    p = tmp_path / "seq.mcap"
    ax = _sequential_log(p)
    blocks = scan(p).blocks
    a_id = int(blocks[0].channel_id[0])
    last_a = [b for b in blocks if a_id in b.channel_id][-1]  # the next chunks hold /b only
    data = bytearray(p.read_bytes())
    data[last_a.file_offset + 200] ^= 0xFF  # inside the chunk's (uncompressed) records: its CRC fails
    q = tmp_path / "dmg.mcap"
    q.write_bytes(bytes(data))
    r = read_mcap(q, ["/a.linear_acceleration.x"])
    assert r.meta["chunks_skipped_by_index"] > 3
    (off, reason), = [(s["offset"], s["reason"]) for s in r.meta["skipped"] if "offset" in s]
    assert off == last_a.file_offset and reason.endswith(f"({last_a.n} messages lost)"), reason
    assert r.n_samples == ax.size - np.count_nonzero(last_a.channel_id == a_id)
