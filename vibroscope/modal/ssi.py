"""Covariance-driven stochastic subspace identification (SSI-COV) and its stabilization diagram."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.modal.mac import mac
from vibroscope.signals import Signals

__all__ = ["ssi_cov", "Stabilization", "output_covariances"]


def output_covariances(y: np.ndarray, n_lags: int, ref: Sequence[int] | None = None) -> np.ndarray:
    """Unbiased output covariances ``R_i = E[y_{k+i} y_ref,kᵀ]`` for lags ``0 … n_lags − 1``.

    Parameters
    ----------
    y : ndarray, shape (n_channels, n_samples)
        Zero-mean outputs.
    n_lags : int
        Number of lags.
    ref : sequence of int, optional
        Reference channels (columns of ``R_i``); default all.

    Returns
    -------
    ndarray, shape (n_lags, n_channels, n_refs)
        In the squared units of `y`.
    """
    n = y.shape[1]
    yr = y if ref is None else y[list(ref)]
    R = np.empty((n_lags, y.shape[0], yr.shape[0]))
    for i in range(n_lags):
        R[i] = y[:, i:] @ yr[:, : n - i].T / (n - i)
    return R


@dataclass(frozen=True, eq=False)
class Stabilization:
    """Poles of SSI-COV at increasing model orders: the stabilization diagram.

    Attributes
    ----------
    order : ndarray of int, shape (n_poles,)
        Model order of each pole.
    frequency : ndarray, shape (n_poles,)
        Natural frequency in Hz.
    damping : ndarray, shape (n_poles,)
        Damping ratio (dimensionless).
    shapes : ndarray, complex, shape (n_poles, n_points)
        Mode shapes (normalised to unit maximum modulus).
    stable : ndarray of int, shape (n_poles,)
        0 new pole; 1 frequency stable; 2 frequency and damping stable; 3 frequency, damping and
        shape (MAC) stable with respect to a pole of the previous order.
    points : tuple of str
        Channel names.
    settings : dict
        ``fs``, ``n_lags``, ``orders``, and the stability tolerances.
    """

    order: np.ndarray
    frequency: np.ndarray
    damping: np.ndarray
    shapes: np.ndarray
    stable: np.ndarray
    points: tuple[str, ...]
    settings: dict = field(default_factory=dict)

    def modal_model(self, *, min_count: int | None = None, freq_tol: float = 0.01,
                    mac_min: float = 0.9, fmin: float | None = None, fmax: float | None = None) -> ModalModel:
        """Modes as clusters of fully stable poles (``stable == 3``).

        Stable poles are taken by increasing frequency and grouped while within `freq_tol`
        (relative) of the cluster's median frequency and with MAC ≥ `mac_min` to its first member.
        A cluster with at least `min_count` poles (default a quarter of the orders) is a mode: the
        median frequency and damping, and the shape of the member nearest the median frequency.

        Parameters
        ----------
        min_count : int, optional
            Smallest cluster size; default ``max(3, len(orders) // 4)``.
        freq_tol : float, optional
            Relative frequency tolerance of a cluster; default 0.01.
        mac_min : float, optional
            Smallest MAC with the cluster's first pole; default 0.9.
        fmin, fmax : float, optional
            Frequency band in Hz.

        Returns
        -------
        ModalModel
            ``method`` from the settings (``'ssi_cov'``, ``'lscf'``); ``extra["cluster_size"]``,
            ``extra["damping_std"]``, ``extra["mpc"]``.
        """
        method = self.settings.get("method", "ssi_cov")
        n_orders = len(self.settings.get("orders", ())) or int(np.unique(self.order).size)
        min_count = max(3, n_orders // 4) if min_count is None else int(min_count)
        sel = self.stable == 3
        if fmin is not None:
            sel &= self.frequency >= fmin
        if fmax is not None:
            sel &= self.frequency <= fmax
        idx = np.flatnonzero(sel)
        idx = idx[np.argsort(self.frequency[idx])]
        used = np.zeros(len(idx), bool)
        modes = []
        for a in range(len(idx)):
            if used[a]:
                continue
            members = [a]
            f0 = self.frequency[idx[a]]
            for b in range(a + 1, len(idx)):
                if used[b]:
                    continue
                fb = self.frequency[idx[b]]
                if fb > f0 * (1 + 2 * freq_tol):
                    break
                fmed = np.median(self.frequency[idx[members]])
                if abs(fb / fmed - 1) <= freq_tol and mac(self.shapes[idx[a]], self.shapes[idx[b]])[0, 0] >= mac_min:
                    members.append(b)
            if len(members) >= min_count:
                used[members] = True
                p = idx[members]
                fmed = float(np.median(self.frequency[p]))
                rep = p[np.argmin(np.abs(self.frequency[p] - fmed))]
                modes.append((fmed, float(np.median(self.damping[p])), self.shapes[rep], len(p),
                              float(np.std(self.damping[p]))))
        if not modes:
            return ModalModel(np.zeros(0), np.zeros(0), np.zeros((0, len(self.points))), self.points, method,
                              {"cluster_size": np.zeros(0, int), "damping_std": np.zeros(0), "mpc": np.zeros(0),
                               "settings": dict(self.settings)})
        f, z, s, c, zs = zip(*modes)
        shapes = normalize_shapes(np.array(s))
        return ModalModel(np.array(f), np.array(z), shapes, self.points, method,
                          {"cluster_size": np.array(c), "damping_std": np.array(zs), "mpc": mpc(shapes),
                           "settings": dict(self.settings, min_count=min_count, freq_tol=freq_tol, mac_min=mac_min)})


def ssi_cov(
    x: Signals | np.ndarray,
    fs: float | None = None,
    *,
    n_lags: int,
    orders: Sequence[int],
    ref: Sequence[int] | None = None,
    max_damping: float = 0.2,
    tol_frequency: float = 0.01,
    tol_damping: float = 0.05,
    tol_mac: float = 0.98,
) -> Stabilization:
    """Covariance-driven stochastic subspace identification over several model orders.

    The output covariances ``R_i`` (lags 1 … 2·`n_lags`) fill the block Toeplitz matrix
    ``T[p, q] = R_{n_lags + p − q}`` (``p, q = 0 … n_lags − 1``), which factors as observability
    × controllability: ``T = O Γ``. For each order ``n`` the truncated SVD ``T ≈ U_n S_n V_nᵀ``
    gives ``O = U_n S_n^{1/2}``, ``C`` = its first block row and ``A = O↑⁺ O↓`` (shift invariance).
    The eigenvalues ``λ`` of ``A`` give ``μ = fs ln λ``, ``f = |μ| / 2π`` (Hz),
    ``ζ = −Re μ / |μ|``, and the shapes ``C ψ`` (Peeters & De Roeck 1999).

    Parameters
    ----------
    x : Signals or ndarray, shape (n_channels, n_samples)
        Output-only responses (means are removed).
    fs : float, optional
        Sampling frequency in Hz (from `x` when it is a Signals).
    n_lags : int
        Block rows ``i`` of the Toeplitz matrix; its size is ``(i·n_ch) × (i·n_ref)``, so orders up
        to ``i·n_ref`` are possible. Cover a few periods of the lowest mode: ``i / fs ≳ 2 / f_min``.
    orders : sequence of int
        Model orders (even: two poles per mode), each ≤ ``n_lags · n_refs``.
    ref : sequence of int, optional
        Reference channel indices (SSI-COV/ref); default all channels.
    max_damping : float, optional
        Poles with ``ζ`` outside ``(0, max_damping]`` are discarded; default 0.2.
    tol_frequency, tol_damping, tol_mac : float, optional
        Stability criteria against the nearest pole of the previous order: relative frequency
        change ≤ 1 %, relative damping change ≤ 5 %, MAC ≥ 0.98 (defaults).

    Returns
    -------
    Stabilization
        All poles with their stability codes; :meth:`Stabilization.modal_model` extracts modes.

    Raises
    ------
    ValueError
        If an order exceeds ``n_lags · n_refs``, `n_lags` is too long for the record, or `fs` is
        missing for an array.

    References
    ----------
    .. [1] B. Peeters and G. De Roeck, "Reference-based stochastic subspace identification for
       output-only modal analysis", Mechanical Systems and Signal Processing 13(6), 855–878, 1999.
    """
    if isinstance(x, Signals):
        y, fs, points = np.asarray(x.data, float), x.fs, x.channels
    else:
        y = np.atleast_2d(np.asarray(x, dtype=float))
        if fs is None:
            raise ValueError("fs is needed with an array input")
        points = tuple(str(i) for i in range(y.shape[0]))
    fs = float(fs)
    n_ch, n = y.shape
    n_lags = int(n_lags)
    if n_lags < 2 or 2 * n_lags + 1 >= n // 2:
        raise ValueError(f"{n_lags=} must be >= 2 and well below half the record length {n=}")
    n_ref = n_ch if ref is None else len(ref)
    orders = sorted(int(o) for o in orders)
    if not orders or orders[0] < 2 or orders[-1] > n_lags * n_ref:
        raise ValueError(f"{orders=} must lie in [2, n_lags * n_refs = {n_lags * n_ref}]")
    y = y - y.mean(axis=1, keepdims=True)
    R = output_covariances(y, 2 * n_lags + 1, ref)
    T = np.empty((n_lags * n_ch, n_lags * n_ref))
    for p in range(n_lags):
        for q in range(n_lags):
            T[p * n_ch : (p + 1) * n_ch, q * n_ref : (q + 1) * n_ref] = R[n_lags + p - q]
    U, S, _ = np.linalg.svd(T, full_matrices=False)
    rows = []
    prev = None
    for order in orders:
        O = U[:, :order] * np.sqrt(S[:order])
        A = np.linalg.lstsq(O[:-n_ch], O[n_ch:], rcond=None)[0]
        C = O[:n_ch]
        lam, psi = np.linalg.eig(A)
        keep = lam.imag > 0
        lam, psi = lam[keep], psi[:, keep]
        mu = np.log(lam) * fs
        f = np.abs(mu) / (2 * np.pi)
        z = -mu.real / np.abs(mu)
        ok = (z > 0) & (z <= max_damping) & (f < fs / 2)
        f, z = f[ok], z[ok]
        phi = normalize_shapes((C @ psi[:, ok]).T) if ok.any() else np.zeros((0, n_ch), complex)
        code = np.zeros(len(f), int)
        if prev is not None and len(prev[0]) and len(f):
            pf, pz, pphi = prev
            for k in range(len(f)):
                j = int(np.argmin(np.abs(pf - f[k])))
                if abs(pf[j] - f[k]) / f[k] <= tol_frequency:
                    code[k] = 1
                    if abs(pz[j] - z[k]) / z[k] <= tol_damping:
                        code[k] = 2
                        if mac(pphi[j], phi[k])[0, 0] >= tol_mac:
                            code[k] = 3
        rows.append((np.full(len(f), order), f, z, phi, code))
        prev = (f, z, phi)
    order_a, f_a, z_a, phi_a, code_a = (np.concatenate(c) for c in zip(*rows))
    phi_a = phi_a.reshape(-1, n_ch)
    return Stabilization(order_a, f_a, z_a, phi_a, code_a, tuple(points),
                         dict(method="ssi_cov", fs=fs, n_lags=n_lags, orders=tuple(orders),
                              ref=None if ref is None else tuple(ref),
                              max_damping=max_damping, tol_frequency=tol_frequency, tol_damping=tol_damping,
                              tol_mac=tol_mac))
