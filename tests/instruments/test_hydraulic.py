"""The linear hydraulic motor (Merritt 1967) under P and PD2 position control."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.instruments.hydraulic import (HYDRAULIC_NOMINAL, hydraulic_closed_loop, hydraulic_comparison, hydraulic_motor,
                                             hydraulic_natural_frequency_rad_s)
from vibroscope.viewers.instruments import figure_hydraulic


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # control.damp on the integrator pole
def test_hydraulic_natural_frequency_formula():
    p = HYDRAULIC_NOMINAL
    wh = hydraulic_natural_frequency_rad_s(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    assert wh == pytest.approx(np.sqrt(4 * 1.0e9 * 1.2e-3**2 / (6.0e-4 * 150.0)))
    wn, z, _ = control.damp(hydraulic_motor(), doprint=False)
    osc = wn > 1
    assert np.allclose(wn[osc], wh) and np.allclose(z[osc], p["zeta_h"])


def test_hydraulic_p_loop_stability_limit():
    # Merritt: the P loop is stable for K_v < 2 zeta_h omega_h
    p = HYDRAULIC_NOMINAL
    wh = hydraulic_natural_frequency_rad_s(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    kq_a = p["K_q"] / p["A"]
    lim = 2 * p["zeta_h"] * wh / kq_a
    assert np.all(control.poles(hydraulic_closed_loop(0.95 * lim)).real < 0)
    assert np.any(control.poles(hydraulic_closed_loop(1.05 * lim)).real > 0)
    assert float(control.dcgain(hydraulic_closed_loop(0.5 * lim, 0.0, 1e-3))) == pytest.approx(1.0)


def test_hydraulic_pd2_beats_p():
    c = hydraulic_comparison()
    assert np.all(control.poles(hydraulic_closed_loop(**c.gains_pd2)).real < 0)
    # ITAE pole placement: the characteristic polynomial is the standard form
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


def test_figure(tmp_path, check_png):
    out = figure_hydraulic(tmp_path / "hydraulic.png")
    check_png(out)
