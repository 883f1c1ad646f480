"""``vibroscope modal LOG.mcap | FRF.uff | FRF.csv | MODES.unv``: modal identification an engineer can check.

From a log the record is read and analysed as by ``vibroscope analyse`` (LSCF + LSFD with an
input, SSI-COV without); from an FRF file (UFF 58, complex CSV, pyuff text FRFs) LSCF + LSFD
runs on the measured FRFs. A file that already holds modes -- UFF 55 (with its UFF 15 / 2411
geometry), a model file, a ``MODES.json`` (:func:`vibroscope.io.mode_sets.read_mode_set`) -- is
shown as it is: the table, the shapes on the geometry as a PNG and in rerun. The physical modes are chosen automatically (or at ``--select``
frequencies); the stabilization diagram, the synthesized-vs-measured FRFs and the mode shapes
are written as PNGs and to a rerun recording, the modes as ``MODES.json``, UFF 55 and a model
file that ``vibroscope simulate`` runs.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np

from vibroscope._checks import LazyChoices
from vibroscope.commands._options import select_frequencies as _select_freqs

__all__ = ["add_parser", "run", "identify_frf", "cross_check_text", "CROSS_CHECK_MAX_DF", "FRF_SUFFIXES"]

#: file suffixes read as FRF files (everything else is read as an MCAP log)
FRF_SUFFIXES = (".uff", ".unv", ".uf", ".csv", ".txt")


def add_parser(sub) -> None:
    """Register ``modal`` on the CLI's sub-parsers.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The sub-parsers of the ``vibroscope`` parser.
    """
    p = sub.add_parser(
        "modal",
        help="modal identification (LSCF/LSFD, SSI-COV, FDD/EFDD, peak picking) from a log or FRF files",
        description=(
            "Identify natural frequencies, damping ratios and mode shapes from an MCAP log (with "
            "--input: LSCF + LSFD on the H1 FRFs; without: output-only SSI-COV) or from measured FRF "
            "files (UFF 58, complex CSV, pyuff text FRFs; several files combine into one FRF matrix). "
            "Physical modes are selected automatically (stable across orders, physical damping, "
            "MPC, inside the excited band); the rejected candidates are listed with the reason."
        ),
    )
    p.add_argument("source", nargs="+", type=Path,
                   help="an MCAP log, one or more FRF files, or a mode set to show (UFF 55 with its geometry, "
                        "a model file, a MODES.json)")
    p.add_argument("--method", default="auto", choices=LazyChoices("vibroscope.modal.methods", "METHOD_CHOICES"),
                   metavar="METHOD", help="modal identification: %(choices)s (the methods of "
                                          "vibroscope.modal.methods by key or result name); default auto: LSCF "
                                          "with an input or an FRF file, SSI-COV without an input")
    p.add_argument("--select", default="auto", metavar="auto|F1,F2,..",
                   help="modes: 'auto' (physical-mode selection) or the frequencies (Hz) to take from the "
                        "stabilization diagram")
    p.add_argument("--input", help="force channel of a log (message path)")
    p.add_argument("--outputs", nargs="+", metavar="PATH", help="response channels of a log")
    p.add_argument("--coords", type=Path, help="sensor coordinates CSV (channel or sensor number, x, y, z, direction)")
    p.add_argument("--fs", type=float, help="resample a log to this rate (Hz)")
    p.add_argument("--fmin", type=float, help="lowest frequency of the band (Hz); default from the data")
    p.add_argument("--fmax", type=float, help="highest frequency of the band (Hz); default from the data")
    p.add_argument("--kind", choices=LazyChoices("vibroscope.spectral.kinds", "FRF_KINDS"), metavar="KIND",
                   help="what an FRF file holds when it does not say: %(choices)s (default: unknown)")
    p.add_argument("--df", type=float, default=1.0, help="line spacing (Hz) of text FRFs without an axis (default 1)")
    p.add_argument("--json", type=Path, metavar="MODES.json", help="write the modes (and rejected candidates)")
    p.add_argument("--export-model", type=Path, metavar="MODEL.toml",
                   help="write the identified modal model (kind = \"modal\"; LSCF only) for `vibroscope simulate`")
    p.add_argument("--uff55", type=Path, metavar="FILE", help="write the mode shapes as UFF 55")
    p.add_argument("--uff15", type=Path, metavar="FILE",
                   help="write the sensor geometry (nodes of --uff55, from --coords) as UFF 15")
    p.add_argument("--uff58", type=Path, metavar="FILE", help="write the FRFs (measured or estimated) as UFF 58")
    p.add_argument("--ods", type=float, nargs="+", metavar="F", help="operating deflection shapes at these frequencies (Hz)")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="folder of the default outputs (default: the current directory, never beside the source)")
    p.add_argument("--figures", type=Path, metavar="DIR",
                   help="PNG figures directory (default: <out>/<source stem>_modal_figures/)")
    p.add_argument("--rrd", type=Path, help="rerun recording (default: <out>/<source stem>_modal.rrd)")
    p.add_argument("--no-figures", action="store_true", help="write no PNG figures")
    p.add_argument("--no-rrd", action="store_true", help="write no rerun recording")
    p.add_argument("--spawn", action="store_true", help="open a rerun viewer")
    p.set_defaults(func=run)


def identify_frf(frf, *, method: str = "auto", fmin=None, fmax=None, select=None):
    """Modes of measured FRFs: LSCF + LSFD (default) or peak picking, physical-mode selection.

    Parameters
    ----------
    frf : FRF
        Measured FRFs.
    method : str, optional
        A method of :data:`vibroscope.modal.methods.METHOD_CHOICES` that runs on FRFs: 'auto'
        or 'lscf' (LSCF + LSFD, also for 'polymax'), 'peak' (peak picking); default 'auto'.
    fmin, fmax : float, optional
        Band in Hz; default the FRF's axis (where the coherence, if any, is defined).
    select : sequence of float, optional
        Take the modes nearest these frequencies (Hz) from the stabilization diagram instead of the
        automatic selection.

    Returns
    -------
    Identification

    Raises
    ------
    ValueError
        For an unknown or an output-only method (:func:`vibroscope.modal.methods.resolve_method`).
    """
    from vibroscope.modal.methods import identify

    # (merge_duplicates=False: peak picking on FRF files has never merged duplicate candidates)
    return identify(method, frf=frf, fmin=fmin, fmax=fmax, select=select, merge_duplicates=False)


def _default_out(source: Path, suffix: str, out_dir=None) -> Path:
    from vibroscope.commands._outputs import default_output

    return default_output(source, "modal", suffix, out_dir)


def _planned_outputs(args) -> dict:
    """Option -> output path (None: not written) of a ``modal`` command line, defaults resolved."""
    first = args.source[0]
    out_dir = getattr(args, "out", None)
    return {"--json": args.json, "--export-model": args.export_model, "--uff55": args.uff55,
            "--uff15": args.uff15, "--uff58": args.uff58,
            "--figures": None if getattr(args, "no_figures", False) else (
                args.figures or _default_out(first, "_figures", out_dir)),
            "--rrd": None if args.no_rrd else (args.rrd or _default_out(first, ".rrd", out_dir))}


def run(args) -> int:
    """Run ``vibroscope modal``; prints the modes and where the outputs went.

    The default outputs go to the current directory or ``--out DIR``
    (``<source stem>_modal.rrd``, ``<source stem>_modal_figures/``); every output is checked
    against the inputs before any work and written atomically
    (:mod:`vibroscope.commands._outputs`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Raises
    ------
    VibroscopeError
        When an output is an input file, or the identification fails.
    """
    from vibroscope.commands._outputs import check_out_dir, check_outputs, resolve_outputs
    from vibroscope.commands._report import report_text
    from vibroscope.modal.methods import MODAL_METHODS, display_name
    from vibroscope.errors import VibroscopeError

    check_out_dir(args.out)
    # `--out res --json m.json`: res/m.json
    resolve_outputs(args, ("json", "export_model", "uff55", "uff15", "uff58", "figures", "rrd"), args.out)
    from vibroscope.commands._options import check_options as _check_options

    _check_options(args)
    check_outputs(_planned_outputs(args), {"source": list(args.source), "coordinates": args.coords})
    sources = list(args.source)
    first = sources[0]
    select = _select_freqs(args.select)
    from vibroscope.io.mode_sets import MODE_SET_SUFFIXES, is_mode_set

    if first.suffix.lower() in MODE_SET_SUFFIXES and is_mode_set(first):
        return _show_mode_set(args, sources, select)
    is_frf = first.suffix.lower() in FRF_SUFFIXES
    if not is_frf and len(sources) > 1:
        raise VibroscopeError(f"one MCAP log at a time ({len(sources)} sources given)")
    if is_frf:
        from vibroscope.io.frf_files import read_frf

        from vibroscope.errors import LogFormatError
        from vibroscope.io.frf_files import uff_datasets

        try:
            h = read_frf([str(s) for s in sources] if len(sources) > 1 else str(first), kind=args.kind, df=args.df)
        except LogFormatError:
            # no FRF record, but mode shapes (an export that also holds time data or spectra): show those
            if first.suffix.lower() in (".uff", ".unv", ".uf") and len(sources) == 1 and 55 in uff_datasets(first):
                return _show_mode_set(args, sources, select)
            raise
        try:
            ident = identify_frf(h, method=args.method, fmin=args.fmin, fmax=args.fmax, select=select)
        except ValueError as exc:
            raise VibroscopeError(str(exc)) from None
        mm = ident.modes
        print(f"{first}{' + %d more' % (len(sources) - 1) if len(sources) > 1 else ''}: FRF {len(h.outputs)} outputs x "
              f"{len(h.inputs)} inputs, {h.frequencies.size} lines {h.frequencies[0]:.4g}–{h.frequencies[-1]:.4g} Hz; "
              f"modes by {display_name(mm.method)}")
        _print_modes(ident, args.json)
        signals = psd = csd = None
        sv = _mif(h)
    else:
        from vibroscope.commands._read_log import analyse_log

        try:
            an = analyse_log(first, input=args.input, outputs=args.outputs, fs=args.fs, fmin=args.fmin,
                             fmax=args.fmax, method=args.method, select=select)
        except ValueError as exc:
            raise VibroscopeError(f"{first}: {exc}") from None
        print(report_text(an, source=str(first)))
        ident, h, mm = an.identification, an.frf, an.modal
        m = MODAL_METHODS.get(mm.method)
        if an.frf is None and m is not None and m.cross_check and select is None:
            _cross_check(an)
        signals, psd, csd, sv = an.signals, an.psd, an.csd, an.singular_values
    synth = ident.lsfd.synthesize() if ident.lsfd is not None and h is not None else None  # on the fitted lines
    if synth is not None:
        err = ident.lsfd.error(h)
        print("synthesized FRF error (LSFD model vs measured, per output): "
              + ", ".join(f"{100 * e:.2f} %" for e in np.atleast_1d(err)))
    _write(args, first, ident, h, synth, signals, psd, csd, sv)
    return 0


def _show_mode_set(args, sources: list, select) -> int:
    """``modal`` on a file of modes: the table, and the figures, recording and files asked for."""
    from vibroscope.errors import VibroscopeError
    from vibroscope.io.mode_sets import read_mode_set
    from vibroscope.modal import mpc
    from vibroscope.modal.automatic import Identification

    first = sources[0]
    if len(sources) > 1:
        raise VibroscopeError(f"{first}: holds modes; show one mode set at a time, or compare two with "
                              f"`vibroscope compare {first} {sources[1]}`")
    given = {"--method": args.method != "auto", "--select": select is not None, "--input": args.input,
             "--outputs": args.outputs, "--fs": args.fs, "--fmin": args.fmin, "--fmax": args.fmax,
             "--kind": args.kind, "--ods": args.ods, "--uff58": args.uff58, "--export-model": args.export_model}
    bad = [k for k, v in given.items() if v]
    if bad:
        raise VibroscopeError(f"{first}: holds identified modes, not FRFs or time data: {', '.join(bad)} do not apply")
    ms = read_mode_set(first, coords=args.coords)
    mm = ms.modes
    geo = (f"geometry of {len(mm.points)} points from {ms.coords.source}" if ms.coords is not None
           else "no geometry (points laid out on a line; give --coords)")
    print(f"{first}: {len(mm)} modes at {len(mm.points)} points ({ms.format}, {mm.method}); {geo}")
    m = mpc(mm.shapes) if len(mm) else np.zeros(0)
    print(f"{'mode':>4} {'f_n [Hz]':>10} {'zeta [%]':>9} {'MPC':>5}")
    for k in range(len(mm)):
        print(f"{k + 1:>4} {mm.natural_frequencies[k]:>10.4f} {100 * mm.damping_ratios[k]:>9.3f} {m[k]:>5.2f}")
    print(f"compare with another mode set (test vs model, or another test): vibroscope compare {first} OTHER")
    ident = Identification(mm, (), None, {"source": str(first), "format": ms.format})
    _write(args, first, ident, None, None, None, None, None, None, coords=ms.coords)
    return 0


def _shapes_3d(mm, coords, folder: Path) -> list[Path]:
    """``modes_3d.png`` (shapes on the geometry) when the points spread in a plane or a volume."""
    from vibroscope.viewers.figures import plot_mode_shapes_3d, save_figure as _save

    if coords is None or not len(mm) or np.count_nonzero(np.ptp(coords.xyz, axis=0) > 0) < 2:
        return []  # points on a line: modes.png says it all
    return [_save(plot_mode_shapes_3d(mm, coords.as_mapping()), folder / "modes_3d.png")]


def _cross_check(an) -> None:
    """polyMAX on the output spectra beside SSI-COV: each SSI mode with its own polyMAX mode (one to one)."""
    from vibroscope.modal.automatic import polymax_oma

    st = an.identification.settings
    try:
        pm = polymax_oma(an.signals.select(an.settings["outputs"]), f_low=st.get("f_low_hz") or 1.0,
                         fmin=an.settings.get("fmin"), fmax=an.settings.get("fmax")).modes
    except (ValueError, np.linalg.LinAlgError) as exc:
        print(f"cross-check polyMAX (output spectra) not run: {exc}")
        return
    print(cross_check_text(an.modal, pm))


#: largest relative frequency difference of an SSI-COV mode and the polyMAX mode it is paired with
CROSS_CHECK_MAX_DF = 0.1


def cross_check_text(ssi, polymax) -> str:
    """The cross-check line: each SSI-COV mode with the polyMAX mode paired with it, one to one.

    The pairing is one to one by frequency: :func:`vibroscope.modal.match_modes` (the Hungarian
    assignment) on the relative frequency distance alone, pairs more than
    :data:`CROSS_CHECK_MAX_DF` apart dropped. A polyMAX mode confirms at most one SSI-COV mode, so
    of two SSI-COV modes beside one polyMAX mode the farther is shown as not seen by polyMAX. The
    MAC of each pair is shown when both shapes are on the same points, but not paired on: the
    shapes polyMAX gets from the output spectra of closely spaced, heavily damped modes are the
    less certain (on LUMO its 41.11 and 42.42 Hz shapes have MPC 0.54 and 0.82 and MAC 0.04 and
    0.14 with the SSI-COV modes 0.2 % and 0.3 % away).

    Parameters
    ----------
    ssi, polymax : ModalModel
        The SSI-COV modes and the polyMAX modes of the same outputs.

    Returns
    -------
    str
        ``"cross-check polyMAX on the output spectra (N modes), SSI-COV/polyMAX: f/fp Hz (±d %,
        ζ z/zp %, MAC m); f/— Hz (no polyMAX mode); ..."`` in the order of the SSI-COV modes.
    """
    from vibroscope.modal import mac, match_modes

    f, fp = np.asarray(ssi.natural_frequencies, float), np.asarray(polymax.natural_frequencies, float)
    same_points = tuple(ssi.points) == tuple(polymax.points)
    pair = {}
    if len(f) and len(fp):  # shapes of ones: MAC 1 everywhere, the cost is the frequency distance
        m = match_modes((f, np.ones((len(f), 1))), (fp, np.ones((len(fp), 1))),
                        max_frequency_error=CROSS_CHECK_MAX_DF)
        pair = {int(i): int(k) for i, k in m.pairs}
    rows = []
    for i, (fi, zi) in enumerate(zip(f, ssi.damping_ratios)):
        if i not in pair:
            rows.append(f"{fi:.3f}/— Hz (no polyMAX mode)")
            continue
        k = pair[i]
        shape = f", MAC {mac(ssi.shapes[i], polymax.shapes[k])[0, 0]:.2f}" if same_points else ""
        rows.append(f"{fi:.3f}/{fp[k]:.3f} Hz ({100 * (fp[k] / fi - 1):+.2f} %, "
                    f"ζ {100 * zi:.2f}/{100 * polymax.damping_ratios[k]:.2f} %{shape})")
    return f"cross-check polyMAX on the output spectra ({len(fp)} modes), SSI-COV/polyMAX: " + "; ".join(rows)


def _mif(h):
    """Sum of |H|² over outputs and inputs: the background curve of an FRF stabilization diagram."""
    H = np.asarray(h.H)
    with np.errstate(invalid="ignore"):
        s = np.nansum(np.abs(H) ** 2, axis=(1, 2))
    return h.frequencies, s[:, None], "Σ |H|² over outputs and inputs [dB]"


def _print_modes(ident, json_path=None) -> None:
    mm = ident.modes
    print(f"{'mode':>4} {'f_n [Hz]':>10} {'zeta [%]':>9} {'MPC':>5}")
    mp = mm.extra.get("mpc", np.full(len(mm), np.nan))
    for k in range(len(mm)):
        print(f"{k + 1:>4} {mm.natural_frequencies[k]:>10.3f} {100 * mm.damping_ratios[k]:>9.3f} {mp[k]:>5.2f}")
    if not len(mm):
        print("   (no mode passed the physical-mode selection)")
    if ident.rejected:
        where = f"in {json_path}" if json_path else "all listed with --json FILE"
        print(f"  {len(ident.rejected)} candidates rejected ({where}), e.g.:")
        for r in ident.rejected[:4]:
            print(f"    {r.natural_frequency:9.3f} Hz: {r.reason}")


def _mark_uff(path: Path, header: str) -> None:
    """Put `header` (a dataset 151 naming vibroscope, :func:`vibroscope.provenance.uff_header`) before the
    datasets of the Universal File `path`: the mark by which a later run knows the file as its own output."""
    path = Path(path)
    path.write_bytes(header.encode("ascii") + path.read_bytes())


def _write(args, source: Path, ident, h, synth, signals, psd, csd, sv, coords=None) -> None:
    from vibroscope.commands._outputs import AtomicOutputs
    from vibroscope.provenance import json_report, uff_header
    from vibroscope.errors import VibroscopeError
    from vibroscope._checks import jsonable as _jsonable
    from vibroscope.io.coords import line_coords, read_coords

    planned = _planned_outputs(args)
    mm = ident.modes
    pts = list(mm.points)
    sc = coords if coords is not None else read_coords(args.coords, pts) if args.coords else line_coords(pts)
    if args.uff58 and h is None:
        raise VibroscopeError("--uff58 needs FRFs: give --input for a log")
    if args.uff55 and not len(mm):
        raise VibroscopeError("--uff55: no mode was identified, nothing to write (try --fmin/--fmax or --select)")
    if args.export_model and not len(mm):
        raise VibroscopeError("--export-model: no mode was identified, nothing to export (try --fmin/--fmax or "
                              "--select)")
    if args.export_model and ident.lsfd is None:
        raise VibroscopeError("--export-model needs residues: an input (LSCF + LSFD), not an output-only method")
    done = []
    with AtomicOutputs(inputs=[*args.source, args.coords]) as tx:
        if args.json:
            doc = ident.to_dict()
            doc["source"] = [str(s) for s in args.source]
            tx.file(args.json).write_text(json.dumps(json_report(_jsonable(doc)), indent=2))  # NaN -> null
            done.append(f"modes: {args.json}")
        if args.uff55:
            from vibroscope.io.frf_files import write_modes_uff55

            dirs = None
            if args.coords or coords is not None:
                dirs = [int(np.argmax(np.abs(d))) + 1 if d[int(np.argmax(np.abs(d)))] >= 0
                        else -(int(np.argmax(np.abs(d))) + 1) for d in sc.directions]
            write_modes_uff55(mm, tx.file(args.uff55), directions=dirs)
            done.append(f"mode shapes (UFF 55): {args.uff55}")
        if args.uff15:
            from vibroscope.io.frf_files import write_geometry_uff15

            _mark_uff(write_geometry_uff15(tx.file(args.uff15), list(range(1, len(pts) + 1)), sc.xyz), uff_header())
            done.append(f"geometry (UFF 15, node k = point k of the mode shapes): {args.uff15}")
        if args.uff58:
            from vibroscope.io.frf_files import write_frf_uff58

            _mark_uff(write_frf_uff58(h, tx.file(args.uff58)), uff_header())
            done.append(f"FRFs (UFF 58): {args.uff58}")
        if args.export_model:
            export_modal_model(ident.lsfd, tx.file(args.export_model),
                               name=f"{source.stem}, identified by LSCF + LSFD", frf=h)
            done.append(f"modal model: {args.export_model}  (run with: vibroscope simulate "
                        f"{shlex.quote(str(args.export_model))} ...)")
        ods = []
        for f in args.ods or ():
            from vibroscope.spectral.integration import ods as ods_at
            from vibroscope.modal import ods_as_modal_model, with_operating_shapes as _with_ods

            src = h if h is not None else csd
            try:
                ods.append(ods_at(src, f))
            except ValueError as exc:
                raise VibroscopeError(f"--ods {f:g}: {exc}") from None
        if planned["--figures"] is not None:
            from vibroscope.viewers.figures import save_figure as _save, summary_figures

            tmp = tx.directory(planned["--figures"])
            paths = summary_figures(tmp, frf=h, modal=mm if len(mm) else None, sv=sv, coords=sc.as_mapping(),
                                    stabilization=ident.stabilization, synthesized=synth)
            if coords is not None:  # a mode set with its geometry: also the shapes on it in 3-D
                paths += _shapes_3d(mm, coords, tmp)
            for o in ods:
                from vibroscope.viewers.figures import plot_ods

                paths.append(_save(plot_ods(o, sc.as_mapping()), tmp / f"ods_{o.frequency:.4g}Hz.png"))
            done.append(f"figures: {', '.join(str(tx.final(p)) for p in paths)}")
        if not args.no_rrd or args.spawn:
            from vibroscope.viewers.rerun_view import log_analysis

            rrd = planned["--rrd"]
            show = mm
            if ods:
                show = _with_ods(mm, [ods_as_modal_model(o) for o in ods])
            log_analysis(signals=signals, psd=psd, csd=csd, frf=h, modal=show, coords=sc.as_mapping(),
                         rrd_path=tx.file(rrd) if rrd else None, spawn=args.spawn and not rrd,
                         recording_name=f"{source.stem} modal", stabilization=ident.stabilization,
                         synthesized=synth)
            if rrd:
                done.append(f"rerun recording: {rrd}  (open with: rerun {shlex.quote(str(rrd))})")
    for line in done:
        print(line)
    if args.spawn and planned["--rrd"]:  # once under its final name
        from vibroscope.viewers.rerun_view import show_recording

        show_recording(planned["--rrd"])


def export_modal_model(res, path: Path, *, name: str = "", frf=None, driving_points=None) -> Path:
    """Write an LSFD result as a ``kind = "modal"`` model file (pole-residue form).

    Parameters
    ----------
    res : LSFDResult
        Poles, residues and residual terms.
    path : Path
        The TOML file to write.
    name : str, optional
        The model's name.
    frf : FRF, optional
        The measured FRFs: residues and residuals are refitted in the file's plain pole-residue
        form (:func:`vibroscope.modal.lsfd.pole_residue_form`); without it, LSFD's are written.
    driving_points : dict of str to str, optional
        Input channel -> the output channel at the same point. Inputs not named are matched
        automatically: the one output whose receptance modal constants
        (:func:`~vibroscope.models.modal_coordinates.modal_constants`) are all positive and
        nearly real, if exactly one is (or, of several such, the one whose residual terms are
        positive too, :func:`_driving_labels`). A matched input gets its output's ``dof`` label
        (``out<k>``), the mark of a driving point that ``vibroscope gap`` needs.

    Returns
    -------
    Path
    """
    from vibroscope._checks import atomic_file
    from vibroscope.models import Input, Output
    from vibroscope.models.modal_model import PoleResidueModel
    from vibroscope.models.modelfile import dumps_model
    from vibroscope.provenance import toml_header

    from vibroscope.spectral.kinds import FRF_KIND_TABLE

    q = FRF_KIND_TABLE[res.kind].quantity if res.kind in FRF_KIND_TABLE else "displacement"
    R, LR, UR = res.residues, res.lower_residual, res.upper_residual
    if frf is not None:
        from vibroscope.modal.lsfd import pole_residue_form

        R, LR, UR = pole_residue_form(frf, res)
    outputs = tuple(Output(f"out{o + 1}", q, c) for o, c in enumerate(res.outputs))
    labels = [f"in{i + 1}" for i in range(len(res.inputs))]
    probe = PoleResidueModel.from_poles_residues(res.natural_frequencies, res.damping_ratios, R,
                                                 inputs=[Input(dof=lb, channel=c) for lb, c in zip(labels, res.inputs)],
                                                 outputs=outputs)
    labels = _driving_labels(probe, dict(driving_points or {}), LR, UR)
    inputs = tuple(Input(dof=lb, channel=c) for lb, c in zip(labels, res.inputs))
    model = PoleResidueModel.from_poles_residues(res.natural_frequencies, res.damping_ratios, R,
                                                 inputs=inputs, outputs=outputs, lower=LR, upper=UR, name=name)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:  # the model file, after the line that marks it as vibroscope's
        Path(tmp).write_text(toml_header() + dumps_model(model), encoding="utf-8")
    return path


def _driving_labels(model, given: dict, lower=None, upper=None) -> list[str]:
    """Input labels: the ``dof`` label of the output at each input's point (given by channel,
    or the single output with positive, nearly real modal constants), else ``in<k>``.

    With few modes in the band several outputs can have positive constants (two modes in which
    two points move in phase); then the one whose residual terms are those of a driving point
    as well is taken, if exactly one is: a driving point's upper residual (the receptance
    compliance of the modes above the band, ``sum phi^2 / omega^2``) and lower residual (the
    mass line of the modes below it, ``sum phi^2``; for an acceleration output it also holds the
    in-band modes' own high-frequency limit, likewise ``sum phi^2``) are both positive, a
    transfer point's can be of either sign [Ewins, *Modal Testing*, 2000, sec. 4.4]; a residual below
    :data:`~vibroscope.models.modal_coordinates.RESIDUAL_SIGN_MIN` of the in-band modes' scale is not counted. `lower`, `upper`: the residual
    arrays (n_outputs, n_inputs) in the model file's convention
    (:class:`~vibroscope.models.modal_model.PoleResidueModel`), where ``UR`` is a receptance
    compliance and ``LR`` a receptance ``-LR/omega^2`` whatever the output's quantity."""
    from vibroscope.models.modal_coordinates import COMPLEXITY_WARN, RESIDUAL_SIGN_MIN, modal_constants

    A = modal_constants(model)
    out_ch = [o.channel for o in model.outputs]
    labels = []
    for i, inp in enumerate(model.inputs):
        if inp.channel in given:
            labels.append(model.outputs[out_ch.index(given[inp.channel])].dof)
            continue
        a = A[:, :, i]
        ok = np.all((a.real > 0) & (np.abs(a.imag) <= COMPLEXITY_WARN * np.abs(a)), axis=0)
        hits = np.nonzero(ok)[0]
        if hits.size > 1 and upper is not None and lower is not None:
            # each residual against the in-band modes' own scale at that end of the band: their
            # static compliance (sum |A| / omega^2) and their mass line (sum |A|); a residual is
            # counted only when it is at least RESIDUAL_SIGN_MIN of that (a noise-sized residual
            # of either sign says nothing)
            w2 = (2 * np.pi * np.asarray(model.natural_frequencies, float)) ** 2
            ur = np.real(np.asarray(upper)[hits, i]) / np.maximum(np.sum(np.abs(a[:, hits]) / w2[:, None], axis=0), 1e-300)
            lr = np.real(np.asarray(lower)[hits, i]) / np.maximum(np.sum(np.abs(a[:, hits]), axis=0), 1e-300)
            hits = hits[(ur > -RESIDUAL_SIGN_MIN) & (lr > -RESIDUAL_SIGN_MIN)]
        labels.append(model.outputs[int(hits[0])].dof if hits.size == 1 else inp.dof)
    return labels
