"""`vibroscope compare` on the shipped example sweep and the built-in models."""

from __future__ import annotations

from pathlib import Path

import pytest

from vibroscope.cli import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "pneumatic_sweep.csv"


def test_compare_pneumatic_example(tmp_path, capsys):
    rc = main(["compare", "pneumatic", "--sweep", str(EXAMPLE), "--out", str(tmp_path)])
    assert rc == 0
    png = tmp_path / "compare_pneumatic.png"
    assert png.stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "influence coefficients" in out
    assert "| A: 0.006 -> 0.007 |" in out
    assert "| V: 0.00075 -> 0.001 |" in out


@pytest.mark.parametrize("model,csv", [("hydraulic", "k_p\n50\n80\n"), ("block-schema", "omega_n,zeta\n5,0.7\n8,0.7\n")])
def test_compare_builtins(tmp_path, model, csv):
    sweep = tmp_path / "s.csv"
    sweep.write_text(csv)
    assert main(["compare", model, "--sweep", str(sweep), "--out", str(tmp_path)]) == 0
    assert (tmp_path / f"compare_{model}.png").exists()


def test_compare_rrd(tmp_path):
    pytest.importorskip("rerun")
    rrd = tmp_path / "c.rrd"
    assert main(["compare", "pneumatic", "--sweep", str(EXAMPLE), "--out", str(tmp_path), "--rrd", str(rrd)]) == 0
    assert rrd.stat().st_size > 0


def test_compare_errors(tmp_path, capsys):
    sweep = tmp_path / "s.csv"
    sweep.write_text("bogus\n1\n")
    assert main(["compare", "pneumatic", "--sweep", str(sweep), "--out", str(tmp_path)]) == 1
    assert "unknown parameter" in capsys.readouterr().err
    assert main(["compare", "no-such-model", "--sweep", str(sweep), "--out", str(tmp_path)]) == 1
    sweep.write_text("A\nxyz\n")
    assert main(["compare", "pneumatic", "--sweep", str(sweep), "--out", str(tmp_path)]) == 1
    assert main(["compare", "pneumatic", "--sweep", str(tmp_path / "missing.csv"), "--out", str(tmp_path)]) == 1
