"""Small synthetic results for the viewer tests (no identification run)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vibroscope.signals import Signals
from vibroscope.spectral._results import FRF, CrossSpectralMatrix

FN = np.array([2.82, 7.9, 13.1])
ZETA = np.array([0.012, 0.02, np.nan])
POINTS = ("/acc/s1.z", "/acc/s2.z", "/acc/s3.z", "/acc/s4.z")


@dataclass(frozen=True, eq=False)
class FakeModal:
    """Duck-typed stand-in for vibroscope.modal.ModalModel."""

    natural_frequencies: np.ndarray
    damping_ratios: np.ndarray
    shapes: np.ndarray
    points: tuple
    method: str = "fake"
    extra: dict = field(default_factory=dict)


def signals(n: int = 2000, fs: float = 100.0) -> Signals:
    rng = np.random.default_rng(0)
    t = np.arange(n) / fs
    data = np.array([np.sin(2 * np.pi * FN[0] * t) * (k + 1) + 0.1 * rng.standard_normal(n)
                     for k in range(len(POINTS))])
    return Signals(data=data, fs=fs, channels=POINTS, units=["m/s^2"] * len(POINTS), t0=12.5)


def modal() -> FakeModal:
    x = np.arange(1, len(POINTS) + 1) / len(POINTS)
    shapes = np.array([np.sin((2 * r + 1) * np.pi / 2 * x) for r in range(len(FN))], dtype=complex)
    shapes[1] *= np.exp(0.3j)
    shapes[2, 1] += 0.2j
    return FakeModal(FN, ZETA, shapes / np.abs(shapes).max(axis=1, keepdims=True), POINTS)


def coords() -> dict:
    return {p: {"xyz": (0.0, 0.0, 2.0 * (k + 1)), "direction": (1.0, 0.0, 0.0)} for k, p in enumerate(POINTS)}


def spectra(nf: int = 257, fs: float = 100.0):
    f = np.linspace(0, fs / 2, nf)
    resp = np.zeros((nf,), complex)
    for fn, z in zip(FN, [0.012, 0.02, 0.015]):
        w, wn = 2 * np.pi * f, 2 * np.pi * fn
        resp += -w ** 2 / (wn ** 2 - w ** 2 + 2j * z * wn * w)
    H = np.stack([resp * (k + 1) for k in range(len(POINTS))], axis=1)[:, :, None]
    G = np.einsum("fi,fj->fij", np.conj(H[:, :, 0]), H[:, :, 0]) + 1e-6 * np.eye(len(POINTS))
    csd = CrossSpectralMatrix(frequencies=f, G=G, channels=POINTS, units=["m/s^2"] * len(POINTS), scaling="density",
                              settings={"fs": fs, "nperseg": 512})
    psd = csd.psd()
    coh = np.clip(0.95 - 0.4 * np.exp(-((f[:, None] - 20) / 5) ** 2), 0, 1) * np.ones((1, len(POINTS)))
    frf = FRF(frequencies=f, H=H, coherence=coh, inputs=("/shaker/force",), outputs=POINTS, estimator="H1",
              kind="accelerance", units="m/s^2/N", settings={"fs": fs})
    S = np.sort(np.linalg.svd(G, compute_uv=False), axis=1)[:, ::-1]
    return psd, csd, frf, (f, S)
