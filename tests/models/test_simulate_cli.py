"""``vibroscope simulate``: model file -> ROS 2 MCAP, read back like a real recording."""

import numpy as np
import pytest
from scipy import signal

from vibroscope.cli import main
from vibroscope.models.modelfile import load_model
from vibroscope.models.simulate import simulate

from vibroscope.io import read_mcap

MODEL = """\
kind = "lumped"
[[dof]]
name = "m1"
mass = 2.0
[[dof]]
name = "m2"
mass = 1.0
[[element]]
type = "spring"
between = ["m1", "ground"]
k = 5.0e4
[[element]]
type = "spring"
between = ["m2", "m1"]
k = 3.0e4
[[element]]
type = "damper"
between = ["m1", "ground"]
c = 15.0
[[element]]
type = "damper"
between = ["m2", "m1"]
c = 5.0
[[input]]
channel = "/actuator/force_cmd.wrench.force.x"
dof = "m2"
quantity = "force"
[[output]]
channel = "/imu/m1.linear_acceleration.x"
dof = "m1"
quantity = "acceleration"
[[output]]
channel = "/imu/m2.linear_acceleration.x"
dof = "m2"
quantity = "acceleration"
"""
CH = ["/actuator/force_cmd.wrench.force.x", "/imu/m1.linear_acceleration.x", "/imu/m2.linear_acceleration.x"]


@pytest.fixture
def model_file(tmp_path):
    p = tmp_path / "model.toml"
    p.write_text(MODEL)
    return p


def test_excitation_to_mcap_matches_analytic_frf(tmp_path, model_file, capsys):
    out = tmp_path / "sim.mcap"
    rc = main(["simulate", str(model_file), "--excitation", "random:f_lo=1,f_hi=200,rms=10",
               "--out", str(out), "--fs", "500", "--duration", "200", "--seed", "3"])
    assert rc == 0 and out.exists()
    assert "wrote" in capsys.readouterr().out
    log = read_mcap(out, channels=CH)
    assert log.fs == pytest.approx(500.0) and log.n_samples == 100_000
    assert log.units == ("N", "m/s^2", "m/s^2")
    model = load_model(model_file)
    # what was written is the simulation of what was written as input
    ref = simulate(model, log.data[0], log.fs)
    np.testing.assert_allclose(log.data[1:], ref.data[1:], rtol=0, atol=1e-9 * np.abs(ref.data[1:]).max())
    # and its H1 is the analytic accelerance
    f, Pxx = signal.welch(log.data[0], log.fs, nperseg=4096)
    _, Pxy = signal.csd(log.data[0], log.data[1:], log.fs, nperseg=4096)
    _, coh = signal.coherence(log.data[0], log.data[1:], log.fs, nperseg=4096)
    H = model.frf(f)[:, :, 0].T
    ok = (coh > 0.999) & (f > 2) & (f < 195)
    assert ok.sum() > 500
    H1 = Pxy / Pxx[None]
    assert np.max(np.abs(H1[ok] / H[ok] - 1)) < 0.01


def test_input_log_drives_model_sample_for_sample(tmp_path, model_file):
    first = tmp_path / "a.mcap"
    assert main(["simulate", str(model_file), "--excitation", "sweep:f0=2,f1=150,amplitude=10",
                 "--out", str(first), "--duration", "4", "--fs", "1000"]) == 0
    second = tmp_path / "b.mcap"
    assert main(["simulate", str(model_file), "--input", str(first), "--out", str(second), "--noise", "0.05",
                 "--seed", "7"]) == 0
    a, b = read_mcap(first, channels=CH), read_mcap(second, channels=CH)
    assert b.t0 == pytest.approx(a.t0) and b.n_samples == a.n_samples
    np.testing.assert_array_equal(b.data[0], a.data[0])
    d = b.data[1:] - a.data[1:]
    rms = np.sqrt(np.mean(a.data[1:] ** 2, axis=1))
    np.testing.assert_allclose(np.std(d, axis=1), 0.05 * rms, rtol=0.1)
    assert abs(np.corrcoef(d[0], a.data[1])[0, 1]) < 0.1


def test_errors_exit_1(tmp_path, model_file, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(MODEL.replace("mass = 1.0", "mass = -1.0"))
    assert main(["simulate", str(bad), "--excitation", "step:amplitude=1", "--out", str(tmp_path / "x.mcap")]) == 1
    err = capsys.readouterr().err
    assert "bad.toml:7" in err and "mass" in err
    assert main(["simulate", str(model_file), "--excitation", "bogus:x=1", "--out", str(tmp_path / "x.mcap")]) == 1
    assert "bogus" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["simulate", str(model_file), "--out", str(tmp_path / "x.mcap")])  # no source


def test_simulate_then_analyse_finds_exactly_the_model_modes(tmp_path, model_file):
    """simulate writes a recording-like log; analyse finds exactly the model's modes (no spurious
    low-frequency peaks where a grounded structure barely responds and sensor noise dominates)."""
    import json

    log, js = tmp_path / "a.mcap", tmp_path / "a.json"
    assert main(["simulate", str(model_file), "--excitation", "random:f_lo=1,f_hi=150,rms=10", "--out", str(log),
                 "--fs", "1000", "--duration", "120", "--noise", "0.01", "--seed", "3"]) == 0
    assert main(["analyse", str(log), "--input", CH[0], "--fmin", "2", "--fmax", "150", "--json", str(js),
                 "--no-rrd", "--figures", str(tmp_path / "f")]) == 0
    s = json.loads(js.read_text())
    truth = load_model(model_file).modes()
    found = np.array([m["frequency_hz"] for m in s["modes"]])
    assert len(found) == 2
    np.testing.assert_allclose(found, truth.natural_frequencies, rtol=0.005)
    np.testing.assert_allclose([m["damping_ratio"] for m in s["modes"]], truth.damping_ratios, rtol=0.1)


def test_simulate_help_is_plain_text(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "``" not in out and ":func:" not in out  # no reST markup
    # the description keeps its paragraphs and line breaks (RawDescriptionHelpFormatter)
    assert "Drive a model file with an excitation or a recorded input" in out
    assert "\n\nWith --input, the model's input channels" in out


def test_every_command_is_registered():
    """No command is silently left out of the parser (a failing import of a command module is an
    error, not a missing sub-command)."""
    import argparse

    from vibroscope.cli import COMMANDS, build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(COMMANDS) <= set(sub.choices)  # (plus aliases such as "analyze")
    assert all(sub.choices[c].get_default("func") is not None for c in COMMANDS)


def test_an_input_log_with_a_gap_is_refused_naming_the_log_and_channel(tmp_path, model_file, capsys):
    """The force misses 0.3 s: the model is not driven through the gap (the input there is unknown);
    the one-line error names the log, the channel and the gap (before: "MODEL.toml: cannot simulate:
    u contains non-finite values"), and nothing is written."""
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    u = np.sin(2 * np.pi * 5 * np.arange(4000) / 1000.0)
    u[1500:1800] = np.nan
    log = write_ros2_mcap(tmp_path / "gap.mcap", Signals(data=u[None], fs=1000.0, channels=CH[:1], units=["N"], t0=1.0))
    out = tmp_path / "out.mcap"
    assert main(["simulate", str(model_file), "--input", str(log), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(log) in err[0] and CH[0] in err[0] and "300 of 4000 samples missing" in err[0]
    assert "1.5–1.8 s" in err[0] and not out.exists()
