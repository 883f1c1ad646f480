"""Poly-reference least-squares complex frequency-domain estimator (LSCF / polyMAX) of poles from
FRFs, with a stabilization diagram."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.linalg

from vibroscope.modal._results import normalize_shapes
from vibroscope.modal.lsfd import fit_band, fit_residues
from vibroscope.modal.ssi import Stabilization, stability_codes
from vibroscope.spectral import FRF
from vibroscope.spectral.kinds import power_of_jw

__all__ = ["lscf"]

_CHUNK = 4096  # frequency lines per block when summing the Toeplitz sequences


def _default_max_order(n_lines: int, n_inputs: int) -> int:
    """Highest default order: 100 poles in all (``p · n_inputs``), at most a quarter of the lines."""
    return int(max(2, min(100 // n_inputs, n_lines // 4)))


def _normal_matrices(w: np.ndarray, H: np.ndarray, dt: float, P: int):
    """Blocks ``R`` (P+1, P+1), ``S`` (n_o, P+1, (P+1) n_i), ``T`` ((P+1) n_i, (P+1) n_i).

    With ``z_f = exp(−j ω_f Δt)`` and ``c_g[m] = Σ_f z_f^m g_f``: ``R[a, b] = Re c_1[b−a]``,
    ``S_o[a, (b, i)] = −Re c_{H_oi}[b−a]``, ``T[(a, i), (b, k)] = Re c_{Σ_o H_oi* H_ok}[b−a]``
    (Toeplitz blocks: only the ``2P + 1`` sums are computed).
    """
    nf, no, ni = H.shape
    m = np.arange(-P, P + 1)
    K = 1 + no * ni + ni * ni
    c = np.zeros((2 * P + 1, K), complex)
    for s in range(0, nf, _CHUNK):
        Hs = H[s : s + _CHUNK]
        g = np.concatenate([np.ones((len(Hs), 1)), Hs.reshape(len(Hs), no * ni),
                            np.einsum("foi,fok->fik", np.conj(Hs), Hs).reshape(len(Hs), ni * ni)], axis=1)
        E = np.exp(-1j * dt * np.outer(m, w[s : s + _CHUNK]))
        c += E @ g
    D = np.arange(P + 1)[None, :] - np.arange(P + 1)[:, None] + P  # b − a + P
    R = c[D, 0].real
    S = -c[:, 1 : 1 + no * ni].real.reshape(2 * P + 1, no, ni)[D]  # (a, b, o, i)
    S = S.transpose(2, 0, 1, 3).reshape(no, P + 1, (P + 1) * ni)
    T = c[:, 1 + no * ni :].real.reshape(2 * P + 1, ni, ni)[D]  # (a, b, i, k)
    T = T.transpose(0, 2, 1, 3).reshape((P + 1) * ni, (P + 1) * ni)
    return R, S, T


def _companion_poles(alpha: np.ndarray, p: int, ni: int, dt: float) -> np.ndarray:
    """Continuous poles of ``Σ_k z^k α_k`` (``α_p = I``): eigenvalues ``z`` of the block companion
    matrix, ``λ = −ln(z) / Δt``."""
    C = np.zeros((p * ni, p * ni))
    if p > 1:
        C[:-ni, ni:] = np.eye((p - 1) * ni)
    C[-ni:, :] = -alpha.reshape(p, ni, ni).transpose(2, 0, 1).reshape(ni, p * ni)
    z = np.linalg.eigvals(C)
    z = z[z != 0]
    return -np.log(z) / dt


def lscf(
    frf: FRF,
    *,
    orders: Sequence[int] | None = None,
    fmin: float | None = None,
    fmax: float | None = None,
    max_damping: float = 0.2,
    tol_frequency: float = 0.01,
    tol_damping: float = 0.05,
    mac_min: float = 0.98,
) -> Stabilization:
    """Poly-reference least-squares complex frequency-domain estimator (polyMAX) of the poles.

    The FRFs in the band are modelled as a right matrix fraction ``H_o(ω) = B_o(ω) A(ω)⁻¹``
    (row ``o``, one column per input) with polynomials in ``z = exp(−j ω Δt)``,
    ``Δt = 1 / (2 fmax)``: ``A = Σ_k z^k α_k`` (``n_i × n_i`` coefficients) and
    ``B_o = Σ_k z^k β_ok``. The linearised error ``B_o − H_o A`` in least squares, with real
    coefficients (real part of the normal matrices) gives, per output, blocks ``R``, ``S_o``,
    ``T_o``; eliminating the numerators leaves the reduced normal equations
    ``M = 2 Σ_o (T_o − S_oᵀ R⁻¹ S_o)``, solved for ``α`` with the highest-order coefficient fixed
    to the identity. The eigenvalues ``z`` of the block companion matrix give the poles
    ``λ = −ln(z) / Δt``, ``f = |λ| / 2π`` (Hz) and ``ζ = −Re λ / |λ|``. Each output is weighted
    by the inverse of its RMS over the band. The blocks are built once for the highest order
    (Toeplitz sums over the lines) and every lower order uses their leading sub-blocks, with
    ``R⁻¹`` through the leading blocks of one Cholesky factor.

    For the shape criterion of the diagram, each order's poles (inside the band, damping in
    ``(0, max_damping]``) are given residues by a quick LSFD (:func:`vibroscope.modal.lsfd`,
    with residuals); a pole's shape is its residue vector over the outputs for the input
    with the largest one.

    Parameters
    ----------
    frf : FRF
        ``H[f, output, input]`` with one or more inputs (one input: LSCF).
    orders : sequence of int, optional
        Polynomial orders ``p`` (each gives up to ``p · n_inputs`` poles); default
        ``2 … min(100 // n_inputs, n_lines // 4)``.
    fmin, fmax : float, optional
        Frequency band in Hz; default all lines above 0 Hz. Poles outside it are dropped.
    max_damping : float, optional
        Poles with ``ζ`` outside ``(0, max_damping]`` are discarded; default 0.2.
    tol_frequency, tol_damping : float, optional
        Stability criteria against the pole's match in the previous order (among the poles within
        `tol_frequency`, the nearest in pole distance plus ``1 − MAC``; see
        :func:`vibroscope.modal.ssi.stability_codes`): relative frequency change ≤ `tol_frequency`
        (default 1 %), relative damping change ≤ `tol_damping` (5 %).
    mac_min : float, optional
        Smallest MAC with that pole accepted as a stable shape; default 0.98.

    Returns
    -------
    Stabilization
        All poles with their stability codes (1 frequency, 2 and damping, 3 and shape) and
        shapes ``(n_poles, n_outputs)`` at ``frf.outputs``; settings ``method='lscf'``,
        ``fmin``, ``fmax``, ``dt``, ``orders``, ``n_inputs``, the tolerances.
        :meth:`Stabilization.modal_model` extracts the modes; :func:`vibroscope.modal.lsfd`
        then gives residues and scaled shapes.

    Raises
    ------
    ValueError
        If the band holds too few lines for the highest order, or an order is below 1.

    See Also
    --------
    lsfd : Residues and mode shapes for the selected poles.
    auto_lscf : LSCF with automatic settings, pole selection and LSFD.
    peak_picking : Single-mode fits at the FRF's peaks.
    ssi_cov : Output-only poles from the time series (SSI-COV).
    fdd : Output-only modes from the cross-spectral matrix (FDD/EFDD).

    Notes
    -----
    The z-domain basis maps the band onto the unit circle (``ω Δt ≤ π``), which keeps the normal
    matrices well conditioned at high orders [1]_ [2]_. In the stabilization diagram the
    physical poles stay put from order to order while the mathematical ones (fitting noise)
    wander, typically with negative or large damping [2]_.

    References
    ----------
    .. [1] P. Guillaume, P. Verboven, S. Vanlanduit, H. Van der Auweraer and B. Peeters, "A
       poly-reference implementation of the least-squares complex frequency-domain estimator",
       Proc. 21st International Modal Analysis Conference (IMAC XXI), Kissimmee, 2003.
    .. [2] B. Peeters, H. Van der Auweraer, P. Guillaume and J. Leuridan, "The PolyMAX
       frequency-domain method: a new standard for modal parameter estimation?", Shock and
       Vibration 11, 395–409, 2004.

    Examples
    --------
    >>> import numpy as np
    >>> from vibroscope.models import LumpedModel
    >>> from vibroscope.spectral import FRF
    >>> model = LumpedModel.chain([1.0, 1.0], [2e4, 2e4], [4.0, 4.0])
    >>> f = np.arange(1, 2001) * 0.05
    >>> h = FRF(frequencies=f, H=model.frf(f), coherence=np.ones((2000, 2)), inputs=["u"], outputs=["a1", "a2"],
    ...         estimator="analytic", kind="accelerance")
    >>> modes = lscf(h, orders=range(2, 21)).modal_model()
    >>> np.round(modes.natural_frequencies, 3), np.round(modes.damping_ratios, 4)
    (array([13.911, 36.419]), array([0.0087, 0.0229]))
    >>> np.round(model.modes().natural_frequencies, 3)
    array([13.911, 36.419])
    """
    sel, lo, hi = fit_band(frf, fmin, fmax)
    f = frf.frequencies[sel]
    H = frf.H[sel]
    nf, no, ni = H.shape
    if orders is None:
        orders = range(2, _default_max_order(nf, ni) + 1)
    orders = sorted({int(o) for o in orders})
    if not orders or orders[0] < 1:
        raise ValueError(f"{orders=} must be positive polynomial orders")
    P = orders[-1]
    if 2 * nf < (P + 1) * (ni + 1):
        raise ValueError(f"{nf} lines in [{lo}, {hi}] Hz are too few for order {P} with {ni} inputs")
    dt = 1.0 / (2.0 * hi)
    w = 2 * np.pi * f
    power = power_of_jw(frf.kind)
    rows = []
    prev = None
    for p, alpha in _denominators(w, H, dt, orders):
        fr, zr, phi = _order_poles(alpha, p, ni, dt, w, H, power, max_damping, lo, hi)
        code = stability_codes(prev, fr, zr, phi, tol_frequency=tol_frequency, tol_damping=tol_damping,
                               mac_min=mac_min)
        rows.append((np.full(len(fr), p), fr, zr, phi, code))
        prev = (fr, zr, phi)
    order_a, f_a, z_a, phi_a, code_a = (np.concatenate(c) for c in zip(*rows))
    phi_a = phi_a.reshape(-1, no)
    return Stabilization(order=order_a, frequency=f_a, damping=z_a, shapes=phi_a, stable=code_a,
                         points=tuple(frf.outputs),
                         settings=dict(method="lscf", fmin=lo, fmax=hi, dt=dt, orders=tuple(orders), n_inputs=ni,
                                       n_lines=nf, kind=frf.kind, max_damping=max_damping,
                                       tol_frequency=tol_frequency, tol_damping=tol_damping, mac_min=mac_min))


def _denominators(w: np.ndarray, H: np.ndarray, dt: float, orders: list[int]):
    """Yield ``(p, α)`` for each order `p` in `orders`: the denominator coefficients solving the
    reduced normal equations ``M = T − Sᵀ R⁻¹ S`` (summed over outputs) with ``α_p = I``.

    Outputs are weighted by the inverse of their RMS. The blocks are built once for the highest
    order; every lower order uses their leading sub-blocks, with ``R⁻¹`` through the leading
    blocks of one Cholesky factor ``R = L Lᵀ`` (the first p+1 rows of ``L⁻¹ S_o`` depend only on
    the first p+1 rows of ``S_o``).
    """
    no, ni = H.shape[1:]
    P = orders[-1]
    scale = np.sqrt(np.mean(np.abs(H) ** 2, axis=(0, 2)))
    scale[scale == 0] = 1.0
    R, S, T = _normal_matrices(w, H / scale[None, :, None], dt, P)
    try:
        L = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:
        L = np.linalg.cholesky(R + np.eye(P + 1) * 1e-12 * np.trace(R))
    Q = scipy.linalg.solve_triangular(L, S.transpose(1, 0, 2).reshape(P + 1, -1), lower=True)
    Q = Q.reshape(P + 1, no, (P + 1) * ni)
    wanted = set(orders)
    G = np.zeros(((P + 1) * ni, (P + 1) * ni))
    for p in range(P + 1):
        G += Q[p].T @ Q[p]
        if p not in wanted:
            continue
        q = (p + 1) * ni
        M = T[:q, :q] - G[:q, :q]
        Maa, Mab = M[: p * ni, : p * ni], M[: p * ni, p * ni :]
        try:
            alpha = -np.linalg.solve(Maa, Mab)
        except np.linalg.LinAlgError:
            alpha = -np.linalg.lstsq(Maa, Mab, rcond=None)[0]
        yield p, alpha


def _order_poles(alpha, p: int, ni: int, dt: float, w, H, power: int, max_damping: float, lo: float,
                 hi: float):
    """Frequencies (Hz), damping ratios and shapes of one order's physical-looking poles: positive
    frequency inside ``[lo, hi]``, damping in ``(0, max_damping]``, sorted by frequency. A shape
    is the residue vector (quick LSFD) over the outputs for the input with the largest one."""
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = _companion_poles(alpha, p, ni, dt)
        fr = np.abs(lam) / (2 * np.pi)
        zr = -lam.real / np.abs(lam)
    ok = (lam.imag > 0) & (zr > 0) & (zr <= max_damping) & (fr >= lo) & (fr <= hi)
    lam, fr, zr = lam[ok], fr[ok], zr[ok]
    srt = np.argsort(fr)
    lam, fr, zr = lam[srt], fr[srt], zr[srt]
    if not len(lam):
        return fr, zr, np.zeros((0, H.shape[1]), complex)
    res = fit_residues(w, H, lam, power, True, fast=True)[0]  # (n_poles, n_o, n_i)
    ref = np.argmax(np.linalg.norm(res, axis=1), axis=1)
    return fr, zr, normalize_shapes(res[np.arange(len(lam)), :, ref])
