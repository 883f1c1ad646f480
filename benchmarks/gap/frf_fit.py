"""The gap diagnosis's FRF fit (``fit_linear_frf``): analytic Jacobian against scipy's forward
differences, measured in the same run on the same problems.

    python benchmarks/gap/frf_fit.py [--repeat 3]

The problems are the fits the diagnosis makes for its linear effects: a 3-DOF chain's linear
log-factors (9) fitted jointly with an input delay (1 parameter, 3 starts) and with an extra mode at
each DOF (3 parameters, 2 starts), to an FRF measured on a truth with a 1.2 ms delay and a tuned
absorber (5 % multiplicative noise), 600 lines, 60 evaluations per start as in the diagnosis
(``LIN_EFFECT_NFEV``). Printed: the best-of-`repeat` seconds of each, their ratio, and how far the
two fits' costs and parameters are apart (the Jacobian changes the path, not the problem).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def problems():
    from vibroscope.gap._run import LIN_EFFECT_NFEV
    from vibroscope.gap.effects import LinearParams, candidate_specs
    from vibroscope.models.elements import Damper, Spring
    from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

    nominal = LumpedModel.chain([3.9, 0.8, 2.9], [1.8e6, 2.4e5, 9.3e3], [110.0, 28.0, 6.1], input_dof=0)
    nominal = nominal.replace(outputs=tuple(Output(d, "acceleration", f"/imu/{d}.x") for d in ("m1", "m2", "m3")))
    truth = nominal.replace(
        dofs=nominal.dofs + (Dof("absorber", 0.3),),
        elements=nominal.elements + (Spring(("absorber", "m2"), k=0.3 * (2 * np.pi * 45.0) ** 2),
                                     Damper(("absorber", "m2"), c=2 * 0.03 * 0.3 * 2 * np.pi * 45.0)),
        inputs=(Input(dof="m1", channel=nominal.inputs[0].channel, delay=0.0012),))
    f = np.linspace(2.0, 300.0, 600)
    rng = np.random.default_rng(54)
    H = truth.frf(f, quantity=None)[:, :, 0] * (1 + 0.05 * (rng.standard_normal((f.size, 3))
                                                            + 1j * rng.standard_normal((f.size, 3))))
    w = np.ones(H.shape)
    lin = LinearParams(nominal)
    specs = candidate_specs(nominal, {"fs": 1000.0, "f_extra": [40.0]}, ["time_delay", "extra_mode"])
    return nominal, lin, f, H, w, specs, LIN_EFFECT_NFEV


def run(jacobian: str, nominal, lin, f, H, w, specs, nfev):
    from vibroscope.gap.fit import fit_linear_frf

    out = []
    for s in specs:
        _, th, p, cost = fit_linear_frf(nominal, lin, f, H, w, spec=s, p_starts=s.starts, max_nfev=nfev,
                                        jacobian=jacobian)
        out.append((s.label, cost, np.concatenate([th, p])))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    prob = problems()
    best = {}
    res = {}
    for _ in range(a.repeat):
        for jac in ("analytic", "2-point"):
            t = time.perf_counter()
            res[jac] = run(jac, *prob)
            best[jac] = min(best.get(jac, np.inf), time.perf_counter() - t)
    print(f"{len(prob[5])} fits (delay, extra mode at each DOF), {len(prob[1])} linear log-factors each")
    for jac in best:
        print(f"  {jac:9s} {best[jac]:.3f} s (best of {a.repeat})")
    print(f"  ratio     {best['2-point'] / best['analytic']:.2f}x faster with the analytic Jacobian")
    for (lab, c1, x1), (_, c2, x2) in zip(res["analytic"], res["2-point"]):
        print(f"  {lab:28s} cost {c1:.6g} vs {c2:.6g} (rel. {abs(c1 - c2) / max(c2, 1e-300):.1e}), "
              f"max |dx| {np.max(np.abs(x1 - x2)):.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
