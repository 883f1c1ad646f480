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

``vibroscope compare MODES_A MODES_B [--json FILE] [--out DIR]`` compares two mode sets instead
(test vs model, or two tests for mode tracking): each is a UFF 55 file, a model file or a
``MODES.json`` (:func:`vibroscope.io.mode_sets.read_mode_set`). The modes are paired by MAC and
frequency (:func:`vibroscope.modal.compare.compare_mode_sets`), whatever their order; the pairs,
frequency differences and MACs are printed, the MAC matrix written as a PNG.
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
        help="compare two mode sets (MAC, paired modes, frequency differences), or overlay step and Bode "
             "characteristics of a model over a parameter sweep (CSV) and print influence coefficients",
        description="Two forms. `compare MODES_A MODES_B`: two mode sets (UFF 55, a model file, a MODES.json of "
                    "`vibroscope modal --json`), test vs model or test vs test; the modes are paired by MAC and "
                    "frequency whatever their order; prints the pairs with f_B - f_A and the MAC, writes the MAC "
                    "matrix as compare_<A>_<B>.png. `compare MODEL --sweep PARAMS.csv`: a model over a parameter sweep.",
    )
    p.add_argument("model", metavar="MODEL|MODES", nargs="+",
                   help=f"with --sweep: a built-in model ({', '.join(BUILTINS)}) or a TOML model file; without: "
                        f"two mode sets A B (UFF 55 .unv/.uff, model .toml, MODES.json)")
    p.add_argument("--sweep", metavar="PARAMS.csv",
                   help="CSV with a header of parameter names (SI units; dotted TOML keys for a model file) and one row per case")
    p.add_argument("--out", default=".", metavar="DIR",
                   help="folder for compare_<model>.png or compare_<A>_<B>.png (default: .)")
    p.add_argument("--rrd", default=None, metavar="FILE", help="also save a rerun recording of a sweep (needs rerun-sdk)")
    p.add_argument("--json", default=None, metavar="FILE", help="two mode sets: write the comparison (pairs, MAC matrix)")
    p.add_argument("--mac-min", type=float, default=0.5,
                   help="two mode sets: smallest MAC of a pair (default 0.5)")
    p.add_argument("--max-df", type=float, default=50.0, metavar="PERCENT",
                   help="two mode sets: largest frequency difference of a pair in %% of f_A (default 50)")
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

    names = list(args.model) if isinstance(args.model, (list, tuple)) else [args.model]
    if args.sweep is None:
        if len(names) != 2:
            raise VibroscopeError(f"compare needs two mode sets A B (got {len(names)}: {names}), or one MODEL "
                                  f"with --sweep PARAMS.csv")
        return compare_modes(args, names)
    if len(names) != 1:
        raise VibroscopeError(f"--sweep compares one MODEL over a parameter sweep (got {len(names)}: {names}); "
                              f"two mode sets are compared without --sweep")
    if getattr(args, "json", None):
        raise VibroscopeError("--json is for two mode sets, not for a --sweep")
    args.model = names[0]
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


def compare_modes(args, names: list[str]) -> int:
    """``compare A B`` of two mode sets: print the pairs, write the MAC figure and ``--json``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``out``, ``json``, ``mac_min``, ``max_df``, ``rrd``).
    names : list of str
        The two mode-set files, A then B.

    Returns
    -------
    int
        0.

    Raises
    ------
    VibroscopeError
        When a file is not a mode set, an output is an input, or the sets share no points.
    """
    import json
    import math

    from vibroscope.commands._outputs import AtomicOutputs, check_out_dir, check_outputs
    from vibroscope.io.mode_sets import read_mode_set
    from vibroscope.provenance import json_report
    from vibroscope.modal.compare import compare_mode_sets

    if args.rrd:
        raise VibroscopeError(f"--rrd is for a --sweep; show each mode set in rerun with `vibroscope modal {names[0]}`")
    if not (math.isfinite(args.mac_min) and 0 <= args.mac_min <= 1):
        raise VibroscopeError(f"--mac-min {args.mac_min:g}: must be in [0, 1]")
    if not (math.isfinite(args.max_df) and args.max_df > 0):
        raise VibroscopeError(f"--max-df {args.max_df:g}: must be a positive percentage")
    out = Path(args.out)
    check_out_dir(out)
    a_p, b_p = Path(names[0]), Path(names[1])
    png = out / f"compare_{a_p.stem}_{b_p.stem}.png"
    inputs = {"mode set A": a_p, "mode set B": b_p}
    check_outputs({"--json": args.json, "--out": png}, inputs)
    sets = []
    for p in (a_p, b_p):
        if p.suffix.lower() in (".csv", ".txt") or p.suffix.lower() == ".mcap":
            raise VibroscopeError(f"{p}: not a mode set; identify its modes first (`vibroscope modal {p} --json "
                                  f"MODES.json` or --uff55 FILE), then compare the results")
        sets.append(read_mode_set(p))
    a, b = sets
    try:
        c = compare_mode_sets(a.modes, b.modes, mac_min=args.mac_min, max_frequency_error=args.max_df / 100,
                              labels=(str(a_p), str(b_p)))
    except ValueError as exc:
        raise VibroscopeError(f"{a_p} vs {b_p}: {exc}") from None
    print(f"A {a_p}: {len(a.modes)} modes ({a.format}); B {b_p}: {len(b.modes)} modes ({b.format}); MAC on "
          f"{len(c.points)} common points (matched by {c.matched_by})")
    if c.matched_by == "order":
        pairs = [f"{pa}={pb}" for pa, pb in zip(a.modes.points, b.modes.points)]
        print(f"no point name in common: the k-th point of A is taken as the k-th of B ({', '.join(pairs[:6])}"
              f"{', ...' if len(pairs) > 6 else ''}); check that this is the same place and direction")
    print("| A | f_A [Hz] | B | f_B [Hz] | f_B - f_A [Hz] | [%] | MAC | zeta_A [%] | zeta_B [%] |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for (i, j), d, e, m in zip(c.pairs, c.frequency_difference_hz, c.frequency_difference, c.mac_pairs):
        print(f"| {i + 1} | {c.frequencies_a[i]:.4f} | {j + 1} | {c.frequencies_b[j]:.4f} | {d:+.4f} | "
              f"{100 * e:+.2f} | {m:.3f} | {100 * c.damping_a[i]:.3f} | {100 * c.damping_b[j]:.3f} |")
    for lab, idx, f in (("A", c.unpaired_a, c.frequencies_a), ("B", c.unpaired_b, c.frequencies_b)):
        if len(idx):
            print(f"unpaired in {lab} (no partner with MAC >= {args.mac_min:g} within {args.max_df:g} %): "
                  + ", ".join(f"{k + 1} ({f[k]:.4g} Hz)" for k in idx))
    done = []
    with AtomicOutputs(inputs=[a_p, b_p]) as tx:
        from vibroscope.viewers.figures import plot_mode_set_comparison, save_figure as _save

        _save(plot_mode_set_comparison(c), tx.file(png))
        done.append(f"wrote {png}")
        if args.json:
            tx.file(args.json).write_text(json.dumps(json_report(c.to_dict()), indent=2))
            done.append(f"wrote {args.json}")
    for line in done:
        print(line)
    return 0
