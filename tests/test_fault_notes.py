"""Expected properties of a signal are notes, not faults (issue 20, item 6): gravity on an
accelerometer's axes is found from the length of the sensor's mean acceleration vector (standard
gravity, 9.80665 m/s²), a constant output is a note; the console counts the faults in one line
and prints the details with ``--verbose``; the JSON keeps every fault and note in full."""

import json

import numpy as np
import pytest
import scipy.signal as ss

from vibroscope.cli import main
from vibroscope.faults import G_N, detect_faults, fault_summary
from vibroscope.signals import Signals

FS = 1000.0
N = 30_000
IMU = [f"/imu.linear_acceleration.{c}" for c in "xyz"]


def _vibration(seed: int = 1) -> np.ndarray:
    """Three axes of a lightly damped 37 Hz resonance under white noise, shape (3, N), zero mean."""
    rng = np.random.default_rng(seed)
    b, a = ss.iirpeak(37.0, 30, FS)
    y = ss.lfilter(b, a, rng.standard_normal(N))
    return np.vstack([y, 0.5 * y, -y]) + 0.01 * rng.standard_normal((3, N))


def _kinds(faults):
    return [(f.channel.rsplit(".", 1)[-1], f.kind, f.note) for f in faults]


def test_gravity_on_a_tilted_imu_is_a_note_a_larger_offset_a_fault():
    """A sensor tilted by 30°: gravity splits into g·sin 30° on y and g·cos 30° on z; both are notes
    (the mean vector's length is g). The same offsets doubled (length 2g) are dc_offset faults."""
    x = _vibration()
    tilt = np.radians(30.0)
    g = np.array([[0.0], [G_N * np.sin(tilt)], [G_N * np.cos(tilt)]])
    faults = detect_faults(Signals(data=x + g, fs=FS, channels=IMU, units=["m/s^2"] * 3), nperseg=1024)
    assert _kinds(faults) == [("y", "gravity", True), ("z", "gravity", True)]
    assert "gravity" in faults[1].message and f"{G_N * np.cos(tilt):.4g}" in faults[1].message
    faults = detect_faults(Signals(data=x + 2 * g, fs=FS, channels=IMU, units=["m/s^2"] * 3), nperseg=1024)
    assert _kinds(faults) == [("y", "dc_offset", False), ("z", "dc_offset", False)]
    assert fault_summary(faults) == "2 dc_offset"


@pytest.mark.parametrize("unit, mean, kind", [
    ("m/s^2", -9.79, "gravity"),  # one axis, pointing down
    ("m/s²", 9.83, "gravity"),
    ("g", 1.0, "gravity"),  # in g
    ("m/s^2", 9.80665 * 1.08, "dc_offset"),  # 8 % off g: not gravity
    ("m/s^2", 5.0, "dc_offset"),
    ("", 9.81, "dc_offset"),  # no unit: not known to be an acceleration
    ("N", 9.81, "dc_offset"),
])
def test_one_axis_gravity_needs_an_acceleration_unit_and_a_mean_near_g(unit, mean, kind):
    x = _vibration()[:1] * 0.5 + mean
    found = [f for f in detect_faults(Signals(data=x, fs=FS, channels=["/acc"], units=[unit]),
                                      nperseg=1024) if f.kind != "missing_unit"]
    assert [(f.kind, f.note) for f in found] == [(kind, kind == "gravity")]


def test_a_constant_output_is_a_note_a_constant_input_a_fault():
    x = _vibration()
    sig = Signals(data=np.vstack([x[:2], np.full((1, N), 0.25)]), fs=FS, channels=IMU, units=["m/s^2"] * 3)
    (c,) = detect_faults(sig, nperseg=1024)
    assert (c.kind, c.action, c.note) == ("constant", "drop", True)
    sig = Signals(data=np.vstack([np.full((1, N), 3.0), x[:1]]), fs=FS, channels=["/force", "/acc"],
                  units=["N", "m/s^2"])
    (c,) = detect_faults(sig, input="/force", nperseg=1024)
    assert (c.kind, c.action, c.note) == ("constant", "stop", False)


def test_fault_summary_counts_channels_per_kind_most_first():
    x = _vibration()
    x[0, 5000:5100] = np.nan
    x[1, 5000:5100] = np.nan
    x[2, 9000:9400] = 0.0  # a dropout
    faults = detect_faults(Signals(data=x, fs=FS, channels=IMU, units=["m/s^2"] * 3), nperseg=1024)
    assert fault_summary(faults) == "2 nan, 1 dropout"
    assert fault_summary(()) == ""


def _log(tmp_path, x, name):
    from vibroscope.io import write_ros2_mcap

    return write_ros2_mcap(tmp_path / f"{name}.mcap", Signals(data=x, fs=FS, channels=IMU, units=["m/s^2"] * 3, t0=1.0))


def _fault_lines(out: str) -> list[str]:
    return [ln for ln in out.splitlines() if ln.lstrip().startswith(("fault", "note:"))]


def test_imu_log_with_gravity_on_z_has_no_fault_but_a_note_in_the_json(tmp_path, capsys):
    x = _vibration()
    x[2] += G_N
    log = _log(tmp_path, x, "imu")
    js = tmp_path / "s.json"
    assert main(["analyse", str(log), "--json", str(js), "--no-rrd", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert _fault_lines(out) == [] and not [ln for ln in out.splitlines() if "dc_offset" in ln or "gravity:" in ln]
    s = json.loads(js.read_text())
    assert s["faults"] == []
    assert [(n["channel"], n["kind"], n["note"]) for n in s["notes"]] == [(IMU[2], "gravity", True)]
    assert not any("dc_offset" in w or "gravity" in w for w in s["warnings"])
    modes = [float(ln.split()[1]) for ln in out.splitlines() if ln.strip().startswith("1 ")]
    assert modes and abs(modes[0] - 37.0) < 0.5  # the offset is removed by the per-segment detrend


def test_several_faults_are_one_console_line_and_in_full_with_verbose(tmp_path, capsys):
    """A dropout on x, a clipped y and gravity on z: one summary line without --verbose; with it, one
    line per kind of fault and the gravity note; the JSON holds both faults and the note."""
    x = _vibration()
    x[0, 10_000:10_500] = 0.0  # dropout
    x[1] = np.minimum(x[1], np.quantile(x[1], 0.999))  # clipped at the top
    x[2] += G_N
    log = _log(tmp_path, x, "faulty")
    js = tmp_path / "s.json"
    args = ["analyse", str(log), "--json", str(js), "--no-rrd", "--no-figures"]
    assert main(args) == 0
    lines = _fault_lines(capsys.readouterr().out)
    assert lines == ["  faults: 1 dropout, 1 clipping (details: --verbose or --json)"]
    s = json.loads(js.read_text())
    assert sorted((f["channel"], f["kind"]) for f in s["faults"]) == [(IMU[0], "dropout"), (IMU[1], "clipping")]
    assert [(n["channel"], n["kind"]) for n in s["notes"]] == [(IMU[2], "gravity")]
    assert main([*args, "--verbose"]) == 0
    lines = _fault_lines(capsys.readouterr().out)
    assert [ln.split(":")[0].strip() + ":" + ln.split(":")[1].split(" in ")[0] for ln in lines] == [
        "fault: dropout", "fault: clipping", "note: gravity"]
    assert lines[0].startswith(f"  fault: dropout in {IMU[0]}: 500 samples of zeros in 1 span (10–10.5 s)")
