"""The paper's PI + correction block schema (eq. 4, figures 6-7)."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.instruments.block_schema import BLOCK_SCHEMA_PLANT, CORRECTION, PI_REGULATOR, paper_block_schema
from vibroscope.viewers.instruments import figure_block_schema


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


def test_forced_response_of_a_load_step_matches_control():
    s = paper_block_schema(load=True)
    t = np.linspace(0, 40, 4001)
    u = (t >= 15.0) * -0.5
    r = s.forced_response(t, u, from_="d")
    ref = control.forced_response(s.transfer("y", "d"), T=t, U=u).outputs
    np.testing.assert_allclose(r["y"], ref, rtol=0, atol=1e-12)
    assert set(r) == set(s.signals) and np.all(r["r"] == 0)


def test_figure(tmp_path, check_png):
    out = figure_block_schema(tmp_path / "block_schema.png")
    check_png(out)
