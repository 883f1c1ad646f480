"""``vibroscope simulate``: drive a model file with an excitation or a recorded input and
write the result as a ROS 2 MCAP log, like a real recording.

    vibroscope simulate MODEL.toml (--excitation SPEC | --input LOG.mcap) --out LOG.mcap
                        [--fs HZ] [--duration S] [--noise REL] [--seed N]

With ``--input``, the model's input channels (``[[input]] channel``) are read from the log
and the model is driven by them sample for sample (output sample k belongs to input
sample k; between samples the input is reconstructed band-limited, not held).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_parser", "run", "simulate_to_signals"]

#: ``vibroscope simulate --help``: the module docstring in plain text (argparse prints no reST)
_DESCRIPTION = """\
Drive a model file with an excitation or a recorded input and write the result as a
ROS 2 MCAP log, like a real recording.

With --input, the model's input channels ([[input]] channel) are read from the log and
the model is driven by them sample for sample (output sample k belongs to input sample k;
between samples the input is reconstructed band-limited, not held)."""


def add_parser(sub) -> None:
    """Register ``simulate`` on the CLI's sub-parsers.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The sub-parsers of the ``vibroscope`` parser.
    """
    p = sub.add_parser(
        "simulate",
        help="simulate a model file (TOML) under an excitation or a logged input, write a ROS 2 MCAP",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", type=Path, metavar="MODEL.toml", help="model file (kind = lumped | transfer_function | modal)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--excitation",
        metavar="SPEC",
        help='e.g. "random:fmin=1,fmax=200,rms=10", "multisine:fmin=1,fmax=200,lines=odd,rms=5", '
        '"sweep:f0=1,f1=200,amplitude=10", "impact:peak=100,duration=0.002", "step:amplitude=1"',
    )
    src.add_argument("--input", type=Path, metavar="LOG.mcap", help="drive the model with its input channels from this log")
    p.add_argument("--out", type=Path, required=True, metavar="LOG.mcap", help="output MCAP file")
    p.add_argument("--fs", type=float, default=None, help="sample rate in Hz (default 1000; with --input: the log's)")
    p.add_argument("--duration", type=float, default=None, help="record length in s with --excitation (default 60)")
    p.add_argument("--noise", type=float, default=0.0, help="output noise, relative to each output channel's RMS")
    p.add_argument("--seed", type=int, default=None, help="seed of the excitation and the noise")
    p.add_argument("--t0", type=float, default=1_700_000_000.0, help="first time stamp in s with --excitation")
    p.set_defaults(func=run)


def simulate_to_signals(model, *, excitation=None, input_log=None, fs=None, duration=None, noise=0.0, seed=None,
                        t0=1_700_000_000.0):
    """The simulated :class:`~vibroscope.signals.Signals` (inputs then outputs).

    Parameters
    ----------
    model : LumpedModel, TransferFunctionModel or PoleResidueModel
        The model to simulate (:func:`vibroscope.models.simulate.simulate`).
    excitation : str, optional
        An excitation spec (:func:`~vibroscope.models.excitation.parse_excitation`), generated
        for each input with its own seed.
    input_log : str or path-like, optional
        An MCAP log whose channels named by ``model.input_channels()`` are the inputs
        (instead of `excitation`); its rate and start time are used.
    fs : float, optional
        Sampling frequency in Hz; default 1000 with `excitation`, the log's highest topic
        rate with `input_log`.
    duration : float, optional
        Record length in s with `excitation`; default 60. Ignored with `input_log`.
    noise : float, optional
        Gaussian output noise, standard deviation relative to each output channel's RMS,
        >= 0; default 0.
    seed : int, optional
        Seed of the excitation and the noise; default None (not reproducible).
    t0 : float, optional
        Time of the first sample in s with `excitation`; default 1.7e9 (Unix time, 2023-11).

    Returns
    -------
    Signals
        With ``meta["excitation"]`` or ``meta["input_log"]`` set.

    Raises
    ------
    ValueError
        If neither or both of `excitation` and `input_log` are given, or `noise` < 0.
    vibroscope.errors.ChannelError
        If an input channel of `input_log` has missing samples (a gap, a lost chunk): the
        message names the log, the channel and the first gap.
    """
    import numpy as np

    from vibroscope.models.excitation import parse_excitation
    from vibroscope.models.simulate import simulate

    if (excitation is None) == (input_log is None):
        raise ValueError("give exactly one of excitation and input_log")
    if noise < 0:
        raise ValueError(f"{noise=} must be >= 0")
    n_in = len(model.inputs)
    if excitation is not None:
        fs = 1000.0 if fs is None else float(fs)
        duration = 60.0 if duration is None else float(duration)
        n = int(round(duration * fs))
        exc = parse_excitation(excitation)
        rng = np.random.default_rng(seed)
        seeds = rng.integers(2**31, size=n_in + 1)
        u = np.array([exc.generate(fs, n, seed=int(s)) for s in seeds[:n_in]])
        sig = simulate(model, u, fs, t0=t0, noise=noise, seed=int(seeds[-1]))
        return sig.with_meta(excitation=excitation)
    from vibroscope.io import read_mcap

    log = read_mcap(input_log, channels=model.input_channels(), fs=fs)
    for c, row in zip(log.channels, log.data):
        bad = ~np.isfinite(row)
        if bad.any():  # a model is not driven through a gap: the input there is unknown, never invented
            from vibroscope.errors import ChannelError
            from vibroscope.signals import true_runs

            a, b = true_runs(bad)
            raise ChannelError(
                f"{input_log}: input {c}: {int(bad.sum())} of {row.size} samples missing in {a.size} gap(s), the first "
                f"{a[0] / log.fs:.4g}–{b[0] / log.fs:.4g} s after the start: a model cannot be driven through a gap; "
                f"simulate a stretch without one (the longest is {_longest(~bad) / log.fs:.4g} s)")
    sig = simulate(model, log.data, log.fs, t0=log.t0, noise=noise, seed=seed)
    return sig.with_meta(input_log=str(input_log))


def _longest(good: np.ndarray) -> int:
    """Samples of the longest run of True in `good`."""
    from vibroscope.signals import true_runs

    a, b = true_runs(good)
    return int((b - a).max(initial=0))


def _check_options(args) -> None:
    """Refuse non-finite, non-positive or huge numbers in the options before any work."""
    import math

    from vibroscope.errors import VibroscopeError

    for opt in ("fs", "duration"):
        v = getattr(args, opt)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise VibroscopeError(f"--{opt} {v:g}: must be a positive, finite number")
    if not (math.isfinite(args.noise) and args.noise >= 0):
        raise VibroscopeError(f"--noise {args.noise:g}: must be a finite number >= 0")
    if not math.isfinite(args.t0):
        raise VibroscopeError(f"--t0 {args.t0:g}: must be a finite time in s")
    if args.excitation is not None:
        n = (1000.0 if args.fs is None else args.fs) * (60.0 if args.duration is None else args.duration)
        if not 2 <= n <= 1e9:
            raise VibroscopeError(f"--duration x --fs: {n:.4g} samples; between 2 and 1e9 can be simulated")


def run(args) -> int:
    """Run ``vibroscope simulate``; returns the exit status.

    ``--out`` is checked against the model file and the ``--input`` log before any work and
    written under a temporary name renamed when complete (:mod:`vibroscope.commands._outputs`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Raises
    ------
    VibroscopeError
        When ``--out`` is an input file; ModelFileError when the model cannot be simulated.
    """
    from vibroscope.commands._outputs import AtomicOutputs, check_outputs
    from vibroscope.errors import ModelFileError
    from vibroscope.io import write_ros2_mcap
    from vibroscope.models.modelfile import load_model

    check_outputs({"--out": args.out}, {"model file": args.model, "--input log": args.input})
    _check_options(args)
    model = load_model(args.model)
    try:
        sig = simulate_to_signals(
            model,
            excitation=args.excitation,
            input_log=args.input,
            fs=args.fs,
            duration=args.duration,
            noise=args.noise,
            seed=args.seed,
            t0=args.t0,
        )
    except ValueError as exc:
        raise ModelFileError(f"{args.model}: cannot simulate: {exc}") from None
    with AtomicOutputs(inputs=[args.model, args.input]) as tx:
        write_ros2_mcap(tx.file(args.out), sig)
    print(
        f"wrote {args.out}: {sig.n_channels} channels x {sig.n_samples} samples at {sig.fs:g} Hz "
        f"({', '.join(sig.channels)})",
        file=sys.stdout,
    )
    return 0
