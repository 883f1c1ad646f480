"""The signature tests' statistics and their figures' curves describe the same thing."""

from __future__ import annotations

import numpy as np

from vibroscope.gap.signatures import run_signatures


def test_level_dependence_plots_the_output_its_statistic_names():
    """Two outputs, one whose BLA does not change with the level and one 20 dB lower at the high
    level (a closed loop's controller output under friction: EMPS): the statistic is the larger
    change, and the curve is that output's, not the mean of both (-10 dB, which the title's
    20 dB contradicted)."""
    rng = np.random.default_rng(0)
    f = np.linspace(1.0, 50.0, 40)
    H_lo = (1.0 + 0.1j) * np.ones((f.size, 2))
    H_hi = H_lo * np.array([1.0, 0.1])[None, :]
    coh = np.full((f.size, 2), 0.99)
    n = 2000
    u = rng.standard_normal(n)
    tests = run_signatures(
        frequencies=f, H_levels=[H_lo, H_hi], level_rms=[1.0, 4.0], H_meas=H_lo, H_refit=H_lo, coh=coh,
        noise_coh=coh, resid=rng.standard_normal((2, n)) * 1e-3, u=u,
        states={"displacement": rng.standard_normal((1, n)), "velocity": rng.standard_normal((1, n)),
                "relative": {}},
        fs=100.0, out_channels=["/a/pos", "/a/cmd"])
    lvl = next(t for t in tests if t.name == "level_dependence")
    np.testing.assert_allclose(lvl.value, 20.0, rtol=1e-9)
    np.testing.assert_allclose(lvl.y, -20.0, rtol=1e-9)
    assert lvl.flagged and "/a/cmd" in lvl.detail and "/a/cmd" in lvl.y_label
