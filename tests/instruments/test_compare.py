"""`vibroscope compare` on the shipped example sweep and the built-in models."""

from __future__ import annotations

from pathlib import Path

import pytest

from vibroscope.cli import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "pneumatic_sweep.csv"


def test_compare_pneumatic_example(tmp_path, capsys, check_png):
    rc = main(["compare", "pneumatic", "--sweep", str(EXAMPLE), "--out", str(tmp_path)])
    assert rc == 0
    png = tmp_path / "compare_pneumatic.png"
    check_png(png)
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


def test_compare_toml_model(tmp_path, capsys):
    model = tmp_path / "m.toml"
    model.write_text(
        'kind = "lumped"\n[[dof]]\nname = "m1"\nmass = 2.0\n'
        '[[element]]\ntype = "spring"\nbetween = ["m1", "ground"]\nk = 5.0e4\n'
        '[[element]]\ntype = "damper"\nbetween = ["m1", "ground"]\nc = 20.0\n'
        '[[input]]\nchannel = "/f.x"\ndof = "m1"\nquantity = "force"\n'
        '[[output]]\nchannel = "/x.x"\ndof = "m1"\nquantity = "displacement"\n'
    )
    sweep = tmp_path / "s.csv"
    sweep.write_text("dof.m1.mass,element.0.k\n2,5e4\n4,5e4\n2,1e5\n")
    assert main(["compare", str(model), "--sweep", str(sweep), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "compare_m.png").exists()
    # initial acceleration of a force step is F/m: a_max = 1/2 m/s^2 per N
    assert "| dof.m1.mass=2, element.0.k=50000 |" in out and "| 0.5 |" in out
    sweep.write_text("dof.m9.mass\n2\n")
    assert main(["compare", str(model), "--sweep", str(sweep), "--out", str(tmp_path)]) == 1


def test_compare_parameters_the_model_cannot_take(tmp_path, capsys):
    """A mass of 1e300 kg: no rise time, no cut-off: the row is named and the run fails (before: exit 0,
    a row of 'nan', scipy's "Badly conditioned filter coefficients" and a figure)."""
    sweep = tmp_path / "s.csv"
    sweep.write_text("A,V,m\n0.006,0.00075,1e300\n")
    assert main(["compare", "pneumatic", "--sweep", str(sweep), "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "line 2 (A=0.006, V=0.00075, m=1e+300)" in err[0] and "'t_r'" in err[0]
    assert not (tmp_path / "compare_pneumatic.png").exists()
