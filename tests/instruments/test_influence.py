"""Influence coefficients (paper eq. 2-3): finite-difference accuracy and the Table 1 claims."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.instruments.influence import (
    ClaimCheck,
    InfluenceTable,
    check_paper_claims,
    critical_frequency,
    differentiate,
    influence_coefficient,
    influence_table,
    paper_coefficient,
    peak_acceleration,
    pneumatic_influence_table,
    relative_change,
    resonance_frequency,
    response_time,
)
from vibroscope.instruments.pneumatic import pneumatic_motor


@pytest.mark.parametrize("k", [1.0, 2.0, -1.0, 0.5])
def test_power_law_elasticity(k):
    f = lambda p, q=1.0: 3.0 * p**k * q  # noqa: E731
    c = influence_coefficient(f, {"p": 2.0, "q": 5.0}, "p", rel_step=0.01)
    # central difference of relative changes: exact for k in {1, 2}; O(h^2) otherwise
    tol = 1e-12 if k in (1.0, 2.0) else 1e-3
    assert c == pytest.approx(k, abs=tol)
    assert influence_coefficient(f, {"p": 2.0, "q": 5.0}, "q") == pytest.approx(1.0)


def test_square_is_two_and_paper_method():
    assert influence_coefficient(lambda p: p**2, {"p": 3.0}, "p") == pytest.approx(2.0, abs=1e-12)
    # paper eq. 2-3 one-sided: ((p^2 - (1.1p)^2)/p^2) / ((p - 1.1p)/p) = 2.1
    assert influence_coefficient(lambda p: p**2, {"p": 3.0}, "p", method="paper", rel_step=0.1) == pytest.approx(2.1)
    assert influence_coefficient(lambda p: p**2, {"p": 3.0}, "p", method="paper", final=6.0) == pytest.approx(3.0)
    assert relative_change(4.0, 3.0) == 0.25
    with pytest.raises(ValueError):
        influence_coefficient(lambda p: p, {"p": 1.0}, "x")
    with pytest.raises(ValueError):
        influence_coefficient(lambda p: p, {"p": 1.0}, "p", rel_step=2.0)


def test_criteria_on_known_second_order():
    wn, z = 10.0, 0.2
    g = control.tf([wn**2], [1, 2 * z * wn, wn**2])
    assert resonance_frequency(g) == pytest.approx(wn * np.sqrt(1 - 2 * z**2) / 2 / np.pi, rel=1e-6)
    bw = wn * np.sqrt(1 - 2 * z**2 + np.sqrt(4 * z**4 - 4 * z**2 + 2))
    # the closed form is the half-power (1/sqrt 2) point; the default level is exactly -3 dB
    assert critical_frequency(g, level_db=-10 * np.log10(2)) == pytest.approx(bw / 2 / np.pi, rel=1e-9)
    assert critical_frequency(g) == pytest.approx(control.bandwidth(g) / 2 / np.pi, rel=1e-4)
    # first-order: no resonance; rise time ln 9 tau; peak acceleration (slope) K/tau at t=0
    g1 = control.tf([1.0], [0.1, 1.0])
    assert np.isnan(resonance_frequency(g1))
    assert response_time(g1) == pytest.approx(0.1 * np.log(9), rel=1e-3)
    assert peak_acceleration(g1) == pytest.approx(10.0, rel=1e-6)


def test_pneumatic_table_and_physics():
    t = pneumatic_influence_table()
    assert isinstance(t, InfluenceTable)
    assert t.parameters == ("A", "V", "m") and t.criteria == ("t_r", "a_max", "nu_r", "nu_c")
    assert "| A |" in t.to_markdown() and len(t.rows) == 3
    # omega_n ~ A / sqrt(V m) (leakage and friction small): frequency elasticities ~ +1, -1/2, -1/2
    assert t["A", "nu_c"] == pytest.approx(1.0, abs=0.1)
    assert t["V", "nu_c"] == pytest.approx(-0.5, abs=0.1)
    assert t["m", "nu_c"] == pytest.approx(-0.5, abs=0.1)
    assert t["A", "nu_r"] == pytest.approx(1.0, abs=0.1)
    assert t["V", "t_r"] > 0 and t["m", "t_r"] > 0 and t["A", "t_r"] < 0
    # step size independence (finite-difference converged)
    t2 = influence_table({"nu_c": lambda **p: critical_frequency(pneumatic_motor(**p, output="velocity"))},
                         t.nominal, ("A",), rel_step=0.01)
    assert t2["A", "nu_c"] == pytest.approx(t["A", "nu_c"], rel=5e-3)


def test_paper_claims_checked_truthfully():
    t = pneumatic_influence_table()
    checks = check_paper_claims(t)
    assert len(checks) == 4 and all(isinstance(c, ClaimCheck) for c in checks)
    assert all(c.evidence for c in checks)
    mass = checks[2]
    # physics: the critical frequency falls with mass, so "m raises nu_c" cannot hold
    assert t["m", "nu_c"] < 0 and mass.holds is False
    # our table: A raises nu_c (direction agrees) and V raises t_r (direction agrees)
    assert t["A", "nu_c"] > 0 and t["V", "t_r"] > 0


def test_claims_need_the_rows():
    bad = InfluenceTable(("A",), ("t_r",), np.zeros((1, 1)), {}, "x")
    with pytest.raises(ValueError):
        check_paper_claims(bad)


def test_paper_coefficient_from_values_and_differentiate():
    assert paper_coefficient(9.0, 36.0, 3.0, 6.0) == pytest.approx(3.0)
    with pytest.raises(ValueError):
        paper_coefficient(0.0, 1.0, 3.0, 6.0)
    g = control.tf([2.0], [1.0, 3.0])
    assert np.allclose(np.squeeze(differentiate(g, 2).num[0][0]), [2.0, 0.0, 0.0])
    assert np.allclose(np.squeeze(differentiate(g, 0).num[0][0]), [2.0])
    with pytest.raises(ValueError):
        differentiate(g, -1)
