"""The paper's linear pneumatic motor (eq. 1-3) against its closed forms."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.instruments.pneumatic import PNEUMATIC_NOMINAL, pneumatic_motor, pneumatic_natural_frequency_rad_s
from vibroscope.viewers.instruments import figure_pneumatic


@pytest.mark.parametrize("A_cm2", [50.0, 60.0, 70.0, 80.0])
def test_pneumatic_natural_frequency_matches_damp(A_cm2):
    p = dict(PNEUMATIC_NOMINAL, A=A_cm2 * 1e-4)
    wn, z = pneumatic_natural_frequency_rad_s(**p)
    w_num, z_num, poles = control.damp(pneumatic_motor(**p, output="velocity"), doprint=False)
    assert np.allclose(w_num, wn, rtol=1e-10)
    assert np.allclose(z_num, z, rtol=1e-10)
    # hand value at the nominal point: wn^2 = (A^2 + a_m b_m) chi dp / (V m)
    c = p["V"] / (1.4 * p["dp"])
    assert wn == pytest.approx(np.sqrt((p["A"] ** 2 + p["a_m"] * p["b_m"]) / (c * p["m"])))


def test_pneumatic_structure_and_units():
    p = PNEUMATIC_NOMINAL
    gz = pneumatic_motor()
    poles = control.poles(gz)
    assert np.sum(np.abs(poles) < 1e-9) == 1  # one integrator: displacement of a flow
    gv = pneumatic_motor(output="velocity")
    # DC velocity per flow = A / (A^2 + a_m b_m)  (m/s per m^3/s): ~1/A
    assert float(control.dcgain(gv)) == pytest.approx(p["A"] / (p["A"] ** 2 + p["a_m"] * p["b_m"]), rel=1e-9)
    ga = pneumatic_motor(output="acceleration")
    assert float(control.dcgain(ga)) == pytest.approx(0.0, abs=1e-9)
    # SI conversion sanity: nominal natural frequency of a few Hz
    wn, z = pneumatic_natural_frequency_rad_s()
    assert 0.5 < wn / 2 / np.pi < 5 and 0 < z < 1
    with pytest.raises(ValueError):
        pneumatic_motor(A=-1.0)
    with pytest.raises(ValueError):
        pneumatic_motor(output="jerk")


def test_larger_area_raises_natural_frequency():
    w = [pneumatic_natural_frequency_rad_s(**dict(PNEUMATIC_NOMINAL, A=a * 1e-4))[0] for a in (60, 70, 80)]
    assert w[0] < w[1] < w[2]


def test_figure(tmp_path, check_png):
    out = figure_pneumatic(tmp_path / "pneumatic.png")
    assert out == tmp_path / "pneumatic.png"
    check_png(out)
