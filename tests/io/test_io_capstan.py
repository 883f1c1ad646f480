"""Real ROS 2 (Humble) recordings from mcap-bag-parser 0.3.1 (MIT): info on all; automatic
selection reports that there is no acceleration field; chosen numeric fields read; the
``ros2idl`` channel is reported by name and skipped."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.errors import ChannelError
from vibroscope.io import discover_fields, mcap_info, read_mcap

from _io_helpers import copy_without_summary

FILES = ["alternate_bagfile_0", "bagfile_0", "controlled_data_0", "torque_ripple_data_0", "uncontrolled_data_0"]
COUNTS = {"alternate_bagfile_0": 129300, "bagfile_0": 25387, "controlled_data_0": 1356,
          "torque_ripple_data_0": 409150, "uncontrolled_data_0": 1594}


@pytest.fixture(scope="module")
def capstan(shared_data):
    return shared_data / "mcap" / "capstan"


@pytest.mark.parametrize("name", FILES)
def test_info_and_reading(capstan, name):
    p = capstan / f"{name}.mcap"
    info = mcap_info(p)
    assert info.message_count == COUNTS[name] and info.skipped == ()
    js = info.topic("/robot/joint_state")
    assert js.decodable and js.message_count > 100 and js.schema_name == "capstan/msg/RobotJointState"
    with pytest.raises(ChannelError, match="no acceleration field"):
        read_mcap(p)
    fields = discover_fields(p)["/robot/joint_state"]
    chosen = [f for f in fields if ".position[" in f][:2]
    assert chosen
    r = read_mcap(p, chosen)
    assert r.n_channels == 2 and r.n_samples > 100
    tb = r.meta["timebase"]["/robot/joint_state"]
    assert tb["n_messages"] == js.message_count
    # logging gaps are NaN, exactly where reported, never interpolated
    gap_mask = np.zeros(r.n_samples, bool)
    for g in r.meta["gaps"]:
        i0 = round((g["start_s"] - r.t0) * r.fs)
        assert g["topic"] == "/robot/joint_state" and g["length_s"] == pytest.approx(g["n_samples"] / r.fs)
        gap_mask[i0 : i0 + g["n_samples"]] = True
    assert np.array_equal(np.isnan(r.data), np.vstack([gap_mask, gap_mask]))
    assert r.meta["nan_samples"] == {c: int(gap_mask.sum()) for c in chosen}
    if name == "torque_ripple_data_0":  # 647 s of its 1276 s are logging gaps: none of it filled in
        assert tb["gap_time_s"] == pytest.approx(647.0, abs=1.0)
        assert gap_mask.sum() / r.fs > 640.0
        assert any("samples are NaN (not interpolated)" in w for w in r.meta["warnings"])
    if not tb["gaps"]:
        assert np.isfinite(r.data).all() and not r.meta["gaps"]
    if name == "bagfile_0":  # this recording's header stamps are all 0: log time is used, and said so
        assert tb["time_source"] == "log_time"
        assert any("header.stamp unusable" in w for w in r.meta["warnings"])
    else:
        assert tb["time_source"] == "header.stamp"
    assert 1 < r.fs < 1100


def test_ros2idl_channel_reported_and_skipped(capstan):
    p = capstan / "alternate_bagfile_0.mcap"
    t = mcap_info(p).topic("/robot/joint_override")
    assert not t.decodable and "ros2idl" in t.reason and t.message_count == 3796
    r = read_mcap(p, ["/robot/joint_override.position[0]", "/robot/joint_state.position[0]"])
    assert r.channels == ("/robot/joint_state.position[0]",)
    sk = [s for s in r.meta["skipped"] if s.get("topic") == "/robot/joint_override"]
    assert sk and sk[0]["schema"] == "capstan/msg/RobotJointOverride" and "ros2idl" in sk[0]["reason"]
    assert any("/robot/joint_override" in w and "ros2idl" in w for w in r.meta["warnings"])
    with pytest.raises(ChannelError, match="joint_override.*ros2idl"):
        read_mcap(p, ["/robot/joint_override.position[0]"])


def test_info_command(capstan, capsys):
    assert main(["info", str(capstan / "alternate_bagfile_0.mcap")]) == 0
    out = capsys.readouterr().out
    assert "/robot/joint_override" in out and "ros2idl" in out and "129300 messages" in out
    assert main(["info", "--json", str(capstan / "controlled_data_0.mcap")]) == 0
    import json

    d = json.loads(capsys.readouterr().out)
    assert d["message_count"] == 1356


@pytest.mark.parametrize("name, channel", [("alternate_bagfile_0", "/robot/cpu_load.cpu_load"),
                                           ("torque_ripple_data_0", "/robot/joint_state.position[0]")])
def test_chunk_index_skips_unwanted_chunks(capstan, tmp_path, name, channel):
    p = capstan / f"{name}.mcap"
    fast = read_mcap(p, [channel])
    assert fast.meta["indexed"] is True
    # /robot/cpu_load is in 13 of the 17 chunks; /robot/joint_state in all of them
    assert fast.meta["chunks_skipped_by_index"] == (4 if "cpu_load" in channel else 0)
    # the same recording with no summary section: every chunk is read, the samples are the same
    full = read_mcap(copy_without_summary(p, tmp_path / "no_summary.mcap"), [channel])
    assert full.meta["indexed"] is False and full.meta["chunks_skipped_by_index"] == 0
    assert np.array_equal(fast.data, full.data, equal_nan=True) and fast.t0 == full.t0 and fast.fs == full.fs
    assert full.meta["skipped"] == fast.meta["skipped"]
