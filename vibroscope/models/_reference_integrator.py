"""Today's pure-Python trapezoidal integrator, kept verbatim as the reference.

Used ONLY by the equivalence tests (``tests/models/test_integrate.py``,
``tests/models/test_simulate.py``) and the benchmark (``benchmarks/run.py``) as "the
integrator before the compiled kernel"; :func:`vibroscope.models.simulate.simulate` runs
:mod:`vibroscope.models.integrate` instead.

The scheme is the trapezoidal rule (Newmark average acceleration, ``a = 1/2``, ``b = 1/4``,
``c = 1/2`` for internal states) [1]_. Steps whose Newton iteration does not converge are
counted (``_Integrator.newton_failures``) and warned about, as the compiled kernel does.

References
----------
.. [1] N. M. Newmark, "A method of computation for structural dynamics", J. Eng. Mech. Div.
   ASCE 85(EM3):67-94, 1959.
"""

from __future__ import annotations

import warnings

import numpy as np

from vibroscope.models.elements import BoucWen
from vibroscope.models.lumped import LumpedModel

__all__: list[str] = []


# --------------------------------------------------------------------------------------------
# nonlinear path: trapezoidal rule (Newmark a = 1/2, b = 1/4 and c = 1/2 for internal states)
# --------------------------------------------------------------------------------------------
class _Integrator:
    """Trapezoidal integration of ``M xdd + C xd + K x + L^T g(d, v, s) = B u``,
    ``sdot = h(d, v, s)`` with the linear part solved exactly per step and a Newton
    iteration on the nonlinear element forces and states only."""

    def __init__(self, model: LumpedModel, dt: float):
        self.newton_failures = 0  # of the last run()
        self.model = model
        n = model.n_dofs
        A, Bq, _, _ = model.state_matrices()
        self.els = model.nonlinear_elements
        self.L = np.array([model.element_vector(e) for e in self.els]).reshape(len(self.els), n)
        Minv = np.asarray(model.M_inv)
        Bf = np.zeros((2 * n, len(self.els)))
        Bf[n:] = -(Minv @ self.L.T)
        N = np.eye(2 * n) - 0.5 * dt * A
        self.P = np.linalg.solve(N, np.eye(2 * n) + 0.5 * dt * A)
        self.Gu = np.linalg.solve(N, 0.5 * dt * Bq)
        self.Gf = np.linalg.solve(N, 0.5 * dt * Bf)
        E = np.zeros((2 * len(self.els), 2 * n))
        E[0::2, :n] = self.L
        E[1::2, n:] = self.L
        self.E = E
        self.S = E @ self.Gf  # (2 n_e, n_e): de+ / dg+
        self.dt = dt
        self.n = n
        self.state_slices = []
        i = 0
        for e in self.els:
            self.state_slices.append(slice(i, i + e.n_states))
            i += e.n_states
        self.n_s = i

    def remainder(self, e, d, v, s):
        return e.force(d, v, s) - e.linear_stiffness * d - e.linear_damping * v

    def run(self, U: np.ndarray, q0=None, s0=None, *, warn: bool = True):
        """Integrate over the fine-grid input U (n_in, N); returns q (2n, N), g (n_e, N).

        The steps whose Newton iteration stopped at its iteration limit (50 or 60) without
        meeting its tolerance are counted in ``self.newton_failures`` (their last iterates are
        kept), like :attr:`vibroscope.models.integrate.IntegrationResult.newton_failures`;
        `warn` issues one :class:`RuntimeWarning` when there are any.
        """
        self.newton_failures = 0
        if len(self.els) == 1 and self.els[0].n_states <= 1:
            out = self._run_scalar(U, q0, s0)
        else:
            out = self._run_general(U, q0, s0)
        if self.newton_failures and warn:
            warnings.warn(
                f"reference integrator: Newton's iteration did not converge at {self.newton_failures} of "
                f"{U.shape[1] - 1} integration steps; the last iterates were kept",
                RuntimeWarning,
                stacklevel=2,
            )
        return out

    # generic: several elements and/or several internal states; residuals in Python floats,
    # Newton with a forward-difference Jacobian
    def _run_general(self, U, q0, s0):
        n_e, n_s, dt = len(self.els), self.n_s, self.dt
        N = U.shape[1]
        wT = np.ascontiguousarray((self.Gu @ (U[:, :-1] + U[:, 1:])).T)
        q = np.zeros(2 * self.n) if q0 is None else np.array(q0, float)
        s = [0.0] * n_s if s0 is None else [float(v) for v in np.ravel(s0)]
        Q = np.empty((2 * self.n, N))
        G = np.empty((n_e, N))
        Q[:, 0] = q
        els = self.els
        # per element: (element, state start, n_states, linear k, linear c, S rows for d and v)
        info = []
        for i, e in enumerate(els):
            st0 = self.state_slices[i].start
            info.append((e, st0, e.n_states, e.linear_stiffness, e.linear_damping,
                         self.S[2 * i].tolist(), self.S[2 * i + 1].tolist()))
        m = n_e + n_s
        half = 0.5 * dt
        P, Gf, E = self.P, self.Gf, self.E

        def forces(ev, x):
            """remainder forces g (n_e) and state derivatives (n_s) at kinematics ev given
            unknowns x = [g (ignored here), states]"""
            g = [0.0] * n_e
            sd = [0.0] * n_s
            for i, (e, st0, ns, kl, cl, _, _) in enumerate(info):
                d, v = ev[2 * i], ev[2 * i + 1]
                st = x[n_e + st0 : n_e + st0 + ns] if ns else None
                g[i] = e.force(d, v, st) - kl * d - cl * v
                if ns == 1:
                    sd[st0] = float(e.state_derivative(d, v, st))
                elif ns:
                    sd[st0 : st0 + ns] = [float(c) for c in e.state_derivative(d, v, st)]
            return g, sd

        def kin(ep, x):
            ev = list(ep)
            for i, (_, _, _, _, _, Sd, Sv) in enumerate(info):
                ev[2 * i] += sum(a * b for a, b in zip(Sd, x[:n_e]))
                ev[2 * i + 1] += sum(a * b for a, b in zip(Sv, x[:n_e]))
            return ev

        ev = (E @ q).tolist()
        g, sd = forces(ev, [0.0] * n_e + s)
        G[:, 0] = g
        for k in range(N - 1):
            qp = P @ q + wT[k] + Gf @ np.asarray(g)
            ep = (E @ qp).tolist()
            base = [s[j] + half * sd[j] for j in range(n_s)]

            def resid(x):
                gg, ss = forces(kin(ep, x), x)
                return [x[i] - gg[i] for i in range(n_e)] + [x[n_e + j] - base[j] - half * ss[j] for j in range(n_s)]

            x = list(g) + list(s)
            for _ in range(50):
                r = resid(x)
                J = np.empty((m, m))
                for j in range(m):
                    hstep = 1e-7 * max(1.0, abs(x[j]))
                    xx = list(x)
                    xx[j] += hstep
                    rj = resid(xx)
                    J[:, j] = [(a - b) / hstep for a, b in zip(rj, r)]
                dx = np.linalg.solve(J, r)
                x = [a - b for a, b in zip(x, dx.tolist())]
                if all(abs(b) <= 1e-13 * max(1.0, abs(a)) for a, b in zip(x, dx.tolist())):
                    break
            else:
                self.newton_failures += 1
            g = x[:n_e]
            s = x[n_e:]
            q = qp + Gf @ np.asarray(g)
            ev = (E @ q).tolist()
            g, sd = forces(ev, x)
            Q[:, k + 1] = q
            G[:, k + 1] = g
        return Q, G

    # one nonlinear element with <= 1 state: scalar Newton in Python floats (fast); the
    # linear state update in floats for one DOF, in numpy otherwise
    def _run_scalar(self, U, q0, s0):
        e = self.els[0]
        dt = self.dt
        n2 = 2 * self.n
        s_d, s_v = self.S[0, 0], self.S[1, 0]
        w = self.Gu @ (U[:, :-1] + U[:, 1:])
        N = U.shape[1]
        q = np.zeros(n2) if q0 is None else np.array(q0, float)
        kl, cl = e.linear_stiffness, e.linear_damping
        has_state = e.n_states == 1
        z = 0.0 if s0 is None else float(np.ravel(s0)[0])
        Q = np.empty((n2, N))
        Q[:, 0] = q
        Gl = [0.0] * N
        f, sdot = e.force, e.state_derivative
        bw = isinstance(e, BoucWen) and e.nu == 1.0
        if bw:
            al, be, ga, de = e.alpha, e.beta, e.gamma, e.delta
        half = 0.5 * dt
        E0, E1 = self.E[0], self.E[1]
        d, v = float(E0 @ q), float(E1 @ q)
        if has_state:
            g = f(d, v, (z,)) - kl * d - cl * v
            zd = sdot(d, v, (z,))
        else:
            g = f(d, v, None) - kl * d - cl * v
            zd = 0.0
        Gl[0] = g

        def newton(dp, vp, g, z, zd):
            if bw:
                # unknown z+ (= g+): r(z) = z - zb - h/2 zdot(v(z), z), v = vp + s_v z
                zb = z + half * zd
                zz = z
                for _ in range(60):
                    vv = vp + s_v * zz
                    av = abs(vv)
                    az = abs(zz)
                    sv = 1.0 if vv >= 0 else -1.0
                    sz = 1.0 if zz >= 0 else -1.0
                    zdn = al * vv - be * (ga * av * zz + de * vv * az)
                    r = zz - zb - half * zdn
                    dzd = al * s_v - be * (ga * (sv * s_v * zz + av) + de * (s_v * az + vv * sz))
                    dz = r / (1.0 - half * dzd)
                    zz -= dz
                    if abs(dz) <= 1e-15 * (1.0 + abs(zz)) + 1e-300:
                        break
                else:
                    self.newton_failures += 1
                vv = vp + s_v * zz
                return zz, zz, al * vv - be * (ga * abs(vv) * zz + de * vv * abs(zz))
            gg = g
            zz = z
            for _ in range(60):
                dd, vv = dp + s_d * gg, vp + s_v * gg
                if has_state:
                    r1 = gg - (f(dd, vv, (zz,)) - kl * dd - cl * vv)
                    r2 = zz - z - half * (zd + sdot(dd, vv, (zz,)))
                    hs = 1e-7 * max(1.0, abs(gg))
                    hz = 1e-7 * max(1.0, abs(zz))
                    d1, v1 = dp + s_d * (gg + hs), vp + s_v * (gg + hs)
                    a11 = 1.0 - ((f(d1, v1, (zz,)) - kl * d1 - cl * v1) - (gg - r1)) / hs
                    a21 = -half * (sdot(d1, v1, (zz,)) - sdot(dd, vv, (zz,))) / hs
                    a12 = -((f(dd, vv, (zz + hz,)) - kl * dd - cl * vv) - (gg - r1)) / hz
                    a22 = 1.0 - half * (sdot(dd, vv, (zz + hz,)) - sdot(dd, vv, (zz,))) / hz
                    det = a11 * a22 - a12 * a21
                    dg = (a22 * r1 - a12 * r2) / det
                    dz = (a11 * r2 - a21 * r1) / det
                    gg -= dg
                    zz -= dz
                    if abs(dg) <= 1e-13 * (1.0 + abs(gg)) and abs(dz) <= 1e-13 * (1.0 + abs(zz)):
                        break
                else:
                    r1 = gg - (f(dd, vv, None) - kl * dd - cl * vv)
                    hs = 1e-7 * max(1.0, abs(gg))
                    d1, v1 = dp + s_d * (gg + hs), vp + s_v * (gg + hs)
                    a11 = 1.0 - ((f(d1, v1, None) - kl * d1 - cl * v1) - (gg - r1)) / hs
                    dg = r1 / a11
                    gg -= dg
                    if abs(dg) <= 1e-13 * (1.0 + abs(gg)):
                        break
            else:
                self.newton_failures += 1
            zdn = sdot(dp + s_d * gg, vp + s_v * gg, (zz,)) if has_state else 0.0
            return gg, zz, zdn

        if self.n == 1:
            (p11, p12), (p21, p22) = self.P
            gf1, gf2 = self.Gf[:, 0]
            lv = self.L[0, 0]
            w1, w2 = w[0].tolist(), w[1].tolist()
            x1, x2 = float(q[0]), float(q[1])
            X1 = [x1] * N
            X2 = [x2] * N
            for k in range(N - 1):
                qp1 = p11 * x1 + p12 * x2 + w1[k] + gf1 * g
                qp2 = p21 * x1 + p22 * x2 + w2[k] + gf2 * g
                g, z, zd = newton(lv * qp1, lv * qp2, g, z, zd)
                x1 = qp1 + gf1 * g
                x2 = qp2 + gf2 * g
                X1[k + 1] = x1
                X2[k + 1] = x2
                Gl[k + 1] = g
            Q = np.array([X1, X2])
        else:
            P, gf = self.P, self.Gf[:, 0]
            wT = np.ascontiguousarray(w.T)
            for k in range(N - 1):
                qp = P @ q + wT[k] + gf * g
                g, z, zd = newton(float(E0 @ qp), float(E1 @ qp), g, z, zd)
                q = qp + gf * g
                Q[:, k + 1] = q
                Gl[k + 1] = g
        return Q, np.array([Gl])



def _outputs_from_states(model: LumpedModel, Q, G, U):
    """Configured outputs from fine-grid states Q (2n, N), nonlinear forces G, inputs U."""
    n = model.n_dofs
    X, V = Q[:n], Q[n:]
    Minv = np.asarray(model.M_inv)
    acc = None
    rows = []
    for o in model.outputs:
        k = model.dof_index(o.dof)
        if o.quantity == "displacement":
            rows.append(X[k])
        elif o.quantity == "velocity":
            rows.append(V[k])
        else:
            if acc is None:
                F = model.B @ U - model.K @ X - model.C @ V
                if G.shape[0]:
                    L = np.array([model.element_vector(e) for e in model.nonlinear_elements])
                    F = F - L.T @ G
                acc = Minv @ F
            rows.append(acc[k])
    return np.array(rows).reshape(len(model.outputs), -1)



def reference_simulate_fine(model: LumpedModel, U: np.ndarray, fs: float, R: int) -> np.ndarray:
    """Today's nonlinear path on an applied fine-grid input `U` (n_inputs, n R): the
    reference integrator, the outputs on the fine grid and :func:`decimate_fir` by `R`.

    Returns the outputs at `fs`, shape (n_outputs, n)."""
    from vibroscope.models.resample import decimate_fir

    Q, G = _Integrator(model, 1.0 / (fs * R)).run(U)
    y_fine = _outputs_from_states(model, Q, G, U)
    return decimate_fir(y_fine, R) if R > 1 else y_fine
