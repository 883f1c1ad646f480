#!/usr/bin/env python
"""Score `vibroscope gap` on the cases written by gen.py.

Usage:
    python score.py cases_1 [--seed 1] [--resume] [--timeout 1200]

Runs, one case at a time,
    vibroscope gap MODEL.toml LOG... --json report.json --no-progress
records the verdict, wall seconds and whether it equals the true class, and writes
results_<seed>.json and results_<seed>.md next to the cases folder (updated after every case).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
VIBROSCOPE = os.environ.get("VIBROSCOPE") or shutil.which("vibroscope") or "vibroscope"
CLASSES = ["none", "parameter_mismatch", "extra_mode", "time_delay", "coulomb_friction",
           "backlash", "hysteresis", "cubic_stiffness", "saturation"]


def verdict_list(v):
    if v is None:
        return []
    if isinstance(v, str):
        return [v]
    return list(v)


def key_numbers(rep):
    out = dict(gap_before=rep.get("gap_before"), gap_refit=rep.get("gap_refit"),
               gap_after=rep.get("gap_after"), noise_floor=rep.get("noise_floor"),
               shrink=rep.get("shrink"), bands=rep.get("bands"), validation=rep.get("validation"),
               shares=rep.get("shares"))
    v = verdict_list(rep.get("verdict"))
    cands = rep.get("candidates") or []
    winners = []
    for eff in v:
        for c in cands:
            if c.get("effect") == eff:
                winners.append(dict(effect=eff, where=c.get("where"), parameters=c.get("parameters"),
                                    gap_after=c.get("gap_after"), score=c.get("score"),
                                    vanished=c.get("vanished")))
                break
    out["winners"] = winners
    out["top_candidates"] = [dict(effect=c.get("effect"), where=c.get("where"),
                                  parameters=c.get("parameters"), gap_after=c.get("gap_after"),
                                  score=c.get("score"), vanished=c.get("vanished"))
                             for c in cands[:5]]
    # the best candidate of the true class is added by the caller
    return out


def fmt(x, f="{:.4f}"):
    return "-" if x is None else f.format(x)


def run_case(case_dir, timeout):
    truth = json.load(open(os.path.join(case_dir, "truth.json")))
    logs = [os.path.join(case_dir, lg["file"]) for lg in truth["logs"]]
    rep_path = os.path.join(case_dir, "report.json")
    if os.path.exists(rep_path):
        os.remove(rep_path)
    cmd = [VIBROSCOPE, "gap", os.path.join(case_dir, "model.toml"), *logs, "--json", rep_path,
           "--no-progress"]
    t0 = time.time()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        rc, stdout, stderr = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as e:
        rc, stdout, stderr = "timeout", (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or ""), ""
    secs = time.time() - t0
    with open(os.path.join(case_dir, "gap_stdout.txt"), "w") as fh:
        fh.write(stdout or "")
        fh.write("\n--- stderr ---\n")
        fh.write(stderr or "")
    res = dict(case=truth["case"], truth_class=truth["cls"], truth_location=truth["effect"].get("location"),
               truth_effect=truth["effect"], noise_free_gap=truth["noise_free_gap"],
               noise_free_gap_per_log=truth["noise_free_gap_per_log"], n_logs=len(logs),
               excitation=truth["excitation"], levels=[lg["level"] for lg in truth["logs"]],
               noise_fraction=truth["noise_fraction"], nominal_fn_hz=truth["nominal"]["fn_hz"],
               nominal_zeta=truth["nominal"]["zeta"], n_dof=truth["nominal"]["n"],
               command=" ".join(cmd), rc=rc, seconds=secs)
    if rc == 0 and os.path.exists(rep_path):
        rep = json.load(open(rep_path))
        v = verdict_list(rep.get("verdict"))
        res["verdict"] = v
        res["correct"] = (v == [truth["cls"]])
        res["contains_truth"] = truth["cls"] in v
        res["report"] = key_numbers(rep)
        same = [c for c in (rep.get("candidates") or []) if c.get("effect") == truth["cls"]]
        if same:
            c = same[0]
            res["report"]["best_true_class_candidate"] = dict(
                rank=(rep["candidates"].index(c) + 1), where=c.get("where"), parameters=c.get("parameters"),
                gap_after=c.get("gap_after"), score=c.get("score"), vanished=c.get("vanished"))
        res["tool_seconds"] = (rep.get("timings_s") or {}).get("total")
    else:
        res["verdict"] = None
        res["correct"] = False
        res["contains_truth"] = False
        res["error_tail"] = ((stdout or "") + "\n" + (stderr or ""))[-3000:]
    return res


def location_right(r):
    """Whether the first named effect sits where the truth's does (None where not applicable)."""
    if not r.get("correct") or r["truth_class"] in ("none", "parameter_mismatch", "time_delay", "saturation"):
        return None
    w = (r.get("report") or {}).get("winners") or []
    if not w:
        return None
    where = w[0].get("where") or {}
    loc = r["truth_location"]
    if isinstance(loc, list):
        return sorted(where.get("between") or []) == sorted(loc)
    return where.get("dof") == loc


def summarise(results, seed, cases_dir):
    L = [f"# vibroscope gap — independent benchmark, seed {seed}", "",
         f"cases: `{cases_dir}`; {len(results)} scored; tool: `{VIBROSCOPE}`", ""]
    L += ["| class | right / cases | location right | verdicts |", "|---|---|---|---|"]
    tot_ok = 0
    for cls in CLASSES:
        rs = [r for r in results if r["truth_class"] == cls]
        if not rs:
            continue
        ok = sum(r["correct"] for r in rs)
        tot_ok += ok
        vs = ", ".join("+".join(r["verdict"]) if r["verdict"] else f"ERROR({r['rc']})" for r in rs)
        locs = [location_right(r) for r in rs]
        locs = [q for q in locs if q is not None]
        lt = f"{sum(locs)}/{len(locs)}" if locs else "-"
        L.append(f"| {cls} | {ok}/{len(rs)} | {lt} | {vs} |")
    secs = [r["seconds"] for r in results]
    L += ["", f"**overall: {tot_ok}/{len(results)} right**", ""]
    if secs:
        L += [f"wall seconds: median {np.median(secs):.0f}, max {np.max(secs):.0f}, total {np.sum(secs):.0f}", ""]
    # confusion
    L += ["## Misses", ""]
    for r in results:
        if r["correct"]:
            continue
        rp = r.get("report") or {}
        eff = {k: v for k, v in r["truth_effect"].items() if k not in ("law",)}
        L.append(f"### {r['case']}: truth {r['truth_class']} @ {r['truth_location']} -> verdict "
                 f"{'+'.join(r['verdict']) if r['verdict'] else 'ERROR ' + str(r['rc'])}")
        L.append(f"- truth: {json.dumps(eff)}")
        L.append(f"- noise-free gap {r['noise_free_gap']:.3f} (per log {[round(g, 3) for g in r['noise_free_gap_per_log']]}), "
                 f"{r['n_logs']} log(s) at levels {r['levels']}, {r['excitation']}, noise {100 * r['noise_fraction']:.1f} %, "
                 f"nominal fn {[round(f, 2) for f in r['nominal_fn_hz']]} Hz, zeta {[round(z, 4) for z in r['nominal_zeta']]}")
        if rp:
            L.append(f"- report: nominal gap {fmt(rp.get('gap_before'))}, refit {fmt(rp.get('gap_refit'))}, "
                     f"best held-out (after) {fmt(rp.get('gap_after'))}, noise floor {fmt(rp.get('noise_floor'))}, "
                     f"bands {json.dumps(rp.get('bands'))}")
            for w in rp.get("winners", []):
                L.append(f"- winner {w['effect']}: where {json.dumps(w['where'])}, params {json.dumps(w['parameters'])}, gap {fmt(w['gap_after'])}")
            bt = rp.get("best_true_class_candidate")
            if bt:
                L.append(f"- true class's best candidate: rank {bt['rank']}, where {json.dumps(bt['where'])}, "
                         f"params {json.dumps(bt['parameters'])}, gap {fmt(bt['gap_after'])}, vanished {bt['vanished']}")
        else:
            L.append(f"- no report: {r.get('error_tail', '')[-500:]!r}")
        L.append(f"- seconds {r['seconds']:.0f}")
        L.append("")
    return "\n".join(L)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("cases_dir")
    ap.add_argument("--seed", default=None)
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--timeout", type=float, default=1800)
    ap.add_argument("--only", default=None, help="comma-separated case ids")
    ap.add_argument("--summary-only", action="store_true", help="rewrite the markdown from results json")
    a = ap.parse_args(argv)
    cases_dir = os.path.abspath(a.cases_dir)
    seed = a.seed
    if seed is None:
        try:
            seed = json.load(open(os.path.join(cases_dir, "index.json")))["seed"]
        except Exception:
            seed = os.path.basename(cases_dir).split("_")[-1]
    out_json = os.path.join(os.path.dirname(cases_dir), f"results_{seed}.json")
    out_md = os.path.join(os.path.dirname(cases_dir), f"results_{seed}.md")
    results = []
    if a.resume and os.path.exists(out_json):
        results = json.load(open(out_json))["results"]
    if a.summary_only:
        results = json.load(open(out_json))["results"]
        open(out_md, "w").write(summarise(results, seed, cases_dir))
        print(summarise(results, seed, cases_dir))
        return
    done = {r["case"] for r in results}
    cases = sorted(d for d in os.listdir(cases_dir) if d.startswith("case_"))
    if a.only:
        cases = [c for c in cases if c in a.only.split(",")]
    for c in cases:
        if c in done:
            continue
        r = run_case(os.path.join(cases_dir, c), a.timeout)
        results.append(r)
        results.sort(key=lambda q: q["case"])
        print(f"{c} {r['truth_class']:18s} -> {'+'.join(r['verdict']) if r['verdict'] else 'ERROR'} "
              f"{'OK' if r['correct'] else 'MISS'} {r['seconds']:.0f}s", flush=True)
        json.dump(dict(seed=seed, cases_dir=cases_dir, results=results), open(out_json, "w"), indent=1,
                  default=float)
        open(out_md, "w").write(summarise(results, seed, cases_dir))
    print(summarise(results, seed, cases_dir))


if __name__ == "__main__":
    main()
