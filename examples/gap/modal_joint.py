"""A bolted joint behind a modal test: ``modal --export-model`` -> ``gap``, end to end.

A 3-DOF chain stands for a ground vibration test: a body ``m1`` (8 kg) on its support, a wing
``m2`` (3 kg) and a payload ``m3`` (1.5 kg) bolted to it. The wing-payload joint is an Iwan
element: a share of the m2-m3 spring in series with four Jenkins sliders whose slip forces
are spread up to ``F_max`` (Iwan 1966; Segalman 2005), stiff at low amplitude, softer and
more damped as the bolts slip. A shaker drives the wing; accelerometers sit on the three
masses (the wing's is the driving point).

Writes in ``OUT``:

* ``low.mcap``: 60 s of band-limited random force at a low level (the joint barely slips),
  the modal test;
* ``levels_1.mcap``, ``levels_2.mcap``, ``levels_3.mcap``: 20 s each at 1, 2.5 and 6 times a
  level where the joint slips;
* ``truth.json``: the joint's place and parameters.

Then it runs the two commands an engineer would, and prints the verdict:

    vibroscope modal OUT/low.mcap --input /actuator/force.wrench.force.x --export-model OUT/modal.toml
    vibroscope gap OUT/modal.toml OUT/levels_1.mcap OUT/levels_2.mcap OUT/levels_3.mcap --json OUT/gap.json

With ``--clearance GAP`` the joint also has free play: a contact spring of the joint's slipping
stiffness acts beyond +-GAP m (a bolt in a clearance hole: it slips, then bears), so the joint
is a friction and a clearance together, as the aircraft's wing-payload joint of issue #18.

The nominal is the identified modal model, not an exact one: three modes, their residues, and
the driving point found from them. A modal model has no spring at the joint to let slip; the
diagnosis takes a fitted share of the static stiffness across the two measured points out of
the modes (``signed_spring``) and puts the Jenkins or Iwan joint in its place
(:mod:`vibroscope.gap.effects`).

    python examples/gap/modal_joint.py [--out modal_joint] [--clearance GAP] [--no-run]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

FS = 1000.0
T0 = 1_700_000_000.0
JOINT = ("m3", "m2")
#: the joint: share of the m2-m3 spring (N/m) that slips, and the largest slip force (N)
SHARE, F_MAX, N_SLIDERS = 0.5, 6.0, 4


def truth_model(clearance: float = 0.0, stiffness_scale: float = 1.0, damping: float = 1e-4,
                name: str = "wing + payload"):
    """The chain with the Iwan joint between the wing and the payload (and, with `clearance` > 0
    in m, a contact spring of the joint's slipping stiffness beyond that clearance), and without
    them. `stiffness_scale` multiplies every spring (the modes by its square root), `damping`
    is the stiffness-proportional damping factor in s (``c = damping k``)."""
    from dataclasses import replace

    from vibroscope.models import Backlash, BoucWen, LumpedModel, Spring

    k = [x * stiffness_scale for x in (4e5, 1.5e5, 6e4)]
    linear = LumpedModel.chain([8.0, 3.0, 1.5], k, [damping * x for x in k], input_dof=1, name=name)
    els = list(linear.elements)
    j = next(i for i, e in enumerate(els) if isinstance(e, Spring) and set(e.between) == set(JOINT))
    kj = els[j].k
    els[j] = Spring(els[j].between, k=(1 - SHARE) * kj)
    alpha = SHARE * kj / N_SLIDERS
    for i in range(1, N_SLIDERS + 1):  # slider i slips at F_MAX i / N (nu = 2: z = F tanh(k x / F))
        els.append(BoucWen(linear.elements[j].between, alpha=alpha, beta=alpha / (F_MAX * i / N_SLIDERS) ** 2,
                           gamma=0.5, delta=0.5, nu=2.0))
    if clearance > 0:
        els.append(Backlash(linear.elements[j].between, k=SHARE * kj, gap=clearance))
    return replace(linear, elements=tuple(els), name=f"{name}, bolted joint"), linear


def write_logs(out: Path, seed: int = 7, clearance: float = 0.0) -> dict:
    """Simulate the truth (20 sub-steps per sample, 1 % noise) and write the four logs."""
    from vibroscope.io import write_ros2_mcap
    from vibroscope.models.excitation import band_limited_random
    from vibroscope.models.simulate import simulate

    truth, linear = truth_model(clearance)
    out.mkdir(parents=True, exist_ok=True)
    runs = {"low": (60.0, 2.0)} | {f"levels_{i + 1}": (20.0, 25.0 * lv) for i, lv in enumerate((1.0, 2.5, 6.0))}
    for i, (name, (dur, rms)) in enumerate(runs.items()):
        u = band_limited_random(FS, int(dur * FS), fmin=2.0, fmax=150.0, rms=rms, seed=seed + i)
        sig = simulate(truth, u, FS, t0=T0, oversample=20, noise=0.01, seed=seed + 100 + i)
        write_ros2_mcap(out / f"{name}.mcap", sig)
    info = {"effect": "joint_friction", "between": list(JOINT), "joint_share": SHARE,
            "joint_stiffness_N_per_m": SHARE * 6e4, "slip_force_max_N": F_MAX, "sliders": N_SLIDERS,
            "clearance_m": clearance, "contact_stiffness_N_per_m": SHARE * 6e4 if clearance > 0 else 0.0,
            "modes_hz (linear, joint stuck)": [float(f) for f in linear.modes().natural_frequencies]}
    (out / "truth.json").write_text(json.dumps(info, indent=2))
    return info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("modal_joint"))
    ap.add_argument("--clearance", type=float, default=0.0,
                    help="free play of the joint in m, beyond which a contact spring bears (default 0: none)")
    ap.add_argument("--no-run", action="store_true", help="write the logs only")
    args = ap.parse_args(argv)
    info = write_logs(args.out, clearance=args.clearance)
    print("truth:", json.dumps(info))
    if args.no_run:
        return 0
    from vibroscope.cli import main as cli

    o = args.out
    rc = cli(["modal", str(o / "low.mcap"), "--input", "/actuator/force.wrench.force.x",
              "--export-model", str(o / "modal.toml"), "--no-rrd", "--no-figures"])
    if rc:
        return rc
    rc = cli(["gap", str(o / "modal.toml")] + [str(o / f"levels_{i}.mcap") for i in (1, 2, 3)]
             + ["--json", str(o / "gap.json"), "--figures", str(o / "figures")])
    rep = json.loads((o / "gap.json").read_text())
    c = rep["candidates"][0]
    print(f"verdict {rep['verdict']} at {c['where']}: {c['parameters']}")
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
