"""``vibroscope analyse LOG.mcap``: spectra, FRFs, coherence and modal vectors of a log.

The command: its parser and its run (a whole read, or the stream or fleet path chosen). The rest
lives in modules of one concern each, whose names are re-exported here:
:mod:`~vibroscope.commands._read_log` (the log read, the channels and force input chosen),
:mod:`~vibroscope.commands._memory` (the memory budget), :mod:`~vibroscope.commands._streaming`
(``--stream``), :mod:`~vibroscope.commands._fleet` (several logs, ``--dask``),
:mod:`~vibroscope.commands._report` (the printed report and the streamed summary) and
:mod:`~vibroscope.commands._writers` (the summary JSON, recording and figures).
"""

from __future__ import annotations

from pathlib import Path

from vibroscope._checks import LazyChoices
from vibroscope.commands._fleet import run_fleet
from vibroscope.commands._memory import memory_budget, parse_size, whole_read_bytes
from vibroscope.commands._options import check_options as _check_options
from vibroscope.commands._read_log import analyse_log, grid_input, looks_for_input
from vibroscope.commands._report import decimation_text, report_text, stream_report_text, stream_summary
from vibroscope.commands._streaming import run_stream
from vibroscope.commands._writers import write_outputs

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
    from vibroscope.commands._outputs import check_out_dir, check_outputs, default_output, resolve_outputs
    from vibroscope.errors import VibroscopeError

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
    if live:  # the live view first, read block by block (vibroscope.commands._live), then the analysis
        from vibroscope.commands._live import stream_log

        live_input = grid_input(args.log, args.outputs, args.fs)[0] if looks_for_input(args) else args.input
        try:  # the analysis below takes (and reports) the same force-like input
            stream_log(args.log, url=args.connect or None, input=live_input, outputs=args.outputs, fs=args.fs,
                       nperseg=args.nperseg, estimator=args.estimator)
        except (ValueError, ConnectionError) as exc:
            raise VibroscopeError(f"{args.log}: {exc}") from None
    # the figures and the recording are made in workers forked from a drawing server that imports
    # matplotlib and rerun now, on the other core, while this process imports its numerics and reads
    # the log (a viewer to spawn is this process's: rerun is then imported here, in the background)
    server = None
    if figures or (rrd and not args.spawn):
        from vibroscope.viewers import drawing_server

        server = drawing_server.context() if drawing_server.start() else None
    done = False
    try:
        status = _run_one(args, rrd, figures, server)
        done = True
        return status
    finally:
        if server is not None:
            drawing_server.stop(wait=done)


def _run_one(args, rrd, figures, server) -> int:
    """:func:`run` for one log read whole (or streamed), with the drawing server `server` (or None)."""
    from vibroscope.commands._options import select_frequencies as _select_freqs
    from vibroscope.commands._outputs import preload_outputs, preloaded
    from vibroscope.errors import VibroscopeError
    from vibroscope.viewers.ahead import TimeSeriesAhead

    preload_outputs(rrd=args.spawn or (bool(rrd) and server is None), figures=bool(figures) and server is None)
    budget = memory_budget(args.max_memory)
    need = whole_read_bytes(args.log)
    if args.stream or need > budget:
        why = ("--stream" if args.stream else
               f"reading it whole needs about {need / 2**20:.0f} MiB, more than the memory budget "
               f"{budget / 2**20:.0f} MiB (--max-memory)")
        print(f"streaming {args.log} block by block: {why}")
        return run_stream(args, server)
    select = _select_freqs(args.select)
    # what needs only the time series (integrals, signals and kinematics figures) is made in a worker
    # process while the modes are identified on the other core (the background imports joined first:
    # no worker inherits a held import lock)
    ahead = TimeSeriesAhead(figures=bool(figures), kinematics=bool(rrd) or args.spawn, server=server)

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
                      spawn=args.spawn, ods=args.ods, ahead=ahead, server=server)
    return 0
