"""Stability of a pole across model orders is judged against its own match in the previous order.

Two modes at the same natural frequency with different damping and shapes (a symmetric structure
whose two directions are damped differently, like the first bending pair of the LUMO tower): each
order holds a pole of each within the 1 % frequency tolerance. Matched on frequency alone, a pole
is compared with whichever of the two lies nearer in frequency -- half the time the other mode's,
whose damping differs -- and the stable, heavier-damped mode loses its stability at most orders.
Matched by the pole distance of Reynders et al. (2012) (``|λ − λ'| / |λ| + 1 − MAC``) it keeps it.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from vibroscope.modal import mac, ssi_cov
from vibroscope.modal.ssi import stability_codes

FS = 100.0
#: (natural frequency [Hz], damping ratio) of the two modes, and their shapes on four sensors
MODES = [(10.0, 0.005), (10.0, 0.03)]
SHAPES = np.array([[1.0, 0.8, 0.3, 0.1], [0.1, -0.3, 0.8, 1.0]])


def _resonator(f, zeta, n, rng):
    """White noise through one mode's exact discrete poles ``exp(λ / fs)``, ``λ = ω(−ζ ± j√(1 − ζ²))``."""
    w = 2 * np.pi * f
    p = np.exp((-zeta * w + 1j * w * np.sqrt(1 - zeta**2)) / FS)
    return scipy.signal.lfilter([1.0], np.poly([p, np.conj(p)]).real, rng.standard_normal(n))


def _responses(seed, n=60_000, noise=0.01):
    rng = np.random.default_rng(seed)
    q = np.array([_resonator(f, z, n, rng) for f, z in MODES])
    q /= q.std(axis=1, keepdims=True)
    y = SHAPES.T @ q
    return y + noise * y.std(axis=1, keepdims=True) * rng.standard_normal(y.shape)


def test_a_pole_is_matched_by_pole_distance_not_frequency_alone():
    """Previous order: the 3 % mode at 10.00 Hz and the 0.5 % mode at 10.04 Hz (shape B); this
    order's pole of the 3 % mode at 10.03 Hz is nearer in frequency to the other mode's pole, but
    its own (same damping, same shape) is its match: fully stable (3), not 'frequency only' (1)."""
    a, b = SHAPES[1].astype(complex), SHAPES[0].astype(complex)
    prev = (np.array([10.0, 10.04]), np.array([0.03, 0.005]), np.array([a, b]))
    code = stability_codes(prev, np.array([10.03, 10.04]), np.array([0.0301, 0.005]), np.array([a, b]),
                           tol_frequency=0.01, tol_damping=0.05, mac_min=0.98)
    np.testing.assert_array_equal(code, [3, 3])
    # with one candidate in the tolerance nothing changes: a damping jump is still unstable
    code = stability_codes(tuple(v[:1] for v in prev), np.array([10.0]), np.array([0.04]), a[None],
                           tol_frequency=0.01, tol_damping=0.05, mac_min=0.98)
    np.testing.assert_array_equal(code, [1])


def test_two_modes_at_one_frequency_both_stable():
    """SSI-COV (20 block rows, orders 4–40) of the two-mode responses (1 % noise, 600 s, four
    draws): each mode (its poles within 1 % in frequency, 20 % in damping, MAC > 0.95 with its
    shape) is fully stable at more than 65 % of the orders where it appears, over the four draws.
    Matching on frequency alone gave the 3 % mode 30 of 72 (42 %; 6, 10, 8, 6 of 18 per draw),
    pole-distance matching 55 of 72 (76 %)."""
    n_present = np.zeros(len(MODES), int)
    n_stable = np.zeros(len(MODES), int)
    for seed in range(4):
        st = ssi_cov(_responses(seed), FS, n_lags=20, orders=range(4, 41, 2))
        for k, ((f, z), shape) in enumerate(zip(MODES, SHAPES)):
            own = ((np.abs(st.frequency / f - 1) < 0.01) & (np.abs(st.damping / z - 1) < 0.2)
                   & (mac(st.shapes, shape)[:, 0] > 0.95))
            present = np.unique(st.order[own])
            assert len(present) >= 15, (seed, f, z, present)  # both modes are in the diagram
            n_present[k] += len(present)
            n_stable[k] += len(np.unique(st.order[own & (st.stable == 3)]))
    assert np.all(n_stable > 0.65 * n_present), (n_stable, n_present)
