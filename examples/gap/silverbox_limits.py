"""What limits a physical model of the Silverbox (Wigren & Schoukens 2013)?

The circuit emulates ``m y'' + d y' + a y + b y^3 = u``. This script fits variants of that
physical model by output error (simulation error) on the whole estimation part (samples
40 650-127 400) and reports each variant's RMS simulation error (mV) on the arrow part
(samples 100-40 575, the first ``--skip`` samples left out as in the gap diagnosis'
validation mask):

* ``cubic``: m, d, a, b3 (the exported gap model's structure), fitted jointly;
* ``quad``: + b2 y^2 (asymmetric restoring force);
* ``quad+off``, ``cubic+off``, ``cubic+u0``, ``quad+y0``: + input offset u0 (the circuit
  driven by ``u - u0``) and/or output offset y0 (added to the prediction);
* ``quad+off+delay``: + a fractional input delay (0-2 samples);
* the ``quad+off`` parameters at 10 / 40 sub-steps (default 20) and with the output sampled
  instead of FIR-decimated (integrator accuracy);
* ``ZOH``: the input held between samples instead of band-limited, then refitted.

The simulations use a small compiled RK4 kernel (20 sub-steps per sample, outputs decimated
by :func:`vibroscope.models.resample.decimate_fir`) driven by vibroscope's band-limited
input reconstruction (:func:`vibroscope.models.resample.upsample`, the simulator's own),
so that a quadratic term, which the model file cannot express, can be tried.
``--refine`` fits the cubic model with and without offsets with
:func:`vibroscope.gap.refine.refine_model`, i.e. vibroscope's own simulator (trapezoidal
kernel), started from the gap diagnosis' exported cubic model.

Finding: the 5.3 mV of the cubic model come from a DC bias of the input (about 5.3 mV);
with it fitted the arrow error is 0.46 mV (0.39 mV with an output offset too, the same as a
quadratic term plus an output offset).

    python examples/gap/silverbox_limits.py [--data ../shared/data/silverbox] [--json out.json]
    python examples/gap/silverbox_limits.py --refine [cubic] [cubic+u0] [cubic+u0+y0] [--seconds S] [--max-nfev N] [--fast]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import time
from pathlib import Path

import numba
import numpy as np
from scipy.optimize import least_squares

HERE = Path(__file__).resolve().parent


def _sb():
    spec = importlib.util.spec_from_file_location("gap_example_silverbox", HERE / "silverbox.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


SB = _sb()
FS = SB.FS


@numba.njit(cache=True)
def _rk4(U, dt, m, d, a, b2, b3, y00, v00):
    """RK4 of ``m y'' + d y' + a y + b2 y^2 + b3 y^3 = u`` on the fine input `U` (linear between
    fine samples); returns y at every fine sample."""
    n = U.shape[0]
    y = np.empty(n)
    x = y00
    v = v00
    y[0] = x
    im = 1.0 / m
    for i in range(n - 1):
        u0 = U[i]
        u1 = U[i + 1]
        uh = 0.5 * (u0 + u1)
        k1x = v
        k1v = (u0 - d * v - x * (a + x * (b2 + b3 * x))) * im
        xx = x + 0.5 * dt * k1x
        vv = v + 0.5 * dt * k1v
        k2x = vv
        k2v = (uh - d * vv - xx * (a + xx * (b2 + b3 * xx))) * im
        xx = x + 0.5 * dt * k2x
        vv = v + 0.5 * dt * k2v
        k3x = vv
        k3v = (uh - d * vv - xx * (a + xx * (b2 + b3 * xx))) * im
        xx = x + dt * k3x
        vv = v + dt * k3v
        k4x = vv
        k4v = (u1 - d * vv - xx * (a + xx * (b2 + b3 * xx))) * im
        x = x + dt / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v = v + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        if not (abs(x) < 1e6):
            for j in range(i + 1, n):
                y[j] = np.nan
            return y
        y[i + 1] = x
    return y


class Sim:
    """One record's input, reconstructed once on the fine grid (R sub-steps per sample).

    recon: "poly" (band-limited, vibroscope's simulator), "zoh" (held), "linear".
    out: "decimate" (vibroscope's FIR decimation) or "sample" (every R-th fine sample).
    """

    def __init__(self, u, R=20, recon="poly", out="decimate"):
        from vibroscope.models.resample import upsample

        self.u = np.asarray(u, float)
        self.R = R
        self.out = out
        if recon == "zoh":
            self.U = np.repeat(self.u, R)
        else:
            self.U = upsample(self.u[None], R, method=recon)[0]
        self.dt = 1.0 / (FS * R)

    def run(self, m, d, a, b2=0.0, b3=0.0, u0=0.0, y0=0.0, delay=0.0):
        """Output (V) at the samples; `delay` in samples (>= 0, input shifted on the fine grid)."""
        from vibroscope.models.resample import decimate_fir

        U = self.U - u0
        if delay:
            t = np.arange(U.size) - delay * self.R
            U = np.interp(t, np.arange(U.size), U)
        # static equilibrium of the offset force as the initial state (no start transient)
        yi = _equilibrium(U[0], a, b2, b3) if u0 else 0.0
        yf = _rk4(U, self.dt, m, d, a, b2, b3, yi, 0.0)
        if not np.all(np.isfinite(yf)):
            return np.full(self.u.size, np.nan)
        y = decimate_fir(yf, self.R) if (self.out == "decimate" and self.R > 1) else yf[:: self.R]
        return y[: self.u.size] + y0


def _equilibrium(f, a, b2, b3):
    r = np.roots([b3, b2, a, -f])
    r = r[np.abs(r.imag) < 1e-12].real
    return float(r[np.argmin(np.abs(r))]) if r.size else 0.0


NAMES = ("m", "d", "a", "b2", "b3", "u0", "y0", "delay")


def fit(sim, y, mask, p0, free, *, max_nfev=200, scale=None, verbose=0):
    """Output-error fit of the parameters named in `free` (others fixed at `p0`).

    Parameters are fitted as multiples of `scale` (default: |p0| or 1e-3 for zeros).
    Returns (params dict, sol, seconds, n_sims)."""
    p0 = dict(p0)
    scale = scale or {}
    sc = np.array([scale.get(k, abs(p0[k]) if p0[k] else 1e-3) for k in free])
    x0 = np.array([p0[k] for k in free]) / sc
    lo = np.full(len(free), -np.inf)
    hi = np.full(len(free), np.inf)
    for i, k in enumerate(free):
        if k in ("m", "d", "a"):
            lo[i] = 1e-6 * x0[i]
        if k == "delay":
            lo[i], hi[i] = 0.0, 2.0 / sc[i]
    x0 = np.clip(x0, lo + 1e-12, hi - 1e-12)
    den = math.sqrt(np.sum(y[mask] ** 2))
    cnt = [0]

    def params(x):
        p = dict(p0)
        for i, k in enumerate(free):
            p[k] = x[i] * sc[i]
        return p

    def res(x):
        cnt[0] += 1
        yh = sim.run(**params(x))
        r = (y - yh)[mask] / den
        if not np.all(np.isfinite(r)):
            r = np.full(int(mask.sum()), 10.0 / math.sqrt(mask.sum()))
        return r

    t = time.perf_counter()
    sol = least_squares(res, x0, bounds=(lo, hi), method="trf", x_scale=1.0, diff_step=1e-6,
                        max_nfev=max_nfev, verbose=verbose)
    return params(sol.x), sol, time.perf_counter() - t, cnt[0]


def rms_mv(y, yh, mask):
    return 1e3 * float(np.sqrt(np.mean((y - yh)[mask] ** 2)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=HERE.parents[2] / "shared" / "data" / "silverbox")
    ap.add_argument("--skip", type=int, default=87, help="arrow samples left out at its start (diagnosis: 3 tau)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--quick", action="store_true", help="only the cubic and quad+off variants")
    ap.add_argument("--refine", nargs="*", choices=("cubic", "cubic+u0", "cubic+u0+y0"),
                    help="only these variants of the cubic model (default all three), fitted by "
                         "vibroscope.gap.refine_model with vibroscope's simulator")
    ap.add_argument("--seconds", type=float, help="--refine: fit on the first SECONDS of the estimation part only")
    ap.add_argument("--max-nfev", type=int, default=50, help="--refine: least_squares' max_nfev (default 50)")
    ap.add_argument("--fast", action="store_true", help="--refine: the screening integration accuracy")
    a = ap.parse_args(argv)
    if a.refine is not None:
        res = refine_demo(a.data, a.skip, tuple(a.refine) or ("cubic", "cubic+u0", "cubic+u0+y0"),
                          max_nfev=a.max_nfev, seconds=a.seconds, fast=a.fast)
        if a.json:
            a.json.write_text(json.dumps(res, indent=1))
        return 0

    v1, v2 = SB.load(a.data)
    ue, ye = v1[SB.EST], v2[SB.EST]
    ua, ya = v1[SB.ARROW], v2[SB.ARROW]
    me = np.ones(ue.size, bool)
    me[:200] = False
    ma = np.ones(ua.size, bool)
    ma[: a.skip] = False
    print(f"estimation: {ue.size} samples, arrow: {ua.size} samples (RMS {1e3 * ya[ma].std():.2f} mV), "
          f"input means est {1e3 * ue.mean():.3f} mV arrow {1e3 * ua.mean():.3f} mV, "
          f"output means est {1e3 * ye.mean():.3f} mV arrow {1e3 * ya.mean():.3f} mV")

    rows = []

    def report(name, p, se, sa, secs=None, nsim=None):
        yh = sa.run(**p)
        e = rms_mv(ya, yh, ma)
        ef = rms_mv(ye, se.run(**p), me)
        rows.append({"variant": name, "arrow_mV": e, "est_mV": ef, "params": p, "fit_s": secs, "n_sims": nsim})
        extra = f" fit {secs:.1f} s, {nsim} sims" if secs is not None else ""
        print(f"{name:28s} arrow {e:6.3f} mV  est {ef:6.3f} mV {extra}\n    "
              + ", ".join(f"{k}={v:.6g}" for k, v in p.items() if v), flush=True)
        return e

    # start: a from the low-frequency gain, m from the resonance, 5 % damping (as silverbox.py)
    se, sa = Sim(ue), Sim(ua)
    start = {k: 0.0 for k in NAMES}
    start.update(_linear_start(ue, ye))
    p_cubic, sol, secs, n = fit(se, ye, me, start, ("m", "d", "a", "b3"), scale={"b3": start["a"] * 10})
    report("cubic (m,d,a,b3)", p_cubic, se, sa, secs, n)
    p_quad, sol, secs, n = fit(se, ye, me, p_cubic, ("m", "d", "a", "b2", "b3"), scale={"b2": start["a"]})
    report("quad (m,d,a,b2,b3)", p_quad, se, sa, secs, n)
    p_qo, sol, secs, n = fit(se, ye, me, p_quad, ("m", "d", "a", "b2", "b3", "u0", "y0"),
                             scale={"b2": start["a"], "u0": 1e-3, "y0": 1e-3})
    report("quad+off (+u0,y0)", p_qo, se, sa, secs, n)
    if not a.quick:
        p_co, sol, secs, n = fit(se, ye, me, p_cubic, ("m", "d", "a", "b3", "u0", "y0"),
                                 scale={"u0": 1e-3, "y0": 1e-3})
        report("cubic+off (+u0,y0)", p_co, se, sa, secs, n)
        p_cu, sol, secs, n = fit(se, ye, me, p_cubic, ("m", "d", "a", "b3", "u0"), scale={"u0": 1e-3})
        report("cubic+u0", p_cu, se, sa, secs, n)
        p_qy, sol, secs, n = fit(se, ye, me, p_quad, ("m", "d", "a", "b2", "b3", "y0"),
                                 scale={"b2": start["a"], "y0": 1e-3})
        report("quad+y0", p_qy, se, sa, secs, n)
        p_qd, sol, secs, n = fit(se, ye, me, {**p_qo, "delay": 0.1},
                                 ("m", "d", "a", "b2", "b3", "u0", "y0", "delay"),
                                 scale={"b2": start["a"], "u0": 1e-3, "y0": 1e-3, "delay": 0.1})
        report("quad+off+delay", p_qd, se, sa, secs, n)
        # integrator accuracy: the quad+off parameters at 10 / 40 sub-steps, and sampled output
        for R in (10, 40):
            report(f"quad+off, R={R} (no refit)", p_qo, Sim(ue, R), Sim(ua, R))
        report("quad+off, sampled out", p_qo, Sim(ue, out="sample"), Sim(ua, out="sample"))
        # zero-order hold of the input (refitted)
        sez, saz = Sim(ue, recon="zoh"), Sim(ua, recon="zoh")
        report("quad+off, ZOH (no refit)", p_qo, sez, saz)
        p_z, sol, secs, n = fit(sez, ye, me, p_qo, ("m", "d", "a", "b2", "b3", "u0", "y0"),
                                scale={"b2": start["a"], "u0": 1e-3, "y0": 1e-3})
        report("quad+off, ZOH (refit)", p_z, sez, saz, secs, n)
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


def cubic_model(m, d, a, b3):
    """The gap diagnosis' exported structure: mass, spring, damper and cubic spring to ground."""
    from vibroscope.models.elements import CubicSpring, Damper, Spring
    from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

    return LumpedModel(
        dofs=(Dof("m1", m),),
        elements=(Spring(("m1", "ground"), k=a), Damper(("m1", "ground"), c=d), CubicSpring(("m1", "ground"), k3=b3)),
        inputs=(Input(dof="m1", channel=SB.IN_CH),),
        outputs=(Output("m1", "displacement", SB.OUT_CH),),
        name="Silverbox cubic",
    )


def refine_demo(data: Path, skip: int, which=("cubic", "cubic+u0", "cubic+u0+y0"),
                start=(5.487e-6, 2.2526e-4, 1.01098, 4.0746), max_nfev=50, seconds=None, fast=False) -> dict:
    """The cubic model (m, d, a, b3) and an input offset fitted with
    :func:`vibroscope.gap.refine.refine_model` (vibroscope's own simulator) on the whole
    estimation part; arrow error with :func:`vibroscope.gap.refine.simulate_with_offsets`.
    Default start: the gap diagnosis' exported cubic model."""
    from vibroscope.gap.fit import LogSimulator
    from vibroscope.gap.refine import refine_model, simulate_with_offsets

    v1, v2 = SB.load(data)
    ue, ye = v1[SB.EST][None], v2[SB.EST][None]
    ua, ya = v1[SB.ARROW][None], v2[SB.ARROW][None]
    me = np.ones(ue.shape[1], bool)
    me[:200] = False
    ma = np.ones(ua.shape[1], bool)
    ma[:skip] = False
    p0 = np.asarray(start, float)

    def build(x):
        return cubic_model(*(p0 * x))

    out = {}
    variants = {"cubic": (False, False), "cubic+u0": (True, False), "cubic+u0+y0": (True, True)}
    for name in which:
        off, yoff = variants[name]
        c = time.process_time()
        ns = None if seconds is None else [min(ue.shape[1], int(seconds * FS))]
        r = refine_model(build, np.ones(4), np.full(4, 0.2), np.full(4, 5.0), [LogSimulator(ue, FS)], [ye], [me], ns,
                         input_offset=off, output_offset=yoff, max_nfev=max_nfev, fast=fast)
        cpu = time.process_time() - c
        ya_h = simulate_with_offsets(LogSimulator(ua, FS), r.model, input_offset=r.input_offset,
                                     output_offset=r.output_offset)
        e = rms_mv(ya[0], ya_h[0], ma)
        p = dict(zip(("m", "d", "a", "b3"), (p0 * r.x).tolist()))
        p["u0"] = float(r.input_offset[0])
        p["y0"] = float(r.output_offset[0])
        name = "refine_model " + name
        print(f"{name:32s} arrow {e:6.3f} mV  est nrmse {r.nrmse:.5f}  fit {r.seconds:.1f} s wall, {cpu:.1f} s CPU, nfev {r.nfev}, "
              f"{r.n_sims} sims, status {r.status}\n    " + ", ".join(f"{k}={v:.6g}" for k, v in p.items()), flush=True)
        out[name] = {"arrow_mV": e, "params": p, "fit_s": r.seconds, "cpu_s": cpu, "nfev": r.nfev, "n_sims": r.n_sims}
    return out


def _linear_start(u, y):
    from scipy import signal

    f, Pxy = signal.csd(u, y, fs=FS, nperseg=4096)
    _, Pxx = signal.welch(u, fs=FS, nperseg=4096)
    H = Pxy / Pxx
    band = (f > 5) & (f < 150)
    f0 = f[band][np.argmax(np.abs(H[band]))]
    k = 1.0 / np.abs(H[(f > 1) & (f < 10)]).mean()
    m = k / (2 * np.pi * f0) ** 2
    return {"m": m, "d": 2 * 0.05 * math.sqrt(k * m), "a": k}


if __name__ == "__main__":
    raise SystemExit(main())
