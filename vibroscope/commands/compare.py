"""``vibroscope compare MODEL --sweep PARAMS.csv [--out DIR] [--rrd FILE]``.

The founding paper's comparative-analysis instrument: "input data from file where one
parameter changes".  Each row of PARAMS.csv (a header of parameter names, SI units) is one
case; the command overlays the step (indicial) responses and the Bode characteristics of
every case in one PNG, optionally logs them to a rerun ``.rrd`` recording, and prints the
influence coefficients (paper eq. 2-3) of each changed parameter, computed between the
first row (initial) and each later row (final).

MODEL is a built-in name -- ``pneumatic``, ``hydraulic``, ``block-schema`` (see
:mod:`vibroscope.instruments.sweeps`) -- or a TOML model file read by
:func:`vibroscope.models.modelfile.load_model`, whose sweep columns are dotted keys into
the file (``dof.m1.mass``, ``element.0.k``, ``den.2``); the system compared is then its
first-input / first-output transfer function (linear part).

The command composes :func:`vibroscope.instruments.sweeps.sweep` (the numbers) with
:mod:`vibroscope.viewers.instruments` (the PNG and the recording).
"""

from __future__ import annotations

import csv
from pathlib import Path

from vibroscope.errors import VibroscopeError

BUILTINS = ("pneumatic", "hydraulic", "block-schema")


def add_parser(sub) -> None:
    """Register the ``compare`` sub-command.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The sub-parsers of the ``vibroscope`` parser.
    """
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


def _model(name: str):
    """The sweep model: a built-in name or a TOML model file."""
    from vibroscope.instruments.sweeps import builtin_sweep_model, model_file_sweep_model

    if name in BUILTINS:
        return builtin_sweep_model(name)
    path = Path(name)
    if not path.is_file():
        raise VibroscopeError(f"{name}: neither a built-in model ({', '.join(BUILTINS)}) nor a model file")
    try:
        return model_file_sweep_model(path)
    except UnicodeDecodeError as exc:
        raise VibroscopeError(f"{path}: not a text (UTF-8) model file: byte {exc.start} is not UTF-8") from None


def _read_sweep(path: Path) -> tuple[list[str], list[dict[str, float]]]:
    """Header and cases of the sweep CSV (``#`` comment lines and blank lines skipped)."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise VibroscopeError(f"{path}: cannot read the sweep file ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise VibroscopeError(f"{path}: not a CSV sweep file (byte offset {exc.start} is not UTF-8 text)") from None
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


def _print_tables(result) -> None:
    """The criteria of every case and the influence coefficients, as Markdown tables."""
    from vibroscope.instruments.sweeps import CRITERIA

    units = {"t_r": "s", "a_max": result.model.a_max_unit, "nu_r": "Hz", "nu_c": "Hz"}
    print("\ncase criteria (t_r: 10-90 % rise time; a_max: peak acceleration of the step; nu_r: resonance; nu_c: -3 dB)")
    print("| case | " + " | ".join(f"{n} [{units[n]}]" if units[n] else n for n in CRITERIA) + " |")
    print("|---|" + "---:|" * len(CRITERIA))
    for lab, c in zip(result.labels, result.criteria):
        print(f"| {lab} | " + " | ".join(f"{c[n]:.4g}" for n in CRITERIA) + " |")
    print("\ninfluence coefficients C = R_PCD / R_PCF (paper eq. 2-3), first row -> each later row")
    print("| change | " + " | ".join(CRITERIA) + " |")
    print("|---|" + "---:|" * len(CRITERIA))
    first = result.cases[0]
    for k, (h, changed, values) in enumerate(result.influence_rows(), start=1):
        if values is None:
            print(f"| row {k + 1}: {len(changed)} parameters changed ({', '.join(changed) or 'none'}) | "
                  + " | ".join("-" for _ in CRITERIA) + " |")
        else:
            print(f"| {h}: {first[h]:g} -> {result.cases[k][h]:g} | " + " | ".join(f"{v:+.3f}" for v in values) + " |")


def run(args) -> int:
    """Run the comparison; returns the exit status.

    The PNG (``<out>/compare_<model>.png``) and ``--rrd`` are checked against the model file and
    the sweep CSV before any work, and written under temporary names renamed when complete
    (:mod:`vibroscope.commands._outputs`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Raises
    ------
    VibroscopeError
        When an output is an input file, the model or the sweep file is invalid.
    """
    from vibroscope.commands._outputs import AtomicOutputs, check_out_dir, check_outputs
    from vibroscope.instruments.sweeps import sweep
    from vibroscope.viewers.instruments import figure_sweep, log_sweep

    inputs = {"sweep file": args.sweep, "model file": None if args.model in BUILTINS else args.model}
    out = Path(args.out)
    check_out_dir(out)
    check_outputs({"--rrd": args.rrd}, inputs)
    model = _model(args.model)
    png_path = out / f"compare_{model.name}.png"
    check_outputs({"--out": png_path}, inputs)
    header, cases = _read_sweep(Path(args.sweep))
    import warnings

    import numpy as np

    try:
        with warnings.catch_warnings():  # a badly conditioned model is judged by its criteria below
            warnings.simplefilter("ignore", category=Warning)
            result = sweep(model, header, cases)
    except ValueError as exc:
        raise VibroscopeError(f"{args.sweep}: {exc}") from None
    for k, (case, crit) in enumerate(zip(cases, result.criteria), start=2):
        bad = [n for n, v in crit.items() if not np.isfinite(v)]
        if {"t_r", "nu_c"} <= set(bad):  # no rise time and no cut-off (nu_r alone may be absent: no
            # resonance): parameters the model cannot take (a mass of 1e300 kg), no number to compare
            raise VibroscopeError(f"{args.sweep}: line {k} ({', '.join(f'{h}={v:g}' for h, v in case.items())}): the "
                                  f"model's criteria {bad} are not finite numbers with these parameters (values far "
                                  f"outside the model's range?)")

    done = []
    with AtomicOutputs(inputs=[p for p in inputs.values() if p]) as tx:
        figure_sweep(result, tx.file(png_path),
                     title=f"vibroscope compare: model {model.name!r}, sweep {Path(args.sweep).name}")
        done.append(f"wrote {png_path}")
        if args.rrd:
            rrd = log_sweep(result, tx.file(args.rrd), model.name)
            done.append(f"wrote {args.rrd}" if rrd else f"rerun-sdk not installed: {args.rrd} not written")
    for line in done:
        print(line)
    _print_tables(result)
    return 0
