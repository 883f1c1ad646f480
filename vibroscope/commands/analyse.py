"""``vibroscope analyse LOG.mcap``: spectra, FRFs, coherence and modal vectors of a log."""

from __future__ import annotations

import contextlib
import json
import shlex
from pathlib import Path

import numpy as np

from vibroscope._checks import LazyChoices

__all__ = ["add_parser", "run", "analyse_log", "run_stream", "run_fleet", "memory_budget", "whole_read_bytes",
           "parse_size", "stream_report_text", "stream_summary"]

def add_parser(sub) -> None:
    """Register ``analyse`` on the CLI's sub-parsers.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The sub-parsers of the ``vibroscope`` parser.
    """
    p = sub.add_parser(
        "analyse",
        aliases=["analyze"],
        help="spectra, FRFs, coherence and modal vectors of an MCAP log",
        description=(
            "Read an MCAP log (ROS 2 CDR, JSON, protobuf), put the channels on one time grid, and "
            "compute PSDs, the cross-spectral matrix, FRFs with coherence (with --input, or the log's one "
            "force-like channel unless --output-only) and modal "
            "vectors (LSCF + LSFD with a force input, SSI-COV without; the band, orders and physical "
            "modes chosen automatically unless --fmin/--fmax are given). Writes a rerun recording, "
            "PNG figures and, with --json, a machine-readable summary."
        ),
    )
    p.add_argument("log", type=Path, nargs="*",
                   help="the MCAP log (several logs: a fleet analysis, with --dask or on this machine)")
    p.add_argument("--input", help="force channel (message path), e.g. /actuator/force.wrench.force.x; default the "
                                   "log's one force-like channel (a Wrench force, a field in N, or named force/"
                                   "command/input), if it holds exactly one that moves")
    p.add_argument("--output-only", action="store_true",
                   help="ignore any force channel in the log: output-only modal analysis of the responses")
    p.add_argument("--outputs", nargs="+", metavar="PATH",
                   help="response channels (default: every Imu linear_acceleration field)")
    p.add_argument("--coords", type=Path, help="sensor coordinates CSV (channel or sensor number, x, y, z, direction)")
    p.add_argument("--json", type=Path, metavar="SUMMARY.json",
                   help="write the machine-readable summary (a relative path is taken inside --out when given)")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="folder of the default outputs (default: the current directory, never beside the log)")
    p.add_argument("--rrd", type=Path, help="rerun recording to write (default: <out>/<LOG stem>_analyse.rrd; relative: inside --out)")
    p.add_argument("--no-rrd", action="store_true", help="write no rerun recording")
    p.add_argument("--spawn", action="store_true", help="open a rerun viewer")
    p.add_argument("--connect", nargs="?", const="", metavar="URL",
                   help="stream to a running rerun viewer while the log is read: the time series as they arrive "
                        "and the PSD/FRF/coherence refreshed as averages accumulate (default URL: "
                        "rerun+http://127.0.0.1:9876/proxy); then the analysis runs as usual")
    p.add_argument("--figures", type=Path, metavar="DIR", help="PNG figures directory (default: <out>/<LOG stem>_analyse_figures/; relative: inside --out)")
    p.add_argument("--no-figures", action="store_true", help="write no PNG figures")
    p.add_argument("--fs", type=float, help="resample to this rate (Hz); default the highest topic rate")
    p.add_argument("--nperseg", type=int, help="Welch segment length (default: ~16 averages, fine enough for --fmin)")
    p.add_argument("--fmin", type=float, help="lowest frequency searched for modes (Hz)")
    p.add_argument("--fmax", type=float, help="highest frequency analysed (Hz); decimates when well below fs/2")
    p.add_argument("--no-decimate", action="store_true",
                   help="analyse at the log's rate (default: decimate to >= 2.5x the band's top; a periodic input "
                        "only by a factor that divides its period)")
    p.add_argument("--n-modes", type=int, help="number of modes to report")
    p.add_argument("--estimator", default="H1", choices=["H1", "H2", "Hv"], help="FRF estimator (default H1)")
    p.add_argument("--method", default="auto", choices=LazyChoices("vibroscope.modal.methods", "METHOD_CHOICES"),
                   metavar="METHOD", help="modal identification: %(choices)s (the methods of "
                                          "vibroscope.modal.methods by key or result name); default auto: LSCF "
                                          "with --input, SSI-COV without")
    p.add_argument("--select", metavar="F1,F2,..",
                   help="LSCF/SSI-COV: take the modes at these frequencies (Hz) from the stabilization diagram")
    p.add_argument("--ods", type=float, nargs="+", metavar="F",
                   help="operating deflection shapes at these frequencies (Hz), drawn and animated like modes")
    p.add_argument("--progress", action="store_true", help="progress bar while reading")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="print every signal fault (one line per kind) and note (gravity, constant channels); "
                        "default: one line counting the faults per kind (all of them are in --json)")
    p.add_argument("--stream", action="store_true",
                   help="read the log block by block into the spectral accumulators (memory bounded by the block; "
                        "spectra, FRFs and modes from the spectra, drawn and recorded without the time series). "
                        "Chosen "
                        "automatically when the log needs more than --max-memory")
    p.add_argument("--max-memory", metavar="SIZE",
                   help="memory budget for reading a log whole, e.g. 1GB, 512MB (default: half the available "
                        "memory or of the address-space limit, ulimit -v, whichever is smaller)")
    p.add_argument("--dask", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="spread the accumulation of the logs over a Dask cluster (tcp://host:8786; without an "
                        "address a local cluster sized to this machine); writes the fleet table "
                        "(<out>/fleet.csv, fleet.json) and the merged spectra figure")
    p.set_defaults(func=run)


def analyse_log(log: Path, *, input=None, outputs=None, fs=None, progress=False, find_input=False, max_memory=None,
                **kw):
    """Read `log` and run :func:`vibroscope.pipeline.analyse_signals`; returns the Analysis.

    Without `outputs`, the responses are chosen by :func:`vibroscope.io.select.auto_channels`
    (Imu accelerations; else the measurement fields of the busiest topic), and the choice and
    what was skipped (undecodable channels by name) go into the warnings; the log is then
    scanned once (:class:`vibroscope.io.LogIndex`) for both the choice and the read.

    With `find_input` and no `input`, the log's one force-like channel that moves
    (:func:`vibroscope.io.select.find_force_input`: a Wrench force, a field in N, or one named
    force/command/input, outside the responses' topics) is the input; the line saying so (or why
    none was taken) is ``signals.meta["input_choice"]``, printed by :func:`report_text` and
    written to the summary JSON.

    Parameters
    ----------
    log : Path
        The MCAP log.
    input : str, optional
        The force channel (message path); without it the analysis is output-only.
    outputs : sequence of str, optional
        The response channels; default: chosen automatically (see above), at most
        ``MAX_AUTO_CHANNELS`` varying fields when no IMU is found.
    fs : float, optional
        Rate in Hz to resample onto (:func:`vibroscope.io.read_mcap`); default the highest
        topic rate.
    progress : bool, optional
        Show a progress bar while reading; default False.
    find_input : bool, optional
        Without `input`, take the log's one force-like channel as the input (see above);
        default False (output-only without `input`). Only for the methods that use an input
        (:func:`vibroscope.modal.methods.uses_input`).
    max_memory : int, optional
        Memory budget in bytes for reading the log (:func:`vibroscope.io.read_mcap`); default
        half the available memory.
    **kw
        Passed to :func:`vibroscope.pipeline.analyse_signals` (``nperseg``, ``fmin``, ...).

    Returns
    -------
    Analysis
    """
    from vibroscope.errors import VibroscopeError
    from vibroscope.io import LogIndex, read_mcap
    from vibroscope.io.select import MAX_AUTO_CHANNELS, auto_channels, find_force_input
    from vibroscope.pipeline import analyse_signals

    notes, fallback, source, choice = [], False, log, None
    from vibroscope.modal.methods import uses_input

    find_input = find_input and input is None and uses_input(kw.get("method", "auto"))
    if outputs is None or find_input:  # scan the log once: the index serves the choices and the read
        source = LogIndex.open(log, progress=progress, max_memory=max_memory)
    if find_input:
        resp = {source.topic_of(c).topic for c in outputs or ()}
        try:
            found = find_force_input(source, exclude_topics=resp)
            input, choice = found.channel, found.line() or None
        except VibroscopeError as exc:  # the search never stops an output-only analysis
            choice = f"no force input looked for: {exc}"
    if outputs is None:
        # the input's topic holds the force, not a response
        sel = auto_channels(source, exclude_topics=(input.split(".", 1)[0],) if input else ())
        notes.append(f"channels chosen automatically: {sel.reason}")
        notes += [f"{what}: skipped: {why}" for what, why in sel.skipped]
        outputs, fallback = [c for c in sel.channels if c != input], sel.fallback
    sig = read_mcap(source, [input, *outputs] if input else list(outputs), fs=fs, progress=progress,
                    max_memory=max_memory)
    if sig.n_samples < 16:  # not one Welch segment of the shortest length
        raise ValueError(f"the log is too short to analyse: {sig.n_samples} samples on the common grid "
                         f"({sig.duration:.3g} s at {sig.fs:g} Hz); at least 16 are needed")
    if fallback:  # automatic non-IMU choice: keep the fields that move, at most MAX_AUTO_CHANNELS
        finite = {c: sig[c][np.isfinite(sig[c])] for c in outputs}  # NaN marks a gap, not a value
        moving = [c for c in outputs if finite[c].size and finite[c].max() > finite[c].min()]
        if len(moving) > MAX_AUTO_CHANNELS:
            notes.append(f"{len(moving) - MAX_AUTO_CHANNELS} varying fields beyond the first {MAX_AUTO_CHANNELS} "
                         f"not analysed (from {moving[MAX_AUTO_CHANNELS]}); choose with --outputs")
        if len(outputs) > len(moving):
            notes.append(f"{len(outputs) - len(moving)} constant fields not analysed")
        sig = sig.select(([input] if input else []) + moving[:MAX_AUTO_CHANNELS])
    if notes:
        sig = sig.with_meta(warnings=notes + list(sig.meta.get("warnings", [])))
    if choice:
        sig = sig.with_meta(input_choice=choice)
    return analyse_signals(sig, input=input, **kw)


def _takes_log(value: str | None) -> bool:
    """Whether the optional value of ``--dask``/``--connect`` is a log the option swallowed."""
    return bool(value) and (value.endswith(".mcap") or Path(value).is_file())


def run(args) -> int:
    """Run ``vibroscope analyse``; prints the modes found and where the outputs went.

    The outputs go to the current directory or ``--out DIR`` (``<LOG stem>_analyse.rrd``,
    ``<LOG stem>_analyse_figures/``) unless ``--rrd``/``--figures`` name them; every output is
    checked against the inputs before the log is read and written atomically
    (:mod:`vibroscope.commands._outputs`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Raises
    ------
    VibroscopeError
        When an output is an input file (``--json LOG``), or the analysis fails (the log named).
    """
    from vibroscope.commands._options import select_frequencies as _select_freqs
    from vibroscope.commands._outputs import (check_out_dir, check_outputs, default_output, preload_outputs,
                                              preloaded, resolve_outputs)
    from vibroscope.errors import VibroscopeError
    from vibroscope.viewers.ahead import TimeSeriesAhead

    check_out_dir(args.out)
    resolve_outputs(args, ("json", "rrd", "figures"), args.out)  # `--out res --json s.json`: res/s.json
    _check_options(args)
    logs = list(args.log) if isinstance(args.log, (list, tuple)) else [args.log]
    if _takes_log(args.dask):
        logs.insert(0, Path(args.dask))  # `--dask a.mcap b.mcap`: no address, the first log taken by --dask
        args.dask = ""
    live = getattr(args, "connect", None) is not None
    if live and _takes_log(args.connect):
        logs.insert(0, Path(args.connect))  # `--connect a.mcap`: no URL, the log taken by --connect
        args.connect = ""
    if not logs:
        raise VibroscopeError("no log given: vibroscope analyse LOG [LOG ...]")
    if args.dask is not None or len(logs) > 1:
        if live:
            raise VibroscopeError("--connect streams one log to a viewer; a fleet (--dask or several logs) has no "
                                  "live view: give one log, or drop --connect")
        return run_fleet(args, logs)
    args.log = logs[0]
    rrd = None if args.no_rrd else (args.rrd or default_output(args.log, "analyse", ".rrd", args.out))
    figures = None if args.no_figures else (args.figures or default_output(args.log, "analyse", "_figures", args.out))
    check_outputs({"--json": args.json, "--rrd": rrd, "--figures": figures},  # before any work
                  {"log": args.log, "coordinates": args.coords})
    if live:  # the live view first, read block by block (vibroscope.viewers.rerun_live), then the analysis
        from vibroscope.viewers.rerun_live import stream_log

        live_input = grid_input(args.log, args.outputs, args.fs)[0] if looks_for_input(args) else args.input
        try:  # the analysis below takes (and reports) the same force-like input
            stream_log(args.log, url=args.connect or None, input=live_input, outputs=args.outputs, fs=args.fs,
                       nperseg=args.nperseg, estimator=args.estimator)
        except (ValueError, ConnectionError) as exc:
            raise VibroscopeError(f"{args.log}: {exc}") from None
    preload_outputs(rrd=bool(rrd) or args.spawn, figures=bool(figures))  # imported while the analysis runs
    budget = memory_budget(args.max_memory)
    need = whole_read_bytes(args.log)
    if args.stream or need > budget:
        why = ("--stream" if args.stream else
               f"reading it whole needs about {need / 2**20:.0f} MiB, more than the memory budget "
               f"{budget / 2**20:.0f} MiB (--max-memory)")
        print(f"streaming {args.log} block by block: {why}")
        return run_stream(args)
    select = _select_freqs(args.select)
    # what needs only the time series (integrals, signals and kinematics figures) is made in a worker
    # process while the modes are identified on the other core (the background imports joined first:
    # no worker inherits a held import lock)
    ahead = TimeSeriesAhead(figures=bool(figures), kinematics=bool(rrd) or args.spawn)

    def on_signals(sig, outputs) -> None:
        preloaded()
        ahead.start(sig, outputs)

    with ahead:
        try:
            an = analyse_log(args.log, input=args.input, outputs=args.outputs, fs=args.fs, progress=args.progress,
                             find_input=not getattr(args, "output_only", False), nperseg=args.nperseg, fmin=args.fmin,
                             fmax=args.fmax, n_modes=args.n_modes, estimator=args.estimator, method=args.method,
                             select=select, decimation=not getattr(args, "no_decimate", False),
                             max_memory=budget, on_signals=on_signals)
        except ValueError as exc:
            raise VibroscopeError(f"{args.log}: {exc}") from None
        nyq = an.psd.frequencies[-1]
        for f in args.ods or ():  # before the report: nothing is printed as done that will not be written
            if f > nyq:
                raise VibroscopeError(f"--ods {f:g}: above the analysed band's top, {nyq:g} Hz (the Nyquist "
                                      f"frequency of {an.signals.fs:g} Hz)")
        if args.coords:  # the rows against the channels analysed, before the report (one line if they differ)
            from vibroscope.io.coords import read_coords

            read_coords(args.coords, an.settings["outputs"])
        print(report_text(an, source=str(args.log), verbose=getattr(args, "verbose", False)))
        write_outputs(an, args.log, coords=args.coords, json_path=args.json, rrd=rrd, figures=figures,
                      spawn=args.spawn, ods=args.ods, ahead=ahead)
    return 0


def parse_size(text: str) -> int:
    """Bytes of a size such as ``1GB``, ``512MB``, ``1.5G``, ``200000`` (powers of 1024).

    Parameters
    ----------
    text : str
        A number with an optional unit K, M, G, T (with or without B, ``iB``).

    Returns
    -------
    int

    Raises
    ------
    ValueError
        If `text` is not such a size or not positive.
    """
    import re

    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kmgt]?)(i?b)?\s*", str(text), re.I)
    if not m or float(m.group(1)) <= 0:
        raise ValueError(f"{text=} is not a memory size such as 1GB or 512MB")
    return int(float(m.group(1)) * 1024 ** " KMGT".index(m.group(2).upper() or " "))


def memory_budget(max_memory: str | None = None) -> int:
    """The memory (bytes) a log may take when read whole.

    Parameters
    ----------
    max_memory : str, optional
        ``--max-memory`` (:func:`parse_size`); default half the available memory or half the
        address-space limit (``ulimit -v``, ``RLIMIT_AS``), whichever is smaller.

    Returns
    -------
    int

    Raises
    ------
    VibroscopeError
        If `max_memory` is not a size.
    """
    from vibroscope.errors import VibroscopeError

    if max_memory is not None:
        try:
            return parse_size(max_memory)
        except ValueError as exc:
            raise VibroscopeError(f"--max-memory {max_memory}: {exc}") from None
    from vibroscope.io import memory_budget as default_budget

    return default_budget()


def whole_read_bytes(log: Path) -> int:
    """Memory (bytes) that reading `log` whole takes, roughly: the file mapped, plus its chunks
    decompressed (their sizes from the summary; else three times the file), plus the grid.

    Parameters
    ----------
    log : Path
        The MCAP log.

    Returns
    -------
    int
        0 when the file cannot be looked at (the read then says why).
    """
    try:
        size = Path(log).stat().st_size
    except OSError:
        return 0  # the read reports the problem with the file
    try:
        from mcap.reader import SeekingReader

        with open(log, "rb") as fh:
            summ = SeekingReader(fh).get_summary()
        inner = sum(ci.uncompressed_size for ci in summ.chunk_indexes) if summ and summ.chunk_indexes else 3 * size
    except Exception:  # noqa: BLE001 - no usable summary: the rough figure
        inner = 3 * size
    return int(size + 1.5 * inner)


def _needs_time_series(args) -> bool:
    """``--method`` names an output-only method that needs the time series, and no --input is given."""
    from vibroscope.modal.methods import lookup_method

    m = lookup_method(args.method)
    return not args.input and m is not None and m.needs_time_series


def _stream_kw(args) -> dict:
    return dict(input=args.input, outputs=args.outputs, fs=args.fs, nperseg=args.nperseg, fmin=args.fmin,
                fmax=args.fmax, n_modes=args.n_modes, estimator=args.estimator,
                method="auto" if _needs_time_series(args) else args.method, select=None)


def looks_for_input(args) -> bool:
    """Whether ``analyse`` takes the log's force-like channel as the input: no ``--input``, no
    ``--output-only``, and a method that uses an input (as :func:`analyse_log` with `find_input`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    bool
    """
    from vibroscope.modal.methods import uses_input

    return (not getattr(args, "input", None) and not getattr(args, "output_only", False)
            and uses_input(getattr(args, "method", "auto")))


def grid_input(log: Path, outputs=None, fs=None) -> tuple[str | None, str | None]:
    """The force input of a log read block by block (``--stream``, ``--connect``): the one force-like
    channel that moves in the first and last chunks of its topic
    (:meth:`vibroscope.io.blocks.LogGrid.force_input`), as :func:`analyse_log` finds it in a whole
    read.

    Parameters
    ----------
    log : Path
        The MCAP log.
    outputs : sequence of str, optional
        The response channels (their topics are never the input); default chosen automatically.
    fs : float, optional
        Grid rate in Hz; default the highest topic rate.

    Returns
    -------
    tuple of (str or None, str or None)
        (the input's message path, or None; the report's line saying what was taken or why none
        was, or None when the log holds no force-like field).
    """
    from vibroscope.errors import VibroscopeError
    from vibroscope.io.blocks import open_grid

    try:
        found = open_grid(log, outputs, fs=fs).force_input(exclude_channels=outputs or ())
    except (VibroscopeError, ValueError) as exc:  # the search never stops an output-only analysis
        return None, f"no force input looked for: {exc}"
    return found.channel, found.line() or None


def run_stream(args) -> int:
    """``vibroscope analyse --stream LOG``: the log read block by block (:func:`vibroscope.stream.analyse_stream`);
    prints the report and writes the ``--json`` summary, the figures and the rerun recording of the
    spectra, FRFs and modes (:func:`write_outputs`; no time-series figure or entity: a streamed
    analysis never holds the record).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0.

    Raises
    ------
    VibroscopeError
        When the analysis fails (the log named).
    """
    from vibroscope.commands._outputs import check_outputs, default_output
    from vibroscope.commands._options import select_frequencies as _select_freqs
    from vibroscope.errors import VibroscopeError
    from vibroscope.stream import analyse_stream

    rrd = None if args.no_rrd else (args.rrd or default_output(args.log, "analyse", ".rrd", args.out))
    figures = None if args.no_figures else (args.figures or default_output(args.log, "analyse", "_figures", args.out))
    check_outputs({"--json": args.json, "--rrd": rrd, "--figures": figures},
                  {"log": args.log, "coordinates": args.coords})
    kw = _stream_kw(args)
    kw["select"] = _select_freqs(args.select)
    choice = None
    if looks_for_input(args):  # the log's force-like channel, as a whole read takes it
        kw["input"], choice = grid_input(args.log, args.outputs, args.fs)
    if _needs_time_series(args):
        print(f"--method {args.method} needs the time series: output-only modes by EFDD on the spectra instead")
    try:
        an = analyse_stream(args.log, **kw)
    except ValueError as exc:
        raise VibroscopeError(f"{args.log}: {exc}") from None
    if choice:
        import dataclasses

        an = dataclasses.replace(an, settings={**an.settings, "input_choice": choice})
    print(stream_report_text(an, source=str(args.log)))
    # the spectra, FRFs, modes and stabilization diagram need no time series: drawn and recorded as
    # for a whole read (no signals.png, kinematics.png or /signals entities); the summary goes with
    # them, so that all outputs appear together or none
    write_outputs(an, args.log, coords=args.coords, json_path=args.json, rrd=rrd, figures=figures,
                  spawn=args.spawn, ods=args.ods)
    return 0


def stream_report_text(an, *, source: str = "") -> str:
    """Human-readable report of a :class:`vibroscope.stream.StreamAnalysis`.

    Parameters
    ----------
    an : StreamAnalysis
        The streamed analysis.
    source : str, optional
        The log, named on the first line.

    Returns
    -------
    str
    """
    from vibroscope.modal.methods import display_name

    s = an.settings
    lines = [f"{source}: {len(an.spectra.channels)} channels x {an.spectra.samples} samples at {an.spectra.fs:g} Hz "
             f"({an.spectra.samples / an.spectra.fs:.2f} s), streamed; nperseg={s['nperseg']} "
             f"(df={an.spectra.fs / s['nperseg']:.4g} Hz, {s['n_averages']} averages)"]
    how = display_name(an.modal.method)
    lines.append(f"input {s['input']} -> {len(s['outputs'])} outputs, {s['estimator']} FRF, modes by {how}"
                 if s.get("input") else f"output-only: {len(s['outputs'])} responses, modes by {how}")
    if s.get("input_choice"):  # the force-like channel taken as the input, or why none was
        lines.append(s["input_choice"])
    lines += [f"  warning: {w}" for w in an.warnings]
    lines.append(f"{'mode':>4} {'f_n [Hz]':>10} {'zeta [%]':>9}  method")
    for k, (f, z) in enumerate(zip(an.modal.natural_frequencies, an.modal.damping_ratios)):
        lines.append(f"{k + 1:>4} {f:>10.3f} {_percent(z):>9}  {an.modal.method}")
    if len(an.modal.natural_frequencies) == 0:
        lines.append("   (no mode passed the physical-mode selection in the band)")
    elif not np.isfinite(an.modal.damping_ratios).all():
        lines.append(_not_estimated(an.modal.method))
    return "\n".join(lines)


def _percent(z: float) -> str:
    """A damping ratio in % with 3 decimals, or "-" when it was not estimated (NaN)."""
    return f"{100 * z:.3f}" if np.isfinite(z) else "-"


def _not_estimated(method: str) -> str:
    """The report's line saying why a damping ratio reads "-"."""
    if method == "fdd":
        return "   (zeta -: FDD gives no damping; --method efdd estimates it)"
    if method == "efdd":
        return ("   (zeta -: not estimated; EFDD found no decaying correlation in the peak's bell, the frequency "
                "is the peak's)")
    return "   (zeta -: not estimated)"


def stream_summary(an, *, source: str | None = None) -> dict:
    """The ``--json`` summary of a streamed analysis: ``source``, ``fs``, ``n_samples``, ``channels``,
    ``units``, ``input``, ``input_choice`` (when the force-like channel was looked for: see
    :func:`grid_input`), ``outputs``, ``warnings``, ``modes``, ``rejected_modes``, ``settings``
    (``streamed: true``).

    Parameters
    ----------
    an : StreamAnalysis
        The streamed analysis.
    source : str, optional
        The log.

    Returns
    -------
    dict
        JSON-serialisable.
    """
    from vibroscope.modal.automatic import modes_document
    from vibroscope._checks import jsonable as _jsonable

    doc = modes_document(an.modal, an.identification.rejected if an.identification is not None else ())
    sp = an.spectra
    return _jsonable({"source": source, "fs": sp.fs, "n_samples": sp.samples, "duration_s": sp.samples / sp.fs,
                      "channels": list(sp.channels), "units": dict(zip(sp.channels, sp.units)),
                      "input": an.settings.get("input"), "outputs": an.settings.get("outputs"),
                      "warnings": list(an.warnings), "modal_method": an.modal.method, "modes": doc["modes"],
                      "rejected_modes": doc["rejected"],
                      **({"input_choice": an.settings["input_choice"]} if an.settings.get("input_choice") else {}),
                      "settings": {k: v for k, v in an.settings.items() if k not in ("outputs", "input_choice")}})


def run_fleet(args, logs: list) -> int:
    """``vibroscope analyse [--dask [ADDRESS]] LOG LOG ...``: :func:`vibroscope.fleet.analyse_fleet`; writes
    ``<out>/fleet.csv``, ``<out>/fleet.json`` (or ``--json``) and ``<out>/fleet_spectra.png``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    logs : list of Path
        The logs.

    Returns
    -------
    int
        0.

    Raises
    ------
    VibroscopeError
        When no log can be analysed, or every row of the table holds an error (after writing the
        table), or Dask is not installed.
    """
    from vibroscope.errors import VibroscopeError

    try:
        from vibroscope.fleet import analyse_fleet

        import dask.distributed  # noqa: F401 - the [dask] extra
    except ImportError as exc:
        raise VibroscopeError(f"--dask needs dask.distributed (pip install 'vibroscope[dask]'): {exc}") from None
    from vibroscope.commands._outputs import check_out_dir, check_outputs

    out = Path(args.out) if args.out else Path.cwd()
    check_out_dir(args.out)  # before any work: only vibroscope's own earlier outputs are replaced
    check_outputs({"--json": args.json or out / "fleet.json", "--out (table)": out / "fleet.csv",
                   "--out (figure)": None if args.no_figures else out / "fleet_spectra.png"}, {"log": list(logs)})
    out.mkdir(parents=True, exist_ok=True)
    chans = None if args.outputs is None else ([args.input] if args.input else []) + list(args.outputs)
    where = args.dask or "a local cluster"
    print(f"fleet of {len(logs)} logs on {where}")
    try:
        res = analyse_fleet([str(p) for p in logs], client=args.dask or None, channels=chans, input=args.input,
                            fs=args.fs, nperseg=args.nperseg, method=_stream_kw(args)["method"], fmin=args.fmin,
                            fmax=args.fmax, find_input=looks_for_input(args))
    except ValueError as exc:
        raise VibroscopeError(f"fleet analysis: {exc}") from None
    if res.settings.get("input_choice"):  # the first log's force-like channel, the input of every log
        print(res.settings["input_choice"])
    for r in res.rows:
        modes = ", ".join(f"{f:.3f} Hz ({_percent(z)} %)" for f, z in zip(r.frequencies_hz, r.damping_ratios))
        print(f"{r.log}: {r.duration_s:.1f} s; modes {modes or '(none)'}" + (f"; {r.error}" if r.error else ""))
        for w in r.warnings[:3]:
            print(f"  warning: {w}")
        if len(r.warnings) > 3:
            print(f"  ({len(r.warnings) - 3} more warnings in the fleet table)")
    csv_path = res.write_csv(out / "fleet.csv")
    json_path = res.write_json(args.json or out / "fleet.json")
    print(f"fleet table: {csv_path}, {json_path}")
    if not args.no_figures:
        from vibroscope.viewers.figures import save_figure as _save

        import dataclasses

        psd = res.merged.csd().psd()
        moving = [i for i in range(len(psd.channels)) if np.nanmax(psd.values[i]) > 0]  # an axis that never moves
        if moving and len(moving) < len(psd.channels):  # is dropped from the figure (it stays in fleet.json)
            psd = dataclasses.replace(psd, values=psd.values[moving], channels=tuple(psd.channels[i] for i in moving),
                                      units=tuple(psd.units[i] for i in moving))
        fig = psd.plot()
        fig = getattr(fig, "figure", fig)
        print(f"merged spectra: {_save(fig, out / 'fleet_spectra.png')}")
    if all(r.error for r in res.rows):  # the table says why for each; the run did not do its job
        raise VibroscopeError(f"fleet analysis: none of the {len(res.rows)} logs was analysed without error "
                              f"(each row of {csv_path} says why)")
    return 0


def _check_options(args) -> None:
    """Refuse non-finite or non-positive numbers in the options before any work."""
    import math

    from vibroscope.errors import VibroscopeError

    if getattr(args, "output_only", False) and getattr(args, "input", None):
        raise VibroscopeError(f"--output-only and --input {args.input}: give one of them")
    for opt in ("fs", "fmin", "fmax", "nperseg", "n_modes", "df"):
        v = getattr(args, opt, None)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise VibroscopeError(f"--{opt.replace('_', '-')} {v:g}: must be a positive, finite number")
    if getattr(args, "fs", None) is not None and getattr(args, "fmax", None) is not None and args.fmax > args.fs / 2:
        raise VibroscopeError(f"--fmax {args.fmax:g}: above the Nyquist frequency {args.fs / 2:g} Hz of --fs {args.fs:g}")
    for f in getattr(args, "ods", None) or ():
        if not (math.isfinite(f) and f > 0):
            raise VibroscopeError(f"--ods {f:g}: frequencies must be positive and finite (Hz)")
        if getattr(args, "fs", None) is not None and f > args.fs / 2:
            raise VibroscopeError(f"--ods {f:g}: above the Nyquist frequency {args.fs / 2:g} Hz of --fs {args.fs:g}")


def report_text(an, *, source: str = "", true_modes=None, verbose: bool = False) -> str:
    """Human-readable report: record, signal faults, warnings, and the modes (beside true ones when given).

    Parameters
    ----------
    an : Analysis
        From :func:`vibroscope.pipeline.analyse_signals`.
    source : str, optional
        What was analysed (the log's path), at the head of the first line.
    true_modes : ModalModel, optional
        Known modes, listed beside the identified ones with the errors.
    verbose : bool, optional
        Every fault kind on its own line (:func:`vibroscope.faults.fault_lines`) and the notes
        (``Analysis.notes``: gravity, constant channels); default False: one line counting the
        faults per kind (:func:`vibroscope.faults.fault_summary`) and no note.

    Returns
    -------
    str
    """
    from vibroscope.modal.methods import display_name

    sig = an.signals
    n_seg = an.settings.get("n_segments")
    avg = f"{an.settings['n_averages']} of {n_seg} averages" if n_seg else f"{an.settings['n_averages']} averages"
    lines = [f"{source}: {sig.n_channels} channels x {sig.n_samples} samples at {sig.fs:g} Hz "
             f"({sig.duration:.2f} s){decimation_text(an.settings.get('decimation'))}; nperseg={an.settings['nperseg']} "
             f"(df={sig.fs / an.settings['nperseg']:.4g} Hz, {avg})"]
    how = display_name(an.modal.method)
    if an.settings.get("input"):
        lines.append(f"input {an.settings['input']} -> {len(an.settings['outputs'])} outputs, "
                     f"{an.settings['estimator']} FRF, modes by {how}")
    else:
        lines.append(f"output-only: {len(an.settings['outputs'])} responses, modes by {how}")
    if sig.meta.get("input_choice"):  # the force-like channel taken as the input, or why none was
        lines.append(sig.meta["input_choice"])
    from vibroscope.faults import fault_lines, fault_summary

    faults = tuple(f for f in getattr(an, "faults", ()) or () if not f.note)
    notes = tuple(getattr(an, "notes", ()) or ())
    if verbose:
        lines += [f"  fault: {line}" for line in fault_lines(faults)]
        lines += [f"  note: {line}" for line in fault_lines(notes)]
    elif faults:
        lines.append(f"  faults: {fault_summary(faults)} (details: --verbose or --json)")
    shown = {str(f) for f in faults + notes}
    for w in an.warnings:
        if w not in shown:
            lines.append(f"  warning: {w}")
    mm = an.modal
    fstd = mm.extra.get("frequency_std_hz")
    zstd = mm.extra.get("damping_std")
    ident = getattr(an, "identification", None)
    unc = (isinstance(fstd, np.ndarray) and fstd.shape == mm.natural_frequencies.shape and np.any(np.isfinite(fstd))
           and ident is not None and "bootstrap" in str(ident.settings.get("uncertainty")))
    lines.append(f"{'mode':>4} {'f_n [Hz]':>10}" + (f" {'+-std':>7}" if unc else "") + f" {'zeta [%]':>9}"
                 + (f" {'+-std':>7}" if unc else "")
                 + (f" {'true f_n':>10} {'err [%]':>8} {'true zeta':>9}" if true_modes is not None else "") + "  method")
    for k in range(len(mm.natural_frequencies)):
        f, z = mm.natural_frequencies[k], mm.damping_ratios[k]
        row = f"{k + 1:>4} {f:>10.3f}" + (f" {fstd[k]:>7.3f}" if unc else "") + f" {_percent(z):>9}" \
            + (f" {100 * zstd[k]:>7.3f}" if unc else "")
        if true_modes is not None:
            tf = true_modes.natural_frequencies
            j = int(abs(tf - f).argmin())
            row += f" {tf[j]:>10.3f} {100 * (f - tf[j]) / tf[j]:>8.3f} {100 * true_modes.damping_ratios[j]:>8.3f}%"
        lines.append(row + f"  {mm.method}")
    if len(mm.natural_frequencies) == 0:
        lines.append("   (no mode passed the physical-mode selection in the band)")
    elif not np.isfinite(mm.damping_ratios).all():
        lines.append(_not_estimated(mm.method))
    ident = getattr(an, "identification", None)
    if ident is not None and ident.rejected:
        lines.append(f"  {len(ident.rejected)} candidates rejected (listed in the --json summary), e.g.:")
        for r in ident.rejected[:4]:
            lines.append(f"    {r.frequency_hz:9.3f} Hz: {r.reason}")
    if ident is not None and ident.settings.get("uncertainty") and unc:
        lines.append(f"  std: {ident.settings['uncertainty']}")
    sev = getattr(an, "severity", None)
    if sev is not None:
        v = sev.velocity_rms_mm_s
        k = int(np.argmax(v))
        lines.append(f"vibration severity (ISO 20816, velocity RMS {sev.band_hz[0]:g}–{sev.band_hz[1]:g} Hz): "
                     f"max {v[k]:.3g} mm/s at {sev.channels[k]}; median {np.median(v):.3g} mm/s over "
                     f"{len(v)} channels" + (f" ({sev.note})" if sev.note else ""))
    return "\n".join(lines)


def decimation_text(dec: dict | None) -> str:
    """``"; decimated 400 → 50 Hz (why)"``, ``"; not decimated (why)"`` or ``""`` (no decimation
    needed), from ``Analysis.settings["decimation"]`` (:func:`vibroscope.pipeline.analyse_signals`)."""
    if not dec or not dec.get("reason"):
        return ""
    if dec.get("factors"):
        return f"; decimated {dec['fs_in']:g} → {dec['fs_out']:g} Hz ({dec['reason']})"
    return f"; not decimated ({dec['reason']})"


def write_outputs(an, log: Path, *, coords=None, json_path=None, rrd=None, figures=None, spawn=False,
                  true_modes=None, ods=None, ahead=None) -> dict:
    """Write the summary JSON, the rerun recording and the figures of an analysis, atomically.

    With `ods` (frequencies in Hz) the operating deflection shapes at those frequencies (from the
    FRFs with an input, the CSD without) are drawn and animated after the modes. Every output is
    written under a temporary name beside its final path and moved into place when all are
    complete (:class:`vibroscope.commands._outputs.AtomicOutputs`): an exception or Ctrl-C
    leaves earlier outputs untouched and no temporary behind. Replacing an earlier output
    prints ``replacing <path> (earlier output)``.

    Parameters
    ----------
    an : Analysis or StreamAnalysis
        The analysis (:func:`vibroscope.pipeline.analyse_signals`), or a streamed one
        (:func:`vibroscope.stream.analyse_stream`: no time series, so no ``signals.png``,
        ``kinematics.png`` or ``/signals`` entities; its `json_path` summary is
        :func:`stream_summary`).
    log : Path
        The analysed log (named in the summary and the recording; never written).
    coords : Path, optional
        Sensor coordinates CSV (:func:`vibroscope.io.coords.read_coords`); default a line.
    json_path : Path, optional
        The summary JSON to write.
    rrd : Path, optional
        The rerun recording to write.
    figures : Path, optional
        The PNG figures folder to write.
    spawn : bool, optional
        Also open a rerun viewer; default False.
    true_modes : ModalModel, optional
        Reference modes, written beside the identified ones.
    ods : sequence of float, optional
        Operating deflection shape frequencies in Hz.
    ahead : TimeSeriesAhead, optional
        The integrals and time-series figures made while the modes were identified
        (:class:`vibroscope.viewers.ahead.TimeSeriesAhead`), taken instead of computing them again.

    Returns
    -------
    dict
        ``"json"``, ``"figures"`` (list of PNG paths), ``"rrd"``: the final paths written.

    Raises
    ------
    VibroscopeError
        When an output is the log or the coordinates file.
    """
    from vibroscope.commands._outputs import AtomicOutputs, check_outputs, preloaded
    from vibroscope.provenance import json_report
    from vibroscope.io.coords import line_coords, read_coords
    from vibroscope.pipeline import summary_dict

    check_outputs({"--json": json_path, "--rrd": rrd, "--figures": figures}, {"log": log, "coordinates": coords})
    outs = an.settings["outputs"]
    sc = read_coords(coords, outs) if coords else line_coords(outs)
    written = {}
    ident = getattr(an, "identification", None)
    stab = ident.stabilization if ident is not None else None
    synth = ident.lsfd.synthesize() if ident is not None and ident.lsfd is not None and an.frf is not None else None
    sig = getattr(an, "signals", None)  # a streamed analysis holds the spectra only
    acc = [] if sig is None else [c for c, u in zip(sig.channels, sig.units) if c in outs and u in ("m/s^2", "m/s²")]
    ods_shapes = []
    if ods:
        from vibroscope.spectral.integration import ods as ods_at

        from vibroscope.errors import VibroscopeError

        for f in ods:
            try:
                o = ods_at(an.frf if an.frf is not None else an.csd, f)
            except ValueError as exc:
                raise VibroscopeError(f"--ods {f:g}: {exc}") from None
            ods_shapes.append(o)
            print(f"ODS at {o.frequency_hz:.4g} Hz: " + ", ".join(f"{p}: {abs(v):.3f}∠{np.degrees(np.angle(v)):.0f}°"
                                                              for p, v in list(zip(o.points, o.shape))[:6]))
    done = []
    preloaded()  # the libraries imported in the background (run): done before the figure workers fork
    with AtomicOutputs(inputs=[log, coords]) as tx:
        if json_path:
            d = (summary_dict(an, source=str(log), true_modes=true_modes) if sig is not None
                 else stream_summary(an, source=str(log)))
            tx.file(json_path).write_text(json.dumps(json_report(d), indent=2))
            written["json"] = json_path
            done.append(f"summary: {json_path}")
        kin = None
        early = ahead is not None and sig is not None and ahead.holds(sig, acc)
        if acc and (figures or rrd or spawn) and not early:  # integrated once, for the figure and the recording
            from vibroscope.spectral.integration import velocity_and_displacement

            a = an.signals.select(acc)
            kin = velocity_and_displacement(a)
        pending = None
        if figures:  # drawn in worker processes while the recording is written (PendingFigures)
            from vibroscope.viewers.figures import plot_ods
            from vibroscope.viewers.figures import PendingFigures, figure_jobs

            tmp = tx.directory(figures)
            jobs = figure_jobs(tmp, signals=sig, psd=an.psd, frf=an.frf, modal=an.modal, sv=an.singular_values,
                               coords=sc.as_mapping(), true_modes=true_modes, stabilization=stab, synthesized=synth,
                               kinematics=(an.signals.select(acc), *kin) if kin else None,
                               ahead=ahead if early else None)
            jobs += [(lambda o=o: plot_ods(o, sc.as_mapping()), tmp / f"ods_{o.frequency_hz:.4g}Hz.png")
                     for o in ods_shapes]
            pending = PendingFigures(jobs)
        with pending or contextlib.nullcontext():  # an error or Ctrl-C here stops the figure workers
            if rrd or spawn:
                from vibroscope.modal import ods_as_modal_model, with_operating_shapes as _with_ods
                from vibroscope.viewers.rerun_view import log_analysis

                modal = _with_ods(an.modal, [ods_as_modal_model(o) for o in ods_shapes]) if ods_shapes else an.modal
                if early and acc:
                    kin = ahead.kinematics()
                path = log_analysis(kinematics=kin, signals=sig, psd=an.psd, csd=an.csd, frf=an.frf, modal=modal,
                                    coords=sc.as_mapping(), rrd_path=tx.file(rrd) if rrd else None,
                                    spawn=spawn and not rrd,  # a recording under its final name is opened below
                                    recording_name=Path(log).stem, stabilization=stab, synthesized=synth,
                                    singular_values=getattr(an, "singular_values", None))
                written["rrd"] = tx.final(path) if path is not None else None
                if rrd:
                    done.append(f"rerun recording: {rrd}  (open with: rerun {shlex.quote(str(rrd))})")
            if pending is not None:
                from vibroscope.viewers.figures import in_figure_order

                written["figures"] = [tx.final(p) for p in in_figure_order(pending.wait())]
                done.insert(len(done) - bool(rrd), f"figures: {', '.join(str(p) for p in written['figures'])}")
    for line in done:
        print(line)
    if spawn and rrd:
        from vibroscope.viewers.rerun_view import show_recording

        show_recording(rrd)
    return written
