"""`vibroscope modal` on the measured FRF data sets, with no option but the file: the Southampton
three-storey frame (BSD-3, Cristallo) and pyuff's measured accelerances (MIT, ladisk/pyuff)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.io import read_frf, read_modes_uff55
from vibroscope.modal.compare import frequency_shift

#: published measured modes of the frame (``../shared/data/README.md``) and the model's
FRAME_HZ = [6.50, 17.47, 26.50]
FRAME_MODEL_HZ = [6.32, 17.94, 26.51]


def test_southampton_exactly_three_modes(shared_data, tmp_path, capsys, check_png):
    """`vibroscope modal frfs/Experimental.csv`: exactly the three storey modes within 0.5 %; the
    weak narrow peaks (28.9, 42.1, 76.7 Hz, 37–47 dB below) are listed as rejected."""
    js = tmp_path / "m.json"
    assert main(["modal", str(shared_data / "southampton" / "frfs" / "Experimental.csv"), "--json", str(js),
                 "--figures", str(tmp_path / "f"), "--rrd", str(tmp_path / "m.rrd")]) == 0
    doc = json.loads(js.read_text())
    f = np.array([m["frequency_hz"] for m in doc["modes"]])
    assert doc["method"] == "lscf" and len(f) == 3
    np.testing.assert_allclose(f, FRAME_HZ, rtol=0.005)
    assert all(0 < m["damping_ratio"] < 0.01 and m["mpc"] > 0.95 for m in doc["modes"])
    weak = [r["frequency_hz"] for r in doc["rejected"] if r["reason"].startswith("weak")]
    assert any(abs(w - 42.05) < 0.1 for w in weak) and any(abs(w - 76.74) < 0.1 for w in weak)
    text = capsys.readouterr().out
    assert "synthesized FRF error" in text
    for name in ("stabilization", "frf_synthesis", "modes"):
        check_png(tmp_path / "f" / f"{name}.png")
    from vibroscope.viewers.rerun_view import read_rrd

    data = read_rrd(tmp_path / "m.rrd")
    assert any(e.startswith("/stabilization/stable_f_damping_mac/") for e in data)
    assert any(e.startswith("/frf/magnitude_db/synthesized/") for e in data)


def test_southampton_crossval_frequency_shift(shared_data):
    """crossval/: measured vs model FRF magnitudes; the per-mode shifts (published model modes
    6.32, 17.94, 26.51 Hz against the measured 6.50, 17.47, 26.50 Hz)."""
    cv = shared_data / "southampton" / "crossval"
    a = np.loadtxt(cv / "ExpDataSo.csv", delimiter=",")
    b = np.loadtxt(cv / "NumDataSo.csv", delimiter=",")
    sh = frequency_shift((a[:, 0], a[:, 1:]), (b[:, 0], b[:, 1:]))
    np.testing.assert_allclose(sh.measured_hz, FRAME_HZ, rtol=0.005)
    np.testing.assert_allclose(sh.model_hz, FRAME_MODEL_HZ, rtol=0.005)
    np.testing.assert_allclose(100 * sh.shift_relative, [-2.96, 2.73, 0.0], atol=0.1)
    assert sh.unpaired_measured_hz.size == 0 and sh.unpaired_model_hz.size == 0


def test_pyuff_measured_frfs_six_modes(shared_data, tmp_path, capsys):
    """pyuff's meas_point_{1,2,3}.txt (accelerance, 0–1000 Hz): six modes, the synthesized FRF
    error reported, UFF 55 written and read back, the modal model file runs in `simulate`."""
    paths = sorted(str(p) for p in (shared_data / "uff").glob("meas_point_*.txt"))
    js, u55, toml = tmp_path / "m.json", tmp_path / "modes.uff", tmp_path / "model.toml"
    assert main(["modal", *paths, "--kind", "accelerance", "--json", str(js), "--uff55", str(u55),
                 "--export-model", str(toml), "--no-rrd", "--figures", str(tmp_path / "f")]) == 0
    doc = json.loads(js.read_text())
    f = np.array([m["frequency_hz"] for m in doc["modes"]])
    assert len(f) == 6
    text = capsys.readouterr().out
    errs = [float(x.split()[0]) for x in text.split("per output): ")[1].splitlines()[0].split(", ")]
    assert len(errs) == 3 and max(errs) < 5.0  # % (2.6–3.9 % measured)
    back = read_modes_uff55(u55)
    np.testing.assert_allclose(back.natural_frequencies, f, rtol=1e-5)
    np.testing.assert_allclose(back.damping_ratios, [m["damping_ratio"] for m in doc["modes"]], rtol=1e-3)
    # the exported pole-residue model reproduces the measured FRFs as LSFD synthesized them
    from vibroscope.models.modelfile import load_model

    model = load_model(toml)
    h = read_frf(paths, kind="accelerance")
    band = (h.frequencies > 20) & (h.frequencies < 990)
    Hm = model.frf(h.frequencies[band])
    rel = np.linalg.norm(Hm - h.H[band]) / np.linalg.norm(h.H[band])
    assert rel < 0.05


def test_frf_file_errors_are_clear(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("0.1;1+1j\n0.2;x\n")
    assert main(["modal", str(bad), "--no-rrd"]) == 1
    with pytest.raises(SystemExit):
        main(["modal", str(bad), "--method", "nonsense"])


def test_silverbox_log_with_an_input_and_no_imu(shared_data, tmp_path):
    """A log without Imu and with --input: the responses are chosen from the other topics (never
    the input's own), and LSCF gives the Silverbox's one resonance (69.5 Hz, ζ 4.8 %, the nominal
    model of the gap example)."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "sb_example", Path(__file__).resolve().parents[2] / "examples" / "gap" / "silverbox.py")
    sb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sb)
    assert sb.main(["--data", str(shared_data / "silverbox"), "--out", str(tmp_path)]) == 0
    js = tmp_path / "a.json"
    assert main(["analyse", str(tmp_path / "silverbox_estimation.mcap"), "--input", "/silverbox/input.wrench.force.x",
                 "--json", str(js), "--no-rrd", "--figures", str(tmp_path / "f")]) == 0
    s = json.loads(js.read_text())
    assert s["outputs"] == ["/silverbox/output.x"]
    assert len(s["modes"]) == 1
    assert s["modes"][0]["frequency_hz"] == pytest.approx(69.5, rel=0.005)
    assert s["modes"][0]["damping_ratio"] == pytest.approx(0.048, rel=0.05)
