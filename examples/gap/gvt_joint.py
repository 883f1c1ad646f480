"""A ground vibration test shaped as the F-16 benchmark's, with a bolted joint: ``modal --export-model`` -> ``gap``.

The chain of ``modal_joint.py`` (a body ``m1`` 8 kg, a wing ``m2`` 3 kg, a payload ``m3``
1.5 kg bolted to it by an Iwan joint of four sliders slipping at up to 6 N), its springs softened
so that the joint's mode lies at 7.32 Hz, as the torsion mode of the F-16 ground vibration test
(Noel & Schoukens, "F-16 aircraft benchmark based on ground vibration test data", 2017), and
logged as that test was: 400 Hz, a periodic multisine over 2-15 Hz in periods of 8192 samples
(four periods per level here), three accelerometers (the wing's at the shaker: the driving
point), 1 % noise, damping ratios 0.5-1.2 %. Two modes (7.3 and 13.2 Hz) lie in the band, the
third (18.3 Hz) above it: the identified modal model holds it only as an upper residual.

Writes in ``OUT``:

* ``ms_1.mcap``, ``ms_2.mcap``, ``ms_3.mcap``: the multisine at 0.1, 0.5 and 1 N RMS (the joint
  stuck at the first level to within the noise, slipping at the others);
* ``sw_1.mcap``: a linear sine sweep 2-15 Hz over 120 s at the first level's RMS (the low-level
  control run);
* ``truth.json``: the joint's place and parameters.

Then runs what an engineer would, and prints the verdicts::

    vibroscope modal OUT/ms_1.mcap --input /actuator/force.wrench.force.x --export-model OUT/modal.toml
    vibroscope gap OUT/modal.toml OUT/ms_1.mcap OUT/ms_2.mcap OUT/ms_3.mcap --json OUT/gap.json --figures OUT/figures
    vibroscope gap OUT/modal.toml OUT/ms_1.mcap OUT/sw_1.mcap --json OUT/control.json

``python examples/gap/gvt_joint.py [--out gvt_joint] [--no-run] [--no-control]`` and variants the
example does not make by default: ``--clearance M`` (a clearance at the joint), ``--slip-force N``,
``--levels N N N``, ``--seed S`` (the multisine's), ``--noise-seed S``, ``--random`` (band-limited
random input, not periodic), ``--sweeps`` (the sweep written at every level, ``sw_2.mcap`` ..., and
``gap`` run on the sweeps instead of the multisines; the modal model is still identified from
``ms_1.mcap``, the lowest-level multisine)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

FS = 400.0
T0 = 1_700_000_000.0
PERIOD = 8192
#: the springs of modal_joint.py scaled so that its joint mode (20.76 Hz) lies at 7.32 Hz
SCALE = (7.32 / 20.762) ** 2
JOINT = ("m3", "m2")  # as modal_joint.py's: half of the 6e4 SCALE N/m spring slips, at up to 6 N in 4 sliders
SHARE, F_MAX, N_SLIDERS = 0.5, 6.0, 4
LEVELS_N = (0.1, 0.5, 1.0)


def _modal_joint():
    """``modal_joint.py`` beside this file, as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("modal_joint", Path(__file__).with_name("modal_joint.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def truth_model(clearance: float = 0.0, slip_force: float = F_MAX):
    """The chain with the Iwan joint between the wing and the payload, and without it (stuck):
    ``modal_joint.py``'s, its springs scaled by :data:`SCALE`, damping ``c = 2e-4 k``; with
    `clearance` > 0 (m) a contact spring of the joint's slipping stiffness beyond it, the
    sliders slipping at up to `slip_force` (N)."""
    mj = _modal_joint()
    mj.F_MAX = slip_force
    return mj.truth_model(clearance=clearance, stiffness_scale=SCALE, damping=2e-4, name="wing + payload (GVT)")


def write_logs(out: Path, periods: int = 4, *, clearance: float = 0.0, slip_force: float = F_MAX,
               levels=LEVELS_N, seed: int = 1, noise_seed: int = 100, random: bool = False,
               sweeps: bool = False) -> dict:
    """Simulate the truth (40 sub-steps per sample, 1 % noise of seed ``noise_seed + i`` in log
    i) and write the logs: the multisine (of `seed`; `random`: band-limited random noise of seed
    ``seed + i`` instead, not periodic) at each of `levels` (N RMS), and the sweep at the first
    (`sweeps`: at every level, ``sw_2`` ... written after the others, so that they keep their noise)."""
    from vibroscope.io import write_ros2_mcap
    from vibroscope.models.excitation import band_limited_random, multisine, sine_sweep
    from vibroscope.models.simulate import simulate

    truth, linear = truth_model(clearance, slip_force)
    out.mkdir(parents=True, exist_ok=True)
    if random:
        runs = {f"ms_{i + 1}": band_limited_random(FS, periods * PERIOD, fmin=2.0, fmax=15.0, rms=lv, seed=seed + i)
                for i, lv in enumerate(levels)}
    else:
        ms = multisine(FS, PERIOD, fmin=2.0, fmax=15.0, rms=1.0, seed=seed)[0]
        runs = {f"ms_{i + 1}": np.tile(ms, periods) * lv for i, lv in enumerate(levels)}
    for i, lv in enumerate(levels[: len(levels) if sweeps else 1]):
        runs[f"sw_{i + 1}"] = sine_sweep(FS, duration=120.0, f0=2.0, f1=15.0, amplitude=lv * np.sqrt(2))
    for i, (name, u) in enumerate(runs.items()):
        write_ros2_mcap(out / f"{name}.mcap",
                        simulate(truth, u, FS, t0=T0, oversample=40, noise=0.01, seed=noise_seed + i))
    info = {"effect": "joint_friction", "between": list(JOINT), "joint_stiffness_N_per_m": SHARE * 6e4 * SCALE,
            "slip_force_max_N": slip_force, "sliders": N_SLIDERS, "levels_N_rms": list(levels),
            "clearance_m": clearance, "excitation": "band-limited random" if random else "periodic multisine",
            "modes_hz (linear, joint stuck)": [float(f) for f in linear.modes().natural_frequencies]}
    (out / "truth.json").write_text(json.dumps(info, indent=2))
    return info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("gvt_joint"))
    ap.add_argument("--no-run", action="store_true", help="write the logs only")
    ap.add_argument("--no-control", action="store_true", help="skip the low-level control run")
    ap.add_argument("--clearance", type=float, default=0.0, help="a clearance at the joint, m (default none)")
    ap.add_argument("--slip-force", type=float, default=F_MAX, help=f"the sliders' top slip force, N (default {F_MAX:g})")
    ap.add_argument("--levels", type=float, nargs="+", default=list(LEVELS_N), help="input levels, N RMS")
    ap.add_argument("--seed", type=int, default=1, help="the multisine's (or random input's) seed")
    ap.add_argument("--noise-seed", type=int, default=100, help="the noise's seed of the first log")
    ap.add_argument("--random", action="store_true", help="band-limited random input instead of the multisine")
    ap.add_argument("--sweeps", action="store_true",
                    help="the sine sweep at every level, and gap run on the sweeps (the modal model still from ms_1)")
    args = ap.parse_args(argv)
    o = args.out
    print("truth:", json.dumps(write_logs(o, clearance=args.clearance, slip_force=args.slip_force, levels=args.levels,
                                          seed=args.seed, noise_seed=args.noise_seed, random=args.random,
                                          sweeps=args.sweeps)))
    if args.no_run:
        return 0
    from vibroscope.cli import main as cli

    rc = cli(["modal", str(o / "ms_1.mcap"), "--input", "/actuator/force.wrench.force.x",
              "--export-model", str(o / "modal.toml"), "--no-rrd", "--no-figures"])
    if rc:
        return rc
    stem = "sw" if args.sweeps else "ms"
    runs = [("gap", [f"{stem}_{i + 1}.mcap" for i in range(len(args.levels))], ["--figures", str(o / "figures")])]
    if not args.no_control:
        runs.append(("control", ["ms_1.mcap", "sw_1.mcap"], []))
    for name, logs, extra in runs:
        rc = cli(["gap", str(o / "modal.toml")] + [str(o / lg) for lg in logs] + ["--json", str(o / f"{name}.json")] + extra)
        if rc:
            return rc
        rep = json.loads((o / f"{name}.json").read_text())
        c = rep["candidates"][0]
        print(f"{name}: verdict {rep['verdict']} at {c['where']}: {c['parameters']}; held-out {rep['gap_before']:.4g} -> "
              f"{rep['gap_after']:.4g}, floor {rep['noise_floor']:.4g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
