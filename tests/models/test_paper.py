"""The paper's instruments: pneumatic motor, hydraulic P vs PD2, PI + correction block schema."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.models.paper import (
    BLOCK_SCHEMA_PLANT,
    CORRECTION,
    HYDRAULIC_NOMINAL,
    PI_REGULATOR,
    PNEUMATIC_NOMINAL,
    figure_block_schema,
    figure_hydraulic,
    figure_pneumatic,
    hydraulic_closed_loop,
    hydraulic_comparison,
    hydraulic_motor,
    hydraulic_natural_frequency,
    paper_block_schema,
    pneumatic_motor,
    pneumatic_natural_frequency,
)


@pytest.mark.parametrize("A_cm2", [50.0, 60.0, 70.0, 80.0])
def test_pneumatic_natural_frequency_matches_damp(A_cm2):
    p = dict(PNEUMATIC_NOMINAL, A=A_cm2 * 1e-4)
    wn, z = pneumatic_natural_frequency(**p)
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
    wn, z = pneumatic_natural_frequency()
    assert 0.5 < wn / 2 / np.pi < 5 and 0 < z < 1
    with pytest.raises(ValueError):
        pneumatic_motor(A=-1.0)
    with pytest.raises(ValueError):
        pneumatic_motor(output="jerk")


def test_larger_area_raises_natural_frequency():
    w = [pneumatic_natural_frequency(**dict(PNEUMATIC_NOMINAL, A=a * 1e-4))[0] for a in (60, 70, 80)]
    assert w[0] < w[1] < w[2]


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # control.damp on the integrator pole
def test_hydraulic_natural_frequency_formula():
    p = HYDRAULIC_NOMINAL
    wh = hydraulic_natural_frequency(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    assert wh == pytest.approx(np.sqrt(4 * 1.0e9 * 1.2e-3**2 / (6.0e-4 * 150.0)))
    wn, z, _ = control.damp(hydraulic_motor(), doprint=False)
    osc = wn > 1
    assert np.allclose(wn[osc], wh) and np.allclose(z[osc], p["zeta_h"])


def test_hydraulic_p_loop_stability_limit():
    # Merritt: the P loop is stable for K_v < 2 zeta_h omega_h
    p = HYDRAULIC_NOMINAL
    wh = hydraulic_natural_frequency(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    kq_a = p["K_q"] / p["A"]
    lim = 2 * p["zeta_h"] * wh / kq_a
    assert np.all(control.poles(hydraulic_closed_loop(0.95 * lim)).real < 0)
    assert np.any(control.poles(hydraulic_closed_loop(1.05 * lim)).real > 0)
    assert float(control.dcgain(hydraulic_closed_loop(0.5 * lim, 0.0, 1e-3))) == pytest.approx(1.0)


def test_hydraulic_pd2_beats_p():
    c = hydraulic_comparison()
    assert np.all(control.poles(hydraulic_closed_loop(**c.gains_pd2)).real < 0)
    # ITAE pole placement: the characteristic polynomial is the standard form
    p = HYDRAULIC_NOMINAL
    wh = c.omega_h
    g = hydraulic_closed_loop(**c.gains_pd2)
    den = np.squeeze(g.den[0][0]) * wh**2
    w0 = wh / np.sqrt(2.15)
    assert np.allclose(den, [1, 1.75 * w0, 2.15 * w0**2, w0**3], rtol=1e-9)
    assert c.settling_reduction_pct > 40
    assert c.oscillation_reduction_pct > 40
    assert c.step_pd2.final_value == pytest.approx(1.0)
    s = hydraulic_comparison(tuning="same-gain")
    assert s.oscillation_pd2 == pytest.approx(0.0, abs=1e-3) and s.settling_reduction_pct > 0
    assert "P" in c.summary()
    with pytest.raises(ValueError):
        hydraulic_comparison(tuning="magic")


def test_block_schema_closed_loop_dc_gain_and_final_value():
    s = paper_block_schema()
    y = s.transfer("y")
    assert float(control.dcgain(y)) == pytest.approx(1.0, rel=1e-9)
    assert float(control.dcgain(s.transfer("e"))) == pytest.approx(0.0, abs=1e-9)
    # closed loop y/r = L / (1 + L) with L = H_R H_c H_p
    ref = control.feedback(PI_REGULATOR * CORRECTION * BLOCK_SCHEMA_PLANT)
    f = np.logspace(-3, 1, 40)
    assert np.allclose(control.frequency_response(y, 2 * np.pi * f).magnitude.ravel(),
                       control.frequency_response(ref, 2 * np.pi * f).magnitude.ravel(), rtol=1e-8)
    assert np.all(control.poles(y).real < 0)
    # final value theorem in simulation: step responses settle to y = 1, e = 0
    t = np.linspace(0, 150, 15001)
    r = s.step(t)
    assert r["y"].response[-1] == pytest.approx(1.0, abs=2e-3)
    assert r["e"].response[-1] == pytest.approx(0.0, abs=2e-3)
    # regulator output settles to 1 / (plant DC gain * correction DC gain) = 1
    assert r["u"].response[-1] == pytest.approx(1.0, abs=2e-3)


def test_block_schema_load_rejection_and_open_loop():
    s = paper_block_schema(load=True)
    yd = s.transfer("y", "d")
    assert float(control.dcgain(yd)) == pytest.approx(0.0, abs=1e-9)  # PI integrator rejects a constant load
    assert float(control.dcgain(s.transfer("u", "d"))) == pytest.approx(-1.0, rel=1e-9)
    ol = paper_block_schema(closed=False)
    assert np.isinf(np.abs(control.dcgain(ol.transfer("y"))))  # PI integrates without feedback
    assert set(paper_block_schema(load=True).signals) == {"r", "d", "e", "u", "c", "v", "y"}


def test_figures(tmp_path):
    for fn in (figure_pneumatic, figure_hydraulic, figure_block_schema):
        out = tmp_path / f"{fn.__name__}.png"
        fn(out)
        assert out.stat().st_size > 10_000
