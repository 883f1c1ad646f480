"""Withheld-effect benchmark for the sim-to-real gap diagnoser: scorer.

::

    python benchmarks/gap/score.py DIR [--jobs 1] [--markdown] [--cases case_000 ...]
                                       [--rescore] [--diagnose module:function]

For every ``DIR/cases/case_NNN``: load ``nominal.toml`` (:func:`vibroscope.models.modelfile.load_model`),
read ``log.mcap`` -- or, where the case has them, every ``log_*.mcap`` in name order, passed
as a list (the diagnoser holds the last out) -- with ``read_mcap(path,
channels=model.input_channels() + model.output_channels())``, run
``vibroscope.gap.diagnose(model, signals)``, write ``report.to_dict()`` to
``DIR/reports/case_NNN.json`` (plus a ``_benchmark`` key: seconds, error), compare with
``DIR/truth/case_NNN.json`` and print the table (per class and overall).

The report's ``verdict`` is a str or a list of str (several effects named, first = main);
the truth's ``effect`` a str or, for the ``two_effects`` class, a list of two.

top-1        single effect: the (first) verdict == the true effect; two effects: the first
             named effect is one of the two
both         two effects: the set of named effects contains both (single: = top-1)
top-2        true effect among the first two candidates' effects (``none`` counts as the
             rank-1 candidate when the verdict is ``none``); two effects: both among them
location     element effects: the first candidate of the true class joins the true pair
             (unordered); extra_mode: same DOF and frequency within 10 % (two effects: every
             located effect of the pair)
false alarm  ``none`` cases whose verdict is not ``none`` (``unexplained`` counts as one; on
             the effect classes ``unexplained`` is simply wrong)
vanishing    the verdict is an effect, and the winning candidate (candidates[0]) of that
             effect has parameters that make it vanish (time_delay: delay_s < 0.5 / fs;
             zero force, gap, k3, alpha, offset)
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

#: the benchmark's classes in table order (the generator's; unknown ones follow)
CLASSES = ("none", "parameter_mismatch", "extra_mode", "time_delay", "coulomb_friction", "backlash", "hysteresis",
           "cubic_stiffness", "saturation", "asymmetric_friction", "joint_friction", "offset", "two_effects")
ELEMENT_EFFECTS = ("coulomb_friction", "backlash", "hysteresis", "cubic_stiffness", "asymmetric_friction",
                   "joint_friction")
FS_LOG = 1000.0  # the benchmark logs' rate (Hz), for the vanishing-delay rule
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
    from vibroscope.gap.closed_loop import log_channels

    model = load_model(cdir / "nominal.toml")
    ins, outs = log_channels(model) if hasattr(model, "controllers") else (model.input_channels(), model.output_channels())
    chans = ins + outs  # closed loop: the reference, the plant outputs, the controller's output
    logs = sorted(cdir.glob("log_*.mcap"), key=lambda p: p.name)
    if logs:
        signals = [read_mcap(p, channels=chans) for p in logs]
    else:
        signals = read_mcap(cdir / "log.mcap", channels=chans)
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


def _located_one(eff: str, tw: dict, cand: dict | None) -> bool:
    if cand is None:
        return False
    w = cand.get("where") or {}
    if eff in ELEMENT_EFFECTS:
        return _same_pair(w.get("between", ()), tw["between"])
    if eff == "extra_mode":
        f = w.get("frequency_hz")
        return (w.get("dof") == tw["dof"] and f is not None and math.isfinite(float(f))
                and abs(float(f) - tw["frequency_hz"]) <= 0.1 * tw["frequency_hz"])
    return True


def located(truth: dict, cand: dict | None) -> bool:
    """Does candidate `cand` (of the true class) sit where the truth does? (single effect)"""
    return _located_one(truth["effect"], truth["where"], cand)


def truth_effects(truth: dict) -> list[str]:
    e = truth["effect"]
    return [str(x) for x in e] if isinstance(e, (list, tuple)) else [str(e)]


def truth_class(truth: dict) -> str:
    e = truth["effect"]
    return truth.get("class") or (str(e) if isinstance(e, str) else "two_effects")


def verdicts(report: dict) -> list[str]:
    v = report.get("verdict")
    if isinstance(v, (list, tuple)):
        return [str(x) for x in v]
    return [] if v is None else [str(v)]


_VANISH = {  # effect -> parameters that make it vanish
    "time_delay": lambda p: abs(float(p.get("delay_s", 1.0))) < 0.5 / FS_LOG,
    "coulomb_friction": lambda p: float(p.get("Fc_N", 1.0)) == 0.0,
    "asymmetric_friction": lambda p: float(p.get("Fp_N", 1.0)) == 0.0 and float(p.get("Fn_N", 1.0)) == 0.0,
    "backlash": lambda p: float(p.get("gap_m", 1.0)) <= 0.0,
    "cubic_stiffness": lambda p: float(p.get("k3_N_per_m3", 1.0)) == 0.0 and float(p.get("k5_N_per_m5", 0.0)) == 0.0,
    "hysteresis": lambda p: float(p.get("alpha_N_per_m", 1.0)) == 0.0,
    "offset": lambda p: float(p.get("offset_N", p.get("F0_N", 1.0))) == 0.0,
}


def vanishing(report: dict) -> bool:
    """The verdict names an effect and the winning candidate's parameters make it vanish."""
    vs = verdicts(report)
    cands = [c for c in (report.get("candidates") or []) if isinstance(c, dict)]
    if not vs or vs[0] in ("none", "unexplained", "error") or not cands:
        return False
    c = cands[0]
    rule = _VANISH.get(str(c.get("effect")))
    try:
        return bool(rule and rule(c.get("parameters") or {}))
    except (TypeError, ValueError):
        return False


def score_case(report: dict, truth: dict) -> dict:
    """Per-case marks: top1, both, top2, location (None when not applicable), vanishing,
    shrink, seconds."""
    effs = truth_effects(truth)
    cls = truth_class(truth)
    vs = verdicts(report)
    first = vs[0] if vs else None
    cands = [c for c in (report.get("candidates") or []) if isinstance(c, dict)]
    ranked = [c.get("effect") for c in cands]
    if first == "none":
        ranked = ["none"] + ranked
    if len(effs) == 1:
        top1 = first == effs[0]
        both = top1
        top2 = effs[0] in ranked[:2]
    else:
        top1 = first in effs
        both = set(effs) <= set(vs)
        top2 = set(effs) <= set(ranked[:2])
    where = truth["where"] if len(effs) > 1 else [truth["where"]]
    locs = []
    for e, w in zip(effs, where):
        if e in LOCATED:
            locs.append(_located_one(e, w, next((c for c in cands if c.get("effect") == e), None)))
    loc = all(locs) if locs else None
    shrink = report.get("shrink")
    bench = report.get("_benchmark", {})
    return {
        "effect": cls,
        "truth_effects": effs,
        "verdict": report.get("verdict"),
        "top1": top1,
        "both": both,
        "top2": top2,
        "location": loc,
        "vanishing": vanishing(report),
        "shrink": float(shrink) if isinstance(shrink, (int, float)) and math.isfinite(shrink) else float("nan"),
        "seconds": float(bench.get("seconds", float("nan"))),
        "error": bench.get("error"),
        "truth_gap": truth.get("gap_nominal_noise_free"),
    }


def _vkey(v) -> str:
    return "+".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v)


def _rate(xs):
    xs = [x for x in xs if x is not None]
    return (sum(bool(x) for x in xs) / len(xs)) if xs else float("nan")


def _median(xs):
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return float(np.median(xs)) if xs else float("nan")


def _is_none(cls: str) -> bool:
    """A class without a hidden effect: ``none``, ``closed_loop_none``, ``modal_none``."""
    return cls == "none" or cls.endswith("_none")


def summarise(marks: list[dict]) -> dict:
    by = {}
    order = list(CLASSES) + [e for e in EFFECTS if e not in CLASSES]
    order += sorted({m["effect"] for m in marks} - set(order))
    for e in order:
        ms = [m for m in marks if m["effect"] == e]
        if not ms:
            continue
        wrong = Counter(_vkey(m["verdict"]) for m in ms if not m["top1"])
        by[e] = {
            "n": len(ms),
            "top1": _rate([m["top1"] for m in ms]),
            "both": _rate([m["both"] for m in ms]),
            "top2": _rate([m["top2"] for m in ms]),
            "vanishing": _rate([m["vanishing"] for m in ms]),
            "location": _rate([m["location"] for m in ms]) if any(m["location"] is not None for m in ms) else None,
            "false_alarm": _rate([not m["top1"] for m in ms]) if _is_none(e) else None,
            "shrink": _median([m["shrink"] for m in ms]),
            "seconds_median": _median([m["seconds"] for m in ms]),
            "seconds_max": max((m["seconds"] for m in ms), default=float("nan")),
            "errors": sum(m["error"] is not None for m in ms),
            "wrong": dict(wrong.most_common()),
        }
    nn = [m for m in marks if not _is_none(m["effect"])]
    overall = {
        "n": len(marks),
        "top1": _rate([m["top1"] for m in marks]),
        "both": _rate([m["both"] for m in marks]),
        "top2": _rate([m["top2"] for m in marks]),
        "vanishing": _rate([m["vanishing"] for m in marks]),
        "location": _rate([m["location"] for m in marks]),
        "false_alarm": (_rate([not m["top1"] for m in marks if _is_none(m["effect"])])
                        if any(_is_none(m["effect"]) for m in marks) else None),
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
        "shrink_every_class": all(v["shrink"] >= TARGETS["shrink"] for e, v in by.items() if not _is_none(e)),
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
    head = ["class", "n", "top-1", "both", "top-2", "location", "false alarms", "vanishing", "median shrink",
            "median s", "max s", "wrong verdicts"]
    rows = []
    for e, v in list(summary["classes"].items()) + [("overall", summary["overall"])]:
        flags = []
        if e != "overall":
            if v["top1"] < TARGETS["top1"]:
                flags.append("top-1")
            if v["location"] is not None and v["location"] < TARGETS["location"]:
                flags.append("loc")
            if not _is_none(e) and not v["shrink"] >= TARGETS["shrink"]:
                flags.append("shrink")
        wrong = ", ".join(f"{k} {n}" for k, n in v["wrong"].items())
        if v.get("errors"):
            wrong = (wrong + ", " if wrong else "") + f"({v['errors']} errors)"
        rows.append([
            e + (" *" if flags else ""),
            str(v["n"]),
            _pct(v["top1"]),
            _pct(v["both"]) if e in ("two_effects", "overall") else "—",
            _pct(v["top2"]),
            _pct(v["location"]),
            _pct(v["false_alarm"]),
            _pct(v["vanishing"]),
            _pct(v["shrink"]) if not _is_none(e) else "—",
            _sec(v["seconds_median"]),
            _sec(v["seconds_max"]),
            wrong,
        ])
    t = TARGETS
    target_row = ["target", "", f"≥ {100 * t['top1']:.0f} %", "", "", f"≥ {100 * t['location']:.0f} %",
                  f"≤ {100 * t['false_alarm']:.0f} %", "", f"≥ {100 * t['shrink']:.0f} % each", "",
                  f"≤ {t['seconds']:.0f}", ""]
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
    m = score_case(rep, truth)
    mark = ("ok " if m["both"] else "1/2") if m["top1"] else "BAD"
    err = f"  error: {b['error']}" if b.get("error") else ""
    print(f"{name}  {mark} truth {_vkey(truth['effect']):<18s} verdict {_vkey(rep.get('verdict')):<18s} "
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
