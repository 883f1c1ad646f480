"""LumpedModel against closed-form truth: 2-DOF eigenvalues, analytic FRF, state space."""

import numpy as np
import pytest

from vibroscope.models.elements import BoucWen, Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output, demo_model, demo_model_5dof


def two_dof_closed_form(m1, m2, k1, k2):
    """Undamped 2-DOF chain ground-k1-m1-k2-m2: det(K - w^2 M) = 0 solved as a quadratic in w^2."""
    a = m1 * m2
    b = -(m1 * k2 + m2 * (k1 + k2))
    c = k1 * k2
    disc = np.sqrt(b * b - 4 * a * c)
    w2 = np.array([(-b - disc) / (2 * a), (-b + disc) / (2 * a)])
    return np.sqrt(w2) / (2 * np.pi)


def test_matrices_chain():
    m = LumpedModel.chain([2.0, 1.0], [3e4, 1e4], [5.0, 2.0])
    np.testing.assert_array_equal(m.M, np.diag([2.0, 1.0]))
    np.testing.assert_array_equal(m.K, [[4e4, -1e4], [-1e4, 1e4]])
    np.testing.assert_array_equal(m.C, [[7.0, -2.0], [-2.0, 2.0]])
    np.testing.assert_array_equal(m.B, [[1.0], [0.0]])


def test_two_dof_eigenfrequencies_closed_form_undamped():
    m1, m2, k1, k2 = 2.0, 1.0, 3e4, 1e4
    model = LumpedModel.chain([m1, m2], [k1, k2], 0.0)
    modes = model.modes()
    np.testing.assert_allclose(modes.natural_frequencies, two_dof_closed_form(m1, m2, k1, k2), rtol=1e-10)
    np.testing.assert_allclose(modes.damping_ratios, 0.0, atol=1e-10)
    # shapes: x2/x1 = k2 / (k2 - w^2 m2) for mode r
    w2 = (2 * np.pi * modes.natural_frequencies) ** 2
    ratio = k2 / (k2 - w2 * m2)
    sh = modes.shapes
    np.testing.assert_allclose(sh[:, 1] / sh[:, 0], ratio, rtol=1e-8)
    assert np.allclose(np.max(np.abs(sh), axis=1), 1.0)


def test_proportional_damping_matches_undamped_problem():
    # C = a M + b K -> same frequencies as undamped problem, zeta_r = a/(2 w) + b w/2
    masses, springs = [2.0, 1.5, 1.0], [1e5, 8e4, 5e4]
    und = LumpedModel.chain(masses, springs, 0.0)
    a, b = 0.8, 2e-4
    # b K: dampers parallel to the springs (c_i = b k_i); a M: a damper from each mass to ground
    stiff = LumpedModel.chain(masses, springs, [b * k for k in springs])
    prop = stiff.replace(elements=stiff.elements + tuple(
        Damper((d.name, "ground"), c=a * d.mass) for d in stiff.dofs))
    np.testing.assert_allclose(prop.C, a * prop.M + b * prop.K, rtol=1e-12)
    eigw2 = np.sort(np.linalg.eigvals(np.linalg.solve(und.M, und.K)).real)
    w = np.sqrt(eigw2)
    f_und = w / (2 * np.pi)
    np.testing.assert_allclose(und.modes().natural_frequencies, f_und, rtol=1e-10)
    for model, alpha in ((stiff, 0.0), (prop, a)):
        md = model.modes()
        np.testing.assert_allclose(md.natural_frequencies, f_und, rtol=1e-10)
        np.testing.assert_allclose(md.damping_ratios, alpha / (2 * w) + b * w / 2, rtol=1e-8)
    # the mass-proportional part adds damping, most to the lowest mode
    extra = prop.modes().damping_ratios - stiff.modes().damping_ratios
    assert np.all(extra > 0) and np.all(np.diff(extra) < 0)


def test_sdof_frf_closed_form():
    m, k, c = 2.0, 5e4, 10.0
    model = LumpedModel.chain([m], [k], [c])
    f = np.linspace(1, 100, 50)
    w = 2 * np.pi * f
    rec = 1 / (k - w**2 * m + 1j * w * c)
    np.testing.assert_allclose(model.frf(f, "displacement")[:, 0, 0], rec, rtol=1e-12)
    np.testing.assert_allclose(model.frf(f, "velocity")[:, 0, 0], 1j * w * rec, rtol=1e-12)
    np.testing.assert_allclose(model.frf(f)[:, 0, 0], -(w**2) * rec, rtol=1e-12)
    # Bouc-Wen benchmark linear part: 35.59 Hz, 1.12 % (Noel & Schoukens 2016, Table 2), whose
    # small-motion stiffness is k_L + alpha = 1e5 N/m
    md = LumpedModel.chain([m], [k + 5e4], [c]).modes()
    assert md.natural_frequencies[0] == pytest.approx(35.59, abs=0.005)
    assert md.damping_ratios[0] * 100 == pytest.approx(1.12, abs=0.005)


def test_frf_matches_state_space_and_delay():
    model = demo_model()
    f = np.linspace(2, 150, 40)
    H = model.frf(f)
    assert H.shape == (40, 3, 1)
    ss = model.state_space()
    Hs = ss(2j * np.pi * f)  # (n_out, n_in, n_f)
    np.testing.assert_allclose(H, np.moveaxis(Hs, -1, 0), rtol=1e-9)
    assert ss.noutputs == 3 and ss.ninputs == 1
    delayed = model.replace(inputs=(Input(dof="m3", channel="/a.x", delay=0.01),))
    np.testing.assert_allclose(delayed.frf(f), H * np.exp(-2j * np.pi * f * 0.01)[:, None, None])


def test_frf_peaks_at_modes():
    base = demo_model_5dof()
    model = LumpedModel.chain([d.mass for d in base.dofs], [2.0e5, 1.6e5, 1.2e5, 9.0e4, 6.0e4], 1.0, input_dof=4)
    md = model.modes()
    f = np.linspace(5, 150, 20001)
    mag = np.abs(model.frf(f, "displacement")[:, -1, 0])
    peaks = f[1:-1][(mag[1:-1] > mag[:-2]) & (mag[1:-1] > mag[2:])]
    assert len(peaks) == 5
    # damped peak of receptance at w_n sqrt(1 - 2 zeta^2) (approximately, coupled modes)
    np.testing.assert_allclose(peaks, md.natural_frequencies, rtol=3e-3)


def test_demo_models():
    md = demo_model().modes()
    assert len(md) == 3 and 5 < md.natural_frequencies[0] and md.natural_frequencies[-1] < 150
    assert np.all((md.damping_ratios > 0.009) & (md.damping_ratios < 0.031))
    assert np.all(np.diff(md.natural_frequencies) > 10)
    m = LumpedModel.chain([1, 1], [1, 1])
    assert m.input_channels() == ["/actuator/force.wrench.force.x"]
    assert m.output_channels() == ["/imu/m1.linear_acceleration.x", "/imu/m2.linear_acceleration.x"]
    assert len(demo_model_5dof().modes()) == 5


def test_nonlinear_elements_linear_part():
    m = LumpedModel(
        dofs=(Dof("m1", 2.0),),
        elements=(Spring(("m1", "ground"), k=5e4), Damper(("m1", "ground"), c=10.0), BoucWen(("m1", "ground"))),
        inputs=(Input(dof="m1"),),
        outputs=(Output("m1", "displacement"),),
    )
    assert not m.is_linear
    np.testing.assert_array_equal(m.K, [[5e4]])
    assert len(m.nonlinear_elements) == 1


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        (dict(dofs=(Dof("a", 1.0), Dof("a", 1.0))), "repeat"),
        (dict(dofs=(Dof("a", 1.0),), elements=(Spring(("a", "b"), k=1.0),)), "unknown DOF 'b'"),
        (dict(dofs=(Dof("a", 1.0),), inputs=(Input(dof="z"),)), "unknown DOF 'z'"),
    ],
)
def test_invalid_models(kwargs, msg):
    with pytest.raises(ValueError, match=msg):
        LumpedModel(**kwargs)


def test_invalid_values():
    with pytest.raises(ValueError, match="mass"):
        Dof("a", -1.0)
    with pytest.raises(ValueError, match="k"):
        Spring(("a", "ground"), k=-1.0)
    with pytest.raises(ValueError, match="quantity"):
        Output("a", "jerk")
    with pytest.raises(ValueError, match="quantity"):
        LumpedModel.chain([1.0], [1.0]).frf([1.0], "jerk")
