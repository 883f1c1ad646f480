"""The `vibroscope` command line end to end: demo, info, convert + analyse on real data."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from vibroscope.cli import main


def test_demo_finds_the_true_modes(tmp_path, capsys, check_png):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--duration", "120"]) == 0
    text = capsys.readouterr().out
    assert "true modes" in text and "MAC" in text
    summary = json.loads((out / "demo_summary.json").read_text())
    assert summary["fs"] == 500.0  # decimated from 1 kHz for the 150 Hz band
    true = [m["frequency_hz"] for m in summary["true_modes"]]
    found = [m["frequency_hz"] for m in summary["modes"]]
    assert len(found) == 3
    np.testing.assert_allclose(found, true, rtol=0.01)
    zt = [m["damping_ratio"] for m in summary["true_modes"]]
    zf = [m["damping_ratio"] for m in summary["modes"]]
    np.testing.assert_allclose(found, true, rtol=2e-4)  # LSCF: 0.000-0.006 % measured
    np.testing.assert_allclose(zf, zt, rtol=0.01)  # 0.0-0.3 % measured
    assert summary["modal_method"] == "lscf"
    for m in summary["modes"]:
        assert set(m["shape"]) == set(summary["outputs"]) and m["stable"] and m["mpc"] > 0.99
    assert (out / "demo.rrd").stat().st_size > 10_000
    from vibroscope.viewers.rerun_view import read_rrd

    rrd = read_rrd(out / "demo.rrd")
    for what in ("velocity", "displacement"):  # the acquisition view: integrated, in the time view
        assert sum(e.startswith(f"/{what}/imu/") for e in rrd) == 3
    assert any(e.startswith("/stabilization/") for e in rrd) and any("/synthesized/" in e for e in rrd)
    assert (out / "demo.mcap").exists()
    for name in ("psd", "frf", "modes", "singular_values", "stabilization", "frf_synthesis", "kinematics"):
        check_png(out / "figures" / f"{name}.png")


def test_demo_log_is_a_ros2_recording(tmp_path):
    from vibroscope.commands.demo import make_demo_log
    from vibroscope.io import mcap_info

    path = tmp_path / "d.mcap"
    make_demo_log(path, duration=2.0)
    info = mcap_info(path)
    types = {t.topic: t.schema_name for t in info.topics}
    assert types["/actuator/force"] == "geometry_msgs/msg/WrenchStamped"
    assert types["/imu/m1"] == "sensor_msgs/msg/Imu"
    assert all(t.message_count == 2000 for t in info.topics)


@pytest.fixture(scope="module")
def lumo_mcap(tmp_path_factory, shared_data):
    out = tmp_path_factory.mktemp("lumo") / "lumo.mcap"
    src = shared_data / "lumo" / "data_lumo.csv"
    assert main(["convert", str(src), str(out), "--fs", "1651", "--columns", "0-17",
                 "--kind", "acceleration", "--topic-prefix", "/lumo"]) == 0
    return out


def test_lumo_first_modes_match_published(lumo_mcap, shared_data, tmp_path):
    """Wernitz et al. 2021 (LUMO), published SSI-COV modes 2.82, 13.55, 15.99 Hz: within 1 %,
    output-only through the whole path (CSV -> MCAP -> analyse), shapes at the sensor coordinates."""
    js = tmp_path / "lumo.json"
    rrd = tmp_path / "lumo.rrd"
    assert main(["analyse", str(lumo_mcap), "--coords", str(shared_data / "lumo" / "coords_lumo.csv"),
                 "--fmin", "1", "--fmax", "50", "--method", "efdd", "--json", str(js), "--rrd", str(rrd),
                 "--figures", str(tmp_path / "fig")]) == 0
    s = json.loads(js.read_text())
    assert len(s["outputs"]) == 18 and s["modal_method"] == "efdd"
    found = np.array([m["frequency_hz"] for m in s["modes"]])
    for f_pub in (2.82, 13.55, 15.99):
        assert np.min(np.abs(found - f_pub)) / f_pub < 0.01, (f_pub, found)
    # the shapes are animated at the coordinates: the 3D points of the first mode in the recording
    from vibroscope.viewers.rerun_view import read_rrd

    data = read_rrd(rrd)
    modes = sorted(e for e in data if e.startswith("/modes/mode_") and not e.endswith("undeformed"))
    assert len(modes) == len(s["modes"])
    coords = np.loadtxt(shared_data / "lumo" / "coords_lumo.csv", delimiter=",", skiprows=1, usecols=(2, 3, 4),
                        max_rows=18)
    und = np.asarray(data[modes[0] + "/undeformed"]["static"]["Points3D:positions"])
    np.testing.assert_allclose(und, coords, atol=1e-6)
    frames = data[modes[0]]["Points3D:positions"]
    assert len(frames) == 40  # one animated cycle
    moved = np.asarray(frames[0]) - coords
    assert np.allclose(moved[:, 2], 0, atol=1e-6) and np.abs(moved[:, :2]).max() > 0  # sway, not heave


def test_lumo_ssi_finds_published_modes_and_light_damping(lumo_mcap, tmp_path, check_png):
    """`--method ssi`: the published SSI-COV modes 2.82, 13.55, 15.99, 16.33 Hz within 1 % and the
    light damping (published ~0.2–0.3 %) of the 2.82 and 15.99 Hz modes between 0.1 and 0.5 %;
    the stabilization diagram is drawn."""
    js = tmp_path / "s.json"
    assert main(["analyse", str(lumo_mcap), "--fmin", "1", "--fmax", "50", "--method", "ssi", "--json", str(js),
                 "--no-rrd", "--figures", str(tmp_path / "f")]) == 0
    s = json.loads(js.read_text())
    f = np.array([m["frequency_hz"] for m in s["modes"]])
    z = np.array([m["damping_ratio"] for m in s["modes"]])
    for f_pub in (2.82, 13.55, 15.99, 16.33):
        k = np.argmin(np.abs(f - f_pub))
        assert abs(f[k] / f_pub - 1) < 0.01, (f_pub, f)
        if f_pub in (2.82, 15.99):
            assert 0.001 < z[k] < 0.005, (f_pub, z[k])
    check_png(tmp_path / "f" / "stabilization.png")


@pytest.mark.parametrize("command", ["analyse", "modal"])
def test_lumo_with_no_band_gives_the_modes_not_the_noise(command, lumo_mcap, tmp_path, capsys):
    """No --fmin/--fmax, no method: SSI-COV on the band the data choose finds the published modes
    2.82 (the y-direction partner 2.81 Hz), 13.55, 15.99, 16.33 Hz within 0.5 %, the x-direction
    first bending mode at 2.777 Hz (−1.5 % from the published 2.82, as FDD finds it too), fewer
    than 12 modes in all, light damping, and lists what it rejected."""
    js = tmp_path / "m.json"
    assert main([command, str(lumo_mcap), "--json", str(js), "--no-rrd", "--figures", str(tmp_path / "f")]) == 0
    s = json.loads(js.read_text())
    f = np.array([m["frequency_hz"] for m in s["modes"]])
    z = np.array([m["damping_ratio"] for m in s["modes"]])
    assert len(f) < 12
    for f_pub in (2.82, 13.55, 15.99, 16.33):
        k = np.argmin(np.abs(f - f_pub))
        assert abs(f[k] / f_pub - 1) < 0.005, (f_pub, f)
        assert 0.0005 < z[k] < 0.005, (f_pub, z[k])
    assert np.sum(np.abs(f - 2.8) < 0.1) == 2  # both first bending modes
    assert all(m["frequency_std_hz"] is not None and m["mpc"] > 0.5 for m in s["modes"])
    rejected = s["rejected_modes"] if command == "analyse" else s["rejected"]
    assert rejected and all(r["reason"] for r in rejected)
    assert "stabilization.png" in {p.name for p in (tmp_path / "f").iterdir()}
    if command == "modal":  # the polyMAX cross-check pairs one to one: 41.108 Hz with 41.03 only
        line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("cross-check polyMAX"))
        taken = re.findall(r"[\d.]+/([\d.]+) Hz", line)
        assert taken and len(taken) == len(set(taken)), line
        assert "(no polyMAX mode)" in line, line  # 39.81 Hz: polyMAX has one mode for the two


CAPSTAN = ["alternate_bagfile_0", "bagfile_0", "controlled_data_0", "torque_ripple_data_0", "uncontrolled_data_0"]


@pytest.mark.parametrize("name", CAPSTAN)
def test_capstan_recordings_info_and_analyse(name, shared_data, tmp_path, capsys):
    """Real ROS 2 recordings without IMU: info and analyse run; the ros2idl channel is named and skipped."""
    log = shared_data / "mcap" / "capstan" / f"{name}.mcap"
    assert main(["info", str(log)]) == 0
    js = tmp_path / "s.json"
    assert main(["analyse", str(log), "--json", str(js), "--no-rrd", "--figures", str(tmp_path / "f")]) == 0
    s = json.loads(js.read_text())
    assert s["outputs"] and s["fs"] > 0
    assert any("channels chosen automatically" in w for w in s["warnings"])
    if name == "alternate_bagfile_0":
        assert any("/robot/joint_override" in w and "ros2idl" in w for w in s["warnings"])
        assert "/robot/joint_override" not in " ".join(s["channels"])



# ---------------------------------------------------------------- one line per problem

@pytest.fixture
def failing_analyse(monkeypatch, tmp_path):
    """``analyse`` whose analysis step runs `fault` (the command line around it is the real one)."""
    import vibroscope.commands.analyse as analyse

    monkeypatch.chdir(tmp_path)
    box = {}

    def fake(log, **kw):
        return box["fault"]()

    monkeypatch.setattr(analyse, "analyse_log", fake)
    return box


def _raise(exc):
    def f():
        raise exc
    return f


@pytest.mark.parametrize("exc,line", [
    (TypeError("unsupported operand"), "TypeError: unsupported operand (run with --debug for the traceback)"),
    (OSError(28, "No space left on device"),
     "OSError: [Errno 28] No space left on device (run with --debug for the traceback)"),
    (MemoryError(), "MemoryError (run with --debug for the traceback)"),
    (RuntimeError("two\nlines"), "RuntimeError: two lines (run with --debug for the traceback)"),
])
def test_any_exception_is_one_line_on_stderr(exc, line, failing_analyse, capsys):
    failing_analyse["fault"] = _raise(exc)
    assert main(["analyse", "x.mcap"]) == 1
    out, err = capsys.readouterr()
    assert err == f"vibroscope analyse: error: {line}\n"
    assert "Traceback" not in out + err


def test_vibroscope_error_is_its_message_and_debug_shows_the_traceback(failing_analyse, capsys):
    from vibroscope.errors import LogFormatError

    failing_analyse["fault"] = _raise(LogFormatError("x.mcap: not an MCAP file (magic at byte 0)"))
    assert main(["analyse", "x.mcap"]) == 1
    assert capsys.readouterr().err == "vibroscope analyse: error: x.mcap: not an MCAP file (magic at byte 0)\n"
    failing_analyse["fault"] = _raise(TypeError("boom"))
    for argv in (["--debug", "analyse", "x.mcap"], ["analyse", "x.mcap", "--debug"]):
        with pytest.raises(TypeError, match="boom"):
            main(argv)
    with pytest.raises(LookupError):  # a ChannelError is a KeyError too: --debug re-raises it as it is
        failing_analyse["fault"] = _raise(__import__("vibroscope.errors").errors.ChannelError("/imu: no such topic"))
        main(["analyse", "--debug", "x.mcap"])


def test_warnings_print_one_line_each_once(failing_analyse, capsys):
    import warnings

    def fault():
        for _ in range(3):
            warnings.warn("10 NaN samples in /imu/m1.linear_acceleration.x\nat 1.5 s", RuntimeWarning)
        warnings.warn("force channel constant", UserWarning)
        with np.errstate(divide="warn"):  # an oracle imported earlier in the run may have silenced numpy
            np.log(np.zeros(1))  # numpy's own RuntimeWarning
        raise TypeError("stop")

    failing_analyse["fault"] = fault
    assert main(["analyse", "x.mcap"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err == ["vibroscope analyse: warning: 10 NaN samples in /imu/m1.linear_acceleration.x at 1.5 s",
                   "vibroscope analyse: warning: force channel constant",
                   "vibroscope analyse: warning: divide by zero encountered in log",
                   "vibroscope analyse: error: TypeError: stop (run with --debug for the traceback)"]


def test_ctrl_c_is_interrupted_130(failing_analyse, capsys):
    failing_analyse["fault"] = _raise(KeyboardInterrupt())
    assert main(["analyse", "x.mcap"]) == 130
    assert capsys.readouterr().err == "vibroscope analyse: interrupted\n"


def test_argparse_errors_keep_their_usage_line_and_status_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["analyse", "x.mcap", "--nperseg", "many"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "usage: vibroscope analyse" in err and "invalid int value: 'many'" in err and "Traceback" not in err
    assert main([]) == 2


def test_analyse_opens_no_socket(tmp_path, monkeypatch, capsys):
    """No network at run time (no viewer asked for): ``socket.socket`` raising changes nothing."""
    import socket

    from vibroscope.commands.demo import make_demo_log

    log = tmp_path / "t.mcap"
    make_demo_log(log, duration=4.0, fs=200.0)
    monkeypatch.chdir(tmp_path)
    opened = []

    def no_network(*a, **k):
        opened.append(a)
        raise OSError("network access attempted")

    monkeypatch.setattr(socket, "socket", no_network)
    monkeypatch.setattr(socket, "create_connection", no_network)
    assert main(["analyse", str(log), "--input", "/actuator/force.wrench.force.x", "--json", "s.json"]) == 0
    assert not opened and (tmp_path / "t_analyse.rrd").is_file() and (tmp_path / "s.json").is_file()


def test_analyse_log_arguments_with_optional_values(tmp_path, capsys):
    """`--connect`/`--dask` take an optional URL/address: a log right after them is a log, not an
    address; no log at all, or several logs with --connect, is one clear line (exit 1)."""
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    logs = [str(write_ros2_mcap(tmp_path / f"l{k}.mcap",
                                Signals(data=np.random.default_rng(k).standard_normal((1, 2000)), fs=500.0,
                                        channels=["/imu.linear_acceleration.x"])))
            for k in range(2)]
    assert main(["analyse"]) == 1
    assert "no log given" in capsys.readouterr().err
    assert main(["analyse", "--connect", *logs]) == 1
    assert "a fleet (--dask or several logs) has no live view" in capsys.readouterr().err
    # one log after a bare --connect is the log: it gets as far as looking for a viewer on the default port
    # (the test binds nothing there: a closed port on 127.0.0.1 answers at once)
    import vibroscope.commands._live as live

    code = main(["analyse", "--connect", logs[0], "--no-rrd", "--no-figures"])
    err = capsys.readouterr().err
    assert code == 1 and f"no rerun viewer listening at {live.DEFAULT_URL}" in err and logs[0] in err


def test_analyse_of_an_imu_log_with_a_lost_stretch_writes_every_output(tmp_path, capsys, check_png):
    """Accelerations with 0.3 s missing (a lost chunk): the modes, and every figure and the recording
    are written; the kinematics integrate each stretch between the gaps (before: the run stopped at
    the outputs with "array must not contain infs or NaNs")."""
    import scipy.signal as ss

    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    rng = np.random.default_rng(1)
    b, a = ss.iirpeak(37.0, 30, 1000.0)
    y = ss.lfilter(b, a, rng.standard_normal(30_000))
    x = np.vstack([y, 0.5 * y, -y]) + 0.01 * rng.standard_normal((3, 30_000))
    x[:, 12_000:12_300] = np.nan
    log = write_ros2_mcap(tmp_path / "gap.mcap", Signals(data=x, fs=1000.0,
                                                         channels=[f"/imu.linear_acceleration.{c}" for c in "xyz"],
                                                          units=["m/s^2"] * 3, t0=1.0))
    assert main(["analyse", str(log), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    f = [float(ln.split()[1]) for ln in out.splitlines() if ln.strip().startswith("1 ")]
    assert f and abs(f[0] - 37.0) < 0.5
    check_png(tmp_path / "gap_analyse_figures" / "kinematics.png")
    assert (tmp_path / "gap_analyse.rrd").stat().st_size > 10_000
