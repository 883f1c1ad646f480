"""FRF, mode-shape and geometry files: UFF 58 (FRF, coherence), UFF 55 (modes), UFF 15/2411
(nodes) through pyuff, and complex-valued text/CSV FRF tables.

This module holds :func:`read_frf`, the one reader of FRF files (a file's format chosen by its
suffix and content, several files combined into one FRF), and gives the writers and the other
readers under their old names; each format lives in its own module: :mod:`vibroscope.io.frf_csv`
(text/CSV tables), :mod:`vibroscope.io.uff58` (FRF records), :mod:`vibroscope.io.uff55` (modes),
:mod:`vibroscope.io.uff_geometry` (nodes), :mod:`vibroscope.io.uff` (what they share).

Readers return the project's result objects (:class:`~vibroscope.spectral.FRF`,
:class:`~vibroscope.modal.ModalModel`); every format fault raises
:class:`~vibroscope.errors.LogFormatError` naming the file and the record, line or column.

References
----------
.. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15 (Nodes),
   55 (Data at Nodes), 58 (Function at Nodal DOF), 164 (Units), 2411 (Nodes - Double Precision),
   University of Cincinnati.
.. [2] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research Studies
   Press, 2000, §1.3 (accelerance, mobility, receptance).
"""

from __future__ import annotations

import glob as _glob
import math
import re
from pathlib import Path
from typing import Sequence

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.io.frf_csv import read_text_table
from vibroscope.io.frf_table import KIND_UNITS, FrfTable
from vibroscope.io.uff import UFF_SUFFIXES, uff_datasets
from vibroscope.io.uff55 import read_modes_uff55, write_modes_uff55
from vibroscope.io.uff58 import read_uff58_table, write_frf_uff58
from vibroscope.io.uff_geometry import read_geometry, write_geometry_uff15
from vibroscope.spectral import FRF, FRF_KINDS

__all__ = [
    "read_frf",
    "write_frf_uff58",
    "read_modes_uff55",
    "write_modes_uff55",
    "read_geometry",
    "write_geometry_uff15",
    "uff_datasets",
]


def _check_kind(kind: str | None) -> None:
    if kind is not None and kind not in FRF_KINDS:
        raise ValueError(
            f"Invalid value for the 'kind' parameter. Allowed values are "
            f"{', '.join(repr(a) for a in FRF_KINDS)}, None, but got {kind!r} instead."
        )


def _natural_key(p: Path):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def _expand(path_or_paths) -> list[Path]:
    if isinstance(path_or_paths, (str, Path)):
        s = str(path_or_paths)
        if any(ch in s for ch in "*?[") and not Path(s).exists():
            hits = sorted((Path(p) for p in _glob.glob(s)), key=_natural_key)
            if not hits:
                raise LogFormatError(f"{s}: the pattern matches no file")
            return hits
        return [Path(s)]
    paths = [Path(p) for p in path_or_paths]
    if not paths:
        raise ValueError("path_or_paths is an empty sequence")
    return paths


def _is_uff(path: Path) -> bool:
    if path.suffix.lower() in UFF_SUFFIXES:
        return True
    try:
        with open(path, "rb") as fh:
            head = fh.read(256)
    except OSError:
        return False
    first = next((ln for ln in head.splitlines() if ln.strip()), b"")
    return first.strip() == b"-1"


def _read_one(path: Path, delimiter, df, input_name) -> FrfTable:
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    if _is_uff(path):
        return read_uff58_table(path, input_name)
    return read_text_table(path, delimiter, df)


def _combine(tables: list[FrfTable]) -> FrfTable:
    if len(tables) == 1:
        return tables[0]
    t0 = tables[0]
    for t in tables[1:]:
        f, f0 = t.frequencies, t0.frequencies
        if f.shape != f0.shape or not np.allclose(f, f0, rtol=1e-6, atol=1e-12):
            raise LogFormatError(f"{t.path}: frequency axis ({f.size} points, {f[0]:g}..{f[-1]:g} Hz) "
                                 f"differs from that of {t0.path} ({f0.size} points, "
                                 f"{f0[0]:g}..{f0[-1]:g} Hz)")
        if t.inputs != t0.inputs:
            raise LogFormatError(f"{t.path}: inputs {t.inputs} differ from those of {t0.path} {t0.inputs}")
    outputs: list[str] = []
    for t in tables:
        if t.named:
            names = list(t.outputs)
        elif len(t.outputs) == 1:
            names = [t.path.stem]
        else:
            names = [f"{t.path.stem}:{o}" for o in t.outputs]
        names = [f"{t.path.stem}:{n}" if (n in outputs and not n.startswith(f"{t.path.stem}:")) else n
                 for n in names]
        outputs.extend(names)
    if len(set(outputs)) != len(outputs):
        dup = sorted({o for o in outputs if outputs.count(o) > 1})
        raise LogFormatError(f"output names {dup} occur in more than one of the files")
    kinds = {t.kind for t in tables}
    units = {t.units for t in tables}
    fmts = {t.fmt for t in tables}
    return FrfTable(path=t0.path, frequencies=t0.frequencies, H=np.concatenate([t.H for t in tables], axis=1),
                    coh=np.concatenate([t.coh for t in tables], axis=1), inputs=t0.inputs, outputs=outputs,
                    named=True, kind=kinds.pop() if len(kinds) == 1 else None,
                    units=units.pop() if len(units) == 1 else "", fmt="+".join(sorted(fmts)),
                    extra={k: v for k, v in t0.extra.items() if k != "records"})


def read_frf(
    path_or_paths: str | Path | Sequence[str | Path],
    *,
    kind: str | None = None,
    input_name: str | None = None,
    output_names: Sequence[str] | None = None,
    delimiter: str | None = None,
    df: float = 1.0,
) -> FRF:
    """Read frequency response functions from UFF 58 files or complex-valued text tables.

    Parameters
    ----------
    path_or_paths : str, Path or sequence of them
        One file, several files, or a glob pattern (``"data/meas_point_*.txt"``, matched files
        sorted naturally so ``_10`` follows ``_9``). Several files are combined into one FRF with
        the outputs of each file in turn; they must share the frequency axis (to 1e-6 relative)
        and the inputs. The format of each file is chosen by its suffix and content:

        * **UFF 58** (``.uff``, ``.unv``, ``.uf``, or a first line ``-1``; ASCII or binary):
          records of function type 4 (FRF) become ``H[:, output, input]``; outputs are named
          ``"{rsp_node}{+|-}{X|Y|Z|RX|RY|RZ}"`` (``"{node}"`` for a scalar DOF), or by ID line 1
          when the response node is 0; inputs likewise from the reference node and direction,
          or by ID line 4 when the reference node is 0 (else `input_name`, else ``"input"``).
          Output/input pairs absent from the file are NaN. Coherence comes from function-type-26
          records (multiple coherence, matched by response DOF) or, for a single input, type-6
          records (matched by response and reference DOF); NaN without them. The kind follows
          the ordinate specific data types: numerator 12 (acceleration) / 11 (velocity) /
          8 (displacement) over denominator 13 (excitation force) or 9 (reaction force) gives
          accelerance / mobility / receptance; otherwise None with units from the axis labels.
          Records of other function types (time data, spectra) and other datasets are skipped.
        * **Text / CSV** (anything else): one row per frequency; ``;``, tab, ``,`` or whitespace
          separated (sniffed from the first line unless `delimiter` is given); blank lines and
          lines starting with ``#`` or ``%`` are skipped. Numbers may be real or complex in
          Python/numpy notation (``0.03125+0j``, ``-0.05+0.05j``, ``(re+imj)``, ``1-2i``).
          Without a header, a single column is one complex FRF on the assumed axis
          ``np.arange(n) * df`` (the pyuff/sdypy ``meas_point_*.txt`` files), and several
          columns are the frequency (Hz; a complex value must have zero imaginary part)
          followed by one complex column per output (the Southampton ``frfs/*.csv``). A header
          line (any first line that does not parse as numbers) names the columns; accepted
          names, case-insensitive, words split at ``_ - . ( ) [ ] : /`` and spaces:

          - frequency (first column only): ``f``, ``freq``, ``frequency``, ``Hz``
            (e.g. ``f [Hz]``); without it the axis is ``np.arange(n) * df``;
          - real/imaginary pair: ``re``/``real`` then ``im``/``imag`` with the output's name,
            e.g. ``re_1, im_1``, ``Re(H11), Im(H11)``, ``a1 real, a1 imag``;
          - magnitude/phase pair: ``mag``/``abs``/``amp``/``magnitude`` (linear; in dB, i.e.
            ``20 log10 |H|``, when the name also holds ``dB``, e.g. ``mag_1_dB``, ``dB_1``,
            ``mag 1 [dB]``) then ``phase``/``ph``/``arg``/``angle`` in degrees (radians when
            the name holds ``rad``), e.g. ``freq;mag_1;phase_1``;
          - anything else: one complex column named by the header cell.

    kind : {'accelerance', 'mobility', 'receptance'}, optional
        The response quantity per unit force; overrides what a UFF file states (text files
        state nothing, so their kind is None unless given here). Sets `units` accordingly.
    input_name : str, optional
        The name of the single input (default ``"input"`` for text files; for UFF the reference
        DOF name). Only for an FRF with one input.
    output_names : sequence of str, optional
        Names of the outputs, in order, replacing those of the files (default: header names,
        else ``"1".."n"`` for one file and the file stems for several single-column files).
    delimiter : str, optional
        Column separator of text files (default: sniffed).
    df : float, optional
        Frequency step in Hz of text files without a frequency column (default 1.0 Hz, the
        0-1000 Hz, 1 Hz grid of pyuff's ``meas_point_*.txt``); the axis starts at 0 Hz.

    Returns
    -------
    FRF
        ``frequencies`` (n_freqs,) in Hz; ``H`` complex (n_freqs, n_outputs, n_inputs);
        ``coherence`` (n_freqs, n_outputs), NaN where the file has none; ``estimator`` is
        ``"unknown"`` (a file does not say); ``settings`` holds ``source`` (the files),
        ``format`` (``"uff58"``, ``"csv"``, ``"text"``) and, for text, ``frequency_axis``
        (``"file"`` or the assumed grid).

    Raises
    ------
    LogFormatError
        If a file is missing, unreadable, holds no FRF record (names the dataset and function
        types found), or a line or column does not parse (names the file, line and column).
    ValueError
        If `kind` is not a known kind, `output_names` has the wrong length, or `input_name` is
        given for an FRF with several inputs.

    See Also
    --------
    vibroscope.io.write_frf_uff58 : Write an FRF as UFF dataset 58 records.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 58
       (Function at Nodal DOF), University of Cincinnati.

    Examples
    --------
    >>> frf = read_frf("../shared/data/southampton/frfs/Experimental.csv")  # doctest: +SKIP
    >>> frf.H.shape, frf.frequencies[1] - frf.frequencies[0]  # doctest: +SKIP
    ((4096, 3, 1), 0.03125)
    """
    _check_kind(kind)
    if not (isinstance(df, (int, float, np.floating, np.integer)) and math.isfinite(df) and df > 0):
        raise ValueError(f"{df=} must be a positive frequency step in Hz")
    paths = _expand(path_or_paths)
    t = _combine([_read_one(p, delimiter, df, input_name) for p in paths])
    outputs = list(t.outputs)
    if output_names is not None:
        output_names = [str(o) for o in output_names]
        if len(output_names) != len(outputs):
            raise ValueError(f"{len(output_names)} output_names for {len(outputs)} outputs {outputs}")
        outputs = output_names
    inputs = list(t.inputs)
    if input_name is not None:
        if len(inputs) != 1:
            raise ValueError(f"input_name={input_name!r} given for an FRF with {len(inputs)} inputs {inputs}")
        inputs = [str(input_name)]
    k = kind if kind is not None else t.kind
    units = KIND_UNITS[k] if k is not None else t.units
    settings = {"source": [str(p) for p in paths] if len(paths) > 1 else str(paths[0]), "format": t.fmt,
                **t.extra}
    notes = _non_finite_notes(t.frequencies, t.H, outputs, inputs)
    if notes:
        import warnings

        settings["warnings"] = notes
        for line in notes:
            warnings.warn(f"{settings['source']}: {line}", stacklevel=2)
    return FRF(frequencies=t.frequencies, H=t.H, coherence=t.coh, inputs=inputs, outputs=outputs, estimator="unknown", kind=k,
               units=units, settings=settings)


def _non_finite_notes(f: np.ndarray, H: np.ndarray, outputs: list, inputs: list) -> list[str]:
    """One line per output/input pair that holds some NaN or Inf values (not every one: a pair a
    UFF file lacks is NaN throughout by design): how many, and at which frequencies and rows."""
    from vibroscope.signals import true_runs

    out = []
    bad = ~np.isfinite(H)
    for o in range(H.shape[1]):
        for i in range(H.shape[2]):
            b = bad[:, o, i]
            if b.any() and not b.all():
                a, e = true_runs(b)
                where = ", ".join(f"{f[x]:.6g}–{f[y - 1]:.6g} Hz (rows {x}–{y - 1})" for x, y in zip(a[:3], e[:3]))
                out.append(f"output {outputs[o]!r}" + (f" / input {inputs[i]!r}" if len(inputs) > 1 else "")
                           + f": {int(b.sum())} of {b.size} values not finite (NaN/Inf) at {where}"
                           + (" ..." if a.size > 3 else "") + "; the modal fit skips those lines")
    return out
