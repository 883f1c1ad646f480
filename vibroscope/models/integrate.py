"""Compiled (numba) trapezoidal integrator of lumped models with nonlinear elements.

The model ``M xdd + C xd + K x + L^T g(d, v, s) = B u``, ``s' = h(d, v, s)`` (``d = L x``,
``v = L xd`` the elements' relative displacements and velocities, ``g`` the nonlinear
*remainder* forces ``force - k_lin d - c_lin v``, ``s`` the elements' internal states) is
integrated with the trapezoidal rule: Newmark's average-acceleration scheme (``a = 1/2``,
``b = 1/4``) for the mechanical states and the trapezoidal rule (``c = 1/2``) for the
internal states [1]_; second order and A-stable.

Per step, with ``q = [x, xd]`` (2n) and the first-order matrices ``A, Bq`` of the linear
part, the linear part is solved exactly::

    N = I - dt/2 A,  P = N^-1 (I + dt/2 A),  Gu = N^-1 dt/2 Bq,  Gf = N^-1 dt/2 Bf
    q+ = P q + Gu (u + u+) + Gf (g + g+)            (Bf = [0; -M^-1 L^T])

and Newton's method solves only the small nonlinear system of the unknowns
``x = [g+ (n_e), s+ (n_s)]``::

    g+ - g(d+, v+, s+) = 0,   s+ - s - dt/2 (h(d, v, s) + h(d+, v+, s+)) = 0,
    [d+; v+] = E (P q + Gu (u + u+) + Gf g) + S g+,   S = E Gf

with the analytic Jacobian of every element type. This is the scheme of the pure-Python
reference integrator (:mod:`vibroscope.models._reference_integrator`) it replaces.

The kernel works on flat arrays (:func:`flatten_model`): element type codes, the DOF index
of each end (``-1`` = ground), one parameter row per element and the offsets of each
element's states in the state vector. One kernel serves any number of nonlinear elements
of any types (also none: then it is the plain trapezoidal rule of the linear part).

The kernel releases the GIL (``nogil=True``) and keeps no global mutable state, so
simulations can run in threads; it is compiled once and cached on disk (``cache=True``). Its time
loop allocates nothing and is compiled without numba's reference counting, with the per-step
helpers inlined (:data:`_LOOP`): a 3-DOF model with one cubic spring takes ~110 ns a step, 4x less
than with a reference-counted call per helper, and the same numbers to the last bit. ``|z|^6`` (the
Iwan sliders' exponent) is two multiplications, not ``pow``: within 3 ulp of it, 20 % off an Iwan
step.

References
----------
.. [1] N. M. Newmark, "A method of computation for structural dynamics", J. Eng. Mech. Div.
   ASCE 85(EM3):67-94, 1959.
.. [2] B. F. Spencer Jr., S. J. Dyke, M. K. Sain, J. D. Carlson, "Phenomenological model
   for magnetorheological dampers", J. Eng. Mech. 123(3):230-238, 1997.
.. [3] C. F. Van Loan, "Computing integrals involving the matrix exponential", IEEE Trans.
   Automatic Control 23(3):395-404, 1978.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numba
import numpy as np

from vibroscope.models.elements import GROUND, Backlash, BoucWen, CubicSpring, Element, Friction, MRDamper
from vibroscope.models.lumped import LumpedModel

__all__ = ["ELEMENT_CODES", "FlatModel", "IntegrationResult", "closed_loop_kernel", "flatten_model", "integrate"]

#: width of a parameter row
N_PARAMS = 9
#: most internal states an element may have
MAX_STATES = 2


# --------------------------------------------------------------------------------------------
# flat model
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class FlatModel:
    """A :class:`~vibroscope.models.lumped.LumpedModel` as the flat arrays of the kernel.

    Attributes
    ----------
    dt : float
        Time step in s.
    n_dofs : int
        Number of DOFs ``n``.
    P, Gu, Gf : ndarray, shapes (2n, 2n), (2n, n_inputs), (2n, n_e)
        Exact trapezoidal update of the linear part (see module docstring).
    Sd, Sv : ndarray, shape (n_e, n_e)
        ``d+`` and ``v+`` of element ``i`` change by ``Sd[i, j]`` (m/N), ``Sv[i, j]``
        (m/s/N) per N of remainder force ``g+`` of element ``j``.
    ends : ndarray of int64, shape (n_e, 2)
        DOF index of each element's ends ``(a, b)``; ``-1`` is ground, ``-2`` a point that
        is a combination of DOFs (:meth:`~vibroscope.models.LumpedModel.point_vector`).
    L : ndarray, shape (n_e, n)
        Element vectors: ``d_i = L[i] @ x``, ``v_i = L[i] @ xdot`` (what the kernel uses).
    codes : ndarray of int64, shape (n_e,)
        Element types, :data:`ELEMENT_CODES`.
    params : ndarray, shape (n_e, 9)
        Parameter rows (SI): cubic ``k, k3, k5``; backlash ``k, gap``; friction ``force,
        v_eps, force_neg`` (``force_neg = force`` when symmetric); Bouc-Wen ``alpha, beta, gamma, delta, nu``; MR damper ``alpha, c0, c1,
        k0, k1, gamma, beta, A, n`` (at the element's current). Unused entries are 0.
    k_lin, c_lin : ndarray, shape (n_e,)
        Linear parts (N/m, N s/m) the elements put in ``K`` and ``C``.
    state_offsets : ndarray of int64, shape (n_e + 1,)
        Element ``i`` owns states ``state_offsets[i]:state_offsets[i+1]``.
    Cy, Dy, Hy : ndarray, shapes (n_out, 2n), (n_out, n_inputs), (n_out, n_e)
        Outputs ``y = Cy q + Dy u + Hy g`` (m, m/s or m/s^2).
    """

    dt: float
    n_dofs: int
    P: np.ndarray
    Gu: np.ndarray
    Gf: np.ndarray
    Sd: np.ndarray
    Sv: np.ndarray
    ends: np.ndarray
    L: np.ndarray
    codes: np.ndarray
    params: np.ndarray
    k_lin: np.ndarray
    c_lin: np.ndarray
    state_offsets: np.ndarray
    Cy: np.ndarray
    Dy: np.ndarray
    Hy: np.ndarray

    @property
    def n_elements(self) -> int:
        """Number of nonlinear elements ``n_e``."""
        return int(self.codes.shape[0])

    @property
    def n_states(self) -> int:
        """Total number of internal states ``n_s``."""
        return int(self.state_offsets[-1])


def _mr_damper_row(e: MRDamper) -> tuple:
    alpha, c0, c1 = e.coefficients()
    if c0 + c1 <= 0:
        raise ValueError(f"MR damper needs c0 + c1 > 0, got {c0=}, {c1=}")
    return alpha, c0, c1, e.k0, e.k1, e.gamma, e.beta, e.A, e.n


#: The kernel's element types, the one table of them: type name -> (the integer code that
#: :func:`_element` switches on, the element's parameter row ``prm[i]`` in the order read there).
KERNEL_ELEMENTS = {
    CubicSpring.type: (0, lambda e: (e.k, e.k3, e.k5 or 0.0)),
    Backlash.type: (1, lambda e: (e.k, e.gap)),
    Friction.type: (2, lambda e: (e.force_, e.v_eps, e.force_negative)),
    BoucWen.type: (3, lambda e: (e.alpha, e.beta, e.gamma, e.delta, e.nu)),
    MRDamper.type: (4, _mr_damper_row),
}
#: element type name -> integer code used by the kernel
ELEMENT_CODES = {t: code for t, (code, _) in KERNEL_ELEMENTS.items()}


def _param_row(e: Element) -> np.ndarray:
    row = np.zeros(N_PARAMS)
    p = KERNEL_ELEMENTS[e.type][1](e)
    row[: len(p)] = p
    return row


def flatten_model(model: LumpedModel, dt: float, scheme: str = "trapezoid") -> FlatModel:
    """The flat arrays of `model` for the kernel at time step `dt`.

    Parameters
    ----------
    model : LumpedModel
    dt : float
        Integration time step in s, > 0.
    scheme : {'trapezoid', 'exponential'}, optional
        'trapezoid' (default): the trapezoidal rule of the linear part (module docstring),
        whose resonances are warped by about ``(omega dt)^2 / 12``. 'exponential': the
        linear part's exact transition ``P = expm(A dt)`` and ``Gu = F Bq / 2``,
        ``Gf = F Bf / 2`` with ``F = int_0^dt expm(A s) ds`` (Van Loan's block exponential
        [3]_): the free response of the linear part is exact (no frequency warping), the
        inputs and remainder forces enter as their trapezoidal mean over the step (second
        order), and the kernel is the same.

    Returns
    -------
    FlatModel

    Raises
    ------
    ValueError
        If `dt` is not positive, or an element type has no kernel implementation.

    References
    ----------
    .. [3] C. F. Van Loan, "Computing integrals involving the matrix exponential", IEEE Trans.
       Automatic Control 23(3):395-404, 1978.
    """
    dt = float(dt)
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"{dt=} must be positive")
    n = model.n_dofs
    els = model.nonlinear_elements
    for e in els:
        if e.type not in ELEMENT_CODES or e.n_states > MAX_STATES:
            raise ValueError(f"element type {e.type!r} has no compiled kernel; known: {sorted(ELEMENT_CODES)}")
    n_e = len(els)
    A, Bq, Cq, Dq = model.state_matrices()
    L = np.array([model.element_vector(e) for e in els]).reshape(n_e, n)
    Minv = np.asarray(model.M_inv)
    Bf = np.zeros((2 * n, n_e))
    Bf[n:] = -(Minv @ L.T)
    if scheme == "trapezoid":
        N = np.eye(2 * n) - 0.5 * dt * A
        P = np.linalg.solve(N, np.eye(2 * n) + 0.5 * dt * A)
        Gu = np.linalg.solve(N, 0.5 * dt * Bq)
        Gf = np.linalg.solve(N, 0.5 * dt * Bf)
    elif scheme == "exponential":
        from scipy.linalg import expm

        big = np.zeros((4 * n, 4 * n))
        big[:2 * n, :2 * n] = A * dt
        big[:2 * n, 2 * n:] = np.eye(2 * n) * dt
        E_ = expm(big)
        P, F = E_[:2 * n, :2 * n], E_[:2 * n, 2 * n:]
        Gu = 0.5 * F @ Bq
        Gf = 0.5 * F @ Bf
    else:
        raise ValueError(f"scheme={scheme!r} must be 'trapezoid' or 'exponential'")
    E = np.zeros((2 * n_e, 2 * n))
    E[0::2, :n] = L
    E[1::2, n:] = L
    S = E @ Gf
    ends = np.full((n_e, 2), -1, dtype=np.int64)
    for i, e in enumerate(els):
        for j, end in enumerate(e.between):
            if end != GROUND:
                ends[i, j] = model.dof_index(end) if end in model.dof_names else -2
    offsets = np.zeros(n_e + 1, dtype=np.int64)
    for i, e in enumerate(els):
        offsets[i + 1] = offsets[i] + e.n_states
    Hy = np.zeros((len(model.outputs), n_e))
    for r, o in enumerate(model.outputs):
        if o.quantity == "acceleration":
            Hy[r] = -(model.point_vector(o.dof) @ Minv) @ L.T
    c = np.ascontiguousarray
    return FlatModel(
        dt=dt,
        n_dofs=n,
        P=c(P),
        Gu=c(Gu.reshape(2 * n, -1)),
        Gf=c(Gf),
        Sd=c(S[0::2].reshape(n_e, n_e)),
        Sv=c(S[1::2].reshape(n_e, n_e)),
        ends=ends,
        L=c(L),
        codes=np.array([ELEMENT_CODES[e.type] for e in els], dtype=np.int64),
        params=c(np.array([_param_row(e) for e in els]).reshape(n_e, N_PARAMS)),
        k_lin=np.array([e.linear_stiffness for e in els], dtype=float),
        c_lin=np.array([e.linear_damping for e in els], dtype=float),
        state_offsets=offsets,
        Cy=c(Cq.reshape(len(model.outputs), 2 * n)),
        Dy=c(Dq.reshape(len(model.outputs), -1)),
        Hy=c(Hy),
    )


# --------------------------------------------------------------------------------------------
# compiled parts
# --------------------------------------------------------------------------------------------
_JIT = dict(cache=True, nogil=True, error_model="numpy")
#: the per-step helpers are inlined into the kernels' loops (numba IR inlining)
_INLINE = dict(_JIT, inline="always")
#: the time loops allocate nothing (their work arrays are passed in) and are compiled without
#: numba's reference counting (``_nrt=False``): with it, every array a step touches was
#: reference-counted on every step, which cost more than the arithmetic of a small model (a 3-DOF
#: modal model with one cubic spring: 436 ns a step with it, 108 ns without, the same numbers)
_LOOP = dict(_JIT, _nrt=False)


@numba.njit(**_INLINE)
def _sgn(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@numba.njit(**_INLINE)
def _pow_abs(z, e):
    """``|z|^e`` and its derivative ``e |z|^(e-1) sign(z)`` (0 at z = 0 for e > 1; finite
    large slope instead of infinity for e < 1)."""
    az = abs(z)
    if e == 1.0:
        return az, _sgn(z)
    if e == 2.0:
        return az * az, 2.0 * z
    if az == 0.0:
        return 0.0, 0.0 if e > 1.0 else (1e300 if e < 1.0 else 1.0)
    if e == 6.0:  # the Iwan sliders' exponent (vibroscope.gap.effects.IWAN_NU): no pow call
        a2 = az * az
        p = a2 * a2 * a2
    else:
        p = az**e
    return p, e * p / az * _sgn(z)


@numba.njit(**_INLINE)
def _element(code, prm, i, kl, cl, d, v, s0, s1):
    """Remainder force ``r = force - kl d - cl v`` (N), the state derivatives ``h0, h1`` and
    their partial derivatives with respect to ``d, v, s0, s1``.

    Element ``i``'s parameters are row ``prm[i]`` (indexed, not sliced: no array view per
    call). Returns the 15-tuple ``(r, r_d, r_v, r_s0, r_s1, h0, h0_d, h0_v, h0_s0, h0_s1,
    h1, h1_d, h1_v, h1_s0, h1_s1)``.
    """
    r = rd = rv = rs0 = rs1 = 0.0
    h0 = h0d = h0v = h0s0 = h0s1 = 0.0
    h1 = h1d = h1v = h1s0 = h1s1 = 0.0
    if code == 0:  # cubic spring: k d + k3 d^3 + k5 d^5
        k, k3, k5 = prm[i, 0], prm[i, 1], prm[i, 2]
        d2 = d * d
        r = k * d + (k3 + k5 * d2) * d2 * d - kl * d - cl * v
        rd = k + (3.0 * k3 + 5.0 * k5 * d2) * d2 - kl
        rv = -cl
    elif code == 1:  # backlash
        k, gap = prm[i, 0], prm[i, 1]
        if d > gap:
            f, fd = k * (d - gap), k
        elif d < -gap:
            f, fd = k * (d + gap), k
        else:
            f, fd = 0.0, 0.0
        r = f - kl * d - cl * v
        rd = fd - kl
        rv = -cl
    elif code == 2:  # friction: F t for v >= 0, Fn t for v < 0, t = tanh(v / v_eps); symmetric: F t
        F, ve, Fn = prm[i, 0], prm[i, 1], prm[i, 2]
        t = math.tanh(v / ve)
        Fb = F if v >= 0.0 else Fn
        r = Fb * t - kl * d - cl * v
        rd = -kl
        rv = Fb / ve * (1.0 - t * t) - cl
    elif code == 3:  # Bouc-Wen: force z, z' = alpha v - beta (gamma |v| |z|^(nu-1) z + delta v |z|^nu)
        alpha, beta, gamma, delta, nu = prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3], prm[i, 4]
        r = s0 - kl * d - cl * v
        rd = -kl
        rv = -cl
        rs0 = 1.0
        av = abs(v)
        az = abs(s0)
        if nu == 1.0:
            h0 = alpha * v - beta * (gamma * av * s0 + delta * v * az)
            h0v = alpha - beta * (gamma * _sgn(v) * s0 + delta * az)
            h0s0 = -beta * (gamma * av + delta * v * _sgn(s0))
        else:
            pn, dpn = _pow_abs(s0, nu)  # |z|^nu and its derivative
            # |z|^(nu-1) z = sign(z) |z|^nu, derivative nu |z|^(nu-1) = |dpn|
            h0 = alpha * v - beta * (gamma * av * _sgn(s0) * pn + delta * v * pn)
            h0v = alpha - beta * (gamma * _sgn(v) * _sgn(s0) * pn + delta * pn)
            h0s0 = -beta * (gamma * av * abs(dpn) + delta * v * dpn)
    elif code == 4:  # MR damper (Spencer et al. 1997, eq. 5), states (z, y)
        alpha, c0, c1, k0, k1, gamma, beta, A, n = prm[i, 0], prm[i, 1], prm[i, 2], prm[i, 3], prm[i, 4], prm[i, 5], prm[i, 6], prm[i, 7], prm[i, 8]
        z, y = s0, s1
        den = 1.0 / (c0 + c1)
        yd = (alpha * z + c0 * v + k0 * (d - y)) * den
        yd_d, yd_v, yd_z, yd_y = k0 * den, c0 * den, alpha * den, -k0 * den
        r = c1 * yd + k1 * d - kl * d - cl * v
        rd = c1 * yd_d + k1 - kl
        rv = c1 * yd_v - cl
        rs0 = c1 * yd_z
        rs1 = c1 * yd_y
        rel = v - yd
        pn, dpn = _pow_abs(z, n)  # |z|^n
        # z |z|^(n-1) = sign(z) |z|^n, derivative n |z|^(n-1) = |dpn|
        zpn = _sgn(z) * pn
        h0 = -gamma * abs(rel) * zpn - beta * rel * pn + A * rel
        dphi_dr = -gamma * _sgn(rel) * zpn - beta * pn + A
        dphi_dz = -gamma * abs(rel) * abs(dpn) - beta * rel * dpn
        h0d = dphi_dr * (-yd_d)
        h0v = dphi_dr * (1.0 - yd_v)
        h0s0 = dphi_dr * (-yd_z) + dphi_dz
        h0s1 = dphi_dr * (-yd_y)
        h1, h1d, h1v, h1s0, h1s1 = yd, yd_d, yd_v, yd_z, yd_y
    return (r, rd, rv, rs0, rs1, h0, h0d, h0v, h0s0, h0s1, h1, h1d, h1v, h1s0, h1s1)


@numba.njit(**_INLINE)
def _solve_small(J, F, m):
    """Solve ``J x = F`` in place (Gaussian elimination, partial pivoting); ``F`` becomes
    ``x``. Returns False if `J` is singular."""
    for c in range(m):
        piv, best = c, abs(J[c, c])
        for r in range(c + 1, m):
            if abs(J[r, c]) > best:
                piv, best = r, abs(J[r, c])
        if best == 0.0 or not math.isfinite(best):
            return False
        if piv != c:
            for k in range(m):
                J[c, k], J[piv, k] = J[piv, k], J[c, k]
            F[c], F[piv] = F[piv], F[c]
        inv = 1.0 / J[c, c]
        for r in range(c + 1, m):
            f = J[r, c] * inv
            if f != 0.0:
                for k in range(c + 1, m):
                    J[r, k] -= f * J[c, k]
                F[r] -= f * F[c]
    for c in range(m - 1, -1, -1):
        acc = F[c]
        for k in range(c + 1, m):
            acc -= J[c, k] * F[k]
        F[c] = acc / J[c, c]
    return True


@numba.njit(**_INLINE)
def _kinematics(q, L, n, i):
    d = 0.0
    v = 0.0
    for j in range(n):
        lij = L[i, j]
        if lij != 0.0:
            d += lij * q[j]
            v += lij * q[n + j]
    return d, v


@numba.njit(**_INLINE)
def _eval_all(q, x, n_e, Lk, codes, prm, klin, clin, soff, n, g_out, sd_out):
    """Remainder forces and state derivatives at state q, internal states x[n_e:]."""
    for i in range(n_e):
        d, v = _kinematics(q, Lk, n, i)
        o = soff[i]
        ns = soff[i + 1] - o
        s0 = x[n_e + o] if ns > 0 else 0.0
        s1 = x[n_e + o + 1] if ns > 1 else 0.0
        res = _element(codes[i], prm, i, klin[i], clin[i], d, v, s0, s1)
        g_out[i] = res[0]
        if ns > 0:
            sd_out[o] = res[5]
        if ns > 1:
            sd_out[o + 1] = res[10]


@numba.njit(**_INLINE)
def _outputs(Y, k, q, U, g, Cy, Dy, Hy):
    for r in range(Y.shape[0]):
        acc = 0.0
        for j in range(Cy.shape[1]):
            acc += Cy[r, j] * q[j]
        for j in range(Dy.shape[1]):
            acc += Dy[r, j] * U[j, k]
        for j in range(Hy.shape[1]):
            acc += Hy[r, j] * g[j]
        Y[r, k] = acc


@numba.njit(**_INLINE)
def _trap_step(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, U, k, q, qp, x, x_old,
               g, sd, base, epd, epv, F, J, half, tol, max_iter):  # fmt: skip
    """One trapezoidal step from ``t_k`` to ``t_{k+1}`` over the inputs ``U[:, k]``,
    ``U[:, k + 1]``, in place: ``q`` (2n) and the remainder forces ``g`` become those of the
    new step (``g`` then still to be re-evaluated by :func:`_eval_all`, which also refreshes
    ``sd``), ``x`` holds ``[g+, s+]``; the rest are work arrays. Returns ``(converged,
    newton_iterations)`` (converged is True when there is nothing nonlinear to solve).
    """
    n2 = P.shape[0]
    n = n2 // 2
    n_in = U.shape[0]
    n_e = codes.shape[0]
    n_s = soff[n_e]
    m = n_e + n_s
    iters = 0
    converged = True
    # predictor: linear part with g+ = 0
    for r in range(n2):
        acc = 0.0
        for j in range(n2):
            acc += P[r, j] * q[j]
        for j in range(n_in):
            acc += Gu[r, j] * (U[j, k] + U[j, k + 1])
        for j in range(n_e):
            acc += Gf[r, j] * g[j]
        qp[r] = acc
    if m > 0:
        for i in range(n_e):
            epd[i], epv[i] = _kinematics(qp, Lk, n, i)
            x[i] = g[i]
        for j in range(n_s):
            base[j] = x[n_e + j] + half * sd[j]
        converged = False
        for it in range(max_iter):
            iters += 1
            for r in range(m):
                for c in range(m):
                    J[r, c] = 0.0
            for i in range(n_e):
                d = epd[i]
                v = epv[i]
                for j in range(n_e):
                    d += Sd[i, j] * x[j]
                    v += Sv[i, j] * x[j]
                o = soff[i]
                ns = soff[i + 1] - o
                s_0 = x[n_e + o] if ns > 0 else 0.0
                s_1 = x[n_e + o + 1] if ns > 1 else 0.0
                (rr, rd, rv, rs0, rs1, h0, h0d, h0v, h0s0, h0s1,
                 h1, h1d, h1v, h1s0, h1s1) = _element(codes[i], prm, i, klin[i], clin[i], d, v, s_0, s_1)  # fmt: skip
                F[i] = x[i] - rr
                for j in range(n_e):
                    J[i, j] = -(rd * Sd[i, j] + rv * Sv[i, j])
                J[i, i] += 1.0
                if ns > 0:
                    row = n_e + o
                    J[i, row] = -rs0
                    F[row] = x[row] - base[o] - half * h0
                    for j in range(n_e):
                        J[row, j] = -half * (h0d * Sd[i, j] + h0v * Sv[i, j])
                    J[row, row] = 1.0 - half * h0s0
                    if ns > 1:
                        J[row, row + 1] = -half * h0s1
                if ns > 1:
                    row = n_e + o + 1
                    J[i, row] = -rs1
                    F[row] = x[row] - base[o + 1] - half * h1
                    for j in range(n_e):
                        J[row, j] = -half * (h1d * Sd[i, j] + h1v * Sv[i, j])
                    J[row, row - 1] = -half * h1s0
                    J[row, row] = 1.0 - half * h1s1
            if not _solve_small(J, F, m):
                break
            ok = True
            finite = True
            for j in range(m):
                x_old[j] = x[j]
                x[j] -= F[j]
                if not math.isfinite(x[j]):
                    finite = False
                if abs(F[j]) > tol * max(1.0, abs(x[j])):
                    ok = False
            if not finite:
                for j in range(m):
                    x[j] = x_old[j]
                break
            if ok:
                converged = True
                break
        for i in range(n_e):
            g[i] = x[i]
    for r in range(n2):
        acc = qp[r]
        for j in range(n_e):
            acc += Gf[r, j] * g[j]
        q[r] = acc
    return converged, iters


@numba.njit(**_JIT)
def _trapezoid_kernel(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, Cy, Dy, Hy,
                      U, q0, s0, dt, tol, max_iter, Y, Qo, Go, So):  # fmt: skip
    """Integrate over the fine-grid input ``U`` (n_in, N) from ``q0`` (2n), ``s0`` (n_s).

    Writes the outputs ``Y`` (n_out, N) and, when their second dimension is N, the states
    ``Qo`` (2n, N), remainder forces ``Go`` (n_e, N) and internal states ``So`` (n_s, N).
    Returns ``(newton_failures, newton_iterations)``.
    """
    n2 = P.shape[0]
    n = n2 // 2
    n_in = U.shape[0]
    N = U.shape[1]
    n_e = codes.shape[0]
    n_s = soff[n_e]
    m = n_e + n_s
    half = 0.5 * dt
    store = Qo.shape[1] == N
    q = q0.copy()
    qp = np.empty(n2)
    x = np.zeros(m)
    x_old = np.zeros(m)
    g = np.zeros(n_e)
    sd = np.zeros(n_s)
    base = np.zeros(n_s)
    epd = np.zeros(n_e)
    epv = np.zeros(n_e)
    F = np.zeros(m)
    J = np.zeros((m, m))
    for j in range(n_s):
        x[n_e + j] = s0[j]
    _eval_all(q, x, n_e, Lk, codes, prm, klin, clin, soff, n, g, sd)
    _outputs(Y, 0, q, U, g, Cy, Dy, Hy)
    if store:
        for j in range(n2):
            Qo[j, 0] = q[j]
        for j in range(n_e):
            Go[j, 0] = g[j]
        for j in range(n_s):
            So[j, 0] = x[n_e + j]
    return _trap_loop(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, Cy, Dy, Hy, U, q, qp, x, x_old,
                      g, sd, base, epd, epv, F, J, half, tol, max_iter, Y, Qo, Go, So, store)


@numba.njit(**_LOOP)
def _trap_loop(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, Cy, Dy, Hy, U, q, qp, x, x_old,
               g, sd, base, epd, epv, F, J, half, tol, max_iter, Y, Qo, Go, So, store):
    """The time loop of :func:`_trapezoid_kernel` over the work arrays it allocated (no
    allocation here: compiled without reference counting, :data:`_LOOP`)."""
    n2 = P.shape[0]
    n = n2 // 2
    N = U.shape[1]
    n_e = codes.shape[0]
    n_s = soff[n_e]
    fails = 0
    iters = 0
    for k in range(N - 1):
        ok, it = _trap_step(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, U, k, q, qp, x, x_old,
                            g, sd, base, epd, epv, F, J, half, tol, max_iter)  # fmt: skip
        iters += it
        if not ok:
            fails += 1
        _eval_all(q, x, n_e, Lk, codes, prm, klin, clin, soff, n, g, sd)
        _outputs(Y, k + 1, q, U, g, Cy, Dy, Hy)
        if store:
            for j in range(n2):
                Qo[j, k + 1] = q[j]
            for j in range(n_e):
                Go[j, k + 1] = g[j]
            for j in range(n_s):
                So[j, k + 1] = x[n_e + j]
    return fails, iters


@numba.njit(**_INLINE)
def _row(Cm, Dm, Hm, r, q, u, g):
    """``Cm[r] q + Dm[r] u + Hm[r] g``: a measured quantity."""
    acc = 0.0
    for j in range(Cm.shape[1]):
        acc += Cm[r, j] * q[j]
    for j in range(Dm.shape[1]):
        acc += Dm[r, j] * u[j]
    for j in range(Hm.shape[1]):
        acc += Hm[r, j] * g[j]
    return acc


@numba.njit(**_JIT)
def closed_loop_kernel(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, Cy, Dy, Hy,
                        Cm, Dm, Hm, claw, cgain, cflags, taps, ntaps, cdrive, csat, act_gain,
                        in_off, in_sat, in_delay, Ref, FF, Uol, T, R, tol, max_iter, Y, Cout, cevery):  # fmt: skip
    """Closed loop: plant states, controller states and nonlinear elements, from rest.

    Per controller tick ``k`` (period ``T``, ``Nt`` ticks): the outputs ``Y[:, k]`` and the
    measurements (rows ``3c, 3c+1, 3c+2`` of ``Cm, Dm, Hm``: position, velocity,
    acceleration of controller ``c``'s DOF) at the state of tick k with the input held over
    the previous period; each controller's command ``Cout[c, k]`` (law ``claw[c]``, gains
    ``cgain[c] = (kp, ki, kd, ka, td, t1, kv)``, ``cflags[c] = (sampled velocity, sampled
    acceleration)``, FIR ``taps[c, :ntaps[c]]``, plus feed-forward ``FF[c, k]``, clipped at
    ``csat[c]``); then the held inputs (open-loop ``Uol[:, k]``; driven column
    ``cdrive[c]``: ``clip(act_gain[c] Cout(k - in_delay) + in_off, -in_sat, in_sat)``, the
    command ``in_delay[j]`` ticks earlier, linearly interpolated between ticks and 0 before
    the start) and ``R``
    trapezoidal steps of ``T / R`` over them (with ``R = 1`` and the exact ZOH ``P``, ``Gu``
    of a linear plant, the exact discretisation). Controller ``c`` runs every ``cevery[c]``
    ticks (its own period ``cevery[c] T``: its measurement, filter, derivatives and integral
    advance only then) and holds its command in between. Returns ``(newton_failures,
    newton_iterations)``.
    """
    n2 = P.shape[0]
    n = n2 // 2
    n_in = Uol.shape[0]
    Nt = Ref.shape[1]
    n_e = codes.shape[0]
    n_s = soff[n_e]
    m = n_e + n_s
    n_c = claw.shape[0]
    half = 0.5 * T / R
    q = np.zeros(n2)
    qp = np.empty(n2)
    x = np.zeros(m)
    x_old = np.zeros(m)
    g = np.zeros(n_e)
    sd = np.zeros(n_s)
    base = np.zeros(n_s)
    epd = np.zeros(n_e)
    epv = np.zeros(n_e)
    F = np.zeros(m)
    J = np.zeros((m, m))
    ub = np.zeros((n_in, 2))
    ucur = np.zeros(n_in)
    unew = np.zeros(n_in)
    maxt = taps.shape[1]
    qh = np.zeros((n_c, maxt))
    pf_prev = np.zeros(n_c)
    v_prev = np.zeros(n_c)
    integ = np.zeros(n_c)
    e_prev = np.zeros(n_c)
    w_prev = np.zeros(n_c)
    c_prev = np.zeros(n_c)
    _eval_all(q, x, n_e, Lk, codes, prm, klin, clin, soff, n, g, sd)
    for c in range(n_c):  # at rest at the first measured position
        p0 = _row(Cm, Dm, Hm, 3 * c, q, ucur, g)
        sh = 0.0
        for i in range(ntaps[c]):
            qh[c, i] = p0
            sh += taps[c, i]
        pf_prev[c] = sh * p0
    return _closed_loop_run(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, Cy, Dy, Hy,
                            Cm, Dm, Hm, claw, cgain, cflags, taps, ntaps, cdrive, csat, act_gain,
                            in_off, in_sat, in_delay, Ref, FF, Uol, T, R, tol, max_iter, Y, Cout, cevery,
                            q, qp, x, x_old, g, sd, base, epd, epv, F, J, ub, ucur, unew, qh, pf_prev,
                            v_prev, integ, e_prev, w_prev, c_prev, half)  # fmt: skip


@numba.njit(**_LOOP)
def _closed_loop_run(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, Cy, Dy, Hy,
                     Cm, Dm, Hm, claw, cgain, cflags, taps, ntaps, cdrive, csat, act_gain,
                     in_off, in_sat, in_delay, Ref, FF, Uol, T, R, tol, max_iter, Y, Cout, cevery,
                     q, qp, x, x_old, g, sd, base, epd, epv, F, J, ub, ucur, unew, qh, pf_prev,
                     v_prev, integ, e_prev, w_prev, c_prev, half):  # fmt: skip
    """The tick loop of :func:`closed_loop_kernel` over the work arrays it allocated (no
    allocation here: compiled without reference counting, :data:`_LOOP`)."""
    n2 = P.shape[0]
    n = n2 // 2
    n_in = Uol.shape[0]
    Nt = Ref.shape[1]
    n_e = codes.shape[0]
    n_c = claw.shape[0]
    fails = 0
    iters = 0
    for k in range(Nt):
        for r in range(Y.shape[0]):
            Y[r, k] = _row(Cy, Dy, Hy, r, q, ucur, g)
        for c in range(n_c):
            if k % cevery[c] != 0:  # between this controller's ticks: its command is held
                Cout[c, k] = Cout[c, k - 1]
                continue
            Tc = T * cevery[c]
            pos = _row(Cm, Dm, Hm, 3 * c, q, ucur, g)
            for i in range(ntaps[c] - 1, 0, -1):
                qh[c, i] = qh[c, i - 1]
            qh[c, 0] = pos
            pf = 0.0
            for i in range(ntaps[c]):
                pf += taps[c, i] * qh[c, i]
            vd = (pf - pf_prev[c]) / Tc
            ad = (vd - v_prev[c]) / Tc
            pf_prev[c] = pf
            v_prev[c] = vd
            vel = _row(Cm, Dm, Hm, 3 * c + 1, q, ucur, g) if cflags[c, 0] else vd
            acc = _row(Cm, Dm, Hm, 3 * c + 2, q, ucur, g) if cflags[c, 1] else ad
            kp, ki, kd, ka = cgain[c, 0], cgain[c, 1], cgain[c, 2], cgain[c, 3]
            td, t1, kv = cgain[c, 4], cgain[c, 5], cgain[c, 6]
            e = Ref[c, k] - pos
            law = claw[c]
            if law == 0:  # P
                cmd = kp * e
            elif law == 1:  # PD
                cmd = kp * e - kd * vel
            elif law == 2:  # PID
                integ[c] += 0.5 * ki * Tc * (e + e_prev[c])
                cmd = kp * e + integ[c] - kd * vel
            elif law == 3:  # PD2
                cmd = kp * e - kd * vel - ka * acc
            elif law == 4:  # PI + PDT1 (Tustin)
                integ[c] += 0.5 * ki * Tc * (e + e_prev[c])
                w = kp * e + integ[c]
                a1 = 2.0 * t1 / Tc
                b1 = 2.0 * td / Tc
                cmd = ((1.0 + b1) * w + (1.0 - b1) * w_prev[c] - (1.0 - a1) * c_prev[c]) / (1.0 + a1)
                w_prev[c] = w
                c_prev[c] = cmd
            else:  # cascade
                cmd = kp * kv * e - kv * vel
            e_prev[c] = e
            cmd += FF[c, k]
            if cmd > csat[c]:
                cmd = csat[c]
            elif cmd < -csat[c]:
                cmd = -csat[c]
            Cout[c, k] = cmd
        if k == Nt - 1:
            break
        for j in range(n_in):
            unew[j] = Uol[j, k]
        for c in range(n_c):
            j = cdrive[c]
            cm = Cout[c, k]
            dl = in_delay[j]
            if dl > 0.0:
                d0 = int(dl)
                a = dl - d0
                c0 = Cout[c, k - d0] if k - d0 >= 0 else 0.0
                c1 = Cout[c, k - d0 - 1] if k - d0 - 1 >= 0 else 0.0
                cm = (1.0 - a) * c0 + a * c1
            f = act_gain[c] * cm + in_off[j]
            if f > in_sat[j]:
                f = in_sat[j]
            elif f < -in_sat[j]:
                f = -in_sat[j]
            unew[j] = f
        for j in range(n_in):
            ub[j, 0] = unew[j]
            ub[j, 1] = unew[j]
            ucur[j] = unew[j]
        for r in range(R):
            ok, it = _trap_step(P, Gu, Gf, Sd, Sv, Lk, codes, prm, klin, clin, soff, ub, 0, q, qp, x, x_old,
                                g, sd, base, epd, epv, F, J, half, tol, max_iter)  # fmt: skip
            iters += it
            if not ok:
                fails += 1
            _eval_all(q, x, n_e, Lk, codes, prm, klin, clin, soff, n, g, sd)
    return fails, iters


# --------------------------------------------------------------------------------------------
# Python interface
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class IntegrationResult:
    """Result of :func:`integrate`.

    Attributes
    ----------
    y : ndarray, shape (n_outputs, N)
        The model's outputs on the integration grid (m, m/s or m/s^2).
    q : ndarray, shape (2 n_dofs, N), or None
        States ``[x, xd]`` (m, m/s), when asked for with ``store_states=True``.
    g : ndarray, shape (n_e, N), or None
        Nonlinear remainder forces (N) of the model's nonlinear elements (in the order of
        :attr:`LumpedModel.nonlinear_elements`), when ``store_states=True``.
    s : ndarray, shape (n_s, N), or None
        Internal states of the elements, concatenated in element order (Bouc-Wen ``z``
        in N; MR damper ``z`` in m and ``y`` in m), when ``store_states=True``.
    newton_failures : int
        Steps whose Newton iteration did not converge within ``max_iter`` iterations (or
        hit a singular Jacobian / non-finite iterate); the last iterate was kept.
    newton_iterations : int
        Newton iterations in total.
    """

    y: np.ndarray
    q: np.ndarray | None
    g: np.ndarray | None
    s: np.ndarray | None
    newton_failures: int
    newton_iterations: int


def integrate(
    model: LumpedModel | FlatModel,
    U,
    dt: float | None = None,
    *,
    q0=None,
    s0=None,
    store_states: bool = False,
    tol: float = 1e-13,
    max_iter: int = 50,
    warn: bool = True,
    scheme: str = "trapezoid",
) -> IntegrationResult:
    """Integrate a lumped model over a fine-grid input with the compiled trapezoidal kernel.

    Parameters
    ----------
    model : LumpedModel or FlatModel
        The model, or its flat arrays from :func:`flatten_model` (then `dt` is taken from
        it and must be None or equal).
    U : array_like, shape (n_inputs, N)
        Input forces in N at the integration instants ``t_k = k dt`` (already delayed and
        saturated: this is the force applied to the structure).
    dt : float
        Time step in s (needed with a LumpedModel).
    q0 : array_like, shape (2 n_dofs,), optional
        Initial ``[x, xd]`` (m, m/s); default rest.
    s0 : array_like, shape (n_s,), optional
        Initial internal states; default 0.
    store_states : bool
        Also return the states, remainder forces and internal states at every step.
    tol : float
        Newton stops when every update ``|dx_j| <= tol max(1, |x_j|)``.
    max_iter : int
        Newton iterations per step before the step counts as a failure.
    warn : bool
        Issue one :class:`RuntimeWarning` when any step's Newton iteration failed.
    scheme : {'trapezoid', 'exponential'}, optional
        Discretisation of the linear part (:func:`flatten_model`); default 'trapezoid'.
        Not used with a FlatModel.

    Returns
    -------
    IntegrationResult

    Raises
    ------
    ValueError
        If shapes do not match, `U` is not finite, `dt` is missing or not positive, or an
        element type has no kernel.

    Warns
    -----
    RuntimeWarning
        Once, if Newton did not converge at some steps (their count is in the result).

    References
    ----------
    .. [1] N. M. Newmark, "A method of computation for structural dynamics", J. Eng. Mech.
       Div. ASCE 85(EM3):67-94, 1959.
    """
    if isinstance(model, FlatModel):
        fm = model
        if dt is not None and float(dt) != fm.dt:
            raise ValueError(f"{dt=} differs from the flat model's dt={fm.dt}")
        n_out = fm.Cy.shape[0]
    else:
        if dt is None:
            raise ValueError("dt is needed with a LumpedModel")
        fm = flatten_model(model, dt, scheme)
        n_out = len(model.outputs)
    n2 = 2 * fm.n_dofs
    U = np.ascontiguousarray(np.asarray(U, dtype=float))
    if U.ndim != 2 or U.shape[0] != fm.Gu.shape[1]:
        raise ValueError(f"U must have shape (n_inputs={fm.Gu.shape[1]}, N), got {U.shape}")
    if U.shape[1] < 1:
        raise ValueError("U needs at least one sample")
    if not np.all(np.isfinite(U)):
        raise ValueError("U contains non-finite values")
    N = U.shape[1]
    q0 = np.zeros(n2) if q0 is None else np.array(q0, dtype=float).reshape(n2)
    s0 = np.zeros(fm.n_states) if s0 is None else np.array(s0, dtype=float).reshape(fm.n_states)
    max_iter = int(max_iter)
    if max_iter < 1:
        raise ValueError(f"{max_iter=} must be >= 1")
    Y = np.empty((n_out, N))
    ns = N if store_states else 0
    Qo = np.empty((n2, ns))
    Go = np.empty((fm.n_elements, ns))
    So = np.empty((fm.n_states, ns))
    fails, iters = _trapezoid_kernel(
        fm.P, fm.Gu, fm.Gf, fm.Sd, fm.Sv, fm.L, fm.codes, fm.params, fm.k_lin, fm.c_lin,
        fm.state_offsets, fm.Cy, fm.Dy, fm.Hy, U, q0, s0, fm.dt, float(tol), max_iter,
        Y, Qo, Go, So,
    )  # fmt: skip
    fails, iters = int(fails), int(iters)
    if fails and warn:
        warnings.warn(
            f"Newton's iteration did not converge at {fails} of {N - 1} integration steps "
            f"(tol={tol:g}, max_iter={max_iter}); the last iterates were kept",
            RuntimeWarning,
            stacklevel=2,
        )
    if not store_states:
        Qo = Go = So = None
    return IntegrationResult(y=Y, q=Qo, g=Go, s=So, newton_failures=fails, newton_iterations=iters)
