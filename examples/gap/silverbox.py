"""Silverbox (Wigren & Schoukens, ECC 2013) as a gap-diagnosis case.

Writes, from ``../shared/data/silverbox/SNLS80mV.csv``:

* ``OUT/silverbox_estimation.mcap``: samples 40 650-127 400 (the multisine part),
* ``OUT/silverbox_arrow.mcap``: samples 100-40 575 (the "arrow": filtered noise of growing
  amplitude, the standard test part),
* ``OUT/silverbox_linear.toml``: the nominal model, a linear second-order model (one mass,
  spring and damper) fitted on the estimation part with :func:`vibroscope.gap.fit_linear_model`.

Input V1 (V) is taken as the force ``/silverbox/input.wrench.force.x`` (N) and output V2 (V)
as the displacement ``/silverbox/output.x`` (m): the circuit emulates
``m y'' + d y' + a y + b y^3 = u``.

    python examples/gap/silverbox.py [--data ../shared/data/silverbox] [--out silverbox]
    vibroscope gap silverbox/silverbox_linear.toml silverbox/silverbox_estimation.mcap silverbox/silverbox_arrow.mcap --holdout last --json silverbox/report.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

FS = 610.35
IN_CH = "/silverbox/input.wrench.force.x"
OUT_CH = "/silverbox/output.x"
EST = slice(40650, 127400)
ARROW = slice(100, 40575)


def load(data: Path):
    """(V1, V2) of SNLS80mV.csv as float arrays."""
    raw = np.genfromtxt(data / "SNLS80mV.csv", delimiter=",", skip_header=1, usecols=(0, 1))
    return raw[:, 0], raw[:, 1]


def signals(data: Path):
    """Signals of the estimation and arrow parts."""
    from vibroscope.signals import Signals

    v1, v2 = load(data)
    out = []
    for sl in (EST, ARROW):
        out.append(Signals(data=np.vstack([v1[sl], v2[sl]]), fs=FS, channels=[IN_CH, OUT_CH], units=["N", "m"],
                           t0=sl.start / FS))
    return out


def nominal(est):
    """Linear second-order model fitted on the estimation part (start: static gain and peak)."""
    from scipy import signal

    from vibroscope.gap import fit_linear_model
    from vibroscope.models.elements import Damper, Spring
    from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

    u, y = est.data
    f, Pxy = signal.csd(u, y, fs=FS, nperseg=4096)
    _, Pxx = signal.welch(u, fs=FS, nperseg=4096)
    H = Pxy / Pxx
    band = (f > 5) & (f < 150)
    f0 = f[band][np.argmax(np.abs(H[band]))]
    k = 1.0 / np.abs(H[(f > 1) & (f < 10)]).mean()
    m = k / (2 * np.pi * f0) ** 2
    c = 2 * 0.05 * np.sqrt(k * m)
    start = LumpedModel(
        dofs=(Dof("m1", m),),
        elements=(Spring(("m1", "ground"), k=k), Damper(("m1", "ground"), c=c)),
        inputs=(Input(dof="m1", channel=IN_CH),),
        outputs=(Output("m1", "displacement", OUT_CH),),
        name="Silverbox linear",
    )
    return fit_linear_model(start, est)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data" / "silverbox")
    ap.add_argument("--out", type=Path, default=Path("silverbox"))
    a = ap.parse_args(argv)
    from vibroscope.io import write_ros2_mcap
    from vibroscope.models.modelfile import dump_model

    est, arrow = signals(a.data)
    a.out.mkdir(parents=True, exist_ok=True)
    write_ros2_mcap(a.out / "silverbox_estimation.mcap", est)
    write_ros2_mcap(a.out / "silverbox_arrow.mcap", arrow)
    model = nominal(est)
    dump_model(model, a.out / "silverbox_linear.toml")
    print(f"wrote {a.out}/silverbox_estimation.mcap, silverbox_arrow.mcap, silverbox_linear.toml "
          f"(f_n = {model.modes().natural_frequencies[0]:.2f} Hz, zeta = {100 * model.modes().damping_ratios[0]:.2f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
