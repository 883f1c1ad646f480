"""``vibroscope analyse LOG LOG ...`` / ``--dask``: a fleet of logs on Dask, the fleet table and the
merged spectra figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["run_fleet"]


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
    from vibroscope.commands._read_log import looks_for_input
    from vibroscope.commands._report import percent
    from vibroscope.commands._streaming import stream_kw

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
                            fs=args.fs, nperseg=args.nperseg, method=stream_kw(args)["method"], fmin=args.fmin,
                            fmax=args.fmax, find_input=looks_for_input(args))
    except ValueError as exc:
        raise VibroscopeError(f"fleet analysis: {exc}") from None
    if res.settings.get("input_choice"):  # the first log's force-like channel, the input of every log
        print(res.settings["input_choice"])
    for r in res.rows:
        modes = ", ".join(f"{f:.3f} Hz ({percent(z)} %)" for f, z in zip(r.natural_frequencies, r.damping_ratios))
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
