"""The paper's scenarios are computed in the instruments' room (the viewer only draws them)."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.instruments.scenarios import block_schema_scenario, hydraulic_scenario, pneumatic_scenario


def test_block_schema_scenario_pi_loop_has_no_steady_state_error():
    """A PI regulator in the loop: the plant output settles at the unit reference, and a constant
    load at the plant input is rejected (its effect on y goes back to 0). The PI zero at
    -1/9.9 rad/s leaves a slow tail: settled to 1e-6 only after ~200 s."""
    sc = block_schema_scenario(load_step=-0.5, t_load=15.0, t_end=200.0)
    assert sc.time_s[-1] == 200.0 and sc.time_s.size == 6001
    assert sc.reference["y"][-1] == pytest.approx(1.0, abs=1e-6)
    assert sc.reference["e"][-1] == pytest.approx(0.0, abs=1e-6)
    assert np.all(sc.load["y"][sc.time_s < 15.0] == 0.0)
    assert np.min(sc.load["y"]) < -0.05 and sc.load["y"][-1] == pytest.approx(0.0, abs=1e-6)
    assert set(sc.open_loop) >= {"u", "c", "y"}


def test_pneumatic_scenario_steps_integrate_each_other():
    """Per area, the velocity step response is the time derivative of the displacement one."""
    sc = pneumatic_scenario(areas_cm2=(60.0, 80.0))
    assert sc.areas_cm2 == (60.0, 80.0) and len(sc.steps) == len(sc.bode) == len(sc.nyquist) == 2
    for steps in sc.steps:
        t = steps["displacement"].time_s
        v = np.gradient(steps["displacement"].response, t)
        np.testing.assert_allclose(v[5:-5], steps["velocity"].response[5:-5], atol=2e-3 * np.abs(v).max())


def test_hydraulic_scenario_has_both_tunings():
    sc = hydraulic_scenario()
    assert list(sc) == ["itae", "same-gain"]
