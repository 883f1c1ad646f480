"""What ``analyse`` takes from a log with no option, and the set-ups it refuses or warns about
(issue 20, items 1, 4 and 7).

The shaker case is rebuilt from a lumped model: a 3-DOF chain (modes 3.68, 8.86, 12.36 Hz,
0.3-0.9 % damping) driven on its tip mass by a random-phase multisine (1-20 Hz, 8192-sample
period, 6 periods at 400 Hz), written as a ROS 2 MCAP the way a test rig records it: the
shaker's load cell as ``geometry_msgs/msg/WrenchStamped`` (``/shaker/force``), three
accelerometers as ``sensor_msgs/msg/Imu`` (``/imu/m1..m3``). The model's modes are the oracle.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.errors import ChannelError
from vibroscope.io.mcap_write import write_json_mcap, write_ros2_mcap
from vibroscope.models import LumpedModel
from vibroscope.signals import Signals

FS = 400.0
PERIOD = 8192
FORCE = "/shaker/force.wrench.force.x"
CHOICE = f"input: {FORCE} (force-like: WrenchStamped); --output-only to ignore it"


def _shaker_model() -> LumpedModel:
    return LumpedModel.chain([2.0, 1.5, 1.0], [4000.0, 3000.0, 2500.0], [1.0, 0.8, 0.5], input_dof=2,
                             input_channel=FORCE)


def _shaker_signals(n_periods: int, period: int = PERIOD) -> Signals:
    from vibroscope.models.excitation import multisine
    from vibroscope.models.simulate import simulate

    u, _ = multisine(FS, period, fmin=1.0, fmax=20.0, rms=5.0, seed=1)
    return simulate(_shaker_model(), np.tile(u, n_periods), FS, noise=0.01, seed=2)


@pytest.fixture(scope="module")
def shaker_log(tmp_path_factory):
    """The shaker test (123 s at 400 Hz): WrenchStamped force + three Imu topics."""
    path = tmp_path_factory.mktemp("shaker") / "shaker.mcap"
    write_ros2_mcap(path, _shaker_signals(6))
    return path


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    """The same rig, 2 periods of 2048 samples (10 s): for the checks that need no modes."""
    path = tmp_path_factory.mktemp("short") / "short.mcap"
    write_ros2_mcap(path, _shaker_signals(2, 2048))
    return path


# ---------------------------------------------------------------- item 1: the force is the input

def test_the_force_topic_is_the_input_with_no_option(shaker_log, tmp_path, capsys):
    """No option: the WrenchStamped force is the input (the FRF path, LSCF), the report and the
    JSON say so in one line, and the three modes are the model's within 1 %."""
    js = tmp_path / "s.json"
    assert main(["analyse", str(shaker_log), "--json", str(js), "--no-rrd", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert CHOICE in out.splitlines()
    assert f"input {FORCE} -> 3 outputs" in out
    s = json.loads(js.read_text())
    assert s["input"] == FORCE and s["input_choice"] == CHOICE and s["modal_method"] == "lscf"
    true = _shaker_model().modes().natural_frequencies
    found = np.array([m["frequency_hz"] for m in s["modes"]])
    assert len(found) == 3, found
    np.testing.assert_allclose(np.sort(found), true, rtol=0.01)


def test_output_only_ignores_the_force(shaker_log, tmp_path, capsys):
    """``--output-only``: no input, no FRF, output-only SSI-COV on the three responses only."""
    js = tmp_path / "s.json"
    assert main(["analyse", str(shaker_log), "--output-only", "--json", str(js), "--no-rrd", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "output-only: 3 responses" in out and "force-like" not in out
    s = json.loads(js.read_text())
    assert s["input"] is None and "input_choice" not in s and s["modal_method"] == "ssi_cov"
    assert FORCE not in s["channels"] and len(s["outputs"]) == 3


def test_output_only_and_input_together_is_one_line(short_log, capsys):
    assert main(["analyse", str(short_log), "--output-only", "--input", FORCE, "--no-rrd", "--no-figures"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--output-only" in err[0] and "--input" in err[0]


def test_find_force_input_one_moving_axis_of_a_wrench(short_log):
    """Of the WrenchStamped's force axes only x moves (y, z are 0): x is the one; torques and the
    Imu topics are never candidates."""
    from vibroscope.io.select import find_force_input, force_candidates

    cands = dict(force_candidates(short_log))
    assert set(cands) == {f"/shaker/force.wrench.force.{c}" for c in "xyz"}
    assert set(cands.values()) == {"WrenchStamped"}
    got = find_force_input(short_log)
    assert got.channel == FORCE and got.why == "WrenchStamped"
    assert got.line() == CHOICE
    assert find_force_input(short_log, exclude_topics=("/shaker/force",)).channel is None


def _json_log(path, channels: dict, fs: float = 200.0, n: int = 512):
    t = np.arange(n) / fs
    data = np.array([f(t) for f in channels.values()])
    write_json_mcap(path, Signals(data=data, fs=fs, channels=tuple(channels)))
    return path


def test_find_force_input_by_name_and_two_forces_take_none(tmp_path):
    """A JSON log: a topic named like a command is the input; two moving forces on two topics
    are ambiguous (none taken, the line names both); a dominant axis of one load cell is taken."""
    from vibroscope.io.select import find_force_input

    rng = np.random.default_rng(0)
    sig = lambda t: rng.standard_normal(t.size)  # noqa: E731
    one = _json_log(tmp_path / "one.mcap", {"/rig/command.data": sig, "/acc.a": sig})
    got = find_force_input(one, exclude_topics=("/acc",))
    assert got.channel == "/rig/command.data" and got.why == "named like a force"
    two = _json_log(tmp_path / "two.mcap", {"/left/force.x": sig, "/right/force.x": sig, "/acc.a": sig})
    got = find_force_input(two, exclude_topics=("/acc",))
    assert got.channel is None and set(got.candidates) == {"/left/force.x", "/right/force.x"}
    assert got.line() == "no input taken: 2 force-like channels move (/left/force.x, /right/force.x); name one with --input"
    cell = _json_log(tmp_path / "cell.mcap", {"/cell.force.x": sig, "/cell.force.y": lambda t: 0.01 * sig(t),
                                              "/acc.a": sig})
    got = find_force_input(cell, exclude_topics=("/acc",))
    assert got.channel == "/cell.force.x" and "dominant axis" in got.why


def test_an_output_only_method_never_takes_the_force(short_log, tmp_path):
    """An output-only method (``--method fdd``) on a log with a force: output-only as asked, no error."""
    js = tmp_path / "s.json"
    assert main(["analyse", str(short_log), "--method", "fdd", "--json", str(js), "--no-rrd", "--no-figures"]) == 0
    assert json.loads(js.read_text())["input"] is None


# ------------------------------------------- item 1 in every mode: --stream, --connect, --dask

def test_stream_takes_the_force_as_input(shaker_log, tmp_path, capsys):
    """``--stream`` (block by block): the same force is the input, found in the first and last
    chunks of its topic; the report and the JSON say so in the same line, and the modes are the
    model's within 1 %. ``--output-only`` still ignores it."""
    js = tmp_path / "s.json"
    assert main(["analyse", str(shaker_log), "--stream", "--json", str(js), "--no-rrd", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert CHOICE in out.splitlines() and f"input {FORCE} -> 3 outputs" in out
    s = json.loads(js.read_text())
    assert s["input"] == FORCE and s["input_choice"] == CHOICE and s["modal_method"] == "lscf"
    assert "input_choice" not in s["settings"]
    found = np.sort([m["frequency_hz"] for m in s["modes"]])
    np.testing.assert_allclose(found, _shaker_model().modes().natural_frequencies, rtol=0.01)
    assert main(["analyse", str(shaker_log), "--stream", "--output-only", "--json", str(js), "--no-rrd",
                 "--no-figures"]) == 0
    s = json.loads(js.read_text())
    assert s["input"] is None and "input_choice" not in s and "force-like" not in capsys.readouterr().out


def test_the_grid_finds_the_same_input_as_a_whole_read(short_log, tmp_path):
    """:meth:`LogGrid.force_input` (first and last chunks only) takes what the whole read takes;
    the responses' topics are never the input; two moving forces on two topics: none taken."""
    from vibroscope.io.blocks import open_grid
    from vibroscope.io.select import find_force_input

    got = open_grid(short_log).force_input()
    assert got.channel == FORCE and got.line() == CHOICE == find_force_input(short_log).line()
    assert open_grid(short_log).force_input(exclude_channels=[FORCE]).channel is None
    sig = lambda t: np.random.default_rng(0).standard_normal(t.size)  # noqa: E731
    two = _json_log(tmp_path / "two.mcap", {"/left/force.x": sig, "/right/force.x": sig, "/acc.a": sig})
    got = open_grid(two, ["/acc.a"]).force_input(exclude_channels=["/acc.a"])
    assert got.channel is None and set(got.candidates) == {"/left/force.x", "/right/force.x"}


def test_connect_streams_and_analyses_with_the_force(short_log, tmp_path, monkeypatch, capsys):
    """``--connect``: the live view is a log read block by block, its topics known ahead: the live
    FRFs and the analysis after it take the same force as the input (the viewer is stood in for:
    the call is recorded). ``--output-only``: neither takes it."""
    import vibroscope.commands._live as live

    calls = []
    monkeypatch.setattr(live, "stream_log", lambda log, **kw: calls.append(kw))
    js = tmp_path / "s.json"
    assert main(["analyse", str(short_log), "--connect", "--json", str(js), "--no-rrd", "--no-figures"]) == 0
    assert calls[-1]["input"] == FORCE
    assert CHOICE in capsys.readouterr().out.splitlines()
    s = json.loads(js.read_text())
    assert s["input"] == FORCE and s["input_choice"] == CHOICE
    assert main(["analyse", str(short_log), "--connect", "--output-only", "--json", str(js), "--no-rrd",
                 "--no-figures"]) == 0
    assert calls[-1]["input"] is None and json.loads(js.read_text())["input"] is None


def test_dask_fleet_takes_the_first_logs_force_for_every_log(shaker_log, short_log, tmp_path, capsys):
    """``--dask``: the first log that plans chooses the input as it chooses the channels; every
    log's FRF modes come from it (the model's within 1 % on the long log), and the line is
    printed and in ``fleet.json``'s settings."""
    pytest.importorskip("dask.distributed")
    from dask.distributed import Client

    from vibroscope.fleet import local_cluster

    logs = [str(shaker_log), str(short_log)]
    with local_cluster(1) as lc, Client(lc) as c:
        assert main(["analyse", "--dask", c.scheduler.address, *logs, "--out", str(tmp_path / "auto"),
                     "--no-figures"]) == 0
        assert CHOICE in capsys.readouterr().out.splitlines()
        assert main(["analyse", "--dask", c.scheduler.address, *logs, "--input", FORCE, "--out",
                     str(tmp_path / "given"), "--no-figures"]) == 0
        assert "force-like" not in capsys.readouterr().out
    d = json.loads((tmp_path / "auto" / "fleet.json").read_text())
    assert d["settings"]["input"] == FORCE and d["settings"]["input_choice"] == CHOICE
    assert d["settings"]["channels"][0] == FORCE and len(d["settings"]["channels"]) == 10  # + 3 Imu × xyz
    given = json.loads((tmp_path / "given" / "fleet.json").read_text())
    assert [r["modes"] for r in d["logs"]] == [r["modes"] for r in given["logs"]]  # as with --input
    long = np.array([m["frequency_hz"] for m in d["logs"][0]["modes"]])  # the fleet's fixed resolution keeps
    true = _shaker_model().modes().natural_frequencies  # the upper two of the model's modes, within 1 %
    assert all(np.min(np.abs(long / f - 1)) < 0.01 for f in true[1:]), long


# ---------------------------------------------------------------- item 4: finding field paths

def test_info_fields_lists_numeric_paths_with_unit_and_sample(short_log, capsys):
    from vibroscope.io import read_mcap

    assert main(["info", "--fields", str(short_log)]) == 0
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.startswith("/")}
    assert rows[FORCE][1] == "N" and rows["/imu/m2.linear_acceleration.x"][1] == "m/s^2"
    assert rows["/shaker/force.wrench.torque.z"][1:3] == ["N", "m"]
    first = read_mcap(short_log, [FORCE])[FORCE][0]  # the sample is the first message's value
    assert float(rows[FORCE][2]) == pytest.approx(first, rel=1e-5)
    assert "/shaker/force.wrench" not in rows  # only numbers
    # one topic: its 8 numeric paths (2 stamp fields, force, torque), as JSON
    assert main(["info", str(short_log), "--topic", "/shaker/force", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    paths = [f["path"] for f in d["fields"]]
    assert len(paths) == 8 and all(p.startswith("/shaker/force.") for p in paths)
    f = next(f for f in d["fields"] if f["path"] == FORCE)
    assert f["unit"] == "N" and f["sample"] == pytest.approx(first, rel=1e-12)
    assert main(["info", str(short_log), "--topic", "/nope"]) == 1
    assert "no topic '/nope'" in capsys.readouterr().err


@pytest.mark.parametrize("bad, first", [
    ("/shaker/force", ["/shaker/force.wrench.force.x", "/shaker/force.wrench.force.y", "/shaker/force.wrench.force.z"]),
    ("/shaker/force.wrench", ["/shaker/force.wrench.force.x"]),
    ("/shaker/force.wrench.force.q", ["/shaker/force.wrench.force.x", "/shaker/force.wrench.force.y"]),
    ("/imu/m1.linear_acceleration.q", ["/imu/m1.linear_acceleration.x"]),
])
def test_not_a_number_and_no_such_field_name_the_nearest_paths(short_log, capsys, bad, first):
    """``--input /shaker/force`` (a message, not a number) and a misspelt field: the one-line
    error names the nearest numeric paths, the siblings first."""
    assert main(["analyse", str(short_log), "--input", bad, "--no-rrd", "--no-figures"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and ("is not a number" in err[0] or "not found" in err[0])
    near = err[0].split("numeric paths near it: ", 1)[1].split(" (")[0].split(", ")
    assert near[: len(first)] == first
    assert not any("stamp" in p for p in near)  # bookkeeping is no suggestion


def test_nearest_paths_ranks_extensions_then_siblings():
    from vibroscope.io.paths import nearest_paths

    cands = ["/a.header.stamp.sec", "/a.pos.x", "/a.pos.y", "/a.vel.x", "/b.pos.x"]
    assert nearest_paths("/a.pos", cands)[:2] == ["/a.pos.x", "/a.pos.y"]
    assert nearest_paths("/a.pos.w", cands)[:2] == ["/a.pos.x", "/a.pos.y"]
    assert nearest_paths("/zzz.qqq", cands) == []
    assert len(nearest_paths("/a", cands, n=2)) == 2


def test_read_mcap_error_names_the_nearest_paths(short_log):
    from vibroscope.io import read_mcap

    with pytest.raises(ChannelError, match=r"numeric paths near it: /shaker/force\.wrench\.force\.x"):
        read_mcap(short_log, ["/shaker/force"])


# ---------------------------------------------------------------- item 7: impossible set-ups

def test_an_accelerometer_as_input_is_a_transmissibility(short_log, tmp_path, capsys):
    js = tmp_path / "s.json"
    assert main(["analyse", str(short_log), "--input", "/imu/m3.linear_acceleration.x", "--json", str(js),
                 "--no-rrd", "--no-figures"]) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if "transmissibilit" in ln]
    assert len(lines) == 1 and lines[0].startswith("  warning: input /imu/m3.linear_acceleration.x")
    assert any("transmissibilit" in w for w in json.loads(js.read_text())["warnings"])


def test_a_force_input_is_no_transmissibility(short_log, tmp_path, capsys):
    assert main(["analyse", str(short_log), "--input", FORCE, "--no-rrd", "--no-figures"]) == 0
    assert "transmissibilit" not in capsys.readouterr().out


def test_more_coordinate_rows_than_channels_is_an_error(short_log, tmp_path, capsys):
    """18 rows (numbered sensors, as LUMO's) for the 3 channels of a log whose names carry no
    sensor number: one line naming both counts, before the report, nothing written."""
    coords = tmp_path / "c.csv"
    coords.write_text("sensor number,x,y,z,direction\n" + "".join(f"{k},0,0,{k},1\n" for k in range(1, 19)))
    js = tmp_path / "s.json"
    assert main(["analyse", str(short_log), "--coords", str(coords), "--json", str(js), "--no-rrd",
                 "--no-figures"]) == 1
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and "18 coordinate rows for 3 channels" in err[0]
    assert "mode" not in cap.out and not js.exists()


def test_coordinates_by_sensor_number_and_by_order():
    """Named sensors (/sNN) take their rows from a longer table; other names need one row each."""
    import tempfile
    from pathlib import Path

    from vibroscope.io.coords import read_coords

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "c.csv"
        p.write_text("sensor number,x,y,z\n" + "".join(f"{k},0,0,{k}\n" for k in range(1, 6)))
        sc = read_coords(p, ["/r/s04.a", "/r/s02.a"])
        assert sc.xyz[:, 2].tolist() == [4.0, 2.0]
        with pytest.raises(ChannelError, match="5 coordinate rows for 2 channels"):
            read_coords(p, ["/imu/m1.a", "/imu/m2.a"])
        assert read_coords(p, [f"/imu/m{k}.a" for k in range(1, 6)]).xyz[:, 2].tolist() == [1, 2, 3, 4, 5]
        with pytest.raises(ChannelError, match="5 coordinate rows for 6 channels"):
            read_coords(p, [f"/x{k}.a" for k in range(1, 7)])


@pytest.mark.parametrize("extra, message", [
    ([], "fmax=300 Hz is above the Nyquist frequency 200 Hz"),
    (["--fs", "400"], "--fmax 300: above the Nyquist frequency 200 Hz of --fs 400"),
])
def test_fmax_above_nyquist_is_an_error(short_log, capsys, extra, message):
    assert main(["analyse", str(short_log), "--fmax", "300", *extra, "--no-rrd", "--no-figures"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_analyse_signals_refuses_fmax_above_nyquist():
    from vibroscope.pipeline import analyse_signals

    x = np.random.default_rng(0).standard_normal((2, 4096))
    with pytest.raises(ValueError, match=r"fmax=600 Hz is above the Nyquist frequency 500 Hz \(fs=1000 Hz\)"):
        analyse_signals(Signals(data=x, fs=1000.0, channels=("a", "b")), fmax=600.0)
