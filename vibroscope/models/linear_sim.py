"""Exact linear simulation path: first-order-hold (triangle-hold) discretisation of the
linear part, run as decoupled modal recursions on an upsampled input grid.

References
----------
.. [1] G. F. Franklin, J. D. Powell, M. L. Workman, *Digital Control of Dynamic Systems*,
   3rd ed., 1998, sec. 6.3.2 (triangle-hold equivalent).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg, signal

__all__: list[str] = []


def foh_equivalent(A, B, C, D, dt):
    """First-order-hold (triangle-hold) equivalent, as scipy's ``cont2discrete(method='foh')``.

    With ``xi = x - G2 u`` the discrete state, ``xi[k+1] = Ad xi[k] + Bd u[k]``,
    ``y[k] = C xi[k] + (D + C G2) u[k]`` is exact for inputs linear between samples.
    Returns ``Ad, Bd, Cd, Dd, G2`` (G2 gives the initial ``xi[0] = x[0] - G2 u[0]``).
    """
    n, m = A.shape[0], B.shape[1]
    em = np.zeros((n + 2 * m, n + 2 * m))
    em[:n, :n] = A * dt
    em[:n, n : n + m] = B * dt
    em[n : n + m, n + m :] = np.eye(m)
    ms = linalg.expm(em)
    ad, g1, g2 = ms[:n, :n], ms[:n, n : n + m], ms[:n, n + m :]
    return ad, g1 - g2 + ad @ g2, C, D + C @ g2, g2


def triangle_hold_compensation(U: np.ndarray) -> np.ndarray:
    """Pre-emphasis ``[-1/12, 7/6, -1/12]`` on the fine grid so that the first-order hold,
    whose response is ``sinc^2(f / F) = 1 - (pi f / F)^2 / 3 + ...``, becomes flat to
    ``O((pi f / F)^4 / 15)`` for a band-limited input (ends: edge values repeated)."""
    ext = np.concatenate([U[:, :1], U, U[:, -1:]], axis=1)
    return (7.0 / 6.0) * U - (ext[:, :-2] + ext[:, 2:]) / 12.0


def dlsim_modal(Ad, Bd, Cd, Dd, G2, u, D, u_direct, step):
    """Outputs ``C x[k step] + D u_direct[k]`` of the FOH recursion ``xi[m+1] = Ad xi[m] + Bd u[m]``
    driven by the fine-grid `u` from rest (``x(0) = 0``, so ``xi[0] = -G2 u[0]``), with
    ``x = xi + G2 u``; the feedthrough uses `u_direct` (the coarse, un-pre-emphasised input).

    Diagonalising ``Ad = V diag(lam) V^-1``, each mode is a first-order recursion; over one
    coarse step of `step` fine steps it is ``eta[k+1] = lam^step eta[k] + sum_j
    lam^(step-1-j) (W u)[k step + j]``, the inner sum a block product, the outer one
    :func:`scipy.signal.lfilter` at the coarse rate: memory O(n_modes x n_coarse).
    Falls back to a loop if the eigenvectors are ill-conditioned.
    """
    n_s = Ad.shape[0]
    n_fine = u.shape[1]
    n = u_direct.shape[1]
    xi0 = -G2 @ u[:, 0]
    lam, V = np.linalg.eig(Ad)
    if np.linalg.cond(V) < 1e8:
        W = np.linalg.solve(V, Bd)  # (n_s, n_in)
        eta0 = np.linalg.solve(V, xi0.astype(complex))
        blocks = u[:, : (n - 1) * step].reshape(u.shape[0], n - 1, step)  # (n_in, n-1, step)
        powers = lam[:, None] ** np.arange(step - 1, -1, -1)[None, :]  # (n_s, step)
        eta = np.empty((n_s, n), dtype=complex)
        for r in range(n_s):
            a = (blocks @ powers[r]).T @ W[r]  # (n-1,)
            lr = lam[r] ** step
            eta[r, 0] = eta0[r]
            if n > 1:
                eta[r, 1:] = signal.lfilter([1.0], [1.0, -lr], a, zi=[lr * eta0[r]])[0]
        x = (V @ eta).real
    else:  # pragma: no cover - defective/ill-conditioned systems
        xf = np.zeros((n_s, n_fine))
        xf[:, 0] = xi0
        for k in range(n_fine - 1):
            xf[:, k + 1] = Ad @ xf[:, k] + Bd @ u[:, k]
        x = xf[:, ::step][:, :n]
    x = x + G2 @ u[:, ::step][:, :n]
    return Cd @ x + D @ u_direct

