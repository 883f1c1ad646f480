"""FRF, mode-shape and geometry files: UFF 58 (FRF, coherence), UFF 55 (modes), UFF 15/2411
(nodes) through pyuff, and complex-valued text/CSV FRF tables.

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
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.modal._results import ModalModel
from vibroscope.spectral._results import FRF
from vibroscope.spectral.kinds import FRF_KIND_TABLE, FRF_KINDS

__all__ = [
    "read_frf",
    "write_frf_uff58",
    "read_modes_uff55",
    "write_modes_uff55",
    "read_geometry",
    "write_geometry_uff15",
    "uff_datasets",
]

#: UFF specific data types (dataset 58 records 8-10): response quantity -> FRF kind
_SPEC_TO_KIND = {k.uff_data_type: k.name for k in FRF_KIND_TABLE.values()}
_FORCE_SPEC = (13, 9)  # excitation force, reaction force
_FUNC_TYPES = {
    0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum", 4: "FRF",
    5: "transmissibility", 6: "coherence", 7: "auto correlation", 8: "cross correlation", 9: "PSD",
    10: "ESD", 11: "probability density", 12: "spectrum", 18: "mode indicator function",
    26: "multiple coherence", 27: "order function",
}
_AXIS = {1: "X", 2: "Y", 3: "Z", 4: "RX", 5: "RY", 6: "RZ"}
_AXIS_CODE = {v: k for k, v in _AXIS.items()}
_DOF_RE = re.compile(r"^\s*(\d+)\s*(?:([+-]?)\s*(RX|RY|RZ|X|Y|Z))?\s*$", re.I)
_UFF_SUFFIXES = (".uff", ".unv", ".uf")


# ---------------------------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------------------------

def _dof_name(node: int, direction: int) -> str:
    """``"12+Z"`` for node 12, direction +3; ``"12"`` for a scalar (direction 0)."""
    if direction == 0 or abs(direction) not in _AXIS:
        return f"{node}"
    return f"{node}{'+' if direction > 0 else '-'}{_AXIS[abs(direction)]}"


def _parse_dof(name: str) -> tuple[int, int] | None:
    """``"12+Z"`` -> (12, 3), ``"7-X"`` -> (7, -1), ``"5"`` -> (5, 0); None if not DOF-like."""
    m = _DOF_RE.match(str(name))
    if not m:
        return None
    node = int(m.group(1))
    if node <= 0:
        return None
    if m.group(3) is None:
        return node, 0
    code = _AXIS_CODE[m.group(3).upper()]
    return node, -code if m.group(2) == "-" else code


def _label(v: Any) -> str:
    """An ID line or label as read by pyuff, with ``NONE`` as empty."""
    s = str(v if v is not None else "").strip()
    return "" if s.upper() == "NONE" else s


def _id_line(s: str) -> str:
    """A UFF ID line: one line, at most 80 characters, ``NONE`` when empty."""
    s = " ".join(str(s).split())[:80]
    return s or "NONE"


def _open_uff(path: Path):
    import pyuff

    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    try:
        u = pyuff.UFF(str(path))
        types = [int(t) for t in u.get_set_types()]
    except Exception as exc:  # noqa: BLE001 -- pyuff raises bare Exception
        raise LogFormatError(f"{path}: not a readable UFF file ({exc})") from exc
    if not types:
        raise LogFormatError(f"{path}: no UFF data set found (no '    -1' delimited blocks)")
    return u, types


def uff_datasets(path: str | Path) -> list[int]:
    """The dataset numbers of a Universal File's records, in file order.

    Parameters
    ----------
    path : str or Path
        A Universal File (ASCII or binary).

    Returns
    -------
    list of int
        E.g. ``[164, 15, 55, 55]`` for units, nodes and two mode records.

    Raises
    ------
    LogFormatError
        If the file is missing, unreadable or holds no dataset.
    """
    return _open_uff(Path(path))[1]


def _read_set(u, path: Path, i: int, header_only: bool = False) -> dict:
    try:
        return u.read_sets(i, header_only=header_only)
    except Exception as exc:  # noqa: BLE001
        raise LogFormatError(f"{path}: data set #{i + 1} cannot be read by pyuff ({exc})") from exc


def _summary(types: Sequence[int]) -> str:
    from collections import Counter

    return ", ".join(f"{n}× dataset {t}" for t, n in Counter(types).items())


def _remove(path: Path) -> None:
    if path.exists():
        path.unlink()


def _check_kind(kind: str | None) -> None:
    if kind is not None and kind not in FRF_KINDS:
        raise ValueError(
            f"Invalid value for the 'kind' parameter. Allowed values are "
            f"{', '.join(repr(a) for a in FRF_KINDS)}, None, but got {kind!r} instead."
        )


# ---------------------------------------------------------------------------------------------
# an intermediate table, before names/kind overrides and concatenation
# ---------------------------------------------------------------------------------------------

class _Table:
    def __init__(self, path, f, H, coh, inputs, outputs, named, kind, units, fmt, extra=None):
        self.path, self.f, self.H, self.coh = path, f, H, coh
        self.inputs, self.outputs, self.named = list(inputs), list(outputs), named
        self.kind, self.units, self.fmt, self.extra = kind, units, fmt, dict(extra or {})


# ---------------------------------------------------------------------------------------------
# text / CSV
# ---------------------------------------------------------------------------------------------

_ROLE_WORDS = {
    "re": "re", "real": "re",
    "im": "im", "imag": "im", "imaginary": "im",
    "mag": "mag", "abs": "mag", "amp": "mag", "magnitude": "mag", "amplitude": "mag", "modulus": "mag",
    "phase": "phase", "ph": "phase", "arg": "phase", "angle": "phase", "phi": "phase",
}
_FREQ_WORDS = {"f", "freq", "frequency", "frequencies", "hz", "f_hz", "freq_hz", "frequency_hz"}
_TOKEN_SPLIT = re.compile(r"[\s_\-()\[\]{}.:/|]+")


def _classify(name: str) -> tuple[str, str, dict]:
    """(role, output name, flags) of a header cell; role in freq/re/im/mag/phase/complex."""
    raw = name.strip().strip('"').strip("'")
    toks = [t for t in _TOKEN_SPLIT.split(raw) if t]
    low = [t.lower() for t in toks]
    if low and (low[0] in _FREQ_WORDS or "".join(low) in _FREQ_WORDS):
        return "freq", "", {}
    roles = [_ROLE_WORDS[t] for t in low if t in _ROLE_WORDS]
    db = "db" in low
    rad = "rad" in low
    rest = [t for t, lt in zip(toks, low) if lt not in _ROLE_WORDS and lt not in ("db", "deg", "rad", "degrees")]
    out = "_".join(rest)
    if len(set(roles)) == 1:
        return roles[0], out, {"db": db, "rad": rad}
    if not roles and db:
        return "mag", out, {"db": True, "rad": False}
    return "complex", raw, {}


def _num(tok: str) -> complex:
    t = tok.strip().replace(" ", "").strip('"')
    if t.startswith("(") and t.endswith(")"):
        t = t[1:-1]
    if t.endswith("i") and not t.lower().endswith("inf"):
        t = t[:-1] + "j"
    return complex(t)


def _sniff_delimiter(line: str) -> str | None:
    for d in (";", "\t", ","):
        if d in line:
            return d
    return None  # whitespace


def _read_text(path: Path, delimiter: str | None, df: float) -> _Table:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise LogFormatError(f"{path}: byte {exc.start}: not a UTF-8 text file") from exc
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read ({exc})") from exc
    lines = [(k, ln) for k, ln in enumerate(text.splitlines(), start=1)
             if ln.strip() and not ln.lstrip().startswith(("#", "%"))]
    if not lines:
        raise LogFormatError(f"{path}: no data lines")
    delim = delimiter if delimiter is not None else _sniff_delimiter(lines[0][1])

    def split(ln: str) -> list[str]:
        parts = ln.split(delim) if delim is not None else ln.split()
        if delim is not None and parts and not parts[-1].strip():
            parts = parts[:-1]  # a trailing delimiter
        return parts

    first = split(lines[0][1])
    header: list[str] | None = None
    try:
        [_num(c) for c in first]
    except ValueError:
        header = [c.strip() for c in first]
        lines = lines[1:]
        if not lines:
            raise LogFormatError(f"{path}: a header line and no data lines") from None
    ncol = len(header) if header is not None else len(first)
    vals = np.empty((len(lines), ncol), complex)
    for r, (lineno, ln) in enumerate(lines):
        parts = split(ln)
        if len(parts) != ncol:
            raise LogFormatError(f"{path}: line {lineno}: {len(parts)} columns where "
                                 f"{'the header names' if header else 'the first line has'} {ncol}")
        for c, tok in enumerate(parts):
            try:
                vals[r, c] = _num(tok)
            except ValueError:
                raise LogFormatError(
                    f"{path}: line {lineno}, column {c + 1}: cannot read {tok.strip()[:40]!r} as a number"
                ) from None
    linenos = [ln for ln, _ in lines]

    def real_col(c: int, what: str) -> np.ndarray:
        v = vals[:, c]
        bad = np.nonzero(np.abs(v.imag) > 1e-12 * np.maximum(np.abs(v.real), 1e-300))[0]
        if bad.size:
            raise LogFormatError(f"{path}: line {linenos[bad[0]]}, column {c + 1}: {what} must be real, "
                                 f"got {v[bad[0]]!r}")
        return v.real.copy()

    # --- the columns' roles
    if header is not None:
        cls = [_classify(h) for h in header]
    elif ncol == 1:
        cls = [("complex", "", {})]
    else:
        cls = [("freq", "", {})] + [("complex", "", {})] * (ncol - 1)
    if any(r == "freq" for r, _, _ in cls[1:]):
        k = next(i for i, (r, _, _) in enumerate(cls) if r == "freq" and i > 0)
        raise LogFormatError(f"{path}: line {lines[0][0] - 1 if header else 1}, column {k + 1}: the frequency "
                             f"column must be the first")
    if cls[0][0] == "freq":
        f = real_col(0, "the frequency")
        start = 1
        axis = "file"
    else:
        f = np.arange(len(lines)) * float(df)
        start = 0
        axis = f"assumed: n * {float(df):g} Hz"
    cols: list[np.ndarray] = []
    names: list[str] = []
    c = start
    while c < ncol:
        role, nm, fl = cls[c]
        pair = {"re": "im", "mag": "phase"}.get(role)
        if role == "complex":
            cols.append(vals[:, c])
            names.append(nm)
            c += 1
            continue
        if pair is None or c + 1 >= ncol or cls[c + 1][0] != pair:
            raise LogFormatError(
                f"{path}: header, column {c + 1} ({header[c]!r}): a {role} column must be followed by its "
                f"{pair or ('re' if role == 'im' else 'mag')} partner "
                f"({'re, im' if role in ('re', 'im') else 'mag, phase'} pairs)")
        a = real_col(c, f"{role} ({header[c]!r})")
        b = real_col(c + 1, f"{pair} ({header[c + 1]!r})")
        if role == "re":
            cols.append(a + 1j * b)
        else:
            mag = 10.0 ** (a / 20.0) if fl["db"] else a
            ph = b if cls[c + 1][2].get("rad") else np.radians(b)
            cols.append(mag * np.exp(1j * ph))
        names.append(nm or cls[c + 1][1])
        c += 2
    if not cols:
        raise LogFormatError(f"{path}: no FRF column after the frequency column")
    if not np.all(np.isfinite(f)):
        k = int(np.nonzero(~np.isfinite(f))[0][0])
        raise LogFormatError(f"{path}: line {linenos[k]}, column 1: frequency {f[k]!r} is not finite")
    d = np.diff(f)
    if np.any(d <= 0):
        k = int(np.nonzero(d <= 0)[0][0]) + 1
        raise LogFormatError(f"{path}: line {linenos[k]}, column 1: frequency {f[k]:g} Hz does not increase "
                             f"(previous {f[k - 1]:g} Hz)")
    named = header is not None and all(names)
    if not named:
        names = [str(k + 1) for k in range(len(cols))]
    H = np.stack(cols, axis=1)[:, :, None]
    coh = np.full((f.size, len(cols)), np.nan)
    fmt = "text" if (header is None and ncol == 1) else "csv"
    return _Table(path, f, H, coh, ["input"], names, named, None, "", fmt,
                  {"frequency_axis": axis, "delimiter": delim})


# ---------------------------------------------------------------------------------------------
# UFF 58
# ---------------------------------------------------------------------------------------------

def _read_uff58_frf(path: Path, input_name: str | None) -> _Table:
    u, types = _open_uff(path)
    heads = {i: _read_set(u, path, i, header_only=True) for i, t in enumerate(types) if t == 58}
    ftypes = {i: int(h.get("func_type", 0)) for i, h in heads.items()}
    frf_idx = [i for i, ft in ftypes.items() if ft == 4]
    if not frf_idx:
        found = ", ".join(f"function type {ft} ({_FUNC_TYPES.get(ft, '?')})"
                          for ft in sorted(set(ftypes.values()))) or "none"
        hint = ""
        if 1 in ftypes.values():
            hint = (f"; it holds time data: make it an MCAP log with `vibroscope convert {path} LOG.mcap`, "
                    "then run `vibroscope modal LOG.mcap --input ...` or `vibroscope analyse LOG.mcap`")
        elif 55 in types:
            hint = "; it holds UFF 55 mode shapes: read them with `vibroscope modal` on this file alone"
        raise LogFormatError(
            f"{path}: no UFF 58 FRF record (function type 4) among {len(types)} data sets "
            f"({_summary(types)}); dataset-58 function types found: {found}{hint}")
    recs = {i: _read_set(u, path, i) for i in frf_idx}

    def out_key(i: int, s: dict) -> str:
        node = int(s.get("rsp_node", 0) or 0)
        if node > 0:
            return _dof_name(node, int(s.get("rsp_dir", 0) or 0))
        return _label(s.get("id1")) or f"record{i + 1}"

    def in_key(s: dict) -> str:
        node = int(s.get("ref_node", 0) or 0)
        if node > 0:
            return _dof_name(node, int(s.get("ref_dir", 0) or 0))
        return _label(s.get("id4")) or (input_name or "input")

    i0 = frf_idx[0]
    f = np.asarray(recs[i0]["x"], float)
    outputs: list[str] = []
    inputs: list[str] = []
    pairs: dict[tuple[str, str], int] = {}
    for i in frf_idx:
        s = recs[i]
        x = np.asarray(s["x"], float)
        if x.shape != f.shape or not np.allclose(x, f, rtol=1e-6, atol=1e-9 * max(1.0, abs(f[-1]))):
            raise LogFormatError(f"{path}: data set #{i + 1}: FRF record has a frequency axis of {x.size} points "
                                 f"({x[0]:g}..{x[-1]:g} Hz) unlike data set #{i0 + 1} ({f.size} points, "
                                 f"{f[0]:g}..{f[-1]:g} Hz)")
        o, r = out_key(i, s), in_key(s)
        if (o, r) in pairs:
            o = f"{o} #{i + 1}"
        pairs[(o, r)] = i
        if o not in outputs:
            outputs.append(o)
        if r not in inputs:
            inputs.append(r)
    H = np.full((f.size, len(outputs), len(inputs)), np.nan, complex)
    for (o, r), i in pairs.items():
        H[:, outputs.index(o), inputs.index(r)] = np.asarray(recs[i]["data"])
    # coherence: multiple coherence (26) per output, or ordinary (6) for a single input
    coh = np.full((f.size, len(outputs)), np.nan)
    coh_from: dict[str, int] = {}
    for i, ft in ftypes.items():
        if ft not in (6, 26):
            continue
        s = _read_set(u, path, i)
        o = out_key(i, s)
        if o not in outputs:
            continue
        if ft == 6 and (len(inputs) != 1 or in_key(s) != inputs[0]):
            continue
        if ft == 6 and o in coh_from and ftypes[coh_from[o]] == 26:
            continue  # the multiple coherence wins
        x = np.asarray(s["x"], float)
        if x.shape != f.shape or not np.allclose(x, f, rtol=1e-6, atol=1e-9 * max(1.0, abs(f[-1]))):
            raise LogFormatError(f"{path}: data set #{i + 1}: coherence record for {o!r} has a frequency axis "
                                 f"unlike its FRF (data set #{i0 + 1})")
        coh[:, outputs.index(o)] = np.real(np.asarray(s["data"]))
        coh_from[o] = i
    # kind and units from the specific data types
    kinds = set()
    for i in frf_idx:
        s = recs[i]
        num, den = int(s.get("ordinate_spec_data_type", 0) or 0), int(s.get("orddenom_spec_data_type", 0) or 0)
        kinds.add(_SPEC_TO_KIND.get(num) if den in _FORCE_SPEC else None)
    kind = kinds.pop() if len(kinds) == 1 else None
    if kind:
        units = FRF_KIND_TABLE[kind].unit
    else:
        labs = {(_label(recs[i].get("ordinate_axis_units_lab")), _label(recs[i].get("orddenom_axis_units_lab")))
                for i in frf_idx}
        num, den = labs.pop() if len(labs) == 1 else ("", "")
        units = f"{num}/{den}" if num and den else num
    binary = sorted({int(recs[i].get("binary", 0) or 0) for i in frf_idx})
    extra = {"records": [i + 1 for i in frf_idx], "coherence_records": {o: i + 1 for o, i in coh_from.items()},
             "binary": binary, "id2": _label(recs[i0].get("id2"))}
    return _Table(path, f, H, coh, inputs, outputs, True, kind, units, "uff58", extra)


# ---------------------------------------------------------------------------------------------
# dispatch and combination
# ---------------------------------------------------------------------------------------------

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
    if path.suffix.lower() in _UFF_SUFFIXES:
        return True
    try:
        with open(path, "rb") as fh:
            head = fh.read(256)
    except OSError:
        return False
    first = next((ln for ln in head.splitlines() if ln.strip()), b"")
    return first.strip() == b"-1"


def _read_one(path: Path, delimiter, df, input_name) -> _Table:
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    if _is_uff(path):
        return _read_uff58_frf(path, input_name)
    return _read_text(path, delimiter, df)


def _combine(tables: list[_Table]) -> _Table:
    if len(tables) == 1:
        return tables[0]
    t0 = tables[0]
    for t in tables[1:]:
        if t.f.shape != t0.f.shape or not np.allclose(t.f, t0.f, rtol=1e-6, atol=1e-12):
            raise LogFormatError(f"{t.path}: frequency axis ({t.f.size} points, {t.f[0]:g}..{t.f[-1]:g} Hz) "
                                 f"differs from that of {t0.path} ({t0.f.size} points, "
                                 f"{t0.f[0]:g}..{t0.f[-1]:g} Hz)")
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
    return _Table(t0.path, t0.f, np.concatenate([t.H for t in tables], axis=1),
                  np.concatenate([t.coh for t in tables], axis=1), t0.inputs, outputs, True,
                  kinds.pop() if len(kinds) == 1 else None, units.pop() if len(units) == 1 else "",
                  "+".join(sorted(fmts)), {k: v for k, v in t0.extra.items() if k != "records"})


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
    units = FRF_KIND_TABLE[k].unit if k is not None else t.units
    settings = {"source": [str(p) for p in paths] if len(paths) > 1 else str(paths[0]), "format": t.fmt,
                **t.extra}
    notes = _non_finite_notes(t.f, t.H, outputs, inputs)
    if notes:
        import warnings

        settings["warnings"] = notes
        for line in notes:
            warnings.warn(f"{settings['source']}: {line}", stacklevel=2)
    return FRF(t.f, t.H, t.coh, inputs, outputs, "unknown", k, units, settings)


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


# ---------------------------------------------------------------------------------------------
# UFF 58 writer
# ---------------------------------------------------------------------------------------------

def _date_line() -> str:
    return time.strftime("%d-%b-%y %H:%M:%S")


def write_frf_uff58(frf: FRF, path: str | Path, *, binary: bool = False) -> Path:
    """Write an FRF as a Universal File: one dataset-58 record per output/input pair.

    Parameters
    ----------
    frf : FRF
        ``H`` complex (n_freqs, n_outputs, n_inputs) on ``frequencies`` (Hz, at least 2).
    path : str or Path
        The file to write (overwritten).
    binary : bool, optional
        Write binary 58 records (``58b``: double-precision data) instead of ASCII.

    Returns
    -------
    Path
        `path`.

    Notes
    -----
    Each FRF record has function type 4; its response DOF comes from the output's name when it
    reads as a node DOF (``"12+Z"``, ``"3-X"``, ``"5"``), else response node 0 and the name in
    ID line 1; its reference DOF likewise from the input's name, else reference node 0 and
    the name in ID line 4 -- the conventions :func:`read_frf` reads back. The specific data
    types state the kind (numerator 12/11/8 over 13, excitation force; 0/0 when the kind is
    None); the abscissa is frequency (18) in Hz, evenly spaced when the steps agree to 1e-6.

    For a single input, each output's coherence is written as a function-type-6 record when
    any of it is finite; pyuff writes non-finite values (NaN, inf) as 0, in coherence and FRF
    alike, since the format has no NaN. With several inputs the coherence is the multiple
    coherence (function type 26), which pyuff cannot write, so none is written. Output/input
    pairs whose ``H`` is NaN throughout are not written.

    Precision: ASCII data values are written with 12 significant digits (``E20.12``); the
    abscissa minimum and increment (or, unevenly spaced in ASCII, each abscissa value) with
    6 (``E13.5``), the format's own single-precision abscissa. ID lines hold 80 characters.

    Raises
    ------
    ValueError
        If the FRF has fewer than 2 frequencies.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 58
       (Function at Nodal DOF), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    f = np.asarray(frf.frequencies, float)
    if f.size < 2:
        raise ValueError(f"{f.size=}: a UFF 58 record needs at least 2 frequencies")
    d = np.diff(f)
    even = bool(np.allclose(d, d[0], rtol=1e-6, atol=0.0))
    kind = frf.kind
    k = FRF_KIND_TABLE.get(kind)
    num_spec, den_spec = (k.uff_data_type, 13) if k else (0, 0)
    num_lab, den_lab = (k.response_unit, "N") if k else ("NONE", "NONE")
    common = dict(binary=int(bool(binary)), abscissa_spacing=int(even), abscissa_spec_data_type=18,
                  abscissa_axis_units_lab="Hz", x=f, id3=_date_line())
    dsets: list[dict] = []
    one_input = frf.H.shape[2] == 1
    for i, inp in enumerate(frf.inputs):
        rdof = _parse_dof(inp)
        ref_node, ref_dir = rdof if rdof else (0, 0)
        for o, out in enumerate(frf.outputs):
            h = np.asarray(frf.H[:, o, i], complex)
            if np.all(np.isnan(h)):
                continue
            odof = _parse_dof(out)
            rsp_node, rsp_dir = odof if odof else (0, 0)
            ids = dict(id1=_id_line(out), id2=_id_line(f"{frf.estimator} FRF"), id4=_id_line(inp))
            ds = pyuff.prepare_58(func_type=4, rsp_node=int(rsp_node), rsp_dir=int(rsp_dir),
                                  ref_node=int(ref_node), ref_dir=int(ref_dir), data=h.copy(),
                                  ordinate_spec_data_type=num_spec, orddenom_spec_data_type=den_spec,
                                  ordinate_axis_units_lab=num_lab, orddenom_axis_units_lab=den_lab,
                                  **ids, **common)
            ds["func_id"] = len(dsets) + 1
            dsets.append(ds)
            c = np.asarray(frf.coherence[:, o], float) if frf.coherence.size else np.full(f.size, np.nan)
            if one_input and np.any(np.isfinite(c)):
                ids = dict(ids, id2=_id_line(f"{frf.estimator} coherence"))
                ds = pyuff.prepare_58(func_type=6, rsp_node=int(rsp_node), rsp_dir=int(rsp_dir),
                                      ref_node=int(ref_node), ref_dir=int(ref_dir), data=c.copy(),
                                      ordinate_spec_data_type=0, orddenom_spec_data_type=0,
                                      **ids, **common)
                ds["func_id"] = len(dsets) + 1
                dsets.append(ds)
    if not dsets:
        raise ValueError("the FRF is NaN throughout: nothing to write")
    _remove(path)  # pyuff's binary writer is only reliable in 'add' mode
    u = pyuff.UFF(str(path))
    u.write_sets(dsets, mode="add")
    return path


# ---------------------------------------------------------------------------------------------
# UFF 55 modes
# ---------------------------------------------------------------------------------------------

def _direction_code(v: Any, k: int) -> int:
    if isinstance(v, (int, np.integer)):
        code = int(v)
    else:
        s = str(v).strip().upper()
        sign = -1 if s.startswith("-") else 1
        s = s.lstrip("+-").strip()
        code = sign * ({"X": 1, "Y": 2, "Z": 3, "1": 1, "2": 2, "3": 3}.get(s, 0))
    if abs(code) not in (1, 2, 3):
        raise ValueError(f"directions[{k}]={v!r} must be one of ±1, ±2, ±3 or '+X', '-y', 'z', ...")
    return code


def write_modes_uff55(
    modal_model: ModalModel,
    path: str | Path,
    *,
    node_ids: Sequence[int] | None = None,
    directions: Sequence[int | str] | None = None,
) -> Path:
    """Write mode shapes as UFF dataset 55 records (complex eigenvalue, one per mode).

    Parameters
    ----------
    modal_model : ModalModel
        Natural frequencies (Hz), damping ratios and complex shapes (n_modes, n_points).
    path : str or Path
        The file to write (overwritten).
    node_ids : sequence of int, optional
        The node of each point, shape (n_points,). Default: from a point name that reads as a
        node DOF (``"12+Z"``, ``"12"``), else ``k + 1`` for the k-th point.
    directions : sequence of int or str, optional
        The measuring direction of each point, shape (n_points,): ``±1/±2/±3`` or ``'+X'``,
        ``'-y'``, ``'z'``. Default: from a DOF-like point name, else ``+Z``.

    Returns
    -------
    Path
        `path`.

    Notes
    -----
    Each mode is one record of analysis type 3 (complex eigenvalue, first order), data
    characteristic 2 (3-DOF translation), specific data type 8 (displacement), complex data.
    The eigenvalue (rad/s) is ``λ = -ζ ω + j ω √(1-ζ²)`` with ``ω = 2π f_n``, so the natural
    frequency ``|λ|/2π`` and the damping ratio ``-Re λ / |λ|`` survive; an unknown (NaN) damping
    ratio is written as a NaN real part with ``Im λ = ω``. A point's shape value goes to its
    node's X/Y/Z slot, negated for a negative direction; the other slots are 0. Modal A and B
    are written as 0. ID line 1 holds the model's method. All values are written with 6
    significant digits (``E13.5``).

    Raises
    ------
    ValueError
        If `node_ids`/`directions` have the wrong length or two points share a node DOF, or a
        damping ratio is not in (-1, 1).

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 55
       (Data at Nodes), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    n_pts = len(modal_model.points)
    parsed = [_parse_dof(p) for p in modal_model.points]
    if node_ids is None:
        nodes = [p[0] if p else k + 1 for k, p in enumerate(parsed)]
    else:
        nodes = [int(n) for n in node_ids]
        if len(nodes) != n_pts:
            raise ValueError(f"{len(nodes)} node_ids for {n_pts} points")
    if directions is None:
        dirs = [p[1] if (p and p[1] and abs(p[1]) <= 3) else 3 for p in parsed]
    else:
        if len(directions) != n_pts:
            raise ValueError(f"{len(directions)} directions for {n_pts} points")
        dirs = [_direction_code(v, k) for k, v in enumerate(directions)]
    seen: dict[tuple[int, int], str] = {}
    for p, nd, dr in zip(modal_model.points, nodes, dirs):
        if (nd, abs(dr)) in seen:
            raise ValueError(f"points {seen[(nd, abs(dr))]!r} and {p!r} share node {nd} direction {_AXIS[abs(dr)]}")
        seen[(nd, abs(dr))] = p
    uniq = list(dict.fromkeys(nodes))
    pos = {nd: k for k, nd in enumerate(uniq)}
    dsets = []
    for m in range(len(modal_model)):
        fn = float(modal_model.natural_frequencies[m])
        z = float(modal_model.damping_ratios[m])
        w = 2 * np.pi * fn
        if np.isnan(z):
            eig = complex(np.nan, w)
        else:
            if not -1 < z < 1:
                raise ValueError(f"mode {m + 1}: damping ratio {z} must be in (-1, 1) for a complex eigenvalue")
            eig = complex(-z * w, w * np.sqrt(1 - z * z))
        r = np.zeros((3, len(uniq)), complex)
        for k, (nd, dr) in enumerate(zip(nodes, dirs)):
            r[abs(dr) - 1, pos[nd]] = np.sign(dr) * modal_model.shapes[m, k]
        ds = pyuff.prepare_55(
            id1=_id_line(modal_model.method), id2=_id_line("vibroscope mode shapes"), id3=_id_line(_date_line()),
            id4="NONE", id5=_id_line(f"Mode {m + 1} {fn:.6g} Hz"),
            model_type=1, analysis_type=3, data_ch=2, spec_data_type=8, data_type=5, n_data_per_node=3,
            r1=r[0], r2=r[1], r3=r[2], load_case=1, mode_n=m + 1, eig=eig, modal_a=0j, modal_b=0j,
            node_nums=np.asarray(uniq, dtype=int))
        dsets.append(ds)
    if not dsets:
        raise ValueError("the modal model has no modes: nothing to write")
    _remove(path)
    pyuff.UFF(str(path)).write_sets(dsets, mode="add")
    return path


def read_modes_uff55(path: str | Path) -> ModalModel:
    """Read mode shapes from UFF dataset 55 records.

    Parameters
    ----------
    path : str or Path
        A Universal File holding dataset-55 records of analysis type 2 (normal mode), 3 or 7
        (complex eigenvalue, first or second order); other datasets and analysis types
        (frequency response, static) are skipped.

    Returns
    -------
    ModalModel
        One mode per record, in file order. Complex eigenvalue records give the natural
        frequency ``|λ|/2π`` (Hz) and damping ratio ``-Re λ / |λ|`` (a NaN real part:
        frequency ``Im λ / 2π``, damping NaN); normal-mode records their frequency and modal
        viscous damping ratio. Points are the node DOFs ``"{node}+X|Y|Z"`` (and ``+RX..RZ`` for
        6-DOF real data) that are nonzero in at least one mode, in node order of appearance;
        a node absent from a record counts as 0 (dataset-55 note 9). Shapes are as stored (not
        renormalised). `method` is ID line 1 of the first record (``"uff55"`` when NONE);
        `extra` holds ``mode_numbers``, ``analysis_types`` (arrays, one per mode), ``modal_a``,
        ``modal_b`` (complex eigenvalue records; NaN otherwise) and ``source``.

    Raises
    ------
    LogFormatError
        If the file is unreadable or holds no mode record (names the datasets and analysis
        types found).

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 55
       (Data at Nodes), University of Cincinnati.
    """
    path = Path(path)
    u, types = _open_uff(path)
    recs, found = [], []
    for i, t in enumerate(types):
        if t != 55:
            continue
        s = _read_set(u, path, i)
        at = int(s.get("analysis_type", 0))
        found.append(at)
        if at in (2, 3, 7):
            recs.append((i, s))
    if not recs:
        raise LogFormatError(f"{path}: no UFF 55 mode record (analysis type 2, 3 or 7) among {len(types)} data "
                             f"sets ({_summary(types)}); dataset-55 analysis types found: {sorted(set(found))}")
    freqs, zetas, mode_n, ats, ma, mb = [], [], [], [], [], []
    values: list[dict[tuple[int, int], complex]] = []
    dof_order: list[tuple[int, int]] = []
    for i, s in recs:
        at = int(s["analysis_type"])
        if at == 2:
            fn = float(s.get("freq", np.nan))
            z = float(s.get("modal_damp_vis", np.nan))
            ma.append(np.nan)
            mb.append(np.nan)
        else:
            lam = complex(s.get("eig", np.nan))
            if np.isnan(lam.real):
                fn, z = lam.imag / (2 * np.pi), np.nan
            else:
                wn = abs(lam)
                fn = wn / (2 * np.pi)
                z = -lam.real / wn if wn > 0 else np.nan
            ma.append(complex(s.get("modal_a", np.nan)))
            mb.append(complex(s.get("modal_b", np.nan)))
        freqs.append(fn)
        zetas.append(z)
        mode_n.append(int(s.get("mode_n", len(freqs))))
        ats.append(at)
        nodes = np.asarray(s.get("node_nums", []), int)
        comps = [s[k] for k in ("r1", "r2", "r3", "r4", "r5", "r6") if k in s]
        if any(len(c) != nodes.size for c in comps):
            raise LogFormatError(f"{path}: data set #{i + 1}: {nodes.size} nodes but value arrays of lengths "
                                 f"{[len(c) for c in comps]}")
        vals: dict[tuple[int, int], complex] = {}
        for j, nd in enumerate(nodes):
            for c, comp in enumerate(comps, start=1):
                key = (int(nd), c)
                vals[key] = complex(comp[j])
                if key not in dof_order:
                    dof_order.append(key)
        values.append(vals)
    nonzero = [k for k in dof_order if any(v.get(k, 0) != 0 for v in values)]
    shapes = np.array([[v.get(k, 0j) for k in nonzero] for v in values], complex).reshape(len(values), len(nonzero))
    method = _label(recs[0][1].get("id1")) or "uff55"
    extra = {"mode_numbers": np.asarray(mode_n), "analysis_types": np.asarray(ats),
             "modal_a": np.asarray(ma, complex), "modal_b": np.asarray(mb, complex), "source": str(path)}
    return ModalModel(freqs, zetas, shapes, [_dof_name(n, c) for n, c in nonzero], method, extra)


# ---------------------------------------------------------------------------------------------
# geometry: UFF 15 / 2411 nodes
# ---------------------------------------------------------------------------------------------

def write_geometry_uff15(path: str | Path, node_ids: Sequence[int], xyz: np.ndarray) -> Path:
    """Write node coordinates as UFF dataset 164 (SI units) and 15 (nodes).

    Parameters
    ----------
    path : str or Path
        The file to write (overwritten).
    node_ids : sequence of int, shape (n_nodes,)
        Node labels, unique, positive.
    xyz : array_like, shape (n_nodes, 3)
        Coordinates in m.

    Returns
    -------
    Path
        `path`.

    Notes
    -----
    Dataset 15 stores coordinates with 6 significant digits (``E13.5``); a units record
    (dataset 164, SI, length factor 1) precedes it so that :func:`read_geometry` and other
    readers know the coordinates are in metres.

    Raises
    ------
    ValueError
        If the shapes disagree, `xyz` is not finite, or node ids repeat or are not positive.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15
       (Nodes) and 164 (Units), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    ids = np.asarray(node_ids)
    pts = np.asarray(xyz, float)
    if ids.ndim != 1 or pts.shape != (ids.size, 3):
        raise ValueError(f"{ids.shape=} node_ids need xyz of shape ({ids.size}, 3), got {pts.shape=}")
    if ids.size == 0 or not np.all(np.isfinite(pts)):
        raise ValueError("xyz must hold at least one node and only finite coordinates (m)")
    if not np.issubdtype(ids.dtype, np.integer) and not np.all(ids == np.round(ids)):
        raise ValueError(f"node_ids must be integers, got {ids[:5]}")
    ids = ids.astype(int)
    if np.any(ids <= 0) or np.unique(ids).size != ids.size:
        raise ValueError("node_ids must be positive and unique")
    units = pyuff.prepare_164(units_code=1, units_description="SI: Meter (newton)", temp_mode=2,
                              length=1.0, force=1.0, temp=1.0, temp_offset=273.15)
    nodes = pyuff.prepare_15(node_nums=ids, def_cs=np.zeros(ids.size, int), disp_cs=np.zeros(ids.size, int),
                             color=np.ones(ids.size, int), x=pts[:, 0].copy(), y=pts[:, 1].copy(),
                             z=pts[:, 2].copy())
    _remove(path)
    pyuff.UFF(str(path)).write_sets([units, nodes], mode="add")
    return path


def read_geometry(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read node coordinates from UFF dataset 15 or 2411 records.

    Parameters
    ----------
    path : str or Path
        A Universal File. Every dataset-15 (Nodes) and dataset-2411 (Nodes - Double Precision)
        record contributes its nodes in file order. When a dataset-164 (Units) record is
        present, coordinates are divided by its length factor (the UFF convention for
        converting file units to SI); otherwise they are taken as metres.

    Returns
    -------
    node_ids : ndarray of int, shape (n_nodes,)
    xyz : ndarray, shape (n_nodes, 3)
        Coordinates in m, in each node's definition coordinate system (coordinate systems,
        dataset 2420, are not applied).

    Raises
    ------
    LogFormatError
        If the file is unreadable, holds no node record (names the datasets found), or a node
        id occurs twice.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15,
       164 and 2411, University of Cincinnati.
    """
    path = Path(path)
    u, types = _open_uff(path)
    factor = 1.0
    ids_l, xyz_l = [], []
    for i, t in enumerate(types):
        if t == 164:
            s = _read_set(u, path, i)
            lf = float(s.get("length", 1.0))
            if not (np.isfinite(lf) and lf > 0):
                raise LogFormatError(f"{path}: data set #{i + 1} (units, 164): length factor {lf!r} is not positive")
            factor = lf
        elif t in (15, 2411):
            s = _read_set(u, path, i)
            n = np.asarray(s["node_nums"], float)
            ids_l.append(np.round(n).astype(int))
            xyz_l.append(np.column_stack([np.asarray(s[k], float) for k in ("x", "y", "z")]))
    if not ids_l:
        raise LogFormatError(f"{path}: no node record (dataset 15 or 2411) among {len(types)} data sets "
                             f"({_summary(types)})")
    ids = np.concatenate(ids_l)
    xyz = np.vstack(xyz_l) / factor
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        raise LogFormatError(f"{path}: node ids {uniq[counts > 1][:10].tolist()} occur more than once")
    return ids, xyz
