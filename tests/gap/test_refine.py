"""refine_model: output-error fit of a parameterised model with input/output offsets."""

from __future__ import annotations

import numpy as np

from vibroscope.gap.fit import LogSimulator
from vibroscope.gap.refine import refine_model, simulate_with_offsets
from vibroscope.models.elements import CubicSpring, Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

FS = 610.35
P_TRUE = np.array([5.4e-6, 2.25e-4, 1.0, 4.0])  # Silverbox-like m, d, a, b3


def _model(p):
    m, d, a, b3 = p
    return LumpedModel(dofs=(Dof("m1", m),),
                       elements=(Spring(("m1", "ground"), k=a), Damper(("m1", "ground"), c=d), CubicSpring(("m1", "ground"), k3=b3)),
                       inputs=(Input(dof="m1", channel="u"),), outputs=(Output("m1", "displacement", "y"),),
                       name="t")


def test_refine_recovers_parameters_and_offsets():
    from scipy import signal

    rng = np.random.default_rng(0)
    b, a = signal.butter(4, 150 / (FS / 2))
    u = 0.1 * signal.lfilter(b, a, rng.standard_normal(3000))[None]
    sim = LogSimulator(u, FS)
    y = simulate_with_offsets(sim, _model(P_TRUE), input_offset=[0.005], output_offset=[-0.001])
    mask = np.ones(u.shape[1], bool)
    mask[:200] = False
    p0 = P_TRUE * np.array([1.03, 0.95, 0.97, 1.1])
    r = refine_model(lambda x: _model(p0 * x), np.ones(4), np.full(4, 0.2), np.full(4, 5.0), [sim], [y], [mask],
                     input_offset=True, output_offset=True, max_nfev=30)
    assert r.status > 0
    assert r.nrmse < 1e-5
    np.testing.assert_allclose(p0 * r.x, P_TRUE, rtol=1e-4)
    np.testing.assert_allclose(r.input_offset, [0.005], rtol=1e-3)
    np.testing.assert_allclose(r.output_offset, [-0.001], atol=1e-6)
    # without offsets the same data cannot be matched
    r0 = refine_model(lambda x: _model(p0 * x), np.ones(4), np.full(4, 0.2), np.full(4, 5.0), [sim], [y], [mask],
                      max_nfev=30)
    assert r0.nrmse > 10 * r.nrmse
    assert np.all(r0.input_offset == 0) and np.all(r0.output_offset == 0)
