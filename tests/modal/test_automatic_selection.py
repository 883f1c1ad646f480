"""Automatic mode selection (no n_modes given), as `vibroscope analyse` runs it."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.modal import fdd, match_modes, peak_picking
from vibroscope.models import demo_model, demo_model_5dof
from vibroscope.models.excitation import band_limited_random
from vibroscope.models.simulate import simulate
from vibroscope.spectral import csd_matrix, frf

FS = 1000.0


@pytest.fixture(scope="module", params=["3dof", "5dof"])
def single_force_log(request):
    """One random force at the model's own driving point, 2 % output noise, 0.3 fs band."""
    model = demo_model() if request.param == "3dof" else demo_model_5dof()
    u = band_limited_random(FS, 200_000, fmin=2.0, fmax=300.0, rms=20.0, seed=5)
    return model, simulate(model, u, FS, noise=0.02, seed=6)


def test_peak_picking_finds_exactly_the_excited_modes(single_force_log):
    """The mobility power sum has no spurious peaks over the whole excited band (5–300 Hz)."""
    model, sig = single_force_log
    h = frf(sig, model.input_channels()[0], nperseg=8192)
    est = peak_picking(h, fmin=5.0, fmax=300.0)
    truth = model.modes()
    # the 5-DOF driving point (m5) is nearly a node of mode 5: it is not excited there
    n_excited = 3 if model.n_dofs == 3 else 4
    assert len(est) == n_excited
    m = match_modes(est, truth)
    assert np.all(np.abs(m.frequency_errors) < 0.01) and np.all(m.mac >= 0.98)


def test_fdd_second_singular_value_ignores_noise_floor(single_force_log):
    """With one source the response is rank one: s2 is the noise floor and must add no mode."""
    model, sig = single_force_log
    acc = [c for c in sig.channels if "linear_acceleration" in c]
    G = csd_matrix(sig.select(acc), nperseg=8192)
    one = fdd(G, fmin=5.0, fmax=300.0, efdd=False)
    two = fdd(G, fmin=5.0, fmax=300.0, efdd=False, n_singular=2)
    # s1 alone finds every excited mode (FDD peaks lie within 1 % of the truth at nperseg=8192) ...
    n_excited = 3 if model.n_dofs == 3 else 4
    assert len(one) == n_excited
    m = match_modes(one, model.modes())
    assert len(m.pairs) == n_excited and np.all(np.abs(m.frequency_errors) < 0.015)
    # ... and s2 adds none
    np.testing.assert_allclose(two.natural_frequencies, one.natural_frequencies)
    np.testing.assert_array_equal(two.extra["singular_value"], 0)
