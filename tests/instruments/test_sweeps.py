"""Comparative sweeps: the numbers behind `vibroscope compare`, without the CLI."""

from __future__ import annotations

import subprocess
import sys
import tomllib

import control
import numpy as np
import pytest

from vibroscope.errors import VibroscopeError
from vibroscope.instruments.influence import influence_coefficient, time_grid
from vibroscope.instruments.pneumatic import PNEUMATIC_NOMINAL
from vibroscope.instruments.sweeps import (CRITERIA, builtin_sweep_model, dumps_toml, model_file_sweep_model,
                                           set_dotted, sweep)

MODEL = '''kind = "lumped"
name = "sdof"

[[dof]]
name = "m1"
mass = 2.0

[[element]]
type = "spring"
between = ["m1", "ground"]
k = 5.0e4

[[input]]
channel = "/f.x"
dof = "m1"
quantity = "force"

[[output]]
channel = "/x.x"
dof = "m1"
quantity = "displacement"
'''


def test_influence_rows_are_the_paper_coefficients():
    model = builtin_sweep_model("pneumatic")
    a0, a1 = PNEUMATIC_NOMINAL["A"], 1.2 * PNEUMATIC_NOMINAL["A"]
    r = sweep(model, ["A"], [{"A": a0}, {"A": a1}])
    ((h, changed, values),) = r.influence_rows()
    assert h == "A" and changed == ["A"] and len(values) == len(CRITERIA)
    # the same number as influence_coefficient(method="paper") on the criterion function
    nu_c = dict(zip(CRITERIA, values))["nu_c"]

    def crit(**p):
        return sweep(model, ["A"], [{"A": p["A"]}]).criteria[0]["nu_c"]

    assert nu_c == pytest.approx(influence_coefficient(crit, {"A": a0}, "A", method="paper", final=a1), rel=1e-12)


def test_rows_with_several_changes_have_no_coefficients():
    r = sweep(builtin_sweep_model("block-schema"), ["omega_n", "zeta"],
              [{"omega_n": 5.0, "zeta": 0.7}, {"omega_n": 8.0, "zeta": 0.5}])
    assert r.influence_rows() == [("", ["omega_n", "zeta"], None)]
    assert len(r.steps) == len(r.bodes) == 2 and r.labels[1] == "omega_n=8, zeta=0.5"


def test_common_time_grid_from_the_slowest_pole():
    g1, g2 = control.tf([1.0], [1.0, 1.0]), control.tf([1.0], [0.1, 1.0])
    t = time_grid(g1, g2, n=11, horizon=6.0)
    assert t[-1] == pytest.approx(6.0) and t.size == 11
    assert time_grid(control.tf([1.0], [1.0, 0.0]))[-1] == pytest.approx(8.0)  # integrator only: 1 s


def test_sweep_errors_name_the_row_and_parameter():
    with pytest.raises(ValueError, match="unknown parameter"):
        sweep(builtin_sweep_model("pneumatic"), ["bogus"], [{"bogus": 1.0}])
    with pytest.raises(ValueError, match="row 2"):
        sweep(builtin_sweep_model("pneumatic"), ["A"], [{"A": 1e-3}, {"A": -1.0}])
    with pytest.raises(ValueError, match="not a built-in model"):
        builtin_sweep_model("nope")


def test_dumps_toml_round_trips_a_model_file():
    doc = tomllib.loads(MODEL + '\n[residual]\nlower = [[[1.0, -2.5]]]\nflag = true\n')
    assert tomllib.loads(dumps_toml(doc)) == doc


def test_set_dotted_addresses_tables_by_name_and_index(tmp_path):
    doc = tomllib.loads(MODEL)
    set_dotted(doc, "dof.m1.mass", 3.0, "m.toml")
    set_dotted(doc, "element.0.k", 1e5, "m.toml")
    assert doc["dof"][0]["mass"] == 3.0 and doc["element"][0]["k"] == 1e5
    for key, msg in (("dof.m9.mass", "no entry named"), ("element.4.k", "out of range"),
                     ("nope", "no key"), ("dof.m1.mass.x", "below a value")):
        with pytest.raises(VibroscopeError, match=msg):
            set_dotted(doc, key, 1.0, "m.toml")


def test_model_file_sweep(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(MODEL)
    model = model_file_sweep_model(path)
    assert model.name == "m" and model.order == 2
    r = sweep(model, ["dof.m1.mass"], [{"dof.m1.mass": 2.0}, {"dof.m1.mass": 8.0}])
    wn = [np.sqrt(5e4 / m) / 2 / np.pi for m in (2.0, 8.0)]
    assert [c["nu_r"] for c in r.criteria] == pytest.approx(wn, rel=1e-6)


def test_instruments_import_no_edge_library():
    """rerun only (python-control itself imports matplotlib.pyplot on import)."""
    code = ("import sys, vibroscope.instruments.sweeps, vibroscope.instruments.mr_damper;"
            "print(','.join(m for m in ('rerun', 'mcap', 'dask', 'vibroscope.viewers') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
