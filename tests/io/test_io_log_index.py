"""The log index: one scan per command, the same samples as a read from the path, units
stored in the channel metadata read back, gaps in the topic table."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.writer import Writer

from vibroscope.errors import ChannelError
from vibroscope.io import LogIndex, mcap_info, read_mcap
from vibroscope.io import _scan
from vibroscope.io.log_index import UNITS_KEY
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.io.select import auto_channels
from vibroscope.signals import Signals

from _io_helpers import write_imu_log

T0 = 30_000_000_000


@pytest.fixture
def imu_log(tmp_path):
    rng = np.random.default_rng(11)
    chans = [f"/imu/m{k}.linear_acceleration.{a}" for k in (1, 2) for a in "xz"] + ["/ft.wrench.force.x"]
    s = Signals(data=rng.standard_normal((len(chans), 4096)), fs=1000.0, channels=chans, t0=30.0)
    return write_ros2_mcap(tmp_path / "imu.mcap", s), s


@pytest.fixture
def count_scans(monkeypatch):
    calls = []
    real = _scan.scan

    def counting(*a, **k):
        calls.append(a[0] if a else k.get("path"))
        return real(*a, **k)

    monkeypatch.setattr(_scan, "scan", counting)
    return calls


def test_index_serves_info_selection_and_read_from_one_scan(imu_log, count_scans):
    p, s = imu_log
    idx = LogIndex.open(p)
    info = idx.info()
    assert idx.info() is info and mcap_info(idx) is info
    assert [t.topic for t in info.topics] == ["/ft", "/imu/m1", "/imu/m2"]
    sel = auto_channels(idx)
    assert sel.channels == tuple(f"/imu/m{k}.linear_acceleration.{a}" for k in (1, 2) for a in "xyz")
    r = read_mcap(idx, list(s.channels))
    assert len(count_scans) == 1
    assert np.array_equal(r.data, s.data) and r.channels == s.channels
    ref = read_mcap(p, list(s.channels))  # from the path: the same samples
    assert np.array_equal(ref.data, r.data) and ref.units == r.units and ref.t0 == r.t0
    auto = read_mcap(idx)
    assert auto.channels == tuple(c for c in s.channels if "imu" in c)  # y axes not measured: left out


def test_index_for_some_topics_refuses_others(imu_log):
    p, s = imu_log
    idx = LogIndex.open(p, topics={"/ft"})
    assert read_mcap(idx, ["/ft.wrench.force.x"]).n_samples == 4096
    with pytest.raises(ChannelError, match="opened for the topics"):
        read_mcap(idx, ["/imu/m1.linear_acceleration.x"])


def test_analyse_without_outputs_scans_once(imu_log, count_scans):
    from vibroscope.commands.analyse import analyse_log

    p, s = imu_log
    an = analyse_log(p, input="/ft.wrench.force.x", nperseg=512)
    assert len(count_scans) == 1
    assert an is not None


def _json_log(path, units=None):
    meta = {UNITS_KEY: json.dumps(units)} if units is not None else {}
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start("", "test")
        sid = w.register_schema("m", "jsonschema", b"{}")
        cid = w.register_channel("/j", "json", sid, metadata=meta)
        for k in range(50):
            msg = {"volt": {"x": 0.1 * k}, "linear_acceleration": {"x": 1.0 * k}, "force": [k, -k]}
            w.add_message(cid, log_time=T0 + k * 1_000_000, data=json.dumps(msg).encode(),
                          publish_time=T0 + k * 1_000_000)
        w.finish()
    return path


def test_units_from_channel_metadata_win_over_names(tmp_path):
    chans = ["/j.volt.x", "/j.linear_acceleration.x", "/j.force[1]"]
    p = _json_log(tmp_path / "u.mcap", {"volt.x": "V", "linear_acceleration.x": "g", "force[1]": "kN"})
    assert read_mcap(p, chans).units == ("V", "g", "kN")
    partial = _json_log(tmp_path / "p.mcap", {"volt.x": "V"})  # the rest named by the heuristic
    assert read_mcap(partial, chans).units == ("V", "m/s^2", "N")
    none = _json_log(tmp_path / "n.mcap")
    assert read_mcap(none, chans).units == ("", "m/s^2", "N")


def test_info_counts_gaps(tmp_path, capsys):
    from vibroscope.cli import main

    st = T0 + np.arange(2000, dtype=np.int64) * 1_000_000
    keep = np.ones(2000, bool)
    keep[500:800] = False
    keep[1500:1510] = False
    lt = st.copy()
    lt[1000] += 10**13  # one log time far off (stamps intact)
    p = tmp_path / "g.mcap"
    write_imu_log(p, {"/imu": (st[keep], np.zeros(keep.sum()))}, log_times={"/imu": lt[keep]})
    t = mcap_info(p).topic("/imu")
    # the outlier is left out of the span; its place is one more (1 ms) gap
    assert t.gaps == 3 and t.gap_time_s == pytest.approx(0.311, abs=1e-9) and t.outliers == 1
    assert t.message_count == keep.sum() and (t.start_ns, t.end_ns) == (st[0], st[-1])
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "gaps" in out and "missing s" in out and "outliers" in out
    row = [ln for ln in out.splitlines() if ln.startswith("/imu")][0]
    assert row.split()[6:9] == ["3", "0.311", "1"]


def test_channels_only_inside_chunks_read_on_the_filtered_path(tmp_path, count_scans):
    """repeat_channels=False: the summary lists no channels, so the topic-filtered scan passes
    over every chunk; the read scans again in full rather than saying 'no such topic'."""
    p = tmp_path / "rc.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, repeat_channels=False, repeat_schemas=False, chunk_size=2000)
        w.start("", "t")
        sid = w.register_schema("m", "jsonschema", b"{}")
        ca, cb = w.register_channel("/a", "json", sid), w.register_channel("/b", "json", sid)
        for k in range(500):
            w.add_message(cb if k % 5 == 0 else ca, log_time=T0 + k * 1_000_000,
                          data=json.dumps({"v": k}).encode(), publish_time=0)
        w.finish()
    r = read_mcap(p, ["/b.v"])
    assert np.array_equal(r.data[0], np.arange(0, 500, 5)) and r.fs == 200.0
    assert len(count_scans) <= 2
    with pytest.raises(ChannelError, match="no such topic"):
        read_mcap(p, ["/c.v"])


def test_auto_channels_of_a_json_log_of_accelerometers(tmp_path):
    """A JSON log (no Imu schema) of three accelerometer topics and a force: the automatic choice
    takes the acceleration fields of every topic (m/s² by the stored units), not the busiest topic
    alone, and never the force (before: /imu/m1 only with the force as input, and without an input
    the force itself as the response); the streamed planning chooses the same."""
    from vibroscope.io.blocks import open_grid
    from vibroscope.io.mcap_write import write_json_mcap

    rng = np.random.default_rng(4)
    chans = ["/actuator/force.wrench.force.x"] + [f"/imu/m{k}.linear_acceleration.x" for k in (1, 2, 3)]
    p = write_json_mcap(tmp_path / "j.mcap", Signals(data=rng.standard_normal((4, 3000)), fs=1000.0, channels=chans,
                                                     units=["N"] + ["m/s^2"] * 3, t0=5.0))
    acc = tuple(chans[1:])
    assert auto_channels(p).channels == acc
    assert auto_channels(p, exclude_topics=("/actuator/force",)).channels == acc
    assert open_grid(p).channels == acc
    assert "acceleration fields" in auto_channels(p).reason
