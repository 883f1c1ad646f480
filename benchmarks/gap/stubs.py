"""Stand-in diagnosers to check the scorer (``score.py --diagnose benchmarks/gap/stubs.py:oracle``).

``oracle`` cheats on purpose: it finds the case's truth file through the log path that
``read_mcap`` leaves in ``signals.meta["source"]`` and answers with it, so the scorer must
print 100 % everywhere. ``always_none`` names nothing (top-1 = the share of ``none`` cases).
The real diagnoser never reads ``truth/``.
"""

from __future__ import annotations

import json
from pathlib import Path


def _truth(signals) -> dict:
    src = Path(signals.meta["source"])  # DIR/cases/case_NNN/log.mcap
    return json.loads((src.parents[2] / "truth" / f"{src.parent.name}.json").read_text())


def oracle(model, signals, **_):
    t = _truth(signals[0] if isinstance(signals, (list, tuple)) else signals)
    g = float(t["gap_nominal_noise_free"])
    if isinstance(t["effect"], list):  # two effects: verdict = the list, one candidate each
        cands = [{"effect": e, "where": w, "parameters": p, "gap_after": 0.0, "score": 1.0}
                 for e, w, p in zip(t["effect"], t["where"], t["parameters"])]
    elif t["effect"] != "none":
        cands = [{"effect": t["effect"], "where": t["where"], "parameters": t["parameters"], "gap_after": 0.0,
                  "score": 1.0}]
    else:
        cands = []
    return {
        "metric": "nrmse",
        "gap_before": g,
        "gap_after": 0.0 if t["effect"] != "none" else g,
        "shrink": 1.0 if t["effect"] != "none" else 0.0,
        "candidates": cands,
        "verdict": t["effect"],
    }


def always_none(model, signals, **_):
    return {"metric": "nrmse", "gap_before": None, "gap_after": None, "shrink": None, "candidates": [],
            "verdict": "none"}
