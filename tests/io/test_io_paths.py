"""Message-path parsing and field access."""

import pytest

from vibroscope.errors import ChannelError
from vibroscope.io.paths import MessagePath, format_path, get_field, parse_path


@pytest.mark.parametrize(
    "s, topic, fields",
    [
        ("/imu/m1.linear_acceleration.x", "/imu/m1", ("linear_acceleration", "x")),
        ("/joints.position[2]", "/joints", ("position", 2)),
        ("/a.b[1][3].c", "/a", ("b", 1, 3, "c")),
        ("/topic", "/topic", ()),
        ("/actuator/force_cmd.wrench.force.x", "/actuator/force_cmd", ("wrench", "force", "x")),
    ],
)
def test_parse_roundtrip(s, topic, fields):
    mp = parse_path(s)
    assert mp == MessagePath(topic, fields)
    assert str(mp) == s == format_path(topic, fields)


def test_longest_known_topic_wins():
    topics = ["/a", "/a.b", "/ab"]
    assert parse_path("/a.b.c", topics) == MessagePath("/a.b", ("c",))
    assert parse_path("/a.x", topics) == MessagePath("/a", ("x",))
    with pytest.raises(ChannelError, match="no topic"):
        parse_path("/zz.x", topics)


@pytest.mark.parametrize("bad", ["", "/a.1x", "/a.b..c", "/a[2].x", "/a.b[x]"])
def test_bad_paths_raise(bad):
    with pytest.raises(ChannelError):
        parse_path(bad)


def test_get_field_objects_dicts_lists():
    from types import SimpleNamespace as NS

    msg = NS(header=NS(stamp=NS(sec=3)), data=[1.0, 2.0, 3.0])
    assert get_field(msg, ("header", "stamp", "sec")) == 3
    assert get_field(msg, ("data", 2)) == 3.0
    assert get_field({"a": {"b": [5, 6]}}, ("a", "b", 1)) == 6
    with pytest.raises(ChannelError, match=r"topic '/t'.*'/t\.header\.nope'"):
        get_field(msg, ("header", "nope"), topic="/t")
    with pytest.raises(ChannelError, match=r"data\[7\]"):
        get_field(msg, ("data", 7), topic="/t")
