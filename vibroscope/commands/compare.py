"""``vibroscope compare MODEL --sweep PARAMS.csv [--out DIR] [--rrd FILE]``.

The founding paper's comparative-analysis instrument: "input data from file where one
parameter changes".  Each row of PARAMS.csv (a header of parameter names, SI units) is one
case; the command overlays the step (indicial) responses and the Bode characteristics of
every case in one PNG, optionally logs them to a rerun ``.rrd`` recording, and prints the
influence coefficients (paper eq. 2-3) of each changed parameter, computed between the
first row (initial) and each later row (final).

MODEL is a built-in name -- ``pneumatic`` (velocity per air flow of the pneumatic motor),
``hydraulic`` (P position loop of the valve-controlled cylinder, parameters of
``HYDRAULIC_NOMINAL`` plus ``k_p``), ``block-schema`` (closed loop y/r of the PI + PT1
correction schema with a PT2 plant, parameters ``K``, ``omega_n``, ``zeta``) -- or a TOML
model file read by :func:`vibroscope.models.modelfile.load_model`, whose sweep columns are
dotted keys into the file (``dof.m1.mass``, ``element.0.k``, ``den.2``); the system
compared is then its first-input / first-output transfer function (linear part).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

from vibroscope.errors import VibroscopeError

BUILTINS = ("pneumatic", "hydraulic", "block-schema")


def add_parser(sub) -> None:
    """Register the ``compare`` sub-command."""
    p = sub.add_parser(
        "compare",
        help="overlay step and Bode characteristics of a model over a parameter sweep (CSV), print influence coefficients",
    )
    p.add_argument("model", metavar="MODEL", help=f"built-in model ({', '.join(BUILTINS)}) or a TOML model file")
    p.add_argument("--sweep", required=True, metavar="PARAMS.csv",
                   help="CSV with a header of parameter names (SI units; dotted TOML keys for a model file) and one row per case")
    p.add_argument("--out", default=".", metavar="DIR", help="folder for compare_<model>.png (default: .)")
    p.add_argument("--rrd", default=None, metavar="FILE", help="also save a rerun recording (needs rerun-sdk)")
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- models


def _builtin(name: str):
    """(factory(**params) -> TransferFunction, nominal dict, derivative order to acceleration, labels)."""
    import control

    import vibroscope.models.paper as paper

    if name == "pneumatic":
        nominal = dict(paper.PNEUMATIC_NOMINAL)
        return (lambda **p: paper.pneumatic_motor(**p, output="velocity")), nominal, 1, ("velocity per flow", "m/s per m³/s")
    if name == "hydraulic":
        nominal = dict(paper.HYDRAULIC_NOMINAL, k_p=paper.hydraulic_comparison().gains_p["k_p"])

        def hyd(k_p, **p):
            return paper.hydraulic_closed_loop(k_p, **p)

        return hyd, nominal, 2, ("position x/r", "-")
    if name == "block-schema":
        nominal = {"K": 1.0, "omega_n": 5.0, "zeta": 0.7}

        def bs(K, omega_n, zeta):
            plant = control.tf([K], [1.0 / omega_n**2, 2.0 * zeta / omega_n, 1.0])
            return paper.paper_block_schema(plant=plant).transfer("y")

        return bs, nominal, 2, ("plant output y/r", "-")
    raise KeyError(name)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _toml_dumps(doc: dict) -> str:
    """Minimal TOML writer for model files: scalars, lists, tables and arrays of tables."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, (dict, list)) or
             (isinstance(v, list) and not (v and isinstance(v[0], dict)))]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines += ["", f"[[{k}]]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"


def _set_dotted(doc: dict, key: str, value: float, path: Path) -> None:
    """Set ``key`` (``mass`` / ``dof.m1.mass`` / ``element.0.k`` / ``num.1``) in the parsed TOML."""
    parts = key.split(".")
    cur = doc
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(cur, list):
            if part.lstrip("-").isdigit():
                idx = int(part)
            else:  # array of tables addressed by its "name"
                names = [t.get("name") if isinstance(t, dict) else None for t in cur]
                if part not in names:
                    raise VibroscopeError(f"{path}: sweep column {key!r}: no entry named {part!r}")
                idx = names.index(part)
            if not -len(cur) <= idx < len(cur):
                raise VibroscopeError(f"{path}: sweep column {key!r}: index {idx} out of range")
            if last:
                cur[idx] = value
            else:
                cur = cur[idx]
        elif isinstance(cur, dict):
            if part not in cur:
                raise VibroscopeError(f"{path}: sweep column {key!r}: no key {part!r} in the model file")
            if last:
                cur[part] = value
            else:
                cur = cur[part]
        else:
            raise VibroscopeError(f"{path}: sweep column {key!r}: {part!r} is below a value")


def _toml_model(path: Path):
    """A model-file factory: sweep columns are dotted TOML keys overriding the file's values.

    Examples of columns: ``dof.m1.mass`` (array of tables addressed by ``name``),
    ``element.0.k`` (by index), ``den.2`` (a list entry).  The system compared is the
    first-input / first-output transfer function (the linear part of a lumped model).
    """
    import copy
    import tomllib

    try:
        from vibroscope.models.modelfile import load_model, loads_model
    except ImportError as exc:
        raise VibroscopeError(
            f"{path}: TOML model files need vibroscope.models.modelfile, which is not available ({exc})"
        ) from None
    load_model(path)  # validate once, with the file's own error messages
    doc = tomllib.loads(path.read_text())

    def factory(**overrides):
        import control

        from vibroscope.models.lti import clean_tf

        d = copy.deepcopy(doc)
        for k, v in overrides.items():
            _set_dotted(d, k, v, path)
        m = loads_model(_toml_dumps(d), path=str(path))
        if hasattr(m, "state_space"):
            return clean_tf(m.state_space()[0, 0])
        return control.tf(m.tf())

    return factory, {}, 2, ("output per input", "")


def _read_sweep(path: Path) -> tuple[list[str], list[dict[str, float]]]:
    try:
        text = path.read_text()
    except OSError as exc:
        raise VibroscopeError(f"{path}: cannot read the sweep file ({exc.strerror})") from None
    rows = [r for r in csv.reader(line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#"))]
    if len(rows) < 2:
        raise VibroscopeError(f"{path}: a sweep needs a header line of parameter names and at least one row")
    header = [h.strip() for h in rows[0]]
    cases = []
    for k, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise VibroscopeError(f"{path}: line {k} has {len(r)} fields, the header has {len(header)}")
        try:
            cases.append({h: float(v) for h, v in zip(header, r)})
        except ValueError:
            raise VibroscopeError(f"{path}: line {k}: a value is not a number: {r}") from None
    return header, cases


# --------------------------------------------------------------------------- run


def run(args) -> int:
    """Run the comparison; returns the exit status."""
    import numpy as np

    from vibroscope.models.influence import critical_frequency, peak_acceleration, relative_change, resonance_frequency
    from vibroscope.models.lti import bode, step_response

    name = args.model
    if name in BUILTINS:
        factory, nominal, order, (what, unit) = _builtin(name)
        tag = name
    else:
        path = Path(name)
        if not path.is_file():
            raise VibroscopeError(f"{name}: neither a built-in model ({', '.join(BUILTINS)}) nor a model file")
        factory, nominal, order, (what, unit) = _toml_model(path)
        tag = path.stem
    header, cases = _read_sweep(Path(args.sweep))
    unknown = [h for h in header if nominal and h not in nominal]
    if unknown:
        raise VibroscopeError(f"{args.sweep}: unknown parameter(s) {unknown} for model {name!r}; known: {sorted(nominal)}")

    systems = []
    for k, c in enumerate(cases):
        try:
            systems.append(factory(**{**nominal, **c}))
        except (ValueError, TypeError) as exc:
            raise VibroscopeError(f"{args.sweep}: row {k + 1}: {exc}") from None

    import control

    # common grids from the slowest and fastest poles of all cases
    poles = np.concatenate([control.poles(g) for g in systems])
    poles = poles[np.abs(poles) > 1e-9]
    slow = np.min(np.abs(poles.real[poles.real < 0])) if np.any(poles.real < 0) else 1.0
    fast = np.max(np.abs(poles)) if poles.size else 10.0
    t = np.linspace(0.0, 6.0 / slow, 4001)
    f = np.logspace(np.log10(np.min(np.abs(poles)) / 2 / np.pi) - 1.5, np.log10(fast / 2 / np.pi) + 1, 600)

    labels = [", ".join(f"{h}={c[h]:g}" for h in header) for c in cases]
    steps = [step_response(g, t) for g in systems]
    bodes = [bode(g, f) for g in systems]

    # criteria: t_r, a_max, nu_r, nu_c
    def crit(g, s):
        acc_sys = g if order == 1 else control.tf(np.polymul(np.squeeze(g.num[0][0]), [1.0, 0.0]), g.den[0][0])
        return {
            "t_r": s.rise_time_s,
            "a_max": peak_acceleration(acc_sys, t),
            "nu_r": resonance_frequency(g),
            "nu_c": critical_frequency(g),
        }

    crits = [crit(g, s) for g, s in zip(systems, steps)]

    # figure
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = out / f"compare_{tag}.png"
    fig = plt.figure(figsize=(12, 5.5))
    ax_t = fig.add_subplot(1, 2, 1)
    ax_m = fig.add_subplot(2, 2, 2)
    ax_p = fig.add_subplot(2, 2, 4, sharex=ax_m)
    for s, b, lab in zip(steps, bodes, labels):
        ax_t.plot(s.time_s, s.response, label=lab)
        ax_m.semilogx(b.frequencies_hz, b.magnitude_db, label=lab)
        ax_p.semilogx(b.frequencies_hz, b.phase_deg, label=lab)
    ax_t.set_title(f"step response: {what}")
    ax_t.set_xlabel("time [s]")
    ax_t.set_ylabel(f"{what} [{unit}]" if unit else what)
    ax_m.set_title("Bode")
    ax_m.set_ylabel("magnitude [dB]")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("frequency [Hz]")
    for a in (ax_t, ax_m, ax_p):
        a.grid(True, which="both", alpha=0.3)
    ax_t.legend(fontsize=8)
    fig.suptitle(f"vibroscope compare: model {tag!r}, sweep {Path(args.sweep).name}")
    fig.tight_layout()
    fig.savefig(png, dpi=80)
    plt.close(fig)
    print(f"wrote {png}")

    if args.rrd:
        _log_rerun(Path(args.rrd), tag, labels, steps, bodes)

    # criteria and influence table
    names = ("t_r", "a_max", "nu_r", "nu_c")
    units = {"t_r": "s", "a_max": "m/s² per m³/s" if name == "pneumatic" else "1/s² per unit step",
             "nu_r": "Hz", "nu_c": "Hz"}
    print("\ncase criteria (t_r: 10-90 % rise time; a_max: peak acceleration of the step; nu_r: resonance; nu_c: -3 dB)")
    print("| case | " + " | ".join(f"{n} [{units[n]}]" if units[n] else n for n in names) + " |")
    print("|---|" + "---:|" * len(names))
    for lab, c in zip(labels, crits):
        print(f"| {lab} | " + " | ".join(f"{c[n]:.4g}" for n in names) + " |")
    varied = [h for h in header if len({c[h] for c in cases}) > 1]
    print("\ninfluence coefficients C = R_PCD / R_PCF (paper eq. 2-3), first row -> each later row")
    print("| change | " + " | ".join(names) + " |")
    print("|---|" + "---:|" * len(names))
    for k in range(1, len(cases)):
        changed = [h for h in varied if cases[k][h] != cases[0][h]]
        if len(changed) != 1:
            print(f"| row {k + 1}: {len(changed)} parameters changed ({', '.join(changed) or 'none'}) | " + " | ".join("-" for _ in names) + " |")
            continue
        h = changed[0]
        rp = relative_change(cases[0][h], cases[k][h])
        vals = []
        for n in names:
            a, b = crits[0][n], crits[k][n]
            vals.append(relative_change(a, b) / rp if math.isfinite(a) and math.isfinite(b) and a != 0 else float("nan"))
        print(f"| {h}: {cases[0][h]:g} -> {cases[k][h]:g} | " + " | ".join(f"{v:+.3f}" for v in vals) + " |")
    return 0


def _log_rerun(path: Path, tag: str, labels, steps, bodes) -> None:
    try:
        import rerun as rr
    except ImportError:
        print(f"rerun-sdk not installed: {path} not written")
        return
    import numpy as np

    rec = rr.RecordingStream(f"vibroscope-compare-{tag}")
    for k, (lab, s, b) in enumerate(zip(labels, steps, bodes)):
        ent = f"case_{k + 1}"
        rec.log(f"step/{ent}", rr.SeriesLines(names=lab), static=True)
        rec.send_columns(f"step/{ent}", indexes=[rr.TimeColumn("time", duration=np.asarray(s.time_s))],
                         columns=rr.Scalars.columns(scalars=np.asarray(s.response)))
        rec.log(f"bode_db/{ent}", rr.SeriesLines(names=lab), static=True)
        rec.send_columns(f"bode_db/{ent}", indexes=[rr.TimeColumn("frequency_bin", sequence=np.arange(b.frequencies_hz.size))],
                         columns=rr.Scalars.columns(scalars=np.asarray(b.magnitude_db)))
    rec.save(str(path))
    print(f"wrote {path}")
