#!/usr/bin/env python
"""Independent case generator for `vibroscope gap`.

Written from the tool's public description only (README "Your own log" / section 2 header,
`vibroscope gap --help`, the model-file docstring).  Nothing of vibroscope is imported: the
truth is integrated here with a fixed-step RK4 at 10 kHz (numba), decimated to 1 kHz with
scipy.signal.decimate, and written as ROS 2 MCAP with mcap_ros2.

Usage:
    python gen.py --seed 1 --per-class 3 --out cases_1
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np
from scipy import signal

try:
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*a, **k):
        if a and callable(a[0]):
            return a[0]
        return lambda f: f

CLASSES = ["none", "parameter_mismatch", "extra_mode", "time_delay", "coulomb_friction",
           "backlash", "hysteresis", "cubic_stiffness", "saturation"]
FS_FINE = 10_000.0
FS_LOG = 1_000.0
DEC = 10
DURATION = 60.0
LEVELS = (1.0, 3.0, 10.0)
GAP_LO, GAP_HI = 0.15, 0.60

# nonlinear element codes
NL_NONE, NL_COULOMB, NL_BACKLASH, NL_BOUCWEN, NL_CUBIC = 0, 1, 2, 3, 4
SAT_NONE, SAT_CLIP, SAT_TANH = 0, 1, 2


# ----------------------------------------------------------------------------- integrator
@njit(cache=True)
def _deriv(x, v, z, u, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, fsat,
           acc, dz, F):
    n = m.shape[0]
    for k in range(n):
        F[k] = 0.0
    for e in range(li.shape[0]):
        i = li[e]
        j = lj[e]
        xi = x[i]
        vi = v[i]
        xj = 0.0
        vj = 0.0
        if j >= 0:
            xj = x[j]
            vj = v[j]
        f = lk[e] * (xi - xj) + lc[e] * (vi - vj)
        F[i] -= f
        if j >= 0:
            F[j] += f
    dz[0] = 0.0
    if nltype != NL_NONE:
        i = ni
        j = nj
        d = x[i]
        dv = v[i]
        if j >= 0:
            d -= x[j]
            dv -= v[j]
        f = 0.0
        if nltype == NL_COULOMB:          # p0 = Fc, p1 = v_eps
            f = p[0] * math.tanh(dv / p[1])
        elif nltype == NL_BACKLASH:       # p0 = k, p1 = clearance c
            if d > p[1]:
                f = p[0] * (d - p[1])
            elif d < -p[1]:
                f = p[0] * (d + p[1])
        elif nltype == NL_BOUCWEN:        # p0 = alpha_h (N/m), p1 = A, p2 = beta, p3 = gamma, p4 = n
            zz = z[0]
            az = abs(zz)
            f = p[0] * zz
            dz[0] = p[1] * dv - p[2] * abs(dv) * az ** (p[4] - 1.0) * zz - p[3] * dv * az ** p[4]
        elif nltype == NL_CUBIC:          # p0 = k3
            f = p[0] * d * d * d
        F[i] -= f
        if j >= 0:
            F[j] += f
    uu = u
    if sat_type == SAT_CLIP:
        if uu > fsat:
            uu = fsat
        elif uu < -fsat:
            uu = -fsat
    elif sat_type == SAT_TANH:
        uu = fsat * math.tanh(uu / fsat)
    F[in_dof] += uu
    for k in range(n):
        acc[k] = F[k] / m[k]


@njit(cache=True)
def simulate(u, dt, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, fsat):
    """Fixed-step RK4.  u: applied force at the fine rate (len N).  Force between samples is
    linearly interpolated.  Returns acc, x, v at every fine sample (N, n)."""
    n = m.shape[0]
    N = u.shape[0]
    X = np.zeros((N, n))
    V = np.zeros((N, n))
    A = np.zeros((N, n))
    x = np.zeros(n)
    v = np.zeros(n)
    z = np.zeros(1)
    a1 = np.zeros(n); a2 = np.zeros(n); a3 = np.zeros(n); a4 = np.zeros(n)
    z1 = np.zeros(1); z2 = np.zeros(1); z3 = np.zeros(1); z4 = np.zeros(1)
    xt = np.zeros(n); vt = np.zeros(n); zt = np.zeros(1)
    F = np.zeros(n); v2 = np.zeros(n); v3 = np.zeros(n); v4 = np.zeros(n)
    for s in range(N):
        u0 = u[s]
        u1 = u[s + 1] if s + 1 < N else u[s]
        um = 0.5 * (u0 + u1)
        _deriv(x, v, z, u0, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, fsat, a1, z1, F)
        for k in range(n):
            X[s, k] = x[k]
            V[s, k] = v[k]
            A[s, k] = a1[k]
        # k1: dx = v, dv = a1
        for k in range(n):
            xt[k] = x[k] + 0.5 * dt * v[k]
            vt[k] = v[k] + 0.5 * dt * a1[k]
        zt[0] = z[0] + 0.5 * dt * z1[0]
        _deriv(xt, vt, zt, um, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, fsat, a2, z2, F)
        for k in range(n):
            v2[k] = vt[k]
        for k in range(n):
            xt[k] = x[k] + 0.5 * dt * v2[k]
            vt[k] = v[k] + 0.5 * dt * a2[k]
        zt[0] = z[0] + 0.5 * dt * z2[0]
        _deriv(xt, vt, zt, um, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, fsat, a3, z3, F)
        for k in range(n):
            v3[k] = vt[k]
        for k in range(n):
            xt[k] = x[k] + dt * v3[k]
            vt[k] = v[k] + dt * a3[k]
        zt[0] = z[0] + dt * z3[0]
        _deriv(xt, vt, zt, u1, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, fsat, a4, z4, F)
        for k in range(n):
            v4[k] = vt[k]
        for k in range(n):
            x[k] += dt / 6.0 * (v[k] + 2.0 * v2[k] + 2.0 * v3[k] + v4[k])
            v[k] += dt / 6.0 * (a1[k] + 2.0 * a2[k] + 2.0 * a3[k] + a4[k])
        z[0] += dt / 6.0 * (z1[0] + 2.0 * z2[0] + 2.0 * z3[0] + z4[0])
        bad = False
        for k in range(n):
            if not (abs(x[k]) < 1e6):
                bad = True
        if bad:
            # diverged: fill the rest with nan
            for r in range(s + 1, N):
                for k in range(n):
                    X[r, k] = np.nan
                    V[r, k] = np.nan
                    A[r, k] = np.nan
            break
    return A, X, V


# ----------------------------------------------------------------------------- systems
class System:
    """A lumped chain.  dofs 0..n_main-1 are the modelled masses; further dofs are hidden."""

    def __init__(self, masses, elems, in_dof, out_dofs, names):
        self.m = [float(q) for q in masses]            # kg
        self.elems = [dict(i=int(e["i"]), j=int(e["j"]), k=float(e["k"]), c=float(e["c"])) for e in elems]
        self.in_dof = in_dof
        self.out_dofs = list(out_dofs)
        self.names = list(names)
        self.nl = dict(type=NL_NONE, i=0, j=-1, p=[0.0] * 5)
        self.sat = dict(type=SAT_NONE, fsat=1.0)
        self.delay = 0.0

    def copy(self):
        s = System(self.m, self.elems, self.in_dof, self.out_dofs, self.names)
        s.nl = dict(self.nl, p=list(self.nl["p"]))
        s.sat = dict(self.sat)
        s.delay = self.delay
        return s

    def matrices(self):
        n = len(self.m)
        M = np.diag(self.m)
        K = np.zeros((n, n))
        C = np.zeros((n, n))
        for e in self.elems:
            i, j = e["i"], e["j"]
            for Mat, val in ((K, e["k"]), (C, e["c"])):
                Mat[i, i] += val
                if j >= 0:
                    Mat[j, j] += val
                    Mat[i, j] -= val
                    Mat[j, i] -= val
        return M, K, C

    def modes(self):
        M, K, C = self.matrices()
        n = len(self.m)
        Aq = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
        lam = np.linalg.eigvals(Aq)
        lam = lam[lam.imag > 1e-9]
        wn = np.abs(lam)
        zeta = -lam.real / wn
        o = np.argsort(wn)
        return wn[o] / (2 * np.pi), zeta[o]

    def run(self, u_logged_fine):
        """Simulate with the logged (noise-free) force at the fine rate; return the decimated
        accelerations at the outputs (n_out, N_log) and the fine states."""
        u = u_logged_fine
        if self.delay > 0:
            t = np.arange(len(u)) / FS_FINE
            u = np.interp(t - self.delay, t, u, left=0.0)
        e = self.elems
        A, X, V = simulate(np.ascontiguousarray(u, dtype=np.float64), 1.0 / FS_FINE,
                           np.array(self.m, float),
                           np.array([q["i"] for q in e], np.int64), np.array([q["j"] for q in e], np.int64),
                           np.array([q["k"] for q in e], float), np.array([q["c"] for q in e], float),
                           int(self.nl["type"]), int(self.nl["i"]), int(self.nl["j"]),
                           np.array(self.nl["p"], float), int(self.in_dof),
                           int(self.sat["type"]), float(self.sat["fsat"]))
        return A, X, V


def decimate(y):
    return signal.decimate(y, DEC, ftype="iir", zero_phase=True, axis=0)


def outputs(sys_, u_fine):
    A, X, V = sys_.run(u_fine)
    if not np.all(np.isfinite(A)):
        return None, X, V
    y = decimate(A[:, sys_.out_dofs])
    return y.T, X, V


# ----------------------------------------------------------------------------- excitation
def excitation(rng, kind, rms, seed_extra=0):
    """Force at the fine rate, 60 s, band 1-100 Hz, given RMS."""
    N = int(DURATION * FS_FINE)
    if kind == "random":
        w = rng.standard_normal(N + 20000)
        sos = signal.butter(4, [1.0, 100.0], btype="bandpass", fs=FS_FINE, output="sos")
        u = signal.sosfilt(sos, w)[20000:]      # filter run-in dropped; force starts at t=0
        # fade in over 50 ms so that the record starts from rest with a continuous force
        ramp = np.minimum(1.0, np.arange(N) / (0.05 * FS_FINE))
        u = u * ramp
        info = dict(kind="random", band_hz=[1.0, 100.0], filter="butter4 bandpass")
    else:
        T = float(rng.choice([5.0, 10.0]))
        P = int(T * FS_FINE)
        X = np.zeros(P // 2 + 1, complex)
        k = np.arange(len(X))
        f = k / T
        lines = (f >= 1.0) & (f <= 100.0)
        X[lines] = np.exp(1j * rng.uniform(0, 2 * np.pi, lines.sum()))
        per = np.fft.irfft(X, P)
        u = np.tile(per, int(np.ceil(N / P)))[:N]
        info = dict(kind="multisine", period_s=T, band_hz=[1.0, 100.0], lines=int(lines.sum()))
    u = u / np.sqrt(np.mean(u ** 2)) * rms
    return u, info


# ----------------------------------------------------------------------------- nominal draw
def draw_nominal(rng):
    for _ in range(1000):
        n = int(rng.integers(1, 4))
        m = np.exp(rng.uniform(np.log(0.5), np.log(20.0), n))
        names = [f"m{i + 1}" for i in range(n)]
        elems = [dict(i=0, j=-1, k=1.0, c=0.0)]             # ground - m1
        for i in range(1, n):
            elems.append(dict(i=i, j=i - 1, k=1.0, c=0.0))   # chain
        extra_ground = n >= 2 and rng.random() < 0.5
        if extra_ground:
            elems.append(dict(i=int(rng.integers(1, n)), j=-1, k=1.0, c=0.0))
        rel = np.exp(rng.uniform(np.log(0.3), np.log(3.0), len(elems)))
        for e, r in zip(elems, rel):
            e["k"] = float(r)
        sys_ = System(m, elems, 0, [0], names)
        # scale stiffnesses so that the lowest mode lies at a drawn frequency
        M, K, _ = sys_.matrices()
        w2 = np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real)
        f1_target = math.exp(rng.uniform(math.log(2.5), math.log(30.0)))
        scale = (2 * math.pi * f1_target) ** 2 / w2[0]
        for e in elems:
            e["k"] *= scale
        fn = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K * scale)).real)) / (2 * math.pi)
        if fn[0] < 2.0 or fn[-1] > 80.0:
            continue
        if n > 1 and np.min(np.diff(fn)) / fn[0] < 0.05:
            continue
        # Rayleigh damping: c to ground a*m_i at every mass, b*k parallel to every spring
        z1 = rng.uniform(0.005, 0.05)
        z2 = rng.uniform(0.005, 0.05)
        w = 2 * math.pi * fn
        if n == 1:
            a, b = 0.0, 2 * z1 / w[0]
            if rng.random() < 0.5:
                a, b = 2 * z1 * w[0], 0.0
        else:
            # zeta = a/(2w) + b w/2 at the lowest and the highest mode
            Amat = np.array([[1 / (2 * w[0]), w[0] / 2], [1 / (2 * w[-1]), w[-1] / 2]])
            a, b = np.linalg.solve(Amat, [z1, z2])
            if a < 0 or b < 0:
                continue
        for e in elems:
            e["c"] = float(b * e["k"])
        for i in range(n):
            if a > 0:
                elems.append(dict(i=i, j=-1, k=0.0, c=float(a * m[i])))
        merged = {}
        for e in elems:                      # one element per connection
            key = (e["i"], e["j"])
            if key in merged:
                merged[key]["k"] += e["k"]
                merged[key]["c"] += e["c"]
            else:
                merged[key] = dict(e)
        elems = list(merged.values())
        sys_ = System(m, elems, 0, [0], names)
        fn2, zeta = sys_.modes()
        if np.any(zeta < 0.0045) or np.any(zeta > 0.055) or fn2[0] < 2.0 or fn2[-1] > 80.0:
            continue
        sys_.in_dof = int(rng.integers(0, n))
        nout = int(rng.integers(1, n + 1))
        sys_.out_dofs = sorted(int(q) for q in rng.choice(n, nout, replace=False))
        return sys_, dict(n=n, fn_hz=[float(q) for q in fn2], zeta=[float(q) for q in zeta],
                          rayleigh=dict(a=float(a), b=float(b)), extra_ground_spring=bool(extra_ground))
    raise RuntimeError("could not draw a nominal")


def springs(sys_):
    return [q for q, e in enumerate(sys_.elems) if e["k"] > 0]


def pair_name(sys_, i, j):
    return [sys_.names[i], "ground" if j < 0 else sys_.names[j]]


# ----------------------------------------------------------------------------- effects
def make_effect(cls, rng, nom, ref):
    """Return (apply(s) -> truth System, s_lo, s_hi, increasing, describe(s) -> dict).
    ref: dict of nominal rms quantities at the calibration level."""
    n = len(nom.m)
    if cls == "parameter_mismatch":
        cand = [("m", i) for i in range(n)] + [("k", q) for q in springs(nom)] + \
               [("c", q) for q, e in enumerate(nom.elems) if e["c"] > 0]
        kk = int(rng.integers(2, min(4, len(cand)) + 1)) if len(cand) >= 2 else 1
        pick = [cand[q] for q in rng.choice(len(cand), kk, replace=False)]
        r = rng.uniform(0.3, 1.0, kk) * rng.choice([-1.0, 1.0], kk)
        r /= np.max(np.abs(r))

        def apply(s):
            t = nom.copy()
            for (what, q), rr in zip(pick, r):
                if what == "m":
                    t.m[q] *= 1 + s * rr
                else:
                    t.elems[q][what] *= 1 + s * rr
            return t

        def describe(s):
            ch = []
            for (what, q), rr in zip(pick, r):
                if what == "m":
                    ch.append(dict(param=f"m:{nom.names[q]}", factor=float(1 + s * rr)))
                else:
                    e = nom.elems[q]
                    ch.append(dict(param=f"{what}:{'-'.join(pair_name(nom, e['i'], e['j']))}",
                                   factor=float(1 + s * rr)))
            return dict(location=[c["param"] for c in ch], changes=ch, max_rel_change=float(s))
        return apply, 0.05, 0.30, True, describe

    if cls == "extra_mode":
        host = int(rng.integers(0, n))
        fa = math.exp(rng.uniform(math.log(3.0), math.log(90.0)))
        za = rng.uniform(0.005, 0.05)

        def apply(s):
            t = nom.copy()
            ma = s * nom.m[host]
            t.m.append(ma)
            ia = len(t.m) - 1
            ka = ma * (2 * math.pi * fa) ** 2
            ca = 2 * za * math.sqrt(ka * ma)
            t.elems.append(dict(i=ia, j=host, k=ka, c=ca))
            return t

        def describe(s):
            ma = s * nom.m[host]
            return dict(location=nom.names[host], absorber_mass_kg=float(ma), mass_ratio=float(s),
                        f_absorber_hz=float(fa), zeta_absorber=float(za),
                        k_absorber=float(ma * (2 * math.pi * fa) ** 2))
        return apply, 0.002, 1.0, True, describe

    if cls == "time_delay":
        def apply(s):
            t = nom.copy()
            t.delay = s
            return t
        return apply, 0.001, 0.020, True, lambda s: dict(location="input", delay_s=float(s))

    if cls == "saturation":
        law = SAT_CLIP if rng.random() < 0.6 else SAT_TANH
        frms = ref["f_rms"]

        def apply(s):
            t = nom.copy()
            t.sat = dict(type=law, fsat=s * frms)
            return t
        return apply, 0.2, 5.0, False, lambda s: dict(
            location="input", law="clip" if law == SAT_CLIP else "tanh", f_sat_N=float(s * frms),
            f_sat_over_rms=float(s))

    # the rest act at a connection
    if cls == "coulomb_friction":
        opts = [(i, -1) for i in range(n)] + [(i, i - 1) for i in range(1, n)]
        i, j = opts[int(rng.integers(0, len(opts)))]
        vr = ref["v_rel_rms"](i, j)
        frms = ref["f_rms"]

        def params(s):
            Fc = s * frms
            veps = 0.01 * vr
            # keep the friction's linearised rate F_c/(m v_eps) stable for RK4 at dt
            mmin = min(nom.m[i], nom.m[j]) if j >= 0 else nom.m[i]
            veps = max(veps, Fc / mmin * (1.0 / FS_FINE) / 0.5)
            return Fc, veps

        def apply(s):
            t = nom.copy()
            Fc, veps = params(s)
            t.nl = dict(type=NL_COULOMB, i=i, j=j, p=[Fc, veps, 0, 0, 0])
            return t

        def describe(s):
            Fc, veps = params(s)
            return dict(location=pair_name(nom, i, j), Fc_N=float(Fc), v_eps_m_per_s=float(veps),
                        Fc_over_force_rms=float(s), v_rel_rms_nominal=float(vr))
        return apply, 0.003, 3.0, True, describe

    sp = springs(nom)
    q = sp[int(rng.integers(0, len(sp)))]
    e = nom.elems[q]
    i, j, k = e["i"], e["j"], e["k"]
    dr = ref["d_rel_rms"](i, j)

    if cls == "backlash":
        def apply(s):
            t = nom.copy()
            t.elems[q] = dict(i=i, j=j, k=0.0, c=e["c"])
            t.nl = dict(type=NL_BACKLASH, i=i, j=j, p=[k, s * dr, 0, 0, 0])
            return t
        return apply, 0.005, 3.0, True, lambda s: dict(
            location=pair_name(nom, i, j), k=float(k), clearance_m=float(s * dr),
            clearance_over_rms_deflection=float(s), d_rel_rms_nominal=float(dr))

    if cls == "cubic_stiffness":
        sign = 1.0 if rng.random() < 0.6 else -1.0

        def apply(s):
            t = nom.copy()
            t.nl = dict(type=NL_CUBIC, i=i, j=j, p=[sign * s * k / dr ** 2, 0, 0, 0, 0])
            return t
        return apply, 0.003, 20.0, True, lambda s: dict(
            location=pair_name(nom, i, j), k=float(k), k3_N_per_m3=float(sign * s * k / dr ** 2),
            character="hardening" if sign > 0 else "softening",
            k3_drms2_over_k=float(sign * s), d_rel_rms_nominal=float(dr))

    if cls == "hysteresis":
        nexp = float(rng.uniform(1.0, 2.5))
        zmax = float(rng.uniform(0.2, 1.0)) * dr
        qg = float(rng.uniform(-0.5, 0.9))
        beta = 1.0 / (zmax ** nexp * (1 + qg))
        gamma = qg * beta

        def apply(s):
            t = nom.copy()
            t.nl = dict(type=NL_BOUCWEN, i=i, j=j, p=[s * k, 1.0, beta, gamma, nexp])
            return t
        return apply, 0.005, 3.0, True, lambda s: dict(
            location=pair_name(nom, i, j), k=float(k), alpha_h_N_per_m=float(s * k),
            alpha_h_over_k=float(s), A=1.0, beta=float(beta), gamma=float(gamma), n=nexp,
            z_max_m=float(zmax), d_rel_rms_nominal=float(dr),
            law="F = alpha_h*z, dz/dt = A*dd - beta*|dd|*|z|^(n-1)*z - gamma*dd*|z|^n")
    raise ValueError(cls)


def nrmse_gap(yt, yn):
    return float(np.mean([np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(a ** 2)) for a, b in zip(yt, yn)]))


def calibrate(apply, s_lo, s_hi, increasing, forces, y_nom, rng):
    """Bisection (in log s) for a gap drawn in [GAP_LO, GAP_HI].  Returns (s, gaps per level) or None."""
    target = float(rng.uniform(GAP_LO + 0.03, GAP_HI - 0.05))

    def gap_at(s):
        gs = []
        for u, yn in zip(forces, y_nom):
            yt, _, _ = outputs(apply(s), u)
            if yt is None:
                return math.inf, None
            gs.append(nrmse_gap(yt, yn))
        return float(np.mean(gs)), gs

    lo, hi = math.log(s_lo), math.log(s_hi)
    g_lo, gl_lo = gap_at(s_lo)
    g_hi, gl_hi = gap_at(s_hi)
    weak, strong = (g_lo, g_hi) if increasing else (g_hi, g_lo)
    if not (weak <= GAP_HI and strong >= GAP_LO):
        return None
    best = None
    for _ in range(22):
        mid = 0.5 * (lo + hi)
        g, gl = gap_at(math.exp(mid))
        if GAP_LO <= g <= GAP_HI and (best is None or abs(g - target) < abs(best[1] - target)):
            best = (math.exp(mid), g, gl)
        if abs(g - target) < 0.01:
            break
        too_strong = g > target
        if too_strong == increasing:
            hi = mid
        else:
            lo = mid
    if best is None:
        return None
    return best


# ----------------------------------------------------------------------------- writing
HEADER_DEFS = """================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
VEC3 = """================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""
WRENCH_DEF = "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n" + HEADER_DEFS + \
    """================================================================================
MSG: geometry_msgs/Wrench
geometry_msgs/Vector3 force
geometry_msgs/Vector3 torque
""" + VEC3
IMU_DEF = """std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
""" + HEADER_DEFS + """================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
""" + VEC3

T0_NS = 1_700_000_000 * 10 ** 9


def write_mcap(path, force, accs, names):
    from mcap_ros2.writer import Writer
    with open(path, "wb") as fh:
        w = Writer(fh)
        sw = w.register_msgdef("geometry_msgs/msg/WrenchStamped", WRENCH_DEF)
        si = w.register_msgdef("sensor_msgs/msg/Imu", IMU_DEF)
        zero9 = [0.0] * 9
        N = len(force)
        for s in range(N):
            t = T0_NS + s * 1_000_000
            stamp = {"sec": t // 10 ** 9, "nanosec": t % 10 ** 9}
            w.write_message("/force", sw, {
                "header": {"stamp": stamp, "frame_id": "load_cell"},
                "wrench": {"force": {"x": float(force[s]), "y": 0.0, "z": 0.0},
                           "torque": {"x": 0.0, "y": 0.0, "z": 0.0}}}, log_time=t, publish_time=t, sequence=s)
            for a, nm in zip(accs, names):
                w.write_message(f"/imu/{nm}", si, {
                    "header": {"stamp": stamp, "frame_id": nm},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": zero9,
                    "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0},
                    "angular_velocity_covariance": zero9,
                    "linear_acceleration": {"x": float(a[s]), "y": 0.0, "z": 0.0},
                    "linear_acceleration_covariance": zero9}, log_time=t, publish_time=t, sequence=s)
        w.finish()


def write_model(path, nom, case_id):
    L = [f'# nominal model of {case_id} (independent generator)', 'kind = "lumped"', ""]
    for nm, m in zip(nom.names, nom.m):
        L += ["[[dof]]", f'name = "{nm}"', f"mass = {m:.10g}", ""]
    for e in nom.elems:
        a, b = pair_name(nom, e["i"], e["j"])
        if e["k"] > 0:
            L += ["[[element]]", 'type = "spring"', f'between = ["{a}", "{b}"]', f"k = {e['k']:.10g}", ""]
        if e["c"] > 0:
            L += ["[[element]]", 'type = "damper"', f'between = ["{a}", "{b}"]', f"c = {e['c']:.10g}", ""]
    L += ["[[input]]", 'channel = "/force.wrench.force.x"', f'dof = "{nom.names[nom.in_dof]}"',
          'quantity = "force"', ""]
    for o in nom.out_dofs:
        nm = nom.names[o]
        L += ["[[output]]", f'channel = "/imu/{nm}.linear_acceleration.x"', f'dof = "{nm}"',
              'quantity = "acceleration"', ""]
    with open(path, "w") as fh:
        fh.write("\n".join(L))


# ----------------------------------------------------------------------------- case
def make_case(rng, cls, case_dir, case_id, multi):
    t0 = time.time()
    for attempt in range(60):
        nom, nom_info = draw_nominal(rng)
        n = len(nom.m)
        base = 0.5 * float(np.sum(nom.m))           # N rms at level 1
        exc_kind = "random" if rng.random() < 0.5 else "multisine"
        if multi:
            levels = list(LEVELS)
        else:
            levels = [float(rng.choice(LEVELS))]
        forces, exc_infos = [], []
        for lv in levels:
            u, info = excitation(rng, exc_kind, base * lv)
            forces.append(u)
            exc_infos.append(dict(info, level=lv, force_rms_N=float(base * lv)))
        y_nom, XV = [], []
        ok = True
        for u in forces:
            y, X, V = outputs(nom, u)
            if y is None:
                ok = False
                break
            y_nom.append(y)
            XV.append((X, V))
        if not ok:
            continue
        # calibration level: the middle one for three logs
        cal = len(levels) // 2
        Xc, Vc = XV[cal]

        def d_rel_rms(i, j, Xc=Xc):
            d = Xc[:, i] - (Xc[:, j] if j >= 0 else 0.0)
            return float(np.sqrt(np.mean(d ** 2)))

        def v_rel_rms(i, j, Vc=Vc):
            d = Vc[:, i] - (Vc[:, j] if j >= 0 else 0.0)
            return float(np.sqrt(np.mean(d ** 2)))
        ref = dict(f_rms=base * levels[cal], d_rel_rms=d_rel_rms, v_rel_rms=v_rel_rms)
        if cls == "none":
            truth, s, gaps, eff = nom.copy(), None, [0.0] * len(levels), dict(location=None)
        else:
            apply, s_lo, s_hi, inc, describe = make_effect(cls, rng, nom, ref)
            res = calibrate(apply, s_lo, s_hi, inc, forces, y_nom, rng)
            if res is None:
                print(f"  {case_id} {cls}: attempt {attempt} cannot reach the gap range, redraw", flush=True)
                continue
            s, g, gaps = res
            truth = apply(s)
            eff = describe(s)
        # final truth outputs + noise + write
        os.makedirs(case_dir, exist_ok=True)
        noise_frac = float(rng.uniform(0.01, 0.03))
        logs = []
        gaps_final = []
        for li, (u, yn, info) in enumerate(zip(forces, y_nom, exc_infos)):
            yt, _, _ = outputs(truth, u)
            gaps_final.append(nrmse_gap(yt, yn))
            f_log = decimate(u)
            f_noisy = f_log + noise_frac * np.sqrt(np.mean(f_log ** 2)) * rng.standard_normal(len(f_log))
            acc_noisy = [a + noise_frac * np.sqrt(np.mean(a ** 2)) * rng.standard_normal(len(a)) for a in yt]
            fname = f"log_{li + 1}.mcap"
            write_mcap(os.path.join(case_dir, fname), f_noisy, acc_noisy, [nom.names[o] for o in nom.out_dofs])
            logs.append(dict(file=fname, **info,
                             acc_rms=[float(np.sqrt(np.mean(a ** 2))) for a in yt],
                             noise_free_gap=float(gaps_final[-1])))
        write_model(os.path.join(case_dir, "model.toml"), nom, case_id)
        th = dict(case=case_id, cls=cls, effect=eff,
                  noise_free_gap=float(np.mean(gaps_final)), noise_free_gap_per_log=gaps_final,
                  noise_fraction=noise_frac, excitation=exc_kind, logs=logs,
                  nominal=dict(**nom_info, masses=nom.m, elems=nom.elems,
                               input=nom.names[nom.in_dof], outputs=[nom.names[o] for o in nom.out_dofs]),
                  truth_system=dict(masses=truth.m, elems=truth.elems, nl=truth.nl, sat=truth.sat,
                                    delay=truth.delay),
                  strength_param=s, attempts=attempt + 1, gen_seconds=time.time() - t0)
        with open(os.path.join(case_dir, "truth.json"), "w") as fh:
            json.dump(th, fh, indent=1)
        return th
    raise RuntimeError(f"{case_id}: no case of class {cls} after 60 attempts")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--per-class", type=int, default=3)
    ap.add_argument("--out", default=None)
    ap.add_argument("--classes", default=",".join(CLASSES))
    ap.add_argument("--multi-frac", type=float, default=1 / 3)
    ap.add_argument("--only", type=int, default=None, help="generate only this case index")
    a = ap.parse_args(argv)
    out = a.out or f"cases_{a.seed}"
    classes = a.classes.split(",")
    rng0 = np.random.default_rng(a.seed)
    plan = [c for c in classes for _ in range(a.per_class)]
    order = rng0.permutation(len(plan))
    plan = [plan[q] for q in order]
    nmulti = int(round(a.multi_frac * len(plan)))
    multi = np.zeros(len(plan), bool)
    multi[rng0.choice(len(plan), nmulti, replace=False)] = True
    os.makedirs(out, exist_ok=True)
    index = []
    for idx, cls in enumerate(plan):
        if a.only is not None and idx != a.only:
            continue
        cid = f"case_{idx:03d}"
        rng = np.random.default_rng([a.seed, idx])
        t0 = time.time()
        th = make_case(rng, cls, os.path.join(out, cid), cid, bool(multi[idx]))
        print(f"{cid} {cls:18s} logs={len(th['logs'])} gap={th['noise_free_gap']:.3f} "
              f"loc={th['effect'].get('location')} {time.time() - t0:.1f}s", flush=True)
        index.append(dict(case=cid, cls=cls, logs=len(th["logs"])))
    if a.only is None:
        with open(os.path.join(out, "index.json"), "w") as fh:
            json.dump(dict(seed=a.seed, per_class=a.per_class, cases=index), fh, indent=1)


if __name__ == "__main__":
    main()
