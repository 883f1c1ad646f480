"""EMPS (Janot, Gautier & Brunot 2019): a prismatic robot-joint drive in its position loop.

Writes, from ``../shared/data/emps/DATA_EMPS.mat`` and ``DATA_EMPS_PULSES.mat`` (1 kHz):

* ``OUT/emps_estimation.mcap`` and ``OUT/emps_pulses.mcap``: ROS 2 / JSON MCAP logs with
  ``/emps/qg.x`` (reference, m), ``/emps/qm.x`` (motor position, m), ``/emps/vir.x``
  (controller output, V) and ``/emps/pulses.x`` (the validation log's pulses, added to the
  command: ``vir`` jumps by them, V; zero in the estimation log, so that both logs drive
  the same model);
* ``OUT/emps_nominal.toml``: a rigid mass M = 95.1089 kg with viscous friction
  Fv = 203.5034 N s/m (IDIM-LS, description sec. 3.4) in the cascade controller
  ``vir = kp kv (qg - qm) - kv qm'`` (eq. 6; kp = 160.18 1/s, kv = 243.45 V s/m, velocity
  from the two-tap average ``0.5 qm(k) + 0.5 qm(k-1)`` differenced, 1 kHz, saturation
  10 V, the pulses as its feed-forward), force ``gtau vir`` (gtau = 35.15 N/V);
* ``OUT/emps_friction.toml``: the same with Coulomb friction Fc = 20.3935 N (a
  ``friction`` element) and the IDM offset -3.1648 N (an input ``offset`` of +3.1648 N:
  ``M q'' = gtau vir - Fv q' - Fc sign(q') - offset``, eq. 3).

It then simulates both models with the logged ``qg`` (and pulses) and prints the relative
errors (eq. 11, ``100 ||y - y_sim|| / ||y||``) of qm and vir.

    python examples/gap/emps.py [--data ../shared/data/emps] [--out emps]

References
----------
.. [1] A. Janot, M. Gautier, M. Brunot, "Data set and reference models of EMPS", Nonlinear
   System Identification Benchmarks workshop, 2019.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

FS = 1000.0
CH = {"qg": "/emps/qg.x", "qm": "/emps/qm.x", "vir": "/emps/vir.x", "pulses": "/emps/pulses.x"}
FORCE = "/emps/force.x"
#: IDIM-LS estimates (description sec. 3.4)
M, FV, FC, OFFSET = 95.1089, 203.5034, 20.3935, -3.1648


def load(path: Path) -> dict:
    """The .mat file's vectors as float arrays (``qg``, ``qm``, ``vir``, optional ``pulses``)
    and scalars (``kp``, ``kv``, ``gtau``)."""
    from scipy.io import loadmat

    d = loadmat(path)
    out = {k: d[k].ravel().astype(float) for k in ("qg", "qm", "vir")}
    if "pulses_N" in d:
        out["pulses"] = d["pulses_N"].ravel().astype(float)
    out.update({k: float(d[k][0, 0]) for k in ("kp", "kv", "gtau")})
    return out


def signals(d: dict):
    """The log of one record as Signals."""
    from vibroscope.signals import Signals

    keys = ["qg", "qm", "vir", "pulses"]
    units = {"qg": "m", "qm": "m", "vir": "V", "pulses": "V"}
    # the estimation log has no pulses: a zero channel, so that both logs drive one model
    rows = [d[k] if k in d else np.zeros_like(d["qg"]) for k in keys]
    return Signals(data=np.vstack(rows), fs=FS, channels=[CH[k] for k in keys], units=[units[k] for k in keys])


def model(d: dict, *, friction: bool, pulses: bool = True):
    """The EMPS drive in its cascade loop (nominal, or with Coulomb friction and offset)."""
    from vibroscope.models import Damper, Dof, Input, LumpedModel, Output, make_element
    from vibroscope.models.controller import Controller

    ctl = Controller(name="position", law="cascade", gains={"kp": d["kp"], "kv": d["kv"]}, rate_hz=FS, dof="q",
                     drives=FORCE,
                     reference=CH["qg"], velocity_filter=(0.5, 0.5), gain=d["gtau"], saturation=10.0,
                     output_channel=CH["vir"], output_unit="V", feedforward=CH["pulses"] if pulses else None)
    els = (Damper(("q", "ground"), c=FV),)
    if friction:
        els += (make_element("friction", ("q", "ground"), force=FC),)
    inp = Input(dof="q", channel=FORCE, offset=-OFFSET if friction else 0.0)
    name = "EMPS, IDIM-LS " + ("M, Fv, Fc, offset" if friction else "M, Fv")
    return LumpedModel(dofs=(Dof("q", M),), elements=els, inputs=(inp,),
                       outputs=(Output("q", "displacement", CH["qm"]),), name=name, controllers=(ctl,))


def relerr(y, y_sim) -> float:
    """Eq. (11): ``100 ||y - y_sim|| / ||y||`` in %."""
    return float(100.0 * np.linalg.norm(y - y_sim) / np.linalg.norm(y))


def reproduce(d: dict, *, friction: bool) -> tuple[float, float]:
    """Relative errors (%) of qm and vir when the model is driven by the logged qg (and pulses)."""
    from vibroscope.models.simulate import simulate

    m = model(d, friction=friction)
    u = np.vstack([d["qg"], d.get("pulses", np.zeros_like(d["qg"]))])
    s = simulate(m, u, FS)
    ch = list(s.channels)
    return relerr(d["qm"], s.data[ch.index(CH["qm"])]), relerr(d["vir"], s.data[ch.index(CH["vir"])])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data" / "emps")
    ap.add_argument("--out", type=Path, default=Path("emps"))
    a = ap.parse_args(argv)
    from vibroscope.io import write_ros2_mcap
    from vibroscope.models.modelfile import dump_model

    est, val = load(a.data / "DATA_EMPS.mat"), load(a.data / "DATA_EMPS_PULSES.mat")
    a.out.mkdir(parents=True, exist_ok=True)
    write_ros2_mcap(a.out / "emps_estimation.mcap", signals(est))
    write_ros2_mcap(a.out / "emps_pulses.mcap", signals(val))
    dump_model(model(est, friction=False), a.out / "emps_nominal.toml")
    dump_model(model(est, friction=True), a.out / "emps_friction.toml")
    print(f"wrote {a.out}/emps_estimation.mcap, emps_pulses.mcap, emps_nominal.toml, emps_friction.toml")
    print("relative errors (eq. 11), simulated with the logged qg:")
    for label, d in (("estimation", est), ("pulses", val)):
        for friction in (False, True):
            eq, ev = reproduce(d, friction=friction)
            print(f"  {label:10s} {'M, Fv, Fc, offset' if friction else 'M, Fv':18s} qm {eq:8.4f} %   vir {ev:7.3f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
