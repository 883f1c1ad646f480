"""BlockSchema algebra, Bode/Nyquist and step criteria against closed-form truth."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.instruments.block_schema import Block, BlockSchema, Sum
from vibroscope.instruments.lti import bode, clean_tf, nyquist, step_info, step_response


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
    """Importing the instruments does not import their viewer (python-control itself imports
    matplotlib.pyplot, so that module is not the measure); ``.plot()`` imports it and draws the
    result's own numbers."""
    import subprocess
    import sys

    code = ("import sys, vibroscope.instruments.lti as m; "
            "f = m.bode(m.control.tf([1.0], [1.0, 1.0]), [1.0]); "
            "print('vibroscope.viewers.instruments' in sys.modules, 'vibroscope.viewers' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f = np.logspace(-1, 1, 50)
    try:
        b = bode(G2, f)
        a_mag, a_ph = b.plot(label="G2")
        assert a_mag.figure is a_ph.figure and isinstance(a_mag.figure, matplotlib.figure.Figure)
        assert len(a_mag.figure.axes) == 2 and a_mag.get_xscale() == "log"
        (line,) = a_mag.get_lines()
        assert line.get_label() == "G2"
        np.testing.assert_array_equal(line.get_xdata(), b.frequencies)
        np.testing.assert_array_equal(line.get_ydata(), b.magnitude_db)
        np.testing.assert_array_equal(a_ph.get_lines()[0].get_ydata(), b.phase_deg)
        # G2(jw) = (1 + jw) / (5 - w^2 + 2jw) at the lowest line, 0.1 Hz
        w = 2 * np.pi * 0.1
        assert line.get_ydata()[0] == pytest.approx(20 * np.log10(abs((1 + 1j * w) / (5 - w**2 + 2j * w))), rel=1e-12)

        n = nyquist(G2, f)
        ax = n.plot()
        locus, mirror, critical = ax.get_lines()
        np.testing.assert_array_equal(locus.get_xdata(), n.response.real)
        np.testing.assert_array_equal(locus.get_ydata(), n.response.imag)
        np.testing.assert_array_equal(mirror.get_ydata(), -n.response.imag)
        assert (critical.get_xdata()[0], critical.get_ydata()[0]) == (-1, 0)
        assert len(nyquist(G2, f).plot(mirror=False).get_lines()) == 2

        t = np.linspace(0, 5, 100)
        s = step_response(G2, t)
        ax = s.plot()
        (line,) = ax.get_lines()
        np.testing.assert_array_equal(line.get_xdata(), t)
        np.testing.assert_array_equal(line.get_ydata(), s.response)
        assert ax.get_xlabel() == "time [s]"
        assert "vibroscope.viewers.instruments" in sys.modules
    finally:
        plt.close("all")


# Values of the earlier in-house implementation (numpy polyval for the frequency response, a
# hand-written step_info), recorded before it was replaced by control.frequency_response /
# control.step_info: (system, time grid, rise time, settling time, overshoot %, peak, final value).
_RECORDED_STEPS = [
    (control.tf([16.0], [1, 2.4, 16.0]), np.linspace(0, 15, 30001),
     0.3303351787899117, 2.8080000000000003, 37.23260094872578, 1.3723260094872578, 1.0),
    (G2, np.linspace(0, 10, 5001), 0.18417091165563265, 4.486, 91.18754301427488, 0.38237508602854975, 0.2),
    (control.tf([-2.0], [1, 1]), np.linspace(0, 10, 2001), 2.197226861725981, 3.915, 0.0, 1.9999092001404735, -2.0),
]


@pytest.mark.parametrize("sys, t, rise, settle, overshoot, peak, final", _RECORDED_STEPS)
def test_step_criteria_equal_the_recorded_values(sys, t, rise, settle, overshoot, peak, final):
    r = step_response(sys, t)
    assert r.rise_time_s == pytest.approx(rise, rel=1e-12)
    assert r.settling_time_s == pytest.approx(settle, rel=1e-12)
    assert r.overshoot_pct == pytest.approx(overshoot, rel=1e-12, abs=1e-12)
    assert r.peak == pytest.approx(peak, rel=1e-12)
    assert r.final_value == pytest.approx(final, rel=1e-12)


def test_step_info_equals_the_recorded_values():
    t = np.linspace(0, 10, 2001)
    info = step_info(t, 1 - np.exp(-t))
    assert info == pytest.approx(dict(rise_time_s=2.196823352786585, settling_time_s=3.91, overshoot_pct=0.0,
                                      peak=0.9999546000702375), rel=1e-12)
    zero = step_info(t, 0 * t)
    assert np.isnan(zero["rise_time_s"]) and np.isnan(zero["settling_time_s"]) and zero["peak"] == 0.0
    # never reaching 90 % of the final value: no rise nor settling time (control.step_info would fail)
    slow = step_info(t, 1 - np.exp(-t), final_value=2.0)
    assert np.isnan(slow["rise_time_s"]) and np.isnan(slow["settling_time_s"]) and slow["overshoot_pct"] == 0.0


def test_bode_equals_the_recorded_values():
    r = bode(G2, [0.01, 1.0, 10.0, 100.0])
    np.testing.assert_allclose(r.magnitude, [0.2004893353120184, 0.17337256411293528, 0.01592960676918768,
                                             0.0015915635409895193], rtol=1e-13)
    np.testing.assert_allclose(r.phase_deg, [2.1544397012591068, -79.01774836468499, -89.08633751755458,
                                             -89.90880916383048], rtol=1e-13)
    h = control.frequency_response(G2, 2 * np.pi * np.array([0.01, 1.0])).complex.ravel()
    np.testing.assert_array_equal(nyquist(G2, [0.01, 1.0]).response, h)


def test_bode_of_an_integrator_at_zero_frequency_is_infinite_without_warning():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = bode(control.tf([1.0], [1.0, 0.0]), [0.0, 1.0])
    assert np.isinf(r.magnitude[0]) and r.magnitude[1] == pytest.approx(1 / (2 * np.pi))


def test_clean_tf_keeps_the_system_when_minreal_fails(monkeypatch):
    def fails(*args, **kwargs):
        raise np.linalg.LinAlgError("ill-conditioned")

    monkeypatch.setattr(control, "minreal", fails)
    g = clean_tf(control.tf([2, 2], [2, 6, 4]))  # unreduced, but monic
    np.testing.assert_allclose(np.squeeze(g.den[0][0]), [1, 3, 2])
    np.testing.assert_allclose(np.squeeze(g.num[0][0]), [1, 1])


def test_clean_tf_does_not_swallow_unexpected_errors(monkeypatch):
    def broken(*args, **kwargs):
        raise TypeError("a bug, not a numerical failure")

    monkeypatch.setattr(control, "minreal", broken)
    with pytest.raises(TypeError, match="a bug"):
        clean_tf(control.tf([1, 1], [1, 3, 2]))
