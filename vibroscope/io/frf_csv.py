"""Complex-valued FRF tables in text and CSV files: the delimiter sniffed, a header line's columns
classified (frequency; real/imaginary or magnitude/phase pairs, magnitude in dB, phase in degrees
or radians; complex columns), numbers read in Python/numpy or MATLAB notation, and every fault
named by file, line and column (:func:`read_text_table`, used by
:func:`vibroscope.io.frf_files.read_frf`)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.io.frf_table import FrfTable

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


def read_text_table(path: Path, delimiter: str | None, df: float) -> FrfTable:
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
    return FrfTable(path=path, frequencies=f, H=H, coh=coh, inputs=["input"], outputs=names, named=named,
                    kind=None, units="", fmt=fmt, extra={"frequency_axis": axis, "delimiter": delim})
