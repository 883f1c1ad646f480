"""Withheld-effect benchmark for the sim-to-real gap diagnoser: scorer.

::

    python benchmarks/gap/score.py DIR [--jobs 1] [--markdown] [--cases case_000 ...]
                                       [--rescore] [--diagnose module:function]

For every ``DIR/cases/case_NNN``: load ``nominal.toml`` (:func:`vibroscope.models.modelfile.load_model`),
read ``log.mcap`` with ``read_mcap(path, channels=model.input_channels() + model.output_channels())``,
run ``vibroscope.gap.diagnose(model, signals)``, write ``report.to_dict()`` to
``DIR/reports/case_NNN.json`` (plus a ``_benchmark`` key: seconds, error), compare with
``DIR/truth/case_NNN.json`` and print the table (per class and overall):

top-1        verdict == true effect
top-2        true effect among the first two candidates' effects (``none`` counts as the
             rank-1 candidate when the verdict is ``none``)
location     element effects: the first candidate of the true class joins the true pair
             (unordered); extra_mode: same DOF and frequency within 10 %
false alarm  ``none`` cases whose verdict is not ``none``
shrink       median of the report's ``shrink`` = 1 - gap_after / gap_before
s/case       median and max wall-clock seconds of ``diagnose`` (reading the log excluded)

``--rescore`` recomputes the table from the reports already written (no diagnosis).
``--diagnose module:function`` (or ``path/to/file.py:function``) replaces
``vibroscope.gap:diagnose``, e.g. ``benchmarks/gap/stubs.py:oracle`` to check the scorer.
The summary is also written to ``DIR/score.json``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import math
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from vibroscope.gap.report import EFFECTS  # noqa: E402 - the fixed vocabulary, one definition
ELEMENT_EFFECTS = ("coulomb_friction", "backlash", "hysteresis", "cubic_stiffness")
LOCATED = ELEMENT_EFFECTS + ("extra_mode",)
DEFAULT_DIAGNOSE = "vibroscope.gap:diagnose"

TARGETS = {
    "top1": 0.95,
    "false_alarm": 0.05,
    "location": 0.90,
    "shrink": 0.80,
    "seconds": 60.0,
}


# ---------------------------------------------------------------------------------------------
# running the diagnoser
# ---------------------------------------------------------------------------------------------
def load_function(spec: str):
    """``module:function`` or ``path/to/file.py:function`` -> the callable."""
    mod, _, fn = spec.rpartition(":")
    if not mod or not fn:
        raise ValueError(f"--diagnose {spec!r} must be module:function or file.py:function")
    if mod.endswith(".py") or "/" in mod:
        path = Path(mod).resolve()
        name = "_gapbench_" + path.stem
        if name in sys.modules:
            module = sys.modules[name]
        else:
            s = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(s)
            sys.modules[name] = module
            s.loader.exec_module(module)
    else:
        module = importlib.import_module(mod)
    return getattr(module, fn)


def case_names(root: Path) -> list[str]:
    return sorted(p.name for p in (Path(root) / "cases").iterdir() if (p / "nominal.toml").is_file())


def run_case(root, name: str, diagnose_spec: str = DEFAULT_DIAGNOSE) -> dict:
    """Diagnose one case and write its report; returns the report dict."""
    from vibroscope.io import read_mcap
    from vibroscope.models.modelfile import load_model

    root = Path(root)
    cdir = root / "cases" / name
    out = root / "reports" / f"{name}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    diagnose = load_function(diagnose_spec)
    model = load_model(cdir / "nominal.toml")
    signals = read_mcap(cdir / "log.mcap", channels=model.input_channels() + model.output_channels())
    tic = time.perf_counter()
    try:
        rep = diagnose(model, signals)
        d = rep.to_dict() if hasattr(rep, "to_dict") else dict(rep)
        err = None
    except Exception as exc:  # a failing case is scored as wrong, the run goes on
        d = {"verdict": "error", "candidates": []}
        err = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        tb = traceback.format_exc()
    sec = time.perf_counter() - tic
    d = dict(d)
    d["_benchmark"] = {"seconds": sec, "diagnose": diagnose_spec, "error": err}
    if err is not None:
        d["_benchmark"]["traceback"] = tb
    out.write_text(json.dumps(d, indent=2, default=_json_default) + "\n", encoding="utf-8")
    return d


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def _run_star(args):
    return args[1], run_case(*args)


# ---------------------------------------------------------------------------------------------
# comparing with the truth
# ---------------------------------------------------------------------------------------------
def _same_pair(a, b) -> bool:
    try:
        return sorted(map(str, a)) == sorted(map(str, b))
    except TypeError:
        return False


def located(truth: dict, cand: dict | None) -> bool:
    """Does candidate `cand` (of the true class) sit where the truth does?"""
    if cand is None:
        return False
    w, tw = cand.get("where") or {}, truth["where"]
    if truth["effect"] in ELEMENT_EFFECTS:
        return _same_pair(w.get("between", ()), tw["between"])
    if truth["effect"] == "extra_mode":
        f = w.get("frequency_hz")
        return (w.get("dof") == tw["dof"] and f is not None and math.isfinite(float(f))
                and abs(float(f) - tw["frequency_hz"]) <= 0.1 * tw["frequency_hz"])
    return True


def score_case(report: dict, truth: dict) -> dict:
    """Per-case marks: top1, top2, location (None when not applicable), shrink, seconds."""
    eff = truth["effect"]
    verdict = report.get("verdict")
    cands = [c for c in (report.get("candidates") or []) if isinstance(c, dict)]
    ranked = [c.get("effect") for c in cands]
    if verdict == "none":
        ranked = ["none"] + ranked
    loc = None
    if eff in LOCATED:
        first = next((c for c in cands if c.get("effect") == eff), None)
        loc = located(truth, first)
    shrink = report.get("shrink")
    bench = report.get("_benchmark", {})
    return {
        "effect": eff,
        "verdict": verdict,
        "top1": verdict == eff,
        "top2": eff in ranked[:2],
        "location": loc,
        "shrink": float(shrink) if isinstance(shrink, (int, float)) and math.isfinite(shrink) else float("nan"),
        "seconds": float(bench.get("seconds", float("nan"))),
        "error": bench.get("error"),
        "truth_gap": truth.get("gap_nominal_noise_free"),
    }


def _rate(xs):
    xs = [x for x in xs if x is not None]
    return (sum(bool(x) for x in xs) / len(xs)) if xs else float("nan")


def _median(xs):
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return float(np.median(xs)) if xs else float("nan")


def summarise(marks: list[dict]) -> dict:
    by = {}
    for e in EFFECTS:
        ms = [m for m in marks if m["effect"] == e]
        if not ms:
            continue
        wrong = Counter(m["verdict"] for m in ms if not m["top1"])
        by[e] = {
            "n": len(ms),
            "top1": _rate([m["top1"] for m in ms]),
            "top2": _rate([m["top2"] for m in ms]),
            "location": _rate([m["location"] for m in ms]) if e in LOCATED else None,
            "false_alarm": _rate([not m["top1"] for m in ms]) if e == "none" else None,
            "shrink": _median([m["shrink"] for m in ms]),
            "seconds_median": _median([m["seconds"] for m in ms]),
            "seconds_max": max((m["seconds"] for m in ms), default=float("nan")),
            "errors": sum(m["error"] is not None for m in ms),
            "wrong": dict(wrong.most_common()),
        }
    nn = [m for m in marks if m["effect"] != "none"]
    overall = {
        "n": len(marks),
        "top1": _rate([m["top1"] for m in marks]),
        "top2": _rate([m["top2"] for m in marks]),
        "location": _rate([m["location"] for m in marks if m["effect"] in LOCATED]),
        "false_alarm": by.get("none", {}).get("false_alarm"),
        "shrink": _median([m["shrink"] for m in nn]),
        "seconds_median": _median([m["seconds"] for m in marks]),
        "seconds_max": max((m["seconds"] for m in marks), default=float("nan")),
        "errors": sum(m["error"] is not None for m in marks),
        "wrong": {},
    }
    checks = {
        "top1": overall["top1"] >= TARGETS["top1"],
        "false_alarm": overall["false_alarm"] is None or overall["false_alarm"] <= TARGETS["false_alarm"],
        "location": not math.isfinite(overall["location"]) or overall["location"] >= TARGETS["location"],
        "shrink_every_class": all(v["shrink"] >= TARGETS["shrink"] for e, v in by.items() if e != "none"),
        "seconds": overall["seconds_max"] <= TARGETS["seconds"],
    }
    return {"classes": by, "overall": overall, "targets": TARGETS, "pass": checks}


# ---------------------------------------------------------------------------------------------
# table
# ---------------------------------------------------------------------------------------------
def _pct(x):
    return "—" if x is None or not math.isfinite(x) else f"{100 * x:.0f} %"


def _sec(x):
    return "—" if x is None or not math.isfinite(x) else f"{x:.1f}"


def table(summary: dict, markdown: bool = False) -> str:
    head = ["class", "n", "top-1", "top-2", "location", "false alarms", "median shrink", "median s", "max s",
            "wrong verdicts"]
    rows = []
    for e, v in list(summary["classes"].items()) + [("overall", summary["overall"])]:
        flags = []
        if e != "overall":
            if v["top1"] < TARGETS["top1"]:
                flags.append("top-1")
            if v["location"] is not None and v["location"] < TARGETS["location"]:
                flags.append("loc")
            if e != "none" and not v["shrink"] >= TARGETS["shrink"]:
                flags.append("shrink")
        wrong = ", ".join(f"{k} {n}" for k, n in v["wrong"].items())
        if v.get("errors"):
            wrong = (wrong + ", " if wrong else "") + f"({v['errors']} errors)"
        rows.append([
            e + (" *" if flags else ""),
            str(v["n"]),
            _pct(v["top1"]),
            _pct(v["top2"]),
            _pct(v["location"]),
            _pct(v["false_alarm"]),
            _pct(v["shrink"]) if e != "none" else "—",
            _sec(v["seconds_median"]),
            _sec(v["seconds_max"]),
            wrong,
        ])
    t = TARGETS
    target_row = ["target", "", f"≥ {100 * t['top1']:.0f} %", "", f"≥ {100 * t['location']:.0f} %",
                  f"≤ {100 * t['false_alarm']:.0f} %", f"≥ {100 * t['shrink']:.0f} % each", "", f"≤ {t['seconds']:.0f}", ""]
    rows.append(target_row)
    ok = summary["pass"]
    verdict_line = "targets: " + ", ".join(f"{k} {'PASS' if v else 'FAIL'}" for k, v in ok.items())
    note = "(* = this class misses a target)"
    if markdown:
        out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" if i == 0 or i == len(head) - 1 else "---:"
                                                             for i in range(len(head))) + "|"]
        for r in rows:
            out.append("| " + " | ".join(c.replace("|", "/") for c in r) + " |")
        return "\n".join(out) + f"\n\n{verdict_line} {note}\n"
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    fmt = lambda r: "  ".join(c.ljust(w) if i in (0, len(head) - 1) else c.rjust(w)  # noqa: E731
                              for i, (c, w) in enumerate(zip(r, widths)))
    out = [fmt(head), "  ".join("-" * w for w in widths)]
    out += [fmt(r) for r in rows[:-2]]
    out += ["  ".join("-" * w for w in widths), fmt(rows[-2]), fmt(rows[-1])]
    return "\n".join(out) + f"\n{verdict_line} {note}\n"


# ---------------------------------------------------------------------------------------------
def score(root, *, jobs: int = 1, diagnose: str = DEFAULT_DIAGNOSE, cases=None, rescore: bool = False,
          verbose: bool = False) -> dict:
    """Run (unless `rescore`) and score the benchmark in `root`; returns the summary
    (also written to ``root/score.json``) with the per-case marks under ``cases``."""
    root = Path(root)
    names = list(cases) if cases else case_names(root)
    reports = {}
    if rescore:
        for n in names:
            p = root / "reports" / f"{n}.json"
            if p.is_file():
                reports[n] = json.loads(p.read_text())
    elif jobs > 1:
        from concurrent.futures import ProcessPoolExecutor
        from multiprocessing import get_context

        with ProcessPoolExecutor(jobs, mp_context=get_context("spawn")) as ex:
            for n, rep in ex.map(_run_star, [(str(root), n, diagnose) for n in names]):
                reports[n] = rep
                if verbose:
                    _progress(root, n, rep)
    else:
        for n in names:
            reports[n] = run_case(root, n, diagnose)
            if verbose:
                _progress(root, n, reports[n])
    marks = []
    for n in names:
        if n not in reports:
            continue
        truth = json.loads((root / "truth" / f"{n}.json").read_text())
        m = score_case(reports[n], truth)
        m["case"] = n
        marks.append(m)
    summary = summarise(marks)
    summary["diagnose"] = diagnose
    summary["cases"] = marks
    (root / "score.json").write_text(json.dumps(summary, indent=2, default=_json_default) + "\n")
    return summary


def _progress(root, name, rep):
    truth = json.loads((Path(root) / "truth" / f"{name}.json").read_text())
    b = rep.get("_benchmark", {})
    mark = "ok " if rep.get("verdict") == truth["effect"] else "BAD"
    err = f"  error: {b['error']}" if b.get("error") else ""
    print(f"{name}  {mark} truth {truth['effect']:<18s} verdict {str(rep.get('verdict')):<18s} "
          f"{b.get('seconds', float('nan')):6.1f} s{err}", file=sys.stderr, flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("root", type=Path, help="benchmark folder written by generate.py")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--cases", nargs="+", help="score only these cases (case_000 ...)")
    p.add_argument("--rescore", action="store_true", help="score the reports already written, diagnose nothing")
    p.add_argument("--quiet", action="store_true", help="no per-case progress lines")
    p.add_argument("--diagnose", default=DEFAULT_DIAGNOSE, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    summary = score(a.root, jobs=a.jobs, diagnose=a.diagnose, cases=a.cases, rescore=a.rescore, verbose=not a.quiet)
    print(table(summary, markdown=a.markdown), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
