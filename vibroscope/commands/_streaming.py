"""``vibroscope analyse --stream``: the log read block by block into the spectral accumulators
(:func:`vibroscope.stream.analyse_stream`), reported and written as a whole read is."""

from __future__ import annotations

__all__ = ["run_stream", "stream_kw", "needs_time_series"]


def needs_time_series(args) -> bool:
    """Whether ``--method`` names an output-only method that needs the time series, and no ``--input``
    is given (a streamed analysis then identifies by EFDD on the spectra).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    bool
    """
    from vibroscope.modal.methods import lookup_method

    m = lookup_method(args.method)
    return not args.input and m is not None and m.needs_time_series


def stream_kw(args) -> dict:
    """The keywords of :func:`vibroscope.stream.analyse_stream` from the command line (``select`` None;
    a method that needs the time series becomes ``"auto"``, see :func:`needs_time_series`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    dict
    """
    return dict(input=args.input, outputs=args.outputs, fs=args.fs, nperseg=args.nperseg, fmin=args.fmin,
                fmax=args.fmax, n_modes=args.n_modes, estimator=args.estimator,
                method="auto" if needs_time_series(args) else args.method, select=None)


def run_stream(args, server=None) -> int:
    """``vibroscope analyse --stream LOG``: the log read block by block (:func:`vibroscope.stream.analyse_stream`);
    prints the report and writes the ``--json`` summary, the figures and the rerun recording of the
    spectra, FRFs and modes (:func:`vibroscope.commands._writers.write_outputs`; no time-series figure or entity: a streamed
    analysis never holds the record).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    server : multiprocessing context, optional
        The drawing server `analyse` started (:func:`vibroscope.viewers.drawing_server.context`):
        the figures and the recording are made in its workers, as for a whole read.

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
    from vibroscope.commands._read_log import grid_input, looks_for_input
    from vibroscope.commands._report import report_text
    from vibroscope.commands._writers import write_outputs
    from vibroscope.stream import analyse_stream

    rrd = None if args.no_rrd else (args.rrd or default_output(args.log, "analyse", ".rrd", args.out))
    figures = None if args.no_figures else (args.figures or default_output(args.log, "analyse", "_figures", args.out))
    check_outputs({"--json": args.json, "--rrd": rrd, "--figures": figures},
                  {"log": args.log, "coordinates": args.coords})
    kw = stream_kw(args)
    kw["select"] = _select_freqs(args.select)
    choice = None
    if looks_for_input(args):  # the log's force-like channel, as a whole read takes it
        kw["input"], choice = grid_input(args.log, args.outputs, args.fs)
    if needs_time_series(args):
        print(f"--method {args.method} needs the time series: output-only modes by EFDD on the spectra instead")
    try:
        an = analyse_stream(args.log, **kw)
    except ValueError as exc:
        raise VibroscopeError(f"{args.log}: {exc}") from None
    if choice:
        import dataclasses

        an = dataclasses.replace(an, settings={**an.settings, "input_choice": choice})
    print(report_text(an, source=str(args.log)))
    # the spectra, FRFs, modes and stabilization diagram need no time series: drawn and recorded as
    # for a whole read (no signals.png, kinematics.png or /signals entities); the summary goes with
    # them, so that all outputs appear together or none
    write_outputs(an, args.log, coords=args.coords, json_path=args.json, rrd=rrd, figures=figures,
                  spawn=args.spawn, ods=args.ods, server=server)
    return 0
