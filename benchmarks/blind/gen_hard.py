#!/usr/bin/env python
"""HARD independent case generator for `vibroscope gap` (a variant of gen.py).

Written from the tool's public description only (README up to its first session block,
`vibroscope gap --help`, the model-file docstring).  Nothing of vibroscope is imported.  Same case
layout as gen.py (model.toml, log_N.mcap, truth.json), so score.py scores it unchanged.

What it varies per case (all drawn from a per-case RNG, seed = [seed, case index]):
  * nominal: a chain of 1-4 masses (random naming order), ground spring at the first mass, with
    some probability a ground spring at the far end / at an interior mass, and a spring between two
    non-adjacent masses; non-proportional damping (a damper in parallel with every spring, each with
    its own loss factor, plus some dampers to ground); modes inside the excited band;
  * force input at any DOF, 1-3 accelerometers at random DOFs (the input DOF not always measured);
  * log rate in {500, 1000, 2000} Hz, truth integrated by fixed-step RK4 at max(10 kHz, 10x rate),
    anti-aliased decimation (scipy IIR decimate, zero phase, or polyphase FIR resample_poly);
  * record 30-90 s; excitation band edges drawn (low 0.5-5 Hz, high 0.2-0.45 x log rate);
    band-limited random, flat multisine or a periodic (linear or logarithmic) chirp; a periodic
    input half of the time logged in steady state (a simulated lead-in dropped);
  * levels: ratios 1 : r2 : r2*r3 with r2, r3 in 1.5-3.5; a third of the cases three logs, one level
    each; else one log at one level or stepped through the three levels;
  * absolute force scale drawn over two decades;
  * effect laws unlike the textbook ones (see make_effect), noise-free gap 0.1-1.0 nrmse;
  * noise 1-4 % white on accelerations and force; a quarter of the cases also an accelerometer bias
    (constant, random walk, or a 0.02-0.08 Hz wander).

Usage:
    python gen_hard.py --seed 11 --per-class 3 --out cases_h11
    python gen_hard.py --seed 99 --per-class 1 --out probe --only 3 --force fs_log=2000 --force exc=chirp
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np
from scipy import signal
from scipy.fft import next_fast_len

try:
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*a, **k):
        if a and callable(a[0]):
            return a[0]
        return lambda f: f

CLASSES = ["none", "parameter_mismatch", "extra_mode", "time_delay", "coulomb_friction",
           "backlash", "hysteresis", "cubic_stiffness", "saturation"]
RATES = (500.0, 1000.0, 2000.0)
GAP_LO, GAP_HI = 0.10, 1.00

# nonlinear element codes
NL_NONE, NL_STRIBECK, NL_DEADZONE, NL_BOUCWEN, NL_DAHL, NL_CUBQUINT = 0, 1, 2, 3, 4, 5
SAT_NONE, SAT_CLIP, SAT_KNEE = 0, 1, 2
NP = 8


# ----------------------------------------------------------------------------- integrator
@njit(cache=True)
def _deriv(x, v, z, u, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, s0, s1, acc, dz, F):
    n = m.shape[0]
    for k in range(n):
        F[k] = 0.0
    for e in range(li.shape[0]):
        i = li[e]
        j = lj[e]
        xj = 0.0
        vj = 0.0
        if j >= 0:
            xj = x[j]
            vj = v[j]
        f = lk[e] * (x[i] - xj) + lc[e] * (v[i] - vj)
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
        if nltype == NL_STRIBECK:       # p0 Fc, p1 Fs, p2 vs, p3 ve, p4 cv
            r = dv / p[2]
            f = (p[0] + (p[1] - p[0]) * math.exp(-r * r)) * math.tanh(dv / p[3]) + p[4] * dv
        elif nltype == NL_DEADZONE:     # p0 kc, p1 half clearance
            if d > p[1]:
                f = p[0] * (d - p[1])
            elif d < -p[1]:
                f = p[0] * (d + p[1])
        elif nltype == NL_BOUCWEN:      # p0 alpha, p1 A, p2 beta, p3 gamma, p4 n
            zz = z[0]
            az = abs(zz)
            f = p[0] * zz
            dz[0] = p[1] * dv - p[2] * abs(dv) * az ** (p[4] - 1.0) * zz - p[3] * dv * az ** p[4]
        elif nltype == NL_DAHL:         # p0 sigma, p1 Fc, p2 exponent a; state = force
            zz = z[0]
            f = zz
            sg = 1.0 if dv >= 0.0 else -1.0
            r = 1.0 - zz / p[1] * sg
            g = abs(r) ** p[2]
            if r < 0.0:
                g = -g
            dz[0] = p[0] * dv * g
        elif nltype == NL_CUBQUINT:     # p0 k3, p1 k5
            d2 = d * d
            f = p[0] * d * d2 + p[1] * d * d2 * d2
        F[i] -= f
        if j >= 0:
            F[j] += f
    uu = u
    if sat_type == SAT_CLIP:
        if uu > s0:
            uu = s0
        elif uu < -s0:
            uu = -s0
    elif sat_type == SAT_KNEE:          # u / (1 + |u/L|^p)^(1/p)
        uu = u / (1.0 + abs(u / s0) ** s1) ** (1.0 / s1)
    F[in_dof] += uu
    for k in range(n):
        acc[k] = F[k] / m[k]


@njit(cache=True)
def simulate(u, dt, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, s0, s1, store_xv):
    """Fixed-step RK4; force linear between fine samples.  Returns A (N, n) and, when store_xv,
    X and V (N, n) (else (1, n))."""
    n = m.shape[0]
    N = u.shape[0]
    Nx = N if store_xv else 1
    X = np.zeros((Nx, n))
    V = np.zeros((Nx, n))
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
        _deriv(x, v, z, u0, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, s0, s1, a1, z1, F)
        if store_xv:
            for k in range(n):
                X[s, k] = x[k]
                V[s, k] = v[k]
        for k in range(n):
            A[s, k] = a1[k]
        for k in range(n):
            xt[k] = x[k] + 0.5 * dt * v[k]
            vt[k] = v[k] + 0.5 * dt * a1[k]
        zt[0] = z[0] + 0.5 * dt * z1[0]
        _deriv(xt, vt, zt, um, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, s0, s1, a2, z2, F)
        for k in range(n):
            v2[k] = vt[k]
        for k in range(n):
            xt[k] = x[k] + 0.5 * dt * v2[k]
            vt[k] = v[k] + 0.5 * dt * a2[k]
        zt[0] = z[0] + 0.5 * dt * z2[0]
        _deriv(xt, vt, zt, um, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, s0, s1, a3, z3, F)
        for k in range(n):
            v3[k] = vt[k]
        for k in range(n):
            xt[k] = x[k] + dt * v3[k]
            vt[k] = v[k] + dt * a3[k]
        zt[0] = z[0] + dt * z3[0]
        _deriv(xt, vt, zt, u1, m, li, lj, lk, lc, nltype, ni, nj, p, in_dof, sat_type, s0, s1, a4, z4, F)
        for k in range(n):
            v4[k] = vt[k]
        for k in range(n):
            x[k] += dt / 6.0 * (v[k] + 2.0 * v2[k] + 2.0 * v3[k] + v4[k])
            v[k] += dt / 6.0 * (a1[k] + 2.0 * a2[k] + 2.0 * a3[k] + a4[k])
        z[0] += dt / 6.0 * (z1[0] + 2.0 * z2[0] + 2.0 * z3[0] + z4[0])
        bad = not (abs(z[0]) < 1e12)
        for k in range(n):
            if not (abs(x[k]) < 1e6):
                bad = True
        if bad:
            for r in range(s + 1, N):
                for k in range(n):
                    A[r, k] = np.nan
            if store_xv:
                for r in range(s + 1, N):
                    for k in range(n):
                        X[r, k] = np.nan
                        V[r, k] = np.nan
            break
    return A, X, V


# ----------------------------------------------------------------------------- settings
class Cfg:
    """Per-case acquisition settings."""

    def __init__(self, fs_log, decimator, duration, band, exc, sweep, period, steady, multi, stepped,
                 order, ratios, base_scale):
        self.fs_log = float(fs_log)
        self.fs_fine = max(10_000.0, 10.0 * self.fs_log)
        self.dec = int(round(self.fs_fine / self.fs_log))
        self.decimator = decimator
        self.duration = float(duration)
        self.band = [float(band[0]), float(band[1])]
        self.exc = exc
        self.sweep = sweep
        self.period = period
        self.steady = steady
        self.lead = 0.0
        self.multi = multi
        self.stepped = stepped
        self.order = order
        self.ratios = [float(r) for r in ratios]
        self.base_scale = float(base_scale)

    def as_dict(self):
        return dict(fs_log_hz=self.fs_log, fs_fine_hz=self.fs_fine, decimation_factor=self.dec,
                    decimator=self.decimator, duration_s=self.duration, band_hz=self.band,
                    excitation=self.exc, chirp_sweep=self.sweep, period_s=self.period,
                    steady_state_start=self.steady, lead_in_s=self.lead, three_logs=self.multi,
                    stepped_levels=self.stepped, butter_order=self.order, level_ratios=self.ratios,
                    force_scale_factor=self.base_scale)


def draw_cfg(rng, multi, force):
    fs_log = float(force.get("fs_log", rng.choice(RATES)))
    decimator = str(force.get("decimator", "iir" if rng.random() < 0.5 else "fir"))
    f_lo = float(force.get("f_lo", math.exp(rng.uniform(math.log(0.5), math.log(5.0)))))
    f_hi = float(force.get("f_hi", rng.uniform(0.2, 0.45) * fs_log))
    exc = str(force.get("exc", rng.choice(["random", "multisine", "chirp"])))
    sweep = str(rng.choice(["linear", "log"])) if exc == "chirp" else None
    duration = float(force.get("duration", rng.uniform(30.0, 90.0)))
    if "multi" in force:
        multi = bool(int(force["multi"]))
    stepped = (not multi) and rng.random() < 0.4
    if "stepped" in force:
        stepped = (not multi) and bool(int(force["stepped"]))
    period = None
    steady = False
    if exc in ("multisine", "chirp"):
        seg = duration / 3.0 if stepped else duration
        choices = [T for T in (2.0, 4.0, 5.0, 8.0, 10.0) if T <= seg / 3.0]
        period = float(rng.choice(choices))
        nper = max(3, int(round(seg / period)))
        duration = (3 * nper if stepped else nper) * period
        steady = rng.random() < 0.5
        if "steady" in force:
            steady = bool(int(force["steady"]))
    else:
        duration = round(duration, 1)
    order = int(rng.choice([2, 4, 6]))
    r2, r3 = rng.uniform(1.5, 3.5, 2)
    ratios = [1.0, float(r2), float(r2 * r3)]
    base_scale = 10 ** rng.uniform(-1.0, 1.0)
    return Cfg(fs_log, decimator, duration, [f_lo, f_hi], exc, sweep, period, steady, multi, stepped,
               order, ratios, base_scale)


def decimate(y, cfg):
    """Anti-aliased decimation of y (axis 0) from the fine to the log rate."""
    q = cfg.dec
    if cfg.decimator == "iir":
        stages = [10] if q == 10 else ([10, 2] if q == 20 else [q])
        for s in stages:
            y = signal.decimate(y, s, ftype="iir", zero_phase=True, axis=0)
        return y
    return signal.resample_poly(y, 1, q, axis=0)


# ----------------------------------------------------------------------------- systems
class System:
    def __init__(self, masses, elems, in_dof, out_dofs, names):
        self.m = [float(q) for q in masses]
        self.elems = [dict(i=int(e["i"]), j=int(e["j"]), k=float(e["k"]), c=float(e["c"])) for e in elems]
        self.in_dof = in_dof
        self.out_dofs = list(out_dofs)
        self.names = list(names)
        self.nl = dict(type=NL_NONE, i=0, j=-1, p=[0.0] * NP)
        self.sat = dict(type=SAT_NONE, L=1.0, p=2.0)
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

    def run(self, u, cfg, store_xv=False):
        if self.delay > 0:
            u = fft_delay(u, self.delay, cfg.fs_fine)
        e = self.elems
        p = np.zeros(NP)
        p[:len(self.nl["p"])] = self.nl["p"]
        return simulate(np.ascontiguousarray(u, dtype=np.float64), 1.0 / cfg.fs_fine,
                        np.array(self.m, float),
                        np.array([q["i"] for q in e], np.int64), np.array([q["j"] for q in e], np.int64),
                        np.array([q["k"] for q in e], float), np.array([q["c"] for q in e], float),
                        int(self.nl["type"]), int(self.nl["i"]), int(self.nl["j"]), p, int(self.in_dof),
                        int(self.sat["type"]), float(self.sat["L"]), float(self.sat["p"]), bool(store_xv))


def fft_delay(u, tau, fs):
    """Exact fractional delay of a band-limited signal (zero before it starts)."""
    n = len(u)
    N = next_fast_len(n + int(tau * fs) + 4096)
    U = np.fft.rfft(u, N)
    f = np.fft.rfftfreq(N, 1.0 / fs)
    return np.fft.irfft(U * np.exp(-2j * np.pi * f * tau), N)[:n]


def outputs(sys_, u_fine, cfg, store_xv=False):
    """Decimated accelerations at the outputs (n_out, N_log) of the recorded part, plus the fine
    X, V of the recorded part (when store_xv)."""
    A, X, V = sys_.run(u_fine, cfg, store_xv)
    if not np.all(np.isfinite(A)):
        return None, None, None
    y = decimate(A[:, sys_.out_dofs], cfg)
    nl = int(round(cfg.lead * cfg.fs_log))
    y = y[nl:]
    if store_xv:
        nf = int(round(cfg.lead * cfg.fs_fine))
        X, V = X[nf:], V[nf:]
    return y.T, X, V


# ----------------------------------------------------------------------------- excitation
def unit_signal(rng, cfg, N):
    """Unit-rms excitation at the fine rate, N samples."""
    fs = cfg.fs_fine
    f_lo, f_hi = cfg.band
    if cfg.exc == "random":
        run_in = int(max(2.0, 10.0 / f_lo) * fs)
        w = rng.standard_normal(N + run_in)
        sos = signal.butter(cfg.order, [f_lo, f_hi], btype="bandpass", fs=fs, output="sos")
        u = signal.sosfilt(sos, w)[run_in:]
        u *= np.minimum(1.0, np.arange(N) / (0.05 * fs))
    else:
        T = cfg.period
        P = int(round(T * fs))
        if cfg.exc == "multisine":
            X = np.zeros(P // 2 + 1, complex)
            f = np.arange(len(X)) / T
            lines = (f >= f_lo) & (f <= f_hi)
            X[lines] = np.exp(1j * rng.uniform(0, 2 * np.pi, lines.sum()))
            per = np.fft.irfft(X, P)
        else:  # periodic chirp, phase continuous over the period
            t = np.arange(P) / fs
            if cfg.sweep == "linear":
                ph = 2 * np.pi * (f_lo * t + 0.5 * (f_hi - f_lo) * t ** 2 / T)
                cyc = f_lo * T + 0.5 * (f_hi - f_lo) * T
            else:
                r = f_hi / f_lo
                ph = 2 * np.pi * f_lo * T / math.log(r) * (r ** (t / T) - 1.0)
                cyc = f_lo * T * (r - 1.0) / math.log(r)
            ph -= 2 * np.pi * (cyc - math.floor(cyc)) * t / T
            per = np.sin(ph + rng.uniform(0, 2 * np.pi))
        u = np.tile(per, int(math.ceil(N / P)))[:N]
    return u / np.sqrt(np.mean(u ** 2))


def make_forces(rng, cfg, base):
    """Fine-rate forces (with the lead-in), one per log, and their descriptions."""
    fs = cfg.fs_fine
    Nrec = int(round(cfg.duration * fs))
    Nlead = int(round(cfg.lead * fs))
    N = Nrec + Nlead
    r = cfg.ratios
    forces, infos = [], []
    if cfg.multi:
        for lv in r:
            forces.append(unit_signal(rng, cfg, N) * base * lv)
            infos.append(dict(level=lv, force_rms_N=base * lv))
    elif cfg.stepped:
        order = list(r) if rng.random() < 0.5 else [r[q] for q in rng.permutation(3)]
        env = np.empty(N)
        seg = Nrec // 3
        env[:Nlead + seg] = order[0]
        env[Nlead + seg:Nlead + 2 * seg] = order[1]
        env[Nlead + 2 * seg:] = order[2]
        forces.append(unit_signal(rng, cfg, N) * base * env)
        infos.append(dict(level=[float(q) for q in order], force_rms_N=[float(base * q) for q in order],
                          stepped_segment_s=cfg.duration / 3))
    else:
        lv = float(rng.choice(r))
        forces.append(unit_signal(rng, cfg, N) * base * lv)
        infos.append(dict(level=lv, force_rms_N=base * lv))
    return forces, infos


# ----------------------------------------------------------------------------- nominal draw
def draw_nominal(rng, cfg, force):
    f_lo, f_hi = cfg.band
    f1_lo = max(2.0, 1.5 * f_lo)
    f1_hi = min(40.0, 0.25 * f_hi)
    for _ in range(3000):
        n = int(force.get("n", rng.integers(1, 5)))
        m = np.exp(rng.uniform(math.log(0.2), math.log(30.0), n))
        names = [f"m{q + 1}" for q in rng.permutation(n)]
        conns = [(0, -1)] + [(i, i - 1) for i in range(1, n)]
        topo = dict(fixed_far_end=False, interior_ground=None, nonadjacent=None)
        if n >= 2 and rng.random() < 0.3:
            conns.append((n - 1, -1))
            topo["fixed_far_end"] = True
        if n >= 3 and rng.random() < 0.3:
            q = int(rng.integers(1, n - 1))
            conns.append((q, -1))
            topo["interior_ground"] = q
        if n >= 3 and rng.random() < 0.6:
            pairs = [(i, j) for i in range(n) for j in range(i) if i - j >= 2]
            a, b = pairs[int(rng.integers(0, len(pairs)))]
            conns.append((a, b))
            topo["nonadjacent"] = [a, b]
        conns = list(dict.fromkeys(conns))
        kr = np.exp(rng.uniform(math.log(0.2), math.log(5.0), len(conns)))
        elems = [dict(i=i, j=j, k=float(k), c=0.0) for (i, j), k in zip(conns, kr)]
        sys_ = System(m, elems, 0, [0], names)
        M, K, _ = sys_.matrices()
        w2 = np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real)
        if w2[0] <= 0:
            continue
        f1 = math.exp(rng.uniform(math.log(f1_lo), math.log(f1_hi)))
        sc = (2 * math.pi * f1) ** 2 / w2[0]
        for e in elems:
            e["k"] *= sc
        fn = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K * sc)).real)) / (2 * math.pi)
        if fn[-1] > min(0.6 * f_hi, 350.0):
            continue
        if n > 1 and np.min(np.diff(fn) / fn[:-1]) < 0.05:
            continue
        # non-proportional damping: own loss factor per spring, some dampers to ground
        wm = 2 * math.pi * math.sqrt(fn[0] * fn[-1])
        zt = math.exp(rng.uniform(math.log(0.006), math.log(0.04)))
        for e in elems:
            e["c"] = 2 * zt * e["k"] / wm * math.exp(rng.uniform(-1.2, 1.2))
        gd = [i for i in range(n) if rng.random() < 0.3]
        extra = [dict(i=i, j=-1, k=0.0, c=float(zt * m[i] * wm * math.exp(rng.uniform(-1.2, 1.2)))) for i in gd]
        merged = {}
        for e in elems + extra:
            key = (e["i"], e["j"])
            if key in merged:
                merged[key]["c"] += e["c"]
            else:
                merged[key] = dict(e)
        elems = list(merged.values())
        ok = False
        for _it in range(3):
            sys_ = System(m, elems, 0, [0], names)
            _, zeta = sys_.modes()
            if len(zeta) < n:
                break
            fac = zt / float(np.median(zeta))
            for e in elems:
                e["c"] *= fac
        sys_ = System(m, elems, 0, [0], names)
        fn2, zeta = sys_.modes()
        if len(zeta) == n and np.min(zeta) >= 0.003 and np.max(zeta) <= 0.09 and fn2[0] >= f1_lo * 0.9:
            ok = True
        if not ok:
            continue
        sys_.in_dof = int(force.get("in_dof", rng.integers(0, n)))
        nout = int(rng.integers(1, min(3, n) + 1))
        sys_.out_dofs = sorted(int(q) for q in rng.choice(n, nout, replace=False))
        if "measure_input" in force:
            want = bool(int(force["measure_input"]))
            if want and sys_.in_dof not in sys_.out_dofs:
                sys_.out_dofs = sorted(set(sys_.out_dofs[:-1]) | {sys_.in_dof})
            if not want and n > 1 and sys_.in_dof in sys_.out_dofs:
                rest = [q for q in range(n) if q != sys_.in_dof]
                sys_.out_dofs = sorted(int(q) for q in rng.choice(rest, min(len(rest), nout), replace=False))
        topo["names_in_chain_order"] = names
        return sys_, dict(n=n, fn_hz=[float(q) for q in fn2], zeta=[float(q) for q in zeta],
                          topology=topo, input_measured=sys_.in_dof in sys_.out_dofs)
    raise RuntimeError("could not draw a nominal")


def springs(sys_):
    return [q for q, e in enumerate(sys_.elems) if e["k"] > 0]


def pair_name(sys_, i, j):
    return [sys_.names[i], "ground" if j < 0 else sys_.names[j]]


def m_eff(nom, i, j):
    return nom.m[i] if j < 0 else nom.m[i] * nom.m[j] / (nom.m[i] + nom.m[j])


# ----------------------------------------------------------------------------- effects
def make_effect(cls, rng, nom, ref, cfg, fn, force):
    """Return (apply(s) -> truth System, s_lo, s_hi, increasing, describe(s) -> dict)."""
    n = len(nom.m)
    variant = force.get("variant")
    dt = 1.0 / cfg.fs_fine
    if cls == "parameter_mismatch":
        variant = variant or str(rng.choice(["general", "damping_only", "one_mass"], p=[0.5, 0.25, 0.25]))
        dampers = [("c", q) for q, e in enumerate(nom.elems) if e["c"] > 0]
        if variant == "general":
            cand = [("m", i) for i in range(n)] + [("k", q) for q in springs(nom)] + dampers
            kk = int(rng.integers(1, min(4, len(cand)) + 1))
            pick = [cand[q] for q in rng.choice(len(cand), kk, replace=False)]
            r = rng.uniform(0.3, 1.0, kk) * rng.choice([-1.0, 1.0], kk)
            r /= np.max(np.abs(r))
            lo, hi = 0.005, 0.6
            law = lambda s, rr: 1 + s * rr
        elif variant == "damping_only":
            kk = int(rng.integers(1, len(dampers) + 1))
            pick = [dampers[q] for q in rng.choice(len(dampers), kk, replace=False)]
            r = rng.uniform(0.5, 1.0, kk) * (1.0 if rng.random() < 0.5 else -1.0)
            r /= np.max(np.abs(r))
            lo, hi = 0.02, 3.5
            law = lambda s, rr: math.exp(s * rr)
        else:
            pick = [("m", int(rng.integers(0, n)))]
            r = np.array([rng.choice([-1.0, 1.0])])
            lo, hi = 0.005, 0.7
            law = lambda s, rr: 1 + s * rr

        def apply(s):
            t = nom.copy()
            for (what, q), rr in zip(pick, r):
                if what == "m":
                    t.m[q] *= law(s, rr)
                else:
                    t.elems[q][what] *= law(s, rr)
            return t

        def describe(s):
            ch = []
            for (what, q), rr in zip(pick, r):
                if what == "m":
                    ch.append(dict(param=f"m:{nom.names[q]}", factor=float(law(s, rr))))
                else:
                    e = nom.elems[q]
                    ch.append(dict(param=f"{what}:{'-'.join(pair_name(nom, e['i'], e['j']))}",
                                   factor=float(law(s, rr))))
            return dict(location=[c["param"] for c in ch], variant=variant, changes=ch, strength=float(s))
        return apply, lo, hi, True, describe

    if cls == "extra_mode":
        f_lo, f_hi = cfg.band
        unmeas = [i for i in range(n) if i not in nom.out_dofs]
        variant = variant or str(rng.choice(["unmeasured_host", "top_of_band", "in_band"]))
        if variant == "unmeasured_host" and not unmeas:
            variant = "in_band"
        if variant == "unmeasured_host":
            host = int(rng.choice(unmeas))
        else:
            host = int(rng.integers(0, n))
        if variant == "top_of_band":
            fa = rng.uniform(0.6, 0.92) * f_hi
        else:
            a = max(1.2 * f_lo, 0.5 * fn[0])
            b = min(0.9 * f_hi, 2.0 * fn[-1])
            fa = math.exp(rng.uniform(math.log(a), math.log(b)))
        za = math.exp(rng.uniform(math.log(0.005), math.log(0.05)))

        def apply(s):
            t = nom.copy()
            ma = s * nom.m[host]
            t.m.append(ma)
            ka = ma * (2 * math.pi * fa) ** 2
            t.elems.append(dict(i=len(t.m) - 1, j=host, k=ka, c=2 * za * math.sqrt(ka * ma)))
            return t

        def describe(s):
            ma = s * nom.m[host]
            return dict(location=nom.names[host], variant=variant, host_measured=host in nom.out_dofs,
                        absorber_mass_kg=float(ma), mass_ratio=float(s), f_absorber_hz=float(fa),
                        zeta_absorber=float(za), k_absorber=float(ma * (2 * math.pi * fa) ** 2))
        return apply, 0.0005, 1.0, True, describe

    if cls == "time_delay":
        def apply(s):
            t = nom.copy()
            t.delay = s
            return t
        return apply, 0.0006, 0.030, True, lambda s: dict(
            location="input", delay_s=float(s), delay_samples=float(s * cfg.fs_log),
            method="exact FFT fractional delay of the fine-rate force")

    if cls == "saturation":
        law = force.get("variant") or ("clip" if rng.random() < 0.4 else "knee")
        pk = float(rng.uniform(2.0, 8.0))
        frms = ref["f_rms"]

        def apply(s):
            t = nom.copy()
            t.sat = dict(type=SAT_CLIP if law == "clip" else SAT_KNEE, L=s * frms, p=pk)
            return t

        def describe(s):
            d = dict(location="input", law=law, L_N=float(s * frms), L_over_force_rms=float(s),
                     force_rms_ref_N=float(frms))
            if law == "knee":
                d["p"] = pk
                d["formula"] = "u / (1 + |u/L|^p)^(1/p)"
            return d
        return apply, 0.15, 8.0, False, describe

    # location-bound effects
    sp = springs(nom)
    if cls == "coulomb_friction":
        opts = [(i, -1) for i in range(n)] + [(nom.elems[q]["i"], nom.elems[q]["j"]) for q in sp
                                             if nom.elems[q]["j"] >= 0]
        i, j = opts[int(rng.integers(0, len(opts)))]
        vr = ref["v_rel_rms"](i, j)
        frms = ref["f_rms"]
        fs_fc = float(rng.uniform(1.0, 2.0))
        vs = float(rng.uniform(0.05, 0.5)) * vr
        ve0 = float(math.exp(rng.uniform(math.log(0.002), math.log(0.03)))) * vr
        cv_rel = float(rng.uniform(0.0, 0.5))
        me = m_eff(nom, i, j)

        def params(s):
            Fc = s * frms
            Fs = fs_fc * Fc
            ve = max(ve0, 2.0 * Fs * dt / me)
            cv = cv_rel * Fc / vr
            return Fc, Fs, vs, ve, cv

        def apply(s):
            t = nom.copy()
            Fc, Fs, vs_, ve, cv = params(s)
            t.nl = dict(type=NL_STRIBECK, i=i, j=j, p=[Fc, Fs, vs_, ve, cv, 0, 0, 0])
            return t

        def describe(s):
            Fc, Fs, vs_, ve, cv = params(s)
            return dict(location=pair_name(nom, i, j), Fc_N=Fc, Fs_N=Fs, vs_m_per_s=vs_, ve_m_per_s=ve,
                        cv_N_s_per_m=cv, Fc_over_force_rms=float(s), Fs_over_Fc=fs_fc,
                        viscous_force_at_rms_velocity_over_Fc=cv_rel, v_rel_rms_nominal=vr,
                        formula="(Fc + (Fs-Fc) exp(-(v/vs)^2)) tanh(v/ve) + cv v")
        return apply, 0.001, 3.0, True, describe

    if cls == "backlash":
        q = sp[int(rng.integers(0, len(sp)))]
        e = nom.elems[q]
        i, j, k = e["i"], e["j"], e["k"]
        dr = ref["d_rel_rms"](i, j)
        kc_rel = float(force.get("kc_rel", rng.uniform(0.5, 1.5)))
        # does the structure stay grounded with this spring open?
        others = [x for qq, x in enumerate(nom.elems) if qq != q and x["k"] > 0]
        grounded = _grounded(n, others)

        def apply(s):
            t = nom.copy()
            t.elems[q] = dict(i=i, j=j, k=0.0, c=e["c"])
            t.nl = dict(type=NL_DEADZONE, i=i, j=j, p=[kc_rel * k, s * dr, 0, 0, 0, 0, 0, 0])
            return t
        return apply, 0.03, 3.0, True, lambda s: dict(
            location=pair_name(nom, i, j), k_nominal=k, k_contact=kc_rel * k, k_contact_over_k=kc_rel,
            half_clearance_m=float(s * dr), half_clearance_over_rms_deflection=float(s),
            d_rel_rms_nominal=dr, grounded_when_open=grounded,
            law="spring k replaced by dead zone: kc (d - c) for d > c, kc (d + c) for d < -c, 0 inside")

    # hysteresis and cubic: at a spring (80 %) or anywhere else (a mass to ground, any pair)
    if rng.random() < 0.8:
        q = sp[int(rng.integers(0, len(sp)))]
        i, j, k = nom.elems[q]["i"], nom.elems[q]["j"], nom.elems[q]["k"]
        at_spring = True
    else:
        opts = [(a, -1) for a in range(n)] + [(a, b) for a in range(n) for b in range(a)]
        i, j = opts[int(rng.integers(0, len(opts)))]
        k = nom.m[i] * (2 * math.pi * fn[0]) ** 2
        at_spring = any((x["i"], x["j"]) in ((i, j), (j, i)) and x["k"] > 0 for x in nom.elems)
    dr = ref["d_rel_rms"](i, j)

    if cls == "cubic_stiffness":
        hard = rng.random() < 0.6
        s3 = 1.0 if hard else -1.0
        s5 = 1.0 if (hard or rng.random() < 0.5) else -1.0
        r5 = float(rng.uniform(0.1, 1.0))

        def k35(s):
            k3 = s3 * s * k / dr ** 2
            k5 = s5 * r5 * abs(k3) / dr ** 2
            return k3, k5

        def apply(s):
            t = nom.copy()
            k3, k5 = k35(s)
            t.nl = dict(type=NL_CUBQUINT, i=i, j=j, p=[k3, k5, 0, 0, 0, 0, 0, 0])
            return t

        def describe(s):
            k3, k5 = k35(s)
            return dict(location=pair_name(nom, i, j), at_nominal_spring=at_spring, k_ref=k,
                        k3_N_per_m3=k3, k5_N_per_m5=k5, character="hardening" if hard else "softening",
                        quintic_sign=s5, k3_drms2_over_k=float(s3 * s), k5_drms4_over_k3_drms2=float(s5 * r5),
                        d_rel_rms_nominal=dr, law="F = k3 d^3 + k5 d^5 (in parallel with the nominal)")
        return apply, 0.002, 30.0, True, describe

    if cls == "hysteresis":
        law = force.get("variant") or ("bouc_wen" if rng.random() < 0.65 else "dahl")
        if law == "bouc_wen":
            nexp = float(rng.choice([1.0, 2.0]))
            zmax = float(rng.uniform(0.1, 1.2)) * dr
            qg = float(rng.uniform(-0.7, 1.5))
            beta = 1.0 / (zmax ** nexp * (1 + qg))
            gamma = qg * beta

            def apply(s):
                t = nom.copy()
                t.nl = dict(type=NL_BOUCWEN, i=i, j=j, p=[s * k, 1.0, beta, gamma, nexp, 0, 0, 0])
                return t
            return apply, 0.003, 3.0, True, lambda s: dict(
                location=pair_name(nom, i, j), law="bouc_wen", at_nominal_spring=at_spring, k_ref=k,
                alpha_N_per_m=float(s * k), alpha_over_k=float(s), A=1.0, beta=beta, gamma=gamma,
                gamma_over_beta=qg, n=nexp, z_max_m=zmax, d_rel_rms_nominal=dr,
                formula="F = alpha z, dz/dt = A dd - beta |dd| |z|^(n-1) z - gamma dd |z|^n")
        a_exp = float(rng.uniform(0.6, 2.5))
        y0 = float(rng.uniform(0.1, 1.0)) * dr

        def apply(s):
            t = nom.copy()
            t.nl = dict(type=NL_DAHL, i=i, j=j, p=[s * k, s * k * y0, a_exp, 0, 0, 0, 0, 0])
            return t
        return apply, 0.003, 3.0, True, lambda s: dict(
            location=pair_name(nom, i, j), law="dahl", at_nominal_spring=at_spring, k_ref=k,
            sigma_N_per_m=float(s * k), Fc_N=float(s * k * y0), sigma_over_k=float(s), exponent=a_exp,
            yield_deflection_m=y0, d_rel_rms_nominal=dr,
            formula="F = z, dz/dt = sigma dd sgn(r)|r|^a, r = 1 - z sgn(dd)/Fc")
    raise ValueError(cls)


def _grounded(n, elems):
    g = {-1}
    changed = True
    while changed:
        changed = False
        for e in elems:
            a, b = e["i"], e["j"]
            if (a in g) != (b in g):
                g |= {a, b}
                changed = True
    return all(q in g for q in range(n))


def nrmse_gap(yt, yn):
    return float(np.mean([np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(a ** 2)) for a, b in zip(yt, yn)]))


def calibrate(apply, s_lo, s_hi, increasing, forces, y_nom, rng, cfg):
    target = float(math.exp(rng.uniform(math.log(GAP_LO + 0.02), math.log(GAP_HI - 0.08))))

    def gap_at(s):
        gs = []
        for u, yn in zip(forces, y_nom):
            yt, _, _ = outputs(apply(s), u, cfg)
            if yt is None:
                return math.inf, None
            gs.append(nrmse_gap(yt, yn))
        return float(np.mean(gs)), gs

    lo, hi = math.log(s_lo), math.log(s_hi)
    g_lo, _ = gap_at(s_lo)
    g_hi, _ = gap_at(s_hi)
    weak, strong = (g_lo, g_hi) if increasing else (g_hi, g_lo)
    if not (weak <= GAP_HI and strong >= GAP_LO):
        return None, target, (g_lo, g_hi)
    best = None
    for _ in range(24):
        mid = 0.5 * (lo + hi)
        g, gl = gap_at(math.exp(mid))
        if GAP_LO <= g <= GAP_HI and (best is None or abs(g - target) < abs(best[1] - target)):
            best = (math.exp(mid), g, gl)
        if abs(g - target) < 0.03 * target:
            break
        if (g > target) == increasing:
            hi = mid
        else:
            lo = mid
    return best, target, (g_lo, g_hi)


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


def write_mcap(path, force, accs, names, fs):
    from mcap_ros2.writer import Writer
    step = int(round(1e9 / fs))
    with open(path, "wb") as fh:
        w = Writer(fh)
        sw = w.register_msgdef("geometry_msgs/msg/WrenchStamped", WRENCH_DEF)
        si = w.register_msgdef("sensor_msgs/msg/Imu", IMU_DEF)
        zero9 = [0.0] * 9
        for s in range(len(force)):
            t = T0_NS + s * step
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
    L = [f'# nominal model of {case_id} (independent generator, hard variant)', 'kind = "lumped"', ""]
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


def draw_bias(rng, force):
    kind = force.get("bias")
    if kind is None:
        kind = str(rng.choice(["constant", "random_walk", "wander"])) if rng.random() < 0.25 else "none"
    return kind


def make_bias(rng, kind, N, fs, rms):
    if kind == "none":
        return np.zeros(N), None
    t = np.arange(N) / fs
    const = float(rng.uniform(-0.3, 0.3)) * rms
    if kind == "constant":
        return np.full(N, const), dict(kind=kind, constant=const, constant_over_rms=const / rms)
    lvl = float(rng.uniform(0.005, 0.03))
    if kind == "random_walk":
        w = np.cumsum(rng.standard_normal(N))
        w -= w.mean()
        w *= lvl * rms / np.std(w)
        return const + w, dict(kind=kind, constant=const, rms_over_acc_rms=lvl)
    f = float(rng.uniform(0.02, 0.08))
    ph = float(rng.uniform(0, 2 * np.pi))
    return const + lvl * rms * math.sqrt(2) * np.sin(2 * np.pi * f * t + ph), dict(
        kind=kind, constant=const, rms_over_acc_rms=lvl, f_hz=f)


# ----------------------------------------------------------------------------- case
def make_case(rng, cls, case_dir, case_id, multi, force):
    t0 = time.time()
    for attempt in range(80):
        cfg = draw_cfg(rng, multi, force)
        try:
            nom, nom_info = draw_nominal(rng, cfg, force)
        except RuntimeError:
            continue
        fn, zeta = nom.modes()
        if cfg.steady:
            tau = float(np.max(1.0 / (zeta * 2 * np.pi * fn)))
            lead = 8.0 * tau
            if lead > 150.0:
                cfg.steady = False
            else:
                cfg.lead = max(2, math.ceil(lead / cfg.period)) * cfg.period
        base = 0.5 * float(np.sum(nom.m)) * cfg.base_scale
        forces, lv_infos = make_forces(rng, cfg, base)
        y_nom, XV = [], []
        ok = True
        for u in forces:
            y, X, V = outputs(nom, u, cfg, store_xv=True)
            if y is None:
                ok = False
                break
            y_nom.append(y)
            XV.append((X, V))
        if not ok:
            continue
        cal = len(forces) // 2
        Xc, Vc = XV[cal]
        del XV

        def d_rel_rms(i, j, Xc=Xc):
            d = Xc[:, i] - (Xc[:, j] if j >= 0 else 0.0)
            return float(np.sqrt(np.mean(d ** 2)))

        def v_rel_rms(i, j, Vc=Vc):
            d = Vc[:, i] - (Vc[:, j] if j >= 0 else 0.0)
            return float(np.sqrt(np.mean(d ** 2)))
        nf = int(round(cfg.lead * cfg.fs_fine))
        ref = dict(f_rms=float(np.sqrt(np.mean(forces[cal][nf:] ** 2))), d_rel_rms=d_rel_rms,
                   v_rel_rms=v_rel_rms)
        if cls == "none":
            truth, s, eff, target = nom.copy(), None, dict(location=None), 0.0
        else:
            apply, s_lo, s_hi, inc, describe = make_effect(cls, rng, nom, ref, cfg, fn, force)
            res, target, ends = calibrate(apply, s_lo, s_hi, inc, forces, y_nom, rng, cfg)
            if res is None:
                print(f"  {case_id} {cls}: attempt {attempt} cannot reach the gap range "
                      f"(ends {ends[0]:.3g}, {ends[1]:.3g}), redraw", flush=True)
                continue
            s, g, gaps = res
            truth = apply(s)
            eff = describe(s)
        del Xc, Vc
        os.makedirs(case_dir, exist_ok=True)
        noise_frac = float(rng.uniform(0.01, 0.04))
        bias_kind = draw_bias(rng, force)
        logs, gaps_final, biases = [], [], []
        nl = int(round(cfg.lead * cfg.fs_log))
        for li, (u, yn, info) in enumerate(zip(forces, y_nom, lv_infos)):
            yt, _, _ = outputs(truth, u, cfg)
            gaps_final.append(nrmse_gap(yt, yn))
            f_log = decimate(u, cfg)[nl:]
            f_noisy = f_log + noise_frac * np.sqrt(np.mean(f_log ** 2)) * rng.standard_normal(len(f_log))
            acc_noisy, bl = [], []
            for a in yt:
                rms = float(np.sqrt(np.mean(a ** 2)))
                b, bd = make_bias(rng, bias_kind, len(a), cfg.fs_log, rms)
                bl.append(bd)
                acc_noisy.append(a + noise_frac * rms * rng.standard_normal(len(a)) + b)
            biases.append(bl)
            fname = f"log_{li + 1}.mcap"
            write_mcap(os.path.join(case_dir, fname), f_noisy, acc_noisy,
                       [nom.names[o] for o in nom.out_dofs], cfg.fs_log)
            logs.append(dict(file=fname, **info, samples=len(f_log),
                             acc_rms=[float(np.sqrt(np.mean(a ** 2))) for a in yt],
                             noise_free_gap=float(gaps_final[-1])))
        write_model(os.path.join(case_dir, "model.toml"), nom, case_id)
        th = dict(case=case_id, cls=cls, effect=eff,
                  noise_free_gap=float(np.mean(gaps_final)), noise_free_gap_per_log=gaps_final,
                  gap_target=target, noise_fraction=noise_frac, excitation=cfg.exc,
                  settings=cfg.as_dict(), bias=dict(kind=bias_kind, per_log_per_channel=biases),
                  logs=logs,
                  nominal=dict(**nom_info, masses=nom.m, elems=nom.elems, names=nom.names,
                               input=nom.names[nom.in_dof], outputs=[nom.names[o] for o in nom.out_dofs],
                               force_base_rms_N=base),
                  truth_system=dict(masses=truth.m, elems=truth.elems, nl=truth.nl, sat=truth.sat,
                                    delay=truth.delay),
                  strength_param=s, attempts=attempt + 1, forced=force, gen_seconds=time.time() - t0)
        with open(os.path.join(case_dir, "truth.json"), "w") as fh:
            json.dump(th, fh, indent=1)
        return th
    raise RuntimeError(f"{case_id}: no case of class {cls} after 80 attempts")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--per-class", type=int, default=3)
    ap.add_argument("--out", default=None)
    ap.add_argument("--classes", default=",".join(CLASSES))
    ap.add_argument("--multi-frac", type=float, default=1 / 3)
    ap.add_argument("--only", type=int, default=None, help="generate only this case index")
    ap.add_argument("--class-of-only", default=None, help="with --only: override that case's class")
    ap.add_argument("--force", action="append", default=[],
                    help="KEY=VALUE to pin a draw (fs_log, exc, multi, stepped, steady, bias, n, "
                         "variant, decimator, f_lo, f_hi, duration, kc_rel, in_dof, measure_input)")
    a = ap.parse_args(argv)
    force = {}
    for kv in a.force:
        k, v = kv.split("=", 1)
        force[k] = v
    out = a.out or f"cases_h{a.seed}"
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
        if a.only is not None and a.class_of_only:
            cls = a.class_of_only
        cid = f"case_{idx:03d}"
        rng = np.random.default_rng([a.seed, idx])
        t0 = time.time()
        th = make_case(rng, cls, os.path.join(out, cid), cid, bool(multi[idx]), force)
        st = th["settings"]
        print(f"{cid} {cls:18s} logs={len(th['logs'])} gap={th['noise_free_gap']:.3f} "
              f"fs={st['fs_log_hz']:.0f} exc={st['excitation']}{'/ss' if st['steady_state_start'] else ''}"
              f"{'/stepped' if st['stepped_levels'] else ''} T={st['duration_s']:.1f}s n={th['nominal']['n']} "
              f"out={th['nominal']['outputs']} in={th['nominal']['input']} bias={th['bias']['kind']} "
              f"loc={th['effect'].get('location')} var={th['effect'].get('variant') or th['effect'].get('law')} "
              f"{time.time() - t0:.1f}s", flush=True)
        index.append(dict(case=cid, cls=cls, logs=len(th["logs"])))
    if a.only is None:
        with open(os.path.join(out, "index.json"), "w") as fh:
            json.dump(dict(seed=a.seed, per_class=a.per_class, generator="gen_hard.py", cases=index),
                      fh, indent=1)


if __name__ == "__main__":
    main()
