"""A 5-DOF chain with two close, overlapping modes, and its simulated H1 FRF (test helpers).

The chain was designed once, numerically: a Jacobi inverse eigenvalue problem (Householder
tridiagonalisation of ``Q diag(ω²) Qᵀ`` with prescribed eigenvector components) gave masses and
springs for the target natural frequencies 12, 27, 45, 45.9, 80 Hz with every mode large at the
tip mass m5; springs and chain dampers were then tuned by least squares on
:meth:`LumpedModel.modes` (damped, non-proportional: complex modes) to those frequencies and
ζ = 1 % for every mode, and rounded. Modes 3 and 4 are 2.0 % apart with a modal overlap
``(ζ₃f₃ + ζ₄f₄) / (f₄ − f₃) ≈ 1`` (half-power bandwidths ≈ spacing).
"""

from __future__ import annotations

import numpy as np

from vibroscope.models import LumpedModel, close_modes_model
from vibroscope.models.simulate import simulate
from vibroscope.spectral import FRF, frf

MASSES = (1.0, 0.5360, 0.2978, 0.07561, 0.03865)  # kg
SPRINGS = (70297.0, 8340.0, 5413.6, 8320.8, 4854.9)  # N/m
DAMPERS = (1.587, 3.705, 0.0, 0.6185, 0.1005)  # N s/m
FS = 256.0  # Hz: modes up to 80 Hz, below 0.32 fs
NPERSEG = 8192  # Δf = 0.03125 Hz, 8x finer than the narrowest half-power band (0.24 Hz)


def close_modes_5dof() -> LumpedModel:
    """:func:`vibroscope.models.close_modes_model` (the parameters below, kept for reference).

    Returns
    -------
    LumpedModel
        Modes near 12.0, 27.0, 45.0, 45.9 and 80.0 Hz, all with ζ ≈ 1 %; modes 3 and 4 are
        2 % apart (modal overlap ≈ 1). Every mode is strongly excited at m5.
    """
    model = close_modes_model()
    assert model == LumpedModel.chain(MASSES, SPRINGS, DAMPERS, input_dof=4, name="close modes 5-DOF")
    return model


def analytic_frf(model: LumpedModel, frequencies=None, quantity: str = "acceleration") -> FRF:
    """Noise-free FRF of `model` (default lines ``Δf … fs/2`` of :data:`NPERSEG` at :data:`FS`)."""
    if frequencies is None:
        frequencies = np.arange(1, NPERSEG // 2 + 1) * FS / NPERSEG
    f = np.asarray(frequencies, float)
    kind = {"acceleration": "accelerance", "velocity": "mobility", "displacement": "receptance"}[quantity]
    return FRF(frequencies=f, H=model.frf(f, quantity), coherence=np.ones((len(f), len(model.outputs))),
               inputs=model.input_channels(), outputs=model.output_channels(), estimator="analytic", kind=kind)


def forced_frf(model: LumpedModel, noise: float = 0.02, seed: int = 3, n_segments: int = 16) -> FRF:
    """H1 estimate from a simulated random-force test.

    White Gaussian force (1 N rms) at :data:`FS` for ``n_segments · NPERSEG`` samples
    (31 Hann averages at 50 % overlap for the default 16), outputs with Gaussian noise of
    `noise` × their RMS (:func:`vibroscope.models.simulate.simulate`).

    Parameters
    ----------
    model : LumpedModel
        The model (one force input).
    noise : float
        Relative output noise.
    seed : int
        Seed of the force and of the noise.
    n_segments : int
        Record length in units of :data:`NPERSEG`.

    Returns
    -------
    FRF
        Accelerance, ``H[f, output, input]`` from 0 to ``FS / 2``.
    """
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(NPERSEG * n_segments)
    sig = simulate(model, u, FS, noise=noise, seed=seed + 1)
    return frf(sig, model.input_channels(), nperseg=NPERSEG, kind="accelerance")
