"""The Bouc-Wen hysteretic benchmark (Noël & Schoukens 2016) as a gap-diagnosis case.

Writes, from ``../shared/data/boucwen``:

* ``OUT/boucwen_multisine.mcap``: three periods of the validation multisine (the output is
  the published steady-state period, repeated; ``vibroscope gap`` sees that the log is in
  steady state from its first sample and leaves its first period out by default, so that the
  simulation's start from rest is not compared),
* ``OUT/boucwen_sinesweep.mcap``: the validation sine sweep (from rest),
* ``OUT/boucwen_linear.toml``: the nominal model, the benchmark's linear part with the
  Bouc-Wen force replaced by its small-motion stiffness: m = 2 kg, c = 10 N s/m,
  k = k_L + alpha = 1e5 N/m.

Channels: force ``/shaker/force.wrench.force.x`` (N), displacement ``/shaker/mass.x`` (m).

    python examples/gap/boucwen.py [--data ../shared/data/boucwen] [--out boucwen]
    vibroscope gap boucwen/boucwen_linear.toml boucwen/boucwen_multisine.mcap boucwen/boucwen_sinesweep.mcap --json boucwen/report.json

(``--holdout last`` gives the benchmark's protocol: fitted on the multisine, validated on the
sine sweep.)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

FS = 750.0
IN_CH = "/shaker/force.wrench.force.x"
OUT_CH = "/shaker/mass.x"
N_PERIODS = 3
#: one multisine period in s (8192 samples)
PERIOD_S = 8192 / FS


def load(data: Path, name: str) -> np.ndarray:
    from scipy.io import loadmat

    return np.asarray(loadmat(data / f"{name}.mat")[name], dtype=float).ravel()


def signals(data: Path):
    """Signals of the repeated multisine and of the sine sweep."""
    from vibroscope.signals import Signals

    um, ym = load(data, "uval_multisine"), load(data, "yval_multisine")
    us, ysw = load(data, "uval_sinesweep"), load(data, "yval_sinesweep")
    ms = Signals(data=np.vstack([np.tile(um, N_PERIODS), np.tile(ym, N_PERIODS)]), fs=FS, channels=[IN_CH, OUT_CH],
                 units=["N", "m"])
    sw = Signals(data=np.vstack([us, ysw]), fs=FS, channels=[IN_CH, OUT_CH], units=["N", "m"])
    return ms, sw


def nominal():
    """The benchmark's linear part: m = 2 kg, c = 10 N s/m, k = k_L + alpha = 1e5 N/m."""
    from vibroscope.models.elements import Damper, Spring
    from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

    return LumpedModel(
        dofs=(Dof("m", 2.0),),
        elements=(Spring(("m", "ground"), k=1.0e5), Damper(("m", "ground"), c=10.0)),
        inputs=(Input(dof="m", channel=IN_CH),),
        outputs=(Output("m", "displacement", OUT_CH),),
        name="Bouc-Wen benchmark, linear part",
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data" / "boucwen")
    ap.add_argument("--out", type=Path, default=Path("boucwen"))
    a = ap.parse_args(argv)
    from vibroscope.io import write_ros2_mcap
    from vibroscope.models.modelfile import dump_model

    ms, sw = signals(a.data)
    a.out.mkdir(parents=True, exist_ok=True)
    write_ros2_mcap(a.out / "boucwen_multisine.mcap", ms)
    write_ros2_mcap(a.out / "boucwen_sinesweep.mcap", sw)
    dump_model(nominal(), a.out / "boucwen_linear.toml")
    print(f"wrote {a.out}/boucwen_multisine.mcap, boucwen_sinesweep.mcap, boucwen_linear.toml")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
