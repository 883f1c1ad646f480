"""Fixtures of the modal tests: responses of the lumped demo models simulated by
:func:`vibroscope.models.simulate.simulate` (exact first-order-hold linear path), with one
driving force (for FRFs) or independent random forces on every mass (output-only, the FDD
assumption of a broadband, spatially white excitation)."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.models import Input, demo_model, demo_model_5dof
from vibroscope.models.simulate import simulate

#: (model factory, fs [Hz], nperseg, number of non-overlapping segment lengths simulated)
CASES = {
    "3dof": (demo_model, 256.0, 4096, 21),   # Δf = 0.0625 Hz, 40 averages (50 % overlap)
    "5dof": (demo_model_5dof, 512.0, 16384, 16),  # Δf = 0.03125 Hz, 30 averages
}


def _one_force(model):
    """Force on the first mass: every mode of both chains is well excited there (the 5-DOF
    demo's own driving point, m5, is nearly a node of its 5th mode)."""
    return model.replace(inputs=(Input(dof=model.dofs[0].name, channel="/actuator/force.x"),))


def _all_forces(model):
    return model.replace(inputs=tuple(Input(dof=d.name, channel=f"/actuator/{d.name}.force.x") for d in model.dofs))


@pytest.fixture(scope="session", params=sorted(CASES))
def forced(request):
    """(model, Signals [force, accelerations...], nperseg) with 1 % output noise."""
    factory, fs, nperseg, nseg = CASES[request.param]
    model = _one_force(factory())
    rng = np.random.default_rng(11)
    sig = simulate(model, rng.standard_normal(nperseg * nseg), fs, noise=0.01, seed=12)
    return request.param, model, sig, nperseg


@pytest.fixture(scope="session", params=sorted(CASES))
def ambient(request):
    """(model, Signals of accelerations only, nperseg): independent white forces on all masses."""
    factory, fs, nperseg, nseg = CASES[request.param]
    model = _all_forces(factory())
    rng = np.random.default_rng(21)
    u = rng.standard_normal((model.n_dofs, nperseg * nseg))
    sig = simulate(model, u, fs, noise=0.01, seed=22)
    return request.param, model, sig.select(sig.channels[model.n_dofs :]), nperseg
