"""Withheld-effect benchmark for the sim-to-real gap diagnoser: case generator.

Every case is a random lumped chain model (the *nominal* model, written as ``nominal.toml``)
and a ROS 2 MCAP log (``log.mcap``) of the *truth*: the nominal model with one hidden effect
added (or none), driven by a known band-limited force, with measurement noise on the outputs.
What the hidden effect is, where, and how strong, is written apart, in ``truth/``::

    python benchmarks/gap/generate.py --out DIR [--per-class 10] [--classes ...] [--seed 0]
                                      [--duration 60] [--jobs 1]

    DIR/cases/case_NNN/nominal.toml     the nominal model (vibroscope model file)
    DIR/cases/case_NNN/log.mcap         input (WrenchStamped) + outputs (Imu), 1 kHz
    DIR/truth/case_NNN.json             effect, where, parameters (SI), the true model as
                                        TOML, noise level, input, noise-free nominal gap
    DIR/generate.json                   the command-line arguments (no truth in it)

The truth is simulated with an integrator independent of :mod:`vibroscope.models.simulate`:
LSODA (:func:`scipy.integrate.odeint`, rtol 1e-10) on a numba-compiled right-hand side that
re-implements the element laws, driven by the *continuous* input (a not-a-knot cubic spline
through the force designed on a 16 kHz grid, band-limited below 300 Hz; the logged 1 kHz
samples are every 16th fine sample, so they are exact samples of that force). Delay and
saturation act on the continuous force. Outputs are the accelerations at the log's sample
times, plus white Gaussian noise of 1-3 % of each output's RMS.

Each case depends only on (seed, class, index within class), so a subset of classes
regenerates the same cases. The module is importable (the tests use :func:`make_case`,
:func:`simulate_truth`, :func:`make_input`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numba
import numpy as np
from scipy.integrate import odeint
from scipy.interpolate import CubicSpline

from vibroscope.models.elements import (
    GROUND,
    Backlash,
    BoucWen,
    CubicSpring,
    Damper,
    Friction,
    Spring,
)
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.modelfile import dumps_model

__all__ = [
    "EFFECTS",
    "ELEMENT_EFFECTS",
    "INPUT_CHANNEL",
    "FS",
    "OVERSAMPLE",
    "ContinuousInput",
    "Case",
    "random_chain_model",
    "make_input",
    "simulate_truth",
    "nrmse",
    "make_case",
    "write_case",
    "generate",
    "main",
]

#: the effect vocabulary (fixed)
from vibroscope.gap.report import EFFECTS  # noqa: E402 - the fixed vocabulary, one definition
#: effects that sit on a connection (``where = {"between": [a, b]}``)
ELEMENT_EFFECTS = ("coulomb_friction", "backlash", "hysteresis", "cubic_stiffness")

INPUT_CHANNEL = "/actuator/force_cmd.wrench.force.x"
FS = 1000.0  # log rate, Hz
OVERSAMPLE = 16  # fine grid of the continuous input: 16 kHz
F_BAND_EDGE = 300.0  # the force has no content at or above this frequency, Hz
F_LO = 2.0  # lower band edge of the random part, Hz
LEVELS = (1.0, 2.5, 6.0)  # RMS ratios of the three excitation levels
T0_LOG = 1.7e9  # first header stamp of the logs, s
RTOL = 1e-9  # truth integrator tolerance (relative; absolute is RTOL times each state's scale)
RTOL_CAL = 1e-6  # looser tolerance for the strength calibration runs
CAL_SECONDS = 14.0  # strength calibration runs on this first part of the record
GAP_MIN = 0.05  # every non-none case has at least this noise-free gap
GAP_AIM = (0.08, 0.6)  # calibration-window gaps outside this are redrawn (first 3 attempts)
V_EPS = 1e-3  # friction regularisation velocity, m/s


def output_channel(dof: str) -> str:
    return f"/imu/{dof}.linear_acceleration.x"


# ---------------------------------------------------------------------------------------------
# input
# ---------------------------------------------------------------------------------------------
@dataclass
class ContinuousInput:
    """A force known in continuous time: the cubic spline through `fine` (sampled at
    ``fs * oversample``, starting at t = 0). ``coarse`` = every `oversample`-th sample."""

    fine: np.ndarray
    fs: float = FS
    oversample: int = OVERSAMPLE
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.fine = np.ascontiguousarray(self.fine, dtype=float)
        fsf = self.fs * self.oversample
        spline = CubicSpline(np.arange(self.fine.size) / fsf, self.fine)
        # coefficients per interval, highest power first: (n_intervals, 4)
        self.coeffs = np.ascontiguousarray(spline.c.T)

    def scaled(self, gain: float) -> "ContinuousInput":
        """The same force times `gain` (no new spline fit)."""
        out = object.__new__(ContinuousInput)
        out.fine, out.fs, out.oversample, out.info = self.fine * gain, self.fs, self.oversample, dict(self.info)
        out.coeffs = self.coeffs * gain
        return out

    @property
    def fs_fine(self) -> float:
        return self.fs * self.oversample

    @property
    def coarse(self) -> np.ndarray:
        return self.fine[:: self.oversample].copy()

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        return _spline_eval_many(self.coeffs, self.fs_fine, np.ascontiguousarray(t.ravel())).reshape(t.shape)


@numba.njit(cache=False)
def _spline_eval(C, fsf, t):
    i = int(math.floor(t * fsf))
    if i < 0:
        i = 0
    elif i > C.shape[0] - 1:
        i = C.shape[0] - 1
    dt = t - i / fsf
    return ((C[i, 0] * dt + C[i, 1]) * dt + C[i, 2]) * dt + C[i, 3]


@numba.njit(cache=False)
def _spline_eval_many(C, fsf, t):
    out = np.empty(t.size)
    for j in range(t.size):
        out[j] = _spline_eval(C, fsf, t[j])
    return out


def _raised_cosine(n: int) -> np.ndarray:
    """n samples rising smoothly from 0 to 1 (exclusive ends)."""
    x = (np.arange(n) + 0.5) / n
    return 0.5 - 0.5 * np.cos(np.pi * x)


def _brickwall(x: np.ndarray, fs: float, f_lo: float | None, f_hi: float) -> np.ndarray:
    X = np.fft.rfft(x)
    f = np.fft.rfftfreq(x.size, 1.0 / fs)
    X[f >= f_hi] = 0.0
    if f_lo is not None:
        X[f < f_lo] = 0.0
    return np.fft.irfft(X, x.size)


def make_input(
    rng: np.random.Generator,
    duration: float,
    *,
    kind: str = "random",
    f_hi: float = 200.0,
    levels: bool = True,
    period_s: float = 2.0,
    fs: float = FS,
    oversample: int = OVERSAMPLE,
) -> ContinuousInput:
    """A unit-RMS band-limited force on ``round(duration * fs)`` log samples.

    kind "random": Gaussian noise band-passed to [2 Hz, f_hi); "multisine": a random-phase
    multisine with lines every 1/period_s Hz in [2 Hz, f_hi) (periodic in `period_s`).
    With `levels`, the force is scaled in blocks of 2-4 s cycling over the three levels
    1 : 2.5 : 6 (each cycle a random order), with 0.1 s raised-cosine transitions and a
    0.2 s fade-in and fade-out; the result is low-passed below 300 Hz on the fine grid
    (periodic brick wall), so it is exactly band-limited. Without `levels` (a steady
    multisine, for tests) nothing is tapered.
    """
    n = int(round(duration * fs))
    fsf = fs * oversample
    nf = n * oversample
    if kind == "random":
        base = _brickwall(rng.standard_normal(nf), fsf, F_LO, f_hi)
    elif kind == "multisine":
        npf = int(round(period_s * fsf))
        freqs = np.fft.rfftfreq(npf, 1.0 / fsf)
        spec = np.zeros(freqs.size, complex)
        lines = (freqs >= F_LO) & (freqs < f_hi)
        spec[lines] = np.exp(2j * np.pi * rng.random(lines.sum()))
        one = np.fft.irfft(spec, npf)
        base = np.tile(one, nf // npf + 1)[:nf]
    else:
        raise ValueError(f"kind={kind!r} must be 'random' or 'multisine'")
    base /= np.sqrt(np.mean(base**2))
    info = {"kind": kind, "f_lo_hz": F_LO, "f_hi_hz": float(f_hi), "band_edge_hz": F_BAND_EDGE}
    if kind == "multisine":
        info["period_s"] = float(period_s)
    if levels:
        env = np.empty(nf)
        blocks = []
        t, pos = 0.0, 0
        order: list[int] = []
        while pos < nf:
            if not order:
                order = list(rng.permutation(len(LEVELS)))
            lvl = order.pop(0)
            length = int(round(rng.uniform(2.0, 4.0) * fsf))
            env[pos : pos + length] = LEVELS[lvl]
            blocks.append({"t_start_s": pos / fsf, "duration_s": min(length, nf - pos) / fsf, "level": LEVELS[lvl]})
            pos += length
        # smooth transitions
        ntr = int(0.1 * fsf)
        for b in blocks[1:]:
            i0 = int(round(b["t_start_s"] * fsf))
            a, bb = env[i0 - 1], env[min(i0, nf - 1)]
            lo, hi = max(i0 - ntr // 2, 0), min(i0 + ntr // 2, nf)
            env[lo:hi] = a + (bb - a) * _raised_cosine(hi - lo)
        nfade = int(0.2 * fsf)
        env[:nfade] *= _raised_cosine(nfade)
        env[nf - nfade :] *= _raised_cosine(nfade)[::-1]
        x = _brickwall(base * env, fsf, None, F_BAND_EDGE)
        info["levels"] = list(LEVELS)
        info["blocks"] = blocks
    else:
        x = base
    return ContinuousInput(x, fs, oversample, info)


# ---------------------------------------------------------------------------------------------
# truth integrator (independent of vibroscope.models.simulate)
# ---------------------------------------------------------------------------------------------
# element codes
_SPRING, _DAMPER, _CUBIC, _BACKLASH, _FRICTION, _BOUCWEN = range(6)


# all constants of a model packed into one float array P (one argument: cheap numba dispatch
# from odeint's callback): [fs_fine, delay, saturation, input dof, n_dofs, n_elements, n_z,
# 1/m (n_dofs), then per element: type, a, b, state index, p0..p4]
_HEAD = 7
_EW = 9


@numba.njit(cache=False)
def _forces(y, t, C, P, F, dz):
    """Net force on every DOF (into F) and Bouc-Wen state derivatives (into dz); returns u."""
    fsf, delay, sat = P[0], P[1], P[2]
    in_dof, ndof, nel = int(P[3]), int(P[4]), int(P[5])
    ts = t - delay
    if ts < 0.0:
        u = 0.0
    else:
        u = _spline_eval(C, fsf, ts)
    if sat > 0.0:
        if u > sat:
            u = sat
        elif u < -sat:
            u = -sat
    for i in range(ndof):
        F[i] = 0.0
    F[in_dof] += u
    base = _HEAD + ndof
    for e in range(nel):
        o = base + e * _EW
        typ = int(P[o])
        a = int(P[o + 1])
        b = int(P[o + 2])
        d = 0.0
        v = 0.0
        if a >= 0:
            d += y[a]
            v += y[ndof + a]
        if b >= 0:
            d -= y[b]
            v -= y[ndof + b]
        p0 = P[o + 4]
        p1 = P[o + 5]
        if typ == _SPRING:
            f = p0 * d
        elif typ == _DAMPER:
            f = p0 * v
        elif typ == _CUBIC:
            f = p0 * d + p1 * d * d * d
        elif typ == _BACKLASH:
            if d > p1:
                f = p0 * (d - p1)
            elif d < -p1:
                f = p0 * (d + p1)
            else:
                f = 0.0
        elif typ == _FRICTION:
            f = p0 * math.tanh(v / p1)
        else:  # Bouc-Wen: force z, zdot = alpha v - beta (gamma |v| |z|^(nu-1) z + delta v |z|^nu)
            s = int(P[o + 3])
            z = y[2 * ndof + s]
            az = abs(z)
            alpha, beta, gamma, delta, nu = p0, p1, P[o + 6], P[o + 7], P[o + 8]
            if nu == 1.0:
                dz[s] = alpha * v - beta * (gamma * abs(v) * z + delta * v * az)
            else:
                dz[s] = alpha * v - beta * (gamma * abs(v) * az ** (nu - 1.0) * z + delta * v * az**nu)
            f = z
        if a >= 0:
            F[a] -= f
        if b >= 0:
            F[b] += f
    return u


@numba.njit(cache=False)
def _rhs(y, t, C, P):
    ndof, nz = int(P[4]), int(P[6])
    out = np.empty(y.size)
    F = out[ndof : 2 * ndof]
    dz = out[2 * ndof :]
    _forces(y, t, C, P, F, dz)
    for i in range(ndof):
        out[i] = y[ndof + i]
        out[ndof + i] *= P[_HEAD + i]
    return out


@numba.njit(cache=False)
def _accelerations(Y, t, C, P):
    ndof, nz = int(P[4]), int(P[6])
    A = np.empty((t.size, ndof))
    F = np.empty(ndof)
    dz = np.zeros(max(nz, 1))
    for k in range(t.size):
        _forces(Y[k], t[k], C, P, F, dz)
        for i in range(ndof):
            A[k, i] = F[i] * P[_HEAD + i]
    return A


def _compile(model: LumpedModel):
    names = model.dof_names
    idx = {n: i for i, n in enumerate(names)}
    idx[GROUND] = -1
    etype, ea, eb, ep, estate = [], [], [], [], []
    nz = 0
    for e in model.elements:
        p = np.zeros(5)
        if isinstance(e, Spring):
            code, p[0] = _SPRING, e.k
        elif isinstance(e, Damper):
            code, p[0] = _DAMPER, e.c
        elif isinstance(e, CubicSpring):
            code, p[0], p[1] = _CUBIC, e.k, e.k3
        elif isinstance(e, Backlash):
            code, p[0], p[1] = _BACKLASH, e.k, e.gap
        elif isinstance(e, Friction):
            code, p[0], p[1] = _FRICTION, e.force_, e.v_eps
        elif isinstance(e, BoucWen):
            code, p[:] = _BOUCWEN, (e.alpha, e.beta, e.gamma, e.delta, e.nu)
        else:
            raise ValueError(f"the truth integrator does not support element type {e.type!r}")
        etype.append(code)
        ea.append(idx[e.between[0]])
        eb.append(idx[e.between[1]])
        ep.append(p)
        estate.append(nz if code == _BOUCWEN else -1)
        nz += code == _BOUCWEN
    if len(model.inputs) != 1:
        raise ValueError("the truth integrator supports exactly one force input")
    inp = model.inputs[0]
    return dict(
        delay=float(inp.delay),
        sat=float(inp.saturation or 0.0),
        in_dof=int(idx[inp.dof]),
        minv=1.0 / np.array([d.mass for d in model.dofs]),
        etype=np.array(etype, np.int64),
        ea=np.array(ea, np.int64),
        eb=np.array(eb, np.int64),
        ep=np.array(ep, float).reshape(-1, 5),
        estate=np.array(estate, np.int64),
        nz=int(nz),
    )


@dataclass
class TruthRun:
    """States (n_t, 2 n_dofs + n_z), accelerations of every DOF (n_t, n_dofs), outputs
    (n_outputs, n_t), the applied force (n_t), and integrator statistics."""

    t: np.ndarray
    states: np.ndarray
    accelerations: np.ndarray
    outputs: np.ndarray
    applied_force: np.ndarray
    nfe: int
    seconds: float


def simulate_truth(
    model: LumpedModel,
    u: ContinuousInput,
    n_samples: int | None = None,
    *,
    scales: np.ndarray | None = None,
    rtol: float = RTOL,
) -> TruthRun:
    """Integrate `model` from rest under the continuous force `u` with LSODA and return the
    configured outputs at ``t_k = k / u.fs``, k < n_samples (default: the whole input).

    `scales`: typical magnitude of each state (absolute tolerance = rtol * scale); default
    from the linear part's response to `u`.
    """
    n = u.fine.size // u.oversample if n_samples is None else int(n_samples)
    t = np.arange(n) / u.fs
    cm = _compile(model)
    nd = model.n_dofs
    if scales is None:
        scales = _state_scales(model, u)
    atol = rtol * np.asarray(scales, float)
    E = np.column_stack([cm["etype"], cm["ea"], cm["eb"], cm["estate"], cm["ep"]]).astype(float).reshape(-1, _EW)
    P = np.concatenate([[u.fs_fine, cm["delay"], cm["sat"], cm["in_dof"], nd, E.shape[0], cm["nz"]], cm["minv"],
                        E.ravel()])
    args = (u.coeffs, P)
    y0 = np.zeros(2 * nd + cm["nz"])
    tic = time.perf_counter()
    Y, info = odeint(_rhs, y0, t, args=args, rtol=rtol, atol=atol, mxstep=200000, full_output=True)
    if info["message"] != "Integration successful.":
        raise RuntimeError(f"truth integration failed: {info['message']}")
    A = _accelerations(Y, t, *args)
    sec = time.perf_counter() - tic
    # applied force
    ts = t - cm["delay"]
    fa = np.where(ts < 0, 0.0, u(np.maximum(ts, 0.0)))
    if cm["sat"] > 0:
        fa = np.clip(fa, -cm["sat"], cm["sat"])
    rows = []
    for o in model.outputs:
        i = model.dof_index(o.dof)
        rows.append({"acceleration": A[:, i], "velocity": Y[:, nd + i], "displacement": Y[:, i]}[o.quantity])
    return TruthRun(t, Y, A, np.array(rows), fa, int(info["nfe"][-1]), sec)


def _state_scales(model: LumpedModel, u: ContinuousInput) -> np.ndarray:
    """RMS displacement and velocity of every DOF of the linear part (periodic FFT response
    to the logged input), Bouc-Wen state scale alpha * RMS relative displacement."""
    lin = _linear_part(model)
    x = u.coarse
    f = np.fft.rfftfreq(x.size, 1.0 / u.fs)
    U = np.fft.rfft(x)
    probe = replace(lin, outputs=tuple(Output(d, "displacement") for d in lin.dof_names),
                    inputs=(replace(lin.inputs[0], saturation=None, delay=0.0),))
    with np.errstate(all="ignore"):
        H = probe.frf(np.maximum(f, 1e-3), quantity="displacement")[:, :, 0]
    H[f < 0.5] = 0.0  # no static / rigid-body drift in the scale estimate
    X = np.fft.irfft(H * U[:, None], x.size, axis=0)
    xr = np.sqrt(np.mean(X**2, axis=0))
    vr = np.sqrt(np.mean(np.gradient(X, 1.0 / u.fs, axis=0) ** 2, axis=0))
    floor_x, floor_v = max(xr.max(), 1e-12) * 1e-2, max(vr.max(), 1e-12) * 1e-2
    sc = list(np.maximum(xr, floor_x)) + list(np.maximum(vr, floor_v))
    for e in model.elements:
        if isinstance(e, BoucWen):
            lv = model.element_vector(e)
            sc.append(max(e.alpha * np.sqrt(np.mean((X @ lv) ** 2)), 1e-12))
    return np.array(sc)


def _linear_part(model: LumpedModel) -> LumpedModel:
    """Springs and dampers of `model` plus a spring for the linear stiffness of each nonlinear
    element (used only for tolerance scales); a spring to ground when nothing restrains."""
    els = [e for e in model.elements if isinstance(e, (Spring, Damper))]
    for e in model.elements:
        if isinstance(e, Backlash):
            els.append(Spring(e.between, e.k))
        elif isinstance(e, BoucWen):
            els.append(Spring(e.between, max(e.alpha, 0.0)))
    return replace(model, elements=tuple(els))


def nrmse(y: np.ndarray, yhat: np.ndarray) -> float:
    """Pooled normalised RMS error ``sqrt(sum (y - yhat)^2) / sqrt(sum y^2)``."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    return float(np.sqrt(np.sum((y - yhat) ** 2)) / np.sqrt(np.sum(y**2)))


# ---------------------------------------------------------------------------------------------
# random nominal models
# ---------------------------------------------------------------------------------------------
def _chain_ends(n: int) -> list[tuple[str, str]]:
    return [("m1", GROUND)] + [(f"m{i + 1}", f"m{i}") for i in range(1, n)]


def _chain_model(masses, ks, cs, in_dof: str, name: str = "") -> LumpedModel:
    n = len(masses)
    dofs = tuple(Dof(f"m{i + 1}", float(m)) for i, m in enumerate(masses))
    els = []
    for (a, b), k, c in zip(_chain_ends(n), ks, cs):
        els += [Spring((a, b), float(k)), Damper((a, b), float(c))]
    outs = tuple(Output(d.name, "acceleration", output_channel(d.name)) for d in dofs)
    return LumpedModel(dofs, tuple(els), (Input(in_dof, "force", INPUT_CHANNEL),), outs, name)


def random_chain_model(rng: np.random.Generator, n_dofs: int | None = None, name: str = "") -> LumpedModel:
    """A random chain m1-ground, m2-m1, m3-m2 (1-3 DOFs): masses 0.5-5 kg, modes in 8-120 Hz
    at least 15 % apart, modal damping 1-4 % (dampers solved for drawn modal targets)."""
    n = int(rng.integers(1, 4)) if n_dofs is None else int(n_dofs)
    for _ in range(1000):
        masses = rng.uniform(0.5, 5.0, n)
        ks = masses * (2 * np.pi * np.exp(rng.uniform(np.log(8.0), np.log(120.0), n))) ** 2
        lin = _chain_model(masses, ks, np.zeros(n), "m1")
        w2, phi = _undamped_modes(lin)
        f = np.sqrt(w2) / (2 * np.pi)
        if f.min() < 8.0 or f.max() > 120.0 or (n > 1 and np.min(f[1:] / f[:-1]) < 1.15):
            continue
        # zeta_r ~ sum_i c_i (l_i . phi_r)^2 / (2 w_r m_r)
        L = np.array([lin.element_vector(e) for e in lin.elements if isinstance(e, Spring)])
        mr = np.einsum("ir,i,ir->r", phi, masses, phi)
        A = ((L @ phi) ** 2).T / (2 * np.sqrt(w2) * mr)[:, None]
        for _ in range(30):
            target = rng.uniform(0.012, 0.038, n)
            try:
                cs = np.linalg.solve(A, target)
            except np.linalg.LinAlgError:
                break
            if np.any(cs <= 0):
                continue
            model = _chain_model(masses, ks, cs, f"m{int(rng.integers(1, n + 1))}", name)
            modes = model.modes()
            if (len(modes) == n and np.all(modes.damping_ratios >= 0.01) and np.all(modes.damping_ratios <= 0.04)
                    and modes.natural_frequencies.min() >= 8.0 and modes.natural_frequencies.max() <= 120.0):
                return model
    raise RuntimeError("could not draw a chain model")  # pragma: no cover


def _undamped_modes(model: LumpedModel):
    from scipy.linalg import eigh

    w2, phi = eigh(np.asarray(model.K), np.asarray(model.M))
    return w2, phi


# ---------------------------------------------------------------------------------------------
# hidden effects
# ---------------------------------------------------------------------------------------------
def _pair(a: str, b: str) -> str:
    return f"{a}-{b}"


def _connection_elements(model: LumpedModel, ends):
    k = sum(e.k for e in model.elements if isinstance(e, Spring) and e.between == ends)
    c = sum(e.c for e in model.elements if isinstance(e, Damper) and e.between == ends)
    return k, c


def _with_elements(model: LumpedModel, add=(), replace_spring: tuple | None = None, new_spring=None) -> LumpedModel:
    els = []
    for e in model.elements:
        if replace_spring is not None and isinstance(e, Spring) and e.between == replace_spring:
            els.append(new_spring)
        else:
            els.append(e)
    return replace(model, elements=tuple(els) + tuple(add))


def _with_input(model: LumpedModel, **kw) -> LumpedModel:
    return replace(model, inputs=(replace(model.inputs[0], **kw),))


def _effect_builder(effect: str, nominal: LumpedModel, rng: np.random.Generator, ref: dict):
    """Draw the effect's configuration; return (build(s) -> (truth model, where, parameters,
    details), (s_lo, s_hi), stable(truth run, s) -> bool)."""
    n = nominal.n_dofs
    conns = _chain_ends(n)
    ends = conns[int(rng.integers(len(conns)))]
    k_c, c_c = _connection_elements(nominal, ends)
    lv = nominal.element_vector(Spring(ends, 1.0))
    d_rms = float(np.sqrt(np.mean((ref["states"][:, :n] @ lv) ** 2)))
    d_max = float(np.max(np.abs(ref["states"][:, :n] @ lv)))
    v_rms = float(np.sqrt(np.mean((ref["states"][:, n : 2 * n] @ lv) ** 2)))
    f_conn = float(np.sqrt(np.mean((ref["states"][:, :n] @ lv * k_c + ref["states"][:, n : 2 * n] @ lv * c_c) ** 2)))
    where_el = {"between": list(ends)}
    always = lambda run, s: True  # noqa: E731

    if effect == "parameter_mismatch":
        names = [f"m:{d.name}" for d in nominal.dofs]
        names += [f"k:{_pair(*e)}" for e in conns] + [f"c:{_pair(*e)}" for e in conns]
        count = int(rng.integers(1, 3)) if len(names) > 1 else 1
        chosen = [names[i] for i in rng.choice(len(names), count, replace=False)]
        signs = rng.choice([-1.0, 1.0], count)
        jitter = np.concatenate([[1.0], rng.uniform(0.8, 1.0, count - 1)])

        def build(s):
            masses = {d.name: d.mass for d in nominal.dofs}
            kk = {_pair(*e): _connection_elements(nominal, e)[0] for e in conns}
            cc = {_pair(*e): _connection_elements(nominal, e)[1] for e in conns}
            nominal_vals, true_vals, ratios = {}, {}, {}
            for nm, sg, j in zip(chosen, signs, jitter):
                kind, key = nm.split(":")
                table = {"m": masses, "k": kk, "c": cc}[kind]
                r = 1.0 + sg * max(s * j, 0.15)
                nominal_vals[nm] = table[key]
                table[key] = table[key] * r
                true_vals[nm] = table[key]
                ratios[nm] = r
            masses_l = [masses[d.name] for d in nominal.dofs]
            truth = _chain_model(masses_l, [kk[_pair(*e)] for e in conns], [cc[_pair(*e)] for e in conns],
                                 nominal.inputs[0].dof, nominal.name)
            return truth, {"parameters": list(chosen)}, true_vals, {"nominal": nominal_vals, "ratio": ratios}

        return build, (0.15, 0.40), always

    if effect == "extra_mode":
        attach = nominal.dof_names[int(rng.integers(n))]
        m_att = nominal.dofs[nominal.dof_index(attach)].mass
        fn = nominal.modes().natural_frequencies
        for _ in range(1000):
            f = float(np.exp(rng.uniform(np.log(8.0), np.log(120.0))))
            if np.all(np.abs(f - fn) >= 0.1 * fn):
                break
        zeta = float(rng.uniform(0.01, 0.04))

        def build(mu):
            me = mu * m_att
            k = me * (2 * np.pi * f) ** 2
            c = 2 * zeta * math.sqrt(k * me)
            dofs = nominal.dofs + (Dof("extra", me),)
            els = nominal.elements + (Spring(("extra", attach), k), Damper(("extra", attach), c))
            truth = replace(nominal, dofs=dofs, elements=els)
            params = {"mass_kg": me, "k_N_per_m": k, "c_N_s_per_m": c, "frequency_hz": f, "zeta": zeta}
            return truth, {"dof": attach, "frequency_hz": f}, params, {"mass_ratio": mu, "extra_dof": "extra"}

        return build, (0.03, 0.15), always

    if effect == "time_delay":

        def build(tau):
            return _with_input(nominal, delay=tau), {"side": "input"}, {"delay_s": tau}, {}

        return build, (1e-3, 15e-3), always

    if effect == "saturation":
        uf = ref["u"].fine
        a = np.abs(uf)
        pk = a[1:-1][(a[1:-1] >= a[:-2]) & (a[1:-1] > a[2:])]
        pk = np.sort(pk)[::-1]

        def build(p):
            limit = float(pk[max(int(round(p * pk.size)) - 1, 0)])
            return (_with_input(nominal, saturation=limit), {"side": "input"}, {"limit_N": limit},
                    {"clipped_peak_fraction": p, "input_peak_N": float(pk[0])})

        return build, (0.02, 0.30), always

    if effect == "coulomb_friction":

        def build(fc_rel):
            fc = fc_rel * f_conn
            truth = _with_elements(nominal, add=(Friction(ends, force_=fc, v_eps=V_EPS),))
            return truth, where_el, {"Fc_N": fc, "v_eps_m_per_s": V_EPS}, {"Fc_over_rms_connection_force": fc_rel}

        return build, (0.003, 0.6), always

    if effect == "backlash":

        def build(g_rel):
            gap = g_rel * d_rms
            truth = _with_elements(nominal, replace_spring=ends, new_spring=Backlash(ends, k=k_c, gap=gap))
            return truth, where_el, {"k_N_per_m": k_c, "gap_m": gap}, {"gap_over_rms_deflection": g_rel}

        return build, (0.01, 2.0), always

    if effect == "hysteresis":
        gamma = float(rng.uniform(0.3, 0.9))
        delta = 1.0 - gamma + float(rng.uniform(-0.2, 0.2))
        c_y = float(rng.uniform(0.2, 1.0))  # yield displacement / rms deflection
        beta = 1.0 / ((gamma + delta) * c_y * d_rms)

        def build(a_rel):
            alpha = a_rel * k_c
            truth = _with_elements(nominal, add=(BoucWen(ends, alpha=alpha, beta=beta, gamma=gamma, delta=delta, nu=1.0),))
            params = {"alpha_N_per_m": alpha, "beta_per_m": beta, "gamma": gamma, "delta": delta, "nu": 1.0}
            return truth, where_el, params, {"alpha_over_k": a_rel, "yield_over_rms_deflection": c_y}

        return build, (0.01, 1.5), always

    if effect == "cubic_stiffness":
        sign = float(rng.choice([-1.0, 1.0]))
        ratio = d_max / max(d_rms, 1e-300)
        hi = 3.0 if sign > 0 else 0.45 / (3.0 * ratio**2)

        def build(r):
            k3 = sign * r * k_c / d_rms**2
            truth = _with_elements(nominal, add=(CubicSpring(ends, k3=k3, k=0.0),))
            return truth, where_el, {"k3_N_per_m3": k3}, {"k3_d_rms2_over_k": sign * r}

        def stable(run, r):
            if sign > 0:
                return True
            k3 = r * k_c / d_rms**2
            d_star = math.sqrt(k_c / (3.0 * k3))  # softening: tangent stiffness of the connection vanishes
            d = run.states[:, :n] @ lv
            return bool(np.all(np.isfinite(d)) and np.max(np.abs(d)) < 0.8 * d_star)

        return build, (1e-3 * hi, hi), stable

    raise ValueError(f"unknown effect {effect!r}")


def _calibrate(build, bounds, stable, target, u, n_cal, y_nom_cal, scales, max_iter=7):
    """Strength s in bounds (geometric) whose calibration-window gap is close to `target`
    (gap assumed increasing in s). Returns (s, gap) or (s_hi, gap) when even s_hi falls short."""

    def gap_at(s):
        truth = build(s)[0]
        try:
            run = simulate_truth(truth, u, n_cal, scales=_scales_for(truth, scales), rtol=RTOL_CAL)
        except RuntimeError:
            return math.inf
        if not stable(run, s) or not np.all(np.isfinite(run.outputs)):
            return math.inf
        return nrmse(run.outputs, y_nom_cal)

    lo, hi = bounds
    g_hi = gap_at(hi)
    while not math.isfinite(g_hi) and hi > lo * 1.01:  # unstable at the top: shrink
        hi = math.sqrt(hi * lo) if hi / lo > 4 else lo
        g_hi = gap_at(hi)
    if g_hi <= target:
        return hi, g_hi
    g_lo = gap_at(lo)
    if g_lo >= target:
        return lo, g_lo
    s, g = hi, g_hi
    llo, lhi, glo, ghi = math.log(lo), math.log(hi), math.log(max(g_lo, 1e-12)), math.log(g_hi)
    lt = math.log(target)
    for _ in range(max_iter):
        # interpolate in log-log, guarded towards bisection
        w = (lt - glo) / (ghi - glo) if ghi > glo else 0.5
        w = min(max(w, 0.1), 0.9)
        ls = llo + w * (lhi - llo)
        s = math.exp(ls)
        g = gap_at(s)
        if not math.isfinite(g):
            lhi, ghi = ls, math.log(1e3)
            continue
        if abs(math.log(g) - lt) < 0.12:
            break
        if g < target:
            llo, glo = ls, math.log(g)
        else:
            lhi, ghi = ls, math.log(g)
    if not math.isfinite(g):
        s, g = math.exp(llo), math.exp(glo)
    return s, g


def _scales_for(truth: LumpedModel, nominal_scales: np.ndarray) -> np.ndarray:
    """Tolerance scales for `truth`: the nominal DOFs' scales; an extra DOF gets the largest;
    Bouc-Wen states alpha times the largest displacement scale."""
    nd_nom = (len(nominal_scales)) // 2
    xs, vs = list(nominal_scales[:nd_nom]), list(nominal_scales[nd_nom : 2 * nd_nom])
    while len(xs) < truth.n_dofs:
        xs.append(max(xs))
        vs.append(max(vs))
    sc = xs + vs
    for e in truth.elements:
        if isinstance(e, BoucWen):
            sc.append(max(e.alpha * max(xs), 1e-12))
    return np.array(sc)


# ---------------------------------------------------------------------------------------------
# a case
# ---------------------------------------------------------------------------------------------
@dataclass
class Case:
    nominal: LumpedModel
    truth_model: LumpedModel
    u: ContinuousInput
    outputs: np.ndarray  # noisy, (n_outputs, n)
    outputs_clean: np.ndarray
    truth: dict

    def signals(self):
        from vibroscope.signals import Signals

        data = np.vstack([self.u.coarse[None, : self.outputs.shape[1]], self.outputs])
        chans = self.nominal.input_channels() + self.nominal.output_channels()
        units = ["N"] + ["m/s^2"] * self.outputs.shape[0]
        return Signals(data=data, fs=self.u.fs, channels=chans, units=units, t0=T0_LOG)


def case_rng(seed: int, effect: str, index: int) -> np.random.Generator:
    """The generator of case `index` of class `effect` (independent of the other classes)."""
    return np.random.default_rng([int(seed), EFFECTS.index(effect), int(index)])


def make_case(effect: str, rng: np.random.Generator, duration: float = 60.0) -> Case:
    """Draw one case of class `effect` (see the module docstring)."""
    if effect not in EFFECTS:
        raise ValueError(f"effect={effect!r} must be one of {EFFECTS}")
    tic = time.perf_counter()
    n = int(round(duration * FS))
    n_cal = min(n, int(round(CAL_SECONDS * FS)))
    for attempt in range(8):
        nominal = random_chain_model(rng)
        f_max = float(nominal.modes().natural_frequencies.max())
        kind = str(rng.choice(["random", "multisine"]))
        f_hi = float(rng.uniform(max(150.0, 1.25 * f_max), 280.0))
        u = make_input(rng, duration, kind=kind, f_hi=f_hi)
        # scale the force so that the pooled output RMS is 5-20 m/s^2
        scales = _state_scales(nominal, u)
        probe = nominal.frf(np.fft.rfftfreq(n, 1 / FS))[:, :, 0]
        Y = np.fft.irfft(probe * np.fft.rfft(u.coarse)[:, None], n, axis=0)
        a_target = float(np.exp(rng.uniform(np.log(5.0), np.log(20.0))))
        gain = a_target / np.sqrt(np.mean(Y**2))
        u = u.scaled(gain)
        u.info["rms_N"] = float(np.sqrt(np.mean(u.coarse**2)))
        scales = scales * gain
        nom = simulate_truth(nominal, u, n, scales=scales)
        ref = {"states": nom.states[:n_cal], "u": u}
        if effect == "none":
            truth_model, where, params, details, gap_cal = nominal, {}, {}, {}, 0.0
            strength = None
            run = nom
            break
        target = float(rng.uniform(0.12, 0.45))
        build, bounds, stable = _effect_builder(effect, nominal, rng, ref)
        strength, gap_cal = _calibrate(build, bounds, stable, target, u, n_cal, nom.outputs[:, :n_cal], scales)
        if gap_cal < GAP_MIN or not math.isfinite(gap_cal):
            continue  # too weak (or unstable) even at full strength: draw another case
        if not (GAP_AIM[0] <= gap_cal <= GAP_AIM[1]) and attempt < 3:
            continue  # outside the aimed spread at the bounds of the strength range: redraw (3 tries)
        truth_model, where, params, details = build(strength)
        run = simulate_truth(truth_model, u, n, scales=_scales_for(truth_model, scales))
        gap = nrmse(run.outputs, nom.outputs)
        grow = 0
        while gap < GAP_MIN and grow < 3 and strength < bounds[1]:
            strength = min(strength * 1.4, bounds[1])
            truth_model, where, params, details = build(strength)
            run = simulate_truth(truth_model, u, n, scales=_scales_for(truth_model, scales))
            gap = nrmse(run.outputs, nom.outputs)
            grow += 1
        if gap >= GAP_MIN and stable(run, strength) and np.all(np.isfinite(run.outputs)):
            details = dict(details, target_gap=target)
            break
    else:
        raise RuntimeError(f"could not draw a {effect} case with a gap >= {GAP_MIN}")
    gap = nrmse(run.outputs, nom.outputs)
    clean = run.outputs
    noise_rel = float(rng.uniform(0.01, 0.03))
    rms = np.sqrt(np.mean(clean**2, axis=1))
    noisy = clean + noise_rel * rms[:, None] * rng.standard_normal(clean.shape)
    truth = {
        "effect": effect,
        "where": where,
        "parameters": {k: float(v) for k, v in params.items()},
        "details": _jsonable(details),
        "strength": strength,
        "truth_model": dumps_model(truth_model),
        "noise": {"relative_rms": noise_rel, "sigma": [float(s) for s in noise_rel * rms]},
        "input": _jsonable(u.info),
        "gap_nominal_noise_free": gap,
        "gap_nominal_noisy": nrmse(noisy, nom.outputs),
        "gap_calibration_window": float(gap_cal),
        "duration_s": n / FS,
        "n_dofs": nominal.n_dofs,
        "nominal_modes_hz": [float(x) for x in nominal.modes().natural_frequencies],
        "nominal_damping": [float(x) for x in nominal.modes().damping_ratios],
        "attempts": attempt + 1,
        "integrator": {"method": "scipy.integrate.odeint (LSODA)", "rtol": RTOL, "nfe": run.nfe},
        "generation_s": time.perf_counter() - tic,
    }
    return Case(nominal, truth_model, u, noisy, clean, truth)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    return x


def write_case(out: Path, name: str, case: Case) -> None:
    """``out/cases/<name>/{nominal.toml, log.mcap}`` and ``out/truth/<name>.json``."""
    from vibroscope.io import write_ros2_mcap

    cdir = Path(out) / "cases" / name
    cdir.mkdir(parents=True, exist_ok=True)
    (cdir / "nominal.toml").write_text(dumps_model(case.nominal), encoding="utf-8")
    write_ros2_mcap(cdir / "log.mcap", case.signals())
    tdir = Path(out) / "truth"
    tdir.mkdir(parents=True, exist_ok=True)
    (tdir / f"{name}.json").write_text(json.dumps(dict(case.truth, case=name), indent=2) + "\n", encoding="utf-8")


def _one(job):
    out, name, effect, seed, index, duration = job
    tic = time.perf_counter()
    case = make_case(effect, case_rng(seed, effect, index), duration)
    case.truth["seed"] = {"seed": seed, "class_index": index}
    write_case(Path(out), name, case)
    return name, effect, case.truth["gap_nominal_noise_free"], time.perf_counter() - tic


def generate(out, per_class: int = 10, classes=EFFECTS, seed: int = 0, duration: float = 60.0, jobs: int = 1,
             verbose: bool = False) -> list[tuple]:
    """Generate ``per_class`` cases of every class into `out`; cases are interleaved by class
    (case_000 = first class, case_001 = second class, ...). Returns (name, effect, gap, s)."""
    out = Path(out)
    classes = list(classes)
    for c in classes:
        if c not in EFFECTS:
            raise ValueError(f"unknown class {c!r}; classes are {EFFECTS}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "generate.json").write_text(json.dumps({"per_class": per_class, "classes": classes, "seed": seed,
                                                   "duration": duration}, indent=2) + "\n")
    jobs_list = []
    for j in range(per_class):
        for c in classes:
            jobs_list.append((str(out), f"case_{len(jobs_list):03d}", c, seed, j, duration))
    results = []
    if jobs > 1:
        import multiprocessing as mp

        # fork: the workers inherit this module however it was loaded (script or test import)
        ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
        with ctx.Pool(jobs) as pool:
            for r in pool.imap(_one, jobs_list):
                results.append(r)
                if verbose:
                    print(f"{r[0]}  {r[1]:<20s} gap {r[2]:.3f}  {r[3]:.1f} s", flush=True)
    else:
        for job in jobs_list:
            r = _one(job)
            results.append(r)
            if verbose:
                print(f"{r[0]}  {r[1]:<20s} gap {r[2]:.3f}  {r[3]:.1f} s", flush=True)
    return results


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=Path, help="output folder")
    p.add_argument("--per-class", type=int, default=10, help="cases per class (default 10)")
    p.add_argument("--classes", nargs="+", default=list(EFFECTS), choices=EFFECTS, metavar="CLASS",
                   help=f"classes to generate (default all: {' '.join(EFFECTS)})")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=60.0, help="record length in s (default 60)")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    a = p.parse_args(argv)
    tic = time.perf_counter()
    res = generate(a.out, a.per_class, a.classes, a.seed, a.duration, a.jobs, verbose=True)
    times = [r[3] for r in res]
    print(f"{len(res)} cases in {time.perf_counter() - tic:.1f} s "
          f"(per case: median {np.median(times):.1f} s, max {np.max(times):.1f} s) -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
