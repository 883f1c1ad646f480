"""`vibroscope convert --topic NAME=CHANNEL:TYPE`: a .mat written in a ROS 2 layout that the user
names (issue #20 item 10): WrenchStamped force, Imu accelerations, JSON fields; read back by the
ROS 2 message paths, values equal."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from vibroscope.cli import main
from vibroscope.io import mcap_info, read_mcap
from vibroscope.io.convert import convert_to_mcap, parse_topic

FS = 400.0


def _mat(path):
    """Force (N) and three accelerations (m/s^2), 800 samples at 400 Hz, known values."""
    t = np.arange(800) / FS
    d = {"Force": 3.0 * np.sin(2 * np.pi * 5 * t), "s02": np.cos(2 * np.pi * 7 * t), "s03": 0.5 * t,
         "s04": -(t ** 2), "temp": 20 + t}
    scipy.io.savemat(path, {**{k: v[:, None] for k, v in d.items()}, "fs": FS})
    return d


def test_convert_mat_to_a_ros2_layout_and_read_it_back(tmp_path, capsys):
    d = _mat(tmp_path / "f16.mat")
    out = tmp_path / "f16.mcap"
    assert main(["convert", str(tmp_path / "f16.mat"), str(out), "--units", "Force=N,s02=m/s^2,s03=m/s^2,s04=m/s^2",
                 "--topic", "/shaker/force=Force:wrench", "--topic", "/imu/s02=s02:imu",
                 "--topic", "/imu/s03=s03:sensor_msgs/Imu:linear_acceleration.z",
                 "--topic", "/imu/s04=s04:geometry_msgs/msg/WrenchStamped:wrench.torque.y",
                 "--topic", "/env=temp:json:temperature"]) == 2  # s04 in m/s^2 is no torque (N m)
    assert "wrench.torque.y is in N m" in capsys.readouterr().err
    assert not out.exists()
    assert main(["convert", str(tmp_path / "f16.mat"), str(out), "--units", "Force=N,s02=m/s^2,s03=m/s^2,s04=m/s^2",
                 "--topic", "/shaker/force=Force:wrench", "--topic", "/imu/s02=s02:imu",
                 "--topic", "/imu/s03=s03:sensor_msgs/Imu:linear_acceleration.z",
                 "--topic", "/imu/s04=s04", "--topic", "/env=temp:json:temperature"]) == 0
    types = {t.topic: t.schema_name for t in mcap_info(out).topics}
    assert types == {"/shaker/force": "geometry_msgs/msg/WrenchStamped", "/imu/s02": "sensor_msgs/msg/Imu",
                     "/imu/s03": "sensor_msgs/msg/Imu", "/imu/s04": "sensor_msgs/msg/Imu", "/env": "env"}
    paths = {"/shaker/force.wrench.force.x": "Force", "/imu/s02.linear_acceleration.x": "s02",
             "/imu/s03.linear_acceleration.z": "s03", "/imu/s04.linear_acceleration.x": "s04",
             "/env.temperature": "temp"}
    sig = read_mcap(out, list(paths), resample=False)
    assert sig.fs == pytest.approx(FS)
    for k, (p, name) in enumerate(paths.items()):
        np.testing.assert_array_equal(sig.data[k], d[name])
    assert list(sig.units[:4]) == ["N", "m/s^2", "m/s^2", "m/s^2"]


def test_channels_may_share_a_topic_and_unnamed_ones_keep_the_default_layout(tmp_path):
    d = _mat(tmp_path / "a.mat")
    path, sig = convert_to_mcap(tmp_path / "a.mat", tmp_path / "a.mcap", units="Force=N,s02=m/s^2,s03=m/s^2,s04=m/s^2",
                                topics=["/imu=s02:imu:linear_acceleration.x", "/imu=s03:imu:linear_acceleration.y"])
    assert list(sig.channels[1:3]) == ["/imu.linear_acceleration.x", "/imu.linear_acceleration.y"]
    assert "/vibroscope/s04.linear_acceleration.x" in sig.channels  # not named: as before
    back = read_mcap(path, ["/imu.linear_acceleration.x", "/imu.linear_acceleration.y"], resample=False)
    np.testing.assert_array_equal(back.data, np.vstack([d["s02"], d["s03"]]))


@pytest.mark.parametrize("spec, match", [
    ("/a=Force:foo", "unknown message type 'foo'"),
    ("noequals", "expected NAME=CHANNEL"),
    ("/a=Force:wrench:wrench.force.q", "not a number field of geometry_msgs/msg/WrenchStamped"),
    ("/a.b=Force", "must be a name such as /shaker/force"),
])
def test_bad_topic_specs(spec, match):
    with pytest.raises(ValueError, match=match):
        parse_topic(spec)


def test_topic_errors_name_the_channel(tmp_path):
    _mat(tmp_path / "a.mat")
    with pytest.raises(ValueError, match=r"has no channel 'Nope'; channels are \['Force'"):
        convert_to_mcap(tmp_path / "a.mat", tmp_path / "x.mcap", topics=["/a=Nope:imu"])
    with pytest.raises(ValueError, match="'Force' is in 'N', but sensor_msgs/msg/Imu linear_acceleration.x is in m/s"):
        convert_to_mcap(tmp_path / "a.mat", tmp_path / "x.mcap", units="Force=N", topics=["/a=Force:imu"])
    with pytest.raises(ValueError, match="already a geometry_msgs/msg/WrenchStamped topic"):
        convert_to_mcap(tmp_path / "a.mat", tmp_path / "x.mcap", units="Force=N,s02=m/s^2",
                        topics=["/a=Force", "/a=s02"])
