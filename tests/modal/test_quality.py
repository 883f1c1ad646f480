"""Shape quality indicators (vibroscope.modal.quality) against analytic values: real shapes are
collinear (MPC 1, MPD 0°), a circular shape has MPC 0, a known symmetric phase scatter gives its
MPD, COMAC localises a corrupted point, auto-MAC of orthogonal shapes is the identity."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from vibroscope.modal import ModalModel, mpc
from vibroscope.modal import quality
from vibroscope.modal.quality import QualityTable, automac, comac, complexity, modal_quality, mpd
from vibroscope.models import demo_model_5dof

RNG = np.random.default_rng(3)
REAL = RNG.standard_normal((4, 7))


@pytest.mark.parametrize("scale", [1.0, -2.5, 1j, 0.3 * np.exp(0.7j)])
def test_real_shapes_at_any_complex_scale(scale):
    S = REAL * scale
    np.testing.assert_allclose(mpc(S), 1.0, atol=1e-12)
    np.testing.assert_allclose(mpd(S), 0.0, atol=1e-5)  # degrees (arccos near 1: ~1e-6° rounding)
    np.testing.assert_allclose(complexity(S), 0.0, atol=1e-12)


def test_circular_shape():
    phi = [1.0, 1j]
    assert mpc(phi)[0] == pytest.approx(0.0, abs=1e-15)
    assert complexity(phi)[0] == pytest.approx(1.0)
    assert mpd(phi)[0] == pytest.approx(45.0)  # half the points on each axis: 0° and 90°
    # a travelling wave, exp(j 2π k / n), is circular too
    wave = np.exp(2j * np.pi * np.arange(8) / 8)
    assert mpc(wave)[0] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("alpha_deg", [1.0, 10.0, 30.0])
@pytest.mark.parametrize("n_real", [1, 2, 6])
def test_mpd_of_a_known_symmetric_phase_scatter(alpha_deg, n_real):
    """``n_real`` points of modulus 2 on the real axis (both signs) and a pair of unit points at
    ±α: the best-fit line is the real axis by symmetry, so MPD = 2·α / (2 n_real + 2)."""
    a = np.radians(alpha_deg)
    phi = np.r_[2.0 * (-1.0) ** np.arange(n_real), np.exp(1j * a), -np.exp(-1j * a)]
    assert mpd(phi)[0] == pytest.approx(2 * alpha_deg / (2 * n_real + 2), rel=1e-9)
    # invariant to the overall complex scale, and MPC < 1 with the scatter
    assert mpd(phi * np.exp(1.1j))[0] == pytest.approx(mpd(phi)[0], rel=1e-9)
    assert 0 < complexity(phi)[0] < 1


def test_mpd_matches_pyoma2():
    gen = pytest.importorskip("pyoma2.functions.gen")
    S = RNG.standard_normal((5, 6)) + 0.3j * RNG.standard_normal((5, 6))
    ours = mpd(S)
    theirs = np.degrees([gen.MPD(s) for s in S])
    np.testing.assert_allclose(ours, theirs, rtol=1e-10)


def test_comac_identical_and_corrupted():
    """Pinned-beam modes sin(r π x) at 12 points: identical sets give 1 everywhere; a sign error
    in mode 2 and a gain error in mode 3 at point 4 drop the COMAC there (measured 0.48) and leave
    the other points within 0.5 % of 1 (the corrupted point perturbs the scale factors a little)."""
    x = np.arange(1, 13) / 13
    A = np.array([np.sin(r * np.pi * x) for r in range(1, 5)])
    B = A * np.array([1.0, -3.0, 2j, 0.5 - 0.5j])[:, None]  # each mode at an arbitrary complex scale
    np.testing.assert_allclose(comac(A, B), 1.0, atol=1e-12)
    C = B.copy()
    C[1, 4] *= -1
    C[2, 4] *= 2.0
    c = comac(A, C)
    assert c[4] < 0.6
    np.testing.assert_allclose(np.delete(c, 4), 1.0, atol=0.01)
    # the model's own modes against themselves
    modes = demo_model_5dof().modes()
    np.testing.assert_allclose(comac(modes.shapes, modes.shapes), 1.0, atol=1e-12)
    with pytest.raises(ValueError, match="must be equal"):
        comac(A, B[:, :4])


def test_automac_of_orthogonal_shapes_is_identity():
    Q, _ = np.linalg.qr(RNG.standard_normal((6, 6)))
    np.testing.assert_allclose(automac(Q.T), np.eye(6), atol=1e-12)
    # mass-orthogonal modes of a chain are not orthogonal in the plain MAC unless M ∝ I
    modes = demo_model_5dof().modes()
    M = automac(modes.shapes)
    np.testing.assert_allclose(np.diag(M), 1.0)
    np.testing.assert_allclose(M, M.T, atol=1e-12)


def test_modal_quality_table():
    modes = demo_model_5dof().modes()
    est = ModalModel(natural_frequencies=modes.natural_frequencies, damping_ratios=modes.damping_ratios,
                     shapes=modes.shapes, points=[f"/imu/{d}" for d in modes.dofs], method="analytic")
    q = modal_quality(est)
    assert isinstance(q, QualityTable) and len(q) == 5
    assert q.automac.shape == (5, 5) and not q.mpc.flags.writeable
    # non-proportional damping of the chain makes the modes very slightly complex
    assert np.all(q.mpc > 0.999) and np.all(q.mpd_deg < 1.0)
    np.testing.assert_allclose(q.complexity, 1 - q.mpc)
    np.testing.assert_allclose(q.natural_frequencies, modes.natural_frequencies)
    off = q.automac - np.diag(np.diag(q.automac))
    np.testing.assert_allclose(q.automac_max, off.max(axis=1))
    d = q.to_dict()
    assert d["method"] == "analytic" and len(d["modes"]) == 5 and len(d["automac"]) == 5
    # an empty model
    empty = ModalModel(natural_frequencies=np.zeros(0), damping_ratios=np.zeros(0), shapes=np.zeros((0, 3)),
                       points=["a", "b", "c"], method="fdd")
    assert len(modal_quality(empty)) == 0
    with pytest.raises(TypeError):
        modal_quality(np.zeros(3))


def test_doctests():
    res = doctest.testmod(quality, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0 and res.attempted > 0
