"""MR damper (Spencer 1997): energy versus current, linear small-motion limit, convergence."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.instruments.mr_damper import (
    MRDamperParams,
    linear_limit_energy,
    mr_damper_force,
    mr_damper_rhs,
    simulate_mr_damper,
    sine_test,
)
from vibroscope.viewers.instruments import figure_mr_hysteresis


def _sine(amplitude, freq, fs, cycles):
    t = np.arange(int(cycles * fs / freq) + 1) / fs
    w = 2 * np.pi * freq
    return amplitude * np.sin(w * t), amplitude * w * np.cos(w * t)


def test_spencer_coefficients():
    p = MRDamperParams.spencer1997()
    c0 = p.at_current(0.0)
    assert (c0.alpha, c0.c0, c0.c1, c0.k0, c0.k1, c0.x0) == pytest.approx((14000, 2100, 28300, 4690, 500, 0.143))
    c2 = p.at_current(2.0)  # = Spencer at 2.25 V
    assert c2.alpha == pytest.approx(14000 + 69500 * 2.25)
    assert c2.c0 == pytest.approx(2100 + 350 * 2.25)
    assert c2.c1 == pytest.approx(28300 + 295 * 2.25)
    assert len(p.alpha_poly) == 4  # cubic polynomial in i
    with pytest.raises(ValueError):
        p.at_current(-1.0)


def test_rhs_and_force_consistency():
    c = MRDamperParams.spencer1997().at_current(1.0)
    y, z, x, xd = 0.001, 0.002, 0.004, 0.1
    ydot, zdot = mr_damper_rhs((y, z), x, xd, c)
    f = mr_damper_force(x, xd, y, z, c)
    # the two expressions of the force agree
    f2 = c.alpha * z + c.c0 * (xd - ydot) + c.k0 * (x - y) + c.k1 * (x - c.x0)
    assert f == pytest.approx(f2, rel=1e-12)
    assert f == pytest.approx(c.c1 * ydot + c.k1 * (x - c.x0))


def test_energy_grows_with_current():
    x, xd = _sine(0.015, 2.5, 2000.0, 2)
    e = [simulate_mr_damper(x, 2000.0, i, xdot=xd).loop_energy(0.4) for i in (0.0, 0.5, 1.0, 1.5, 2.0)]
    assert all(b > a for a, b in zip(e, e[1:]))
    assert e[0] > 0
    # Spencer 1997 peak force at 2.25 V and 1.5 cm / 2.5 Hz is about 1.5 kN
    r = simulate_mr_damper(x, 2000.0, 2.0, xdot=xd)
    assert 1200 < np.max(np.abs(r.force)) < 2000


@pytest.mark.parametrize("current", [0.0, 1.0, 2.0])
def test_small_amplitude_matches_linear_limit(current):
    amp, freq, fs = 1e-7, 5.0, 20000.0
    x, xd = _sine(amp, freq, fs, 3)
    r = simulate_mr_damper(x, fs, current, xdot=xd)
    assert r.loop_energy(1 / freq) == pytest.approx(linear_limit_energy(r.coeffs, amp, freq), rel=1e-4)


def test_integration_converges():
    x, xd = _sine(0.015, 2.5, 2000.0, 1)
    ref = simulate_mr_damper(x, 2000.0, 1.0, xdot=xd, max_step=6.25e-6).force
    err = [np.max(np.abs(simulate_mr_damper(x, 2000.0, 1.0, xdot=xd, max_step=h).force - ref)) for h in (1e-4, 5e-5)]
    assert err[1] < err[0] / 4  # RK4: ~16x per halving
    assert err[1] < 0.05  # N, on a ~1 kN force


def test_default_velocity_and_validation():
    x, xd = _sine(0.01, 1.0, 1000.0, 1)
    a = simulate_mr_damper(x, 1000.0, 0.5)
    b = simulate_mr_damper(x, 1000.0, 0.5, xdot=xd)
    assert np.max(np.abs(a.force - b.force)) < 0.01 * np.max(np.abs(b.force))
    force, y, z = a
    assert force.shape == x.shape and not force.flags.writeable
    with pytest.raises(ValueError):
        simulate_mr_damper(x, -1.0, 0.5)
    with pytest.raises(ValueError):
        simulate_mr_damper(x, 1000.0, 0.5, xdot=xd[:-1])


def test_figure(tmp_path, check_png):
    out = tmp_path / "mr.png"
    figure_mr_hysteresis(out, currents=(0.0, 2.0))
    check_png(out)


def test_hysteresis_equals_the_simulator_elements_law():
    """One Spencer law: the instrument's simulated loop, sample by sample, is the law of the
    simulator's MRDamper element (models.elements) on the same x, x', y, z."""
    from vibroscope.models.elements import MRDamper, spencer_mr_damper_rates

    (r,) = sine_test((1.5,), 0.015, 2.5, cycles=1)
    c = r.coeffs
    el = MRDamper.from_coefficients(("m1", "ground"), c)
    for k in range(0, r.x.size, 37):
        x, v, y, z = r.x[k], r.xdot[k], r.y[k], r.z[k]
        ydot, zdot = mr_damper_rhs((y, z), x, v, c)
        np.testing.assert_array_equal(el.state_derivative(x, v, (z, y)), [zdot, ydot])
        assert el.force(x, v, (z, y)) - c.k1 * c.x0 == pytest.approx(r.force[k], rel=1e-12, abs=1e-9)
    # vectorised over the whole record, the shared law gives the instrument's force
    ydot, _ = spencer_mr_damper_rates(r.x, r.xdot, r.y, r.z, alpha=c.alpha, c0=c.c0, c1=c.c1, k0=c.k0,
                                      gamma=c.gamma, beta=c.beta, A=c.A, n=c.n)
    np.testing.assert_array_equal(r.force, c.c1 * ydot + c.k1 * (r.x - c.x0))


def test_simulation_equals_the_recorded_values():
    """Force of the earlier implementation (its own copy of the law), recorded before the law moved."""
    x, xd = _sine(0.015, 2.5, 2000.0, 1)
    r = simulate_mr_damper(x, 2000.0, 1.0, xdot=xd)
    np.testing.assert_allclose(r.force[::200], _RECORDED_FORCE, rtol=1e-12)
    assert r.loop_energy(0.4) == pytest.approx(_RECORDED_ENERGY, rel=1e-12)


_RECORDED_FORCE = [469.0000739228436, 44.8334337175732, -1159.153876835775, -187.83804065283934, 1015.0699500408598]
_RECORDED_ENERGY = 58.17145894891515
