"""Can the TRUE model of a benchmark case reproduce its own log?

Strong backlash or cubic stiffness on a light, weakly sprung mass can make a chaotic (or
neutrally stable) system whose response no simulator reproduces over tens of seconds: two
correct integrators drift apart. Such a case does not test the diagnoser. This check
simulates the case's true model (read from ``truth/``, which the diagnoser never sees) with
vibroscope's simulator at its default and at twice its default oversampling, its outputs taken
at the sample instants as the truth integrators take them (``output_sampling="point"``; the
default low-pass would leave a friction's or a clipped force's aliased harmonics as a gap of its
own), and reports the nrmse of each against the log and against each other.

    python benchmarks/gap/predictability.py DIR [case_NNN ...]

Truths the model file cannot express (``truth_model`` null: Iwan joints, asymmetric
friction, a force offset) are not checked (reported predictable). Multi-log cases are
checked on their first log.

A case is *unpredictable* when the true model's own gap exceeds twice the measurement noise
(``truth["noise"]["relative_rms"]``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def truth_gap(root: Path, name: str) -> dict:
    """The true model's nrmse against the log (default and 2x oversampling) and the noise."""
    from vibroscope.io import read_mcap
    from vibroscope.models.modelfile import load_model, loads_model
    from vibroscope.models.simulate import default_oversample, simulate

    truth = json.loads((root / "truth" / f"{name}.json").read_text())
    noise = float(truth["noise"]["relative_rms"])
    if truth.get("truth_model") is None:  # the model file cannot express this truth: not checked
        nan = float("nan")
        return {"case": name, "effect": truth["effect"], "noise": noise, "truth_gap": nan, "truth_gap_2R": nan,
                "integrators_apart": nan, "predictable": True, "checked": False}
    nominal = load_model(root / "cases" / name / "nominal.toml")
    true_model = loads_model(truth["truth_model"])
    log = (truth.get("logs") or ["log.mcap"])[0]
    sig = read_mcap(root / "cases" / name / log, nominal.input_channels() + nominal.output_channels())
    u, y = np.asarray(sig.data[:1]), np.asarray(sig.data[1:])
    R = default_oversample(true_model, sig.fs)
    ya = np.asarray(simulate(true_model, u, sig.fs, oversample=R, output_sampling="point").data[1:])
    yb = np.asarray(simulate(true_model, u, sig.fs, oversample=2 * R, output_sampling="point").data[1:])

    def nr(a, b):
        return float(np.sqrt(np.sum((a - b) ** 2) / np.sum(a**2)))

    g = nr(y, ya)
    return {"case": name, "effect": truth["effect"], "noise": noise, "truth_gap": g, "truth_gap_2R": nr(y, yb),
            "integrators_apart": nr(ya, yb), "predictable": g <= 2 * noise, "checked": True}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    root = Path(argv[0])
    names = argv[1:] or sorted(p.name for p in (root / "cases").iterdir())
    for n in names:
        r = truth_gap(root, n)
        eff = "+".join(r["effect"]) if isinstance(r["effect"], (list, tuple)) else str(r["effect"])
        print(f"{r['case']}  {eff:<18} noise {r['noise']:.4f}  true model's gap {r['truth_gap']:.4f} "
              f"(2x oversampling {r['truth_gap_2R']:.4f}, apart {r['integrators_apart']:.4f})  "
              f"{'predictable' if r['predictable'] else 'UNPREDICTABLE'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
