"""Uncertainty of identified natural frequencies and damping ratios by a block bootstrap.

The record is cut into `n_blocks` contiguous blocks; each block gives its own output covariances
(SSI-COV) or cross-spectra (LSCF). A bootstrap replicate draws `n_blocks` blocks with
replacement, averages their covariances / spectra, re-identifies the poles at a fixed model order
and pairs them with the modes (nearest frequency within 2 %, MAC ≥ 0.8). The standard deviation
over the replicates (robust: 1.4826 × the median absolute deviation) is the reported uncertainty. Blocks much longer than the correlation time
of the response (its slowest mode's decay) make them nearly independent, which the bootstrap
assumes (Efron & Tibshirani 1993, ch. 8, the moving-block bootstrap; Reynders, Pintelon & De Roeck
2008 estimate the same variances from the block covariances by first-order perturbation).

References
----------
.. [1] B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall, 1993.
.. [2] E. Reynders, R. Pintelon and G. De Roeck, "Uncertainty bounds on modal parameters obtained
   from stochastic subspace identification", Mechanical Systems and Signal Processing 22(4),
   948–969, 2008.
"""

from __future__ import annotations

from dataclasses import dataclass
import warnings
from typing import Sequence

import numpy as np

from vibroscope.modal._results import ModalModel
from vibroscope.modal.mac import mac
from vibroscope.modal.ssi import block_toeplitz, observability_poles, output_covariances

__all__ = ["ModalUncertainty", "ssi_bootstrap", "lscf_bootstrap", "pair_poles"]


@dataclass(frozen=True)
class ModalUncertainty:
    """Standard deviations of the modes' natural frequencies and damping ratios.

    Attributes
    ----------
    frequency_std_hz : ndarray, shape (n_modes,)
        In Hz; NaN when fewer than half of the replicates found the mode.
    damping_std : ndarray, shape (n_modes,)
        Of the damping ratio (dimensionless).
    method : str
        How it was estimated (e.g. ``"block bootstrap, 10 blocks, 30 replicates"``).
    """

    frequency_std_hz: np.ndarray
    damping_std: np.ndarray
    method: str

    def __repr__(self) -> str:
        return f"ModalUncertainty({np.size(self.frequency_std_hz)} modes, {self.method})"


def pair_poles(modes: ModalModel, frequencies: np.ndarray, z: np.ndarray, shapes: np.ndarray, *,
               tol_frequency: float = 0.02, mac_min: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Frequency and damping of the pole that pairs with each mode (NaN when none does).

    Parameters
    ----------
    modes : ModalModel
        The reference modes.
    frequencies, z : ndarray, shape (n_poles,)
        Candidate poles' frequencies (Hz) and damping ratios.
    shapes : ndarray, complex, shape (n_poles, n_points)
        Their shapes at the modes' points.
    tol_frequency : float, optional
        Relative frequency tolerance; default 0.02.
    mac_min : float, optional
        Smallest MAC; default 0.8.

    Returns
    -------
    (f_paired, z_paired) : ndarrays, shape (n_modes,)
    """
    f = frequencies
    fo = np.full(len(modes), np.nan)
    zo = np.full(len(modes), np.nan)
    if not len(f):
        return fo, zo
    M = mac(modes.shapes, shapes) if len(modes) else np.zeros((0, len(f)))
    for r in range(len(modes)):
        fr = modes.natural_frequencies[r]
        ok = (np.abs(f / fr - 1) <= tol_frequency) & (M[r] >= mac_min)
        if ok.any():
            k = np.flatnonzero(ok)[np.argmin(np.abs(f[ok] - fr))]
            fo[r], zo[r] = f[k], z[k]
    return fo, zo


def _ssi_poles(R: np.ndarray, n_lags: int, order: int, fs: float):
    """Poles (f Hz, ζ, shapes) of SSI-COV at one order from covariances R (lags, n_ch, n_ref)."""
    T = block_toeplitz(R, n_lags)
    # leading singular vectors from the small Gram matrix TᵀT (n_lags·n_ref square): U = T V / S
    w, V = np.linalg.eigh(T.T @ T)
    w, V = w[::-1][:order], V[:, ::-1][:, :order]
    S = np.sqrt(np.maximum(w, np.finfo(float).tiny))
    return observability_poles((T @ V) / np.sqrt(S), R.shape[1], fs)


def _robust_spread(F: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1.4826 × the median absolute deviation over the replicates (rows) of frequency and damping:
    a replicate that paired a neighbouring spurious pole must not dominate. NaN for a mode found
    by fewer than half of the replicates."""
    enough = np.sum(np.isfinite(F), axis=0) >= F.shape[0] / 2
    out = []
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for X in (F, Z):
            out.append(np.where(enough, 1.4826 * np.nanmedian(np.abs(X - np.nanmedian(X, axis=0)), axis=0), np.nan))
    return out[0], out[1]


def ssi_bootstrap(y: np.ndarray, fs: float, modes: ModalModel, *, n_lags: int, order: int,
                  ref: Sequence[int] | None = None, n_blocks: int = 10, n_boot: int = 20,
                  seed: int = 0) -> ModalUncertainty:
    """Block-bootstrap standard deviations of SSI-COV natural frequencies and damping ratios.

    Parameters
    ----------
    y : ndarray, shape (n_channels, n_samples)
        The outputs the modes were identified from (same channels as ``modes.points``).
    fs : float
        Sampling frequency in Hz.
    modes : ModalModel
        The identified modes.
    n_lags : int
        Block rows of the Toeplitz matrix used for the identification.
    order : int
        Model order of the replicates (e.g. the largest order among the modes' clusters).
    ref : sequence of int, optional
        Reference channels; default all.
    n_blocks : int, optional
        Contiguous blocks of the record; default 10.
    n_boot : int, optional
        Bootstrap replicates; default 20.
    seed : int, optional
        Seed of the replicate draws.

    Returns
    -------
    ModalUncertainty

    Raises
    ------
    ValueError
        If a block is shorter than four times the covariance lags, or (missing samples) a
        block's covariances cannot be estimated at every lag.
    """
    from vibroscope.modal.ssi import center

    y = center(np.asarray(y, float))
    n = y.shape[1]
    L = n // n_blocks
    if L < 4 * (2 * n_lags + 1):
        raise ValueError(f"{n_blocks=} blocks of {L} samples are too short for {n_lags=} covariance lags")
    Rb = np.stack([output_covariances(y[:, b * L:(b + 1) * L], 2 * n_lags + 1, ref) for b in range(n_blocks)])
    if not np.isfinite(Rb).all():
        raise ValueError("a bootstrap block has lags without any pair of present (non-NaN) samples")
    rng = np.random.default_rng(seed)
    F = np.full((n_boot, len(modes)), np.nan)
    Z = np.full((n_boot, len(modes)), np.nan)
    for i in range(n_boot):
        w = np.bincount(rng.integers(0, n_blocks, n_blocks), minlength=n_blocks).astype(float)
        R = np.tensordot(w / w.sum(), Rb, axes=1)
        f, z, s = _ssi_poles(R, n_lags, order, fs)
        F[i], Z[i] = pair_poles(modes, f, z, s)
    fstd, zstd = _robust_spread(F, Z)
    return ModalUncertainty(fstd, zstd, f"block bootstrap of the output covariances, {n_blocks} blocks, "
                                        f"{n_boot} replicates at order {order}")


def lscf_bootstrap(signals, input: str, outputs, modes: ModalModel, *, nperseg: int, order: int,
                   fmin: float, fmax: float, window: str = "hann", n_blocks: int = 8, n_boot: int = 20,
                   seed: int = 0) -> ModalUncertainty:
    """Block-bootstrap standard deviations of LSCF natural frequencies and damping ratios.

    Each of `n_blocks` contiguous blocks of the record gives its own cross-spectral matrix (Welch,
    `nperseg`); a replicate sums the spectra of blocks drawn with replacement (weighted by their
    averages), forms the H1 FRFs and runs LSCF at one polynomial order; its poles are paired with
    the modes (:func:`pair_poles`).

    Parameters
    ----------
    signals : Signals
        The record the modes were identified from (input and outputs).
    input : str
        The force channel.
    outputs : sequence of str
        Response channels (the modes' points).
    modes : ModalModel
        The identified modes.
    nperseg : int
        Welch segment length of the identification.
    order : int
        LSCF polynomial order of the replicates.
    fmin, fmax : float
        Band in Hz.
    window : str, optional
        Welch window.
    n_blocks : int, optional
        Default 8.
    n_boot : int, optional
        Default 20.
    seed : int, optional

    Returns
    -------
    ModalUncertainty

    Raises
    ------
    ValueError
        If a block holds fewer than two segments.
    """
    from vibroscope.modal.lscf import lscf
    from vibroscope.spectral import CrossSpectralMatrix, csd_matrix, frf

    chans = [input, *outputs]
    sig = signals.select(chans)
    L = sig.n_samples // n_blocks
    if L < 2 * nperseg:
        raise ValueError(f"{n_blocks=} blocks of {L} samples hold fewer than two segments of {nperseg=}")
    parts = [csd_matrix(sig.data[:, b * L:(b + 1) * L], sig.fs, nperseg=nperseg, window=window)
             for b in range(n_blocks)]
    Gb = np.stack([p.G for p in parts])
    nb = np.array([p.settings.get("n_averages", 1) for p in parts], float)
    rng = np.random.default_rng(seed)
    F = np.full((n_boot, len(modes)), np.nan)
    Z = np.full((n_boot, len(modes)), np.nan)
    for i in range(n_boot):
        w = np.bincount(rng.integers(0, n_blocks, n_blocks), minlength=n_blocks) * nb
        G = np.tensordot(w / w.sum(), Gb, axes=1)
        csd = CrossSpectralMatrix(frequencies=parts[0].frequencies, G=G, channels=tuple(chans), units=parts[0].units,
                                  scaling=parts[0].scaling, settings=dict(parts[0].settings))
        h = frf(csd, input, list(outputs))
        st = lscf(h, orders=[order - 1, order], fmin=fmin, fmax=fmax)
        keep = st.order == order
        F[i], Z[i] = pair_poles(modes, st.frequency[keep], st.damping[keep], st.shapes[keep])
    fstd, zstd = _robust_spread(F, Z)
    return ModalUncertainty(fstd, zstd, f"block bootstrap of the cross-spectra, {n_blocks} blocks, "
                                        f"{n_boot} replicates, LSCF order {order} (random error only: the bias of "
                                        f"the H1 estimate is not included)")
