"""The time-domain fit of the gap diagnosis: the parallel Jacobian changes nothing."""

import numpy as np
from scipy import signal

from vibroscope.gap.fit import LogSimulator, fit_time_domain
from vibroscope.models.elements import CubicSpring, Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

FS = 1000.0


def _model(k3: float) -> LumpedModel:
    return LumpedModel(
        dofs=(Dof("m1", 1.0), Dof("m2", 0.5)),
        elements=(Spring(("m1", "ground"), k=4e4), Damper(("m1", "ground"), c=8.0),
                  CubicSpring(("m2", "m1"), k=3e4, k3=k3), Damper(("m2", "m1"), c=4.0)),
        inputs=(Input(dof="m1", channel="f"),),
        outputs=(Output("m1", "acceleration", "a1"), Output("m2", "acceleration", "a2")),
    )


def test_two_parameters_in_two_threads_match_one_thread():
    rng = np.random.default_rng(4)
    u = rng.standard_normal((1, 2000)) * 30
    sim = LogSimulator(u, FS)
    y = sim.run(_model(2e9), fast=True)
    mask = np.ones(u.shape[1], bool)

    def build(p):
        m = _model(float(p[0]) * 1e9)
        els = list(m.elements)
        els[1] = Damper(("m1", "ground"), c=8.0 * float(p[1]))
        return LumpedModel(dofs=m.dofs, elements=tuple(els), inputs=m.inputs, outputs=m.outputs)

    x0, lo, hi = np.array([0.5, 1.5]), np.array([0.0, 0.1]), np.array([10.0, 10.0])
    r1 = fit_time_domain(build, x0, lo, hi, [sim], [y], [mask], [2000], max_nfev=6, jac_workers=1)
    r2 = fit_time_domain(build, x0, lo, hi, [sim], [y], [mask], [2000], max_nfev=6, jac_workers=2)
    np.testing.assert_array_equal(r1[0], r2[0])
    assert r1[1] == r2[1] and r1[2] == r2[2]  # same nrmse, same number of simulations
    g0 = float(np.sqrt(np.mean((sim.run(build(x0), fast=True) - y) ** 2, axis=1).sum()
                       / np.sum(np.mean(y**2, axis=1)) / 2) * np.sqrt(2))
    assert r1[1] < 0.5 * g0  # and it moved towards the truth (2, 1)
