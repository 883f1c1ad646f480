"""BlockSchema algebra, Bode/Nyquist and step criteria against closed-form truth."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.models.lti import (
    Block,
    BlockSchema,
    Sum,
    bode,
    clean_tf,
    nyquist,
    step_info,
    step_response,
)


def _same_tf(a, b, f=np.logspace(-2, 2, 50)):
    return np.allclose(bode(a, f).magnitude, bode(b, f).magnitude, rtol=1e-8) and np.allclose(
        nyquist(a, f).response, nyquist(b, f).response, rtol=1e-8, atol=1e-12
    )


G1 = control.tf([2.0], [1.0, 3.0])
G2 = control.tf([1.0, 1.0], [1.0, 2.0, 5.0])


def test_series_parallel_feedback_match_control_algebra():
    assert _same_tf(BlockSchema.series(G1, G2).transfer("y"), G1 * G2)
    assert _same_tf(BlockSchema.series(G1, G2).transfer("x1"), G1)
    assert _same_tf(BlockSchema.parallel(G1, G2).transfer("y"), G1 + G2)
    fb = BlockSchema.feedback(G1, G2)
    assert _same_tf(fb.transfer("y"), control.feedback(G1, G2))
    # error point e = r - G2 y = 1 / (1 + G1 G2)
    assert _same_tf(fb.transfer("e"), control.feedback(control.tf([1], [1]), G1 * G2))
    pos = BlockSchema.feedback(G1, G2, sign=+1)
    assert _same_tf(pos.transfer("y"), control.feedback(G1, G2, sign=+1))


def test_every_point_and_second_input():
    s = BlockSchema(
        (Block("C", G1, "e", "u"), Block("P", G2, "v", "y")),
        (Sum("e", ("r", "-y")), Sum("v", ("u", "d"))),
        ("r", "d"),
    )
    tfs = s.transfers()
    assert set(tfs) == {"r", "d", "e", "u", "v", "y"}
    assert float(control.dcgain(tfs["r"])) == 1.0 and float(control.dcgain(tfs["d"])) == 0.0
    # disturbance to output: P / (1 + C P)
    assert _same_tf(s.transfer("y", "d"), control.feedback(G2, G1))
    with pytest.raises(ValueError, match="not a signal"):
        s.transfer("nope")
    with pytest.raises(ValueError, match="exogenous"):
        s.transfer("y", "u")


def test_schema_validation():
    with pytest.raises(ValueError, match="unknown signal"):
        BlockSchema((Block("G", G1, "q", "y"),))
    with pytest.raises(ValueError, match="written once"):
        BlockSchema((Block("G", G1, "r", "y"), Block("H", G1, "r", "y")))


def test_bode_first_order_corner():
    fc = 3.0
    r = bode(control.tf([1.0], [1 / (2 * np.pi * fc), 1.0]), [fc, 100 * fc])
    assert r.magnitude[0] == pytest.approx(1 / np.sqrt(2), rel=1e-12)
    assert r.phase_deg[0] == pytest.approx(-45.0, abs=1e-10)
    assert r.magnitude_db[1] == pytest.approx(-40.0, abs=0.01)
    f, mag, ph = r  # unpacks like a tuple
    assert not mag.flags.writeable


def test_nyquist_matches_evaluation():
    f = np.array([0.1, 1.0, 10.0])
    r = nyquist(G2, f)
    expected = [complex(G2(2j * np.pi * fi)) for fi in f]
    assert np.allclose(r.response, expected)


def test_step_second_order_criteria():
    wn, z = 4.0, 0.3
    g = control.tf([wn**2], [1, 2 * z * wn, wn**2])
    r = step_response(g, np.linspace(0, 15, 30001))
    assert r.overshoot_pct == pytest.approx(100 * np.exp(-np.pi * z / np.sqrt(1 - z**2)), rel=1e-3)
    assert r.final_value == pytest.approx(1.0)
    ref = control.step_info(g, T=np.linspace(0, 15, 30001))
    assert r.rise_time_s == pytest.approx(ref["RiseTime"], rel=2e-3)
    assert r.settling_time_s == pytest.approx(ref["SettlingTime"], rel=2e-3)


def test_step_first_order_rise_time_is_ln9_tau():
    tau = 0.5
    r = step_response(control.tf([1], [tau, 1]), np.linspace(0, 10, 20001))
    assert r.rise_time_s == pytest.approx(tau * np.log(9), rel=1e-4)
    info = step_info(r.time_s, r.response, final_value=1.0)
    assert info["settling_time_s"] == pytest.approx(tau * np.log(50), rel=1e-3)


def test_clean_tf_cancels():
    g = clean_tf(control.tf([1, 1], [1, 3, 2]))  # (s+1)/((s+1)(s+2))
    assert len(control.poles(g)) == 1
    assert float(control.dcgain(g)) == pytest.approx(0.5)


def test_plots_are_lazy_and_work():
    import matplotlib.pyplot as plt

    f = np.logspace(-1, 1, 50)
    bode(G2, f).plot(label="G2")
    nyquist(G2, f).plot()
    step_response(G2, np.linspace(0, 5, 100)).plot()
    plt.close("all")
