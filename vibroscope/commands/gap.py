"""``vibroscope gap MODEL.toml LOG.mcap [LOG2.mcap ...]``: where a model and the real machine
disagree, which unmodelled effect explains it, and how far the gap shrinks once it is added.

    vibroscope gap MODEL.toml LOG.mcap [LOG2.mcap ...] --json REPORT.json [--rrd FILE]
                   [--figures DIR] [--export-model FILE] [--effects E1,E2] [--transient S]

The model's ``[[input]]`` channels are read from each log as the command applied to the
system, its ``[[output]]`` channels as the measured responses. With one log the fit and the
held-out validation are a time split (blocks across a sine sweep, not its end); with several at
one level, the last log is held out; at different levels, each is split so (see --holdout).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    """Register ``gap`` on the CLI's sub-parsers.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The sub-parsers of the ``vibroscope`` parser.
    """
    p = sub.add_parser(
        "gap",
        help="diagnose the sim-to-real gap of a model file against logs",
        description=__doc__.split("\n\n")[0].replace("``", ""),
    )
    p.add_argument("model", type=Path, metavar="MODEL.toml", help="nominal model file (kind = lumped | transfer_function)")
    p.add_argument("logs", type=Path, nargs="+", metavar="LOG.mcap", help="log(s) of the real machine (several: see --holdout)")
    p.add_argument("--json", type=Path, metavar="REPORT.json", help="write the report")
    p.add_argument("--rrd", type=Path, metavar="FILE", help="write a rerun recording of the diagnosis")
    p.add_argument("--figures", type=Path, metavar="DIR", help="write PNG figures there")
    p.add_argument("--export-model", type=Path, metavar="FILE", help="write the augmented model file")
    from vibroscope.gap.effects import EFFECT_TABLE

    p.add_argument("--effects", help="comma-separated effects to try (default: the whole vocabulary: "
                   + ", ".join(EFFECT_TABLE) + ")")
    p.add_argument("--nperseg", type=int, metavar="N",
                   help="FRF segment length in samples (default: one period of a periodic input, else a quarter "
                        "of the nominal model's narrowest half-power bandwidth per line)")
    p.add_argument("--workers", type=int, default=2, metavar="N",
                   help="parallel candidate fits (default 2)")
    p.add_argument("--transient", type=float, metavar="S",
                   help="seconds left out at the start of each log (default: one period for a log of a periodic "
                        "input in steady state from its first sample, else three time constants of the nominal's "
                        "slowest mode, at most 5 %% of the record)")
    p.add_argument("--holdout", choices=("auto", "last"), default="auto",
                   help="several logs: 'auto' holds out the last log when all are at one input level, else the "
                        "end of each log (every level fitted and validated); 'last' always holds out the last log")
    p.add_argument("--output-sampling", choices=("auto", "filtered", "sharp", "point"), default="auto",
                   help="how nonlinear simulations meet the log's rate: 'filtered' (decimated by MATLAB's FIR "
                        "stages), 'sharp' (anti-aliased flat to 0.46 fs: a sigma-delta converter), "
                        "'point' (taken at the sample instants: a sensor without an anti-aliasing filter) or "
                        "'auto' (default: the one that fits the best screened candidate best)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``vibroscope gap``; returns the exit status.

    Every output is checked against the model file and the logs before any work and written
    under a temporary name renamed when complete (:mod:`vibroscope.commands._outputs`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Raises
    ------
    VibroscopeError
        When an output is an input file; ModelFileError when the model cannot be diagnosed.
    """
    from vibroscope.commands._outputs import AtomicOutputs, check_outputs
    from vibroscope.provenance import json_report, toml_header
    from vibroscope.errors import ModelFileError
    from vibroscope.gap import diagnose
    from vibroscope.gap.report import EFFECTS
    from vibroscope.io import read_mcap
    from vibroscope.models.modelfile import load_model

    inputs = {"model file": args.model, "log": list(args.logs)}
    check_outputs({"--json": args.json, "--rrd": args.rrd, "--export-model": args.export_model,
                   "--figures": args.figures}, inputs)
    model = load_model(args.model)
    effects = None
    if args.effects:
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        bad = [e for e in effects if e not in EFFECTS]
        if bad:
            raise ModelFileError(f"--effects: unknown effect(s) {bad}; known: {list(EFFECTS)}")
    from vibroscope.gap.closed_loop import log_channels

    channels = sum(log_channels(model), [])  # closed loop: references in; outputs and commands out
    sigs = [read_mcap(log, channels, progress=not args.no_progress).with_meta(source=str(log)) for log in args.logs]
    try:
        if args.nperseg is not None and args.nperseg < 16:
            raise ValueError(f"--nperseg {args.nperseg} must be at least 16 samples")
        report = diagnose(model, sigs, effects=effects, transient_s=args.transient, nperseg=args.nperseg,
                          holdout=args.holdout, output_sampling=args.output_sampling,
                          workers=max(1, args.workers), progress=not args.no_progress)
    except ValueError as exc:
        raise ModelFileError(f"{args.model}: cannot diagnose: {exc}") from None
    print(report.summary())
    done = []
    with AtomicOutputs(inputs=[args.model, *args.logs]) as tx:
        if args.json:
            tx.file(args.json).write_text(json.dumps(json_report(report.to_dict()), indent=2) + "\n",
                                          encoding="utf-8")
            done.append(f"wrote {args.json}")
        if args.export_model:
            tx.file(args.export_model).write_text(toml_header() + report.augmented_model_toml, encoding="utf-8")
            done.append(f"wrote {args.export_model}")
        if args.figures:
            import matplotlib

            matplotlib.use("Agg")
            report.plot(out_dir=tx.directory(args.figures))
            done.append(f"wrote figures to {args.figures}")
        if args.rrd:
            from vibroscope.viewers.rerun_gap import log_gap_report

            log_gap_report(report, path=tx.file(args.rrd))
            done.append(f"wrote {args.rrd}")
    for line in done:
        print(line)
    sys.stdout.flush()
    return 0
