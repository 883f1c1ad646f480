"""Converters from CSV, MATLAB .mat and UFF 58 files to Signals and to MCAP logs."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal, Sequence

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.signals import Signals

__all__ = ["read_csv", "read_mat", "read_uff58", "read_any", "convert_to_mcap", "parse_columns", "normalize_unit"]

_ACC_UNITS = {"m/s^2", "m/s2", "m/s**2", "m s^-2", "m s-2", "m/s/s"}


def normalize_unit(u: str) -> str:
    """Normalise a unit spelling.

    Parameters
    ----------
    u : str
        A unit as found in a file (``m/s2``, ``NONE``).

    Returns
    -------
    str
        ``m/s^2`` for the spellings of an acceleration, ``""`` for ``NONE``, else `u`.
    """
    u = (u or "").strip()
    if u.upper() == "NONE":
        return ""
    return "m/s^2" if u in _ACC_UNITS else u


def parse_columns(spec: str | Sequence[int] | None) -> list[int] | None:
    """Parse a column selection.

    Parameters
    ----------
    spec : str or sequence of int or None
        ``"0-17"``, ``"0,2,5-7"`` (inclusive ranges, 0-based) or indices.

    Returns
    -------
    list of int or None
        The column indices (None for None).

    Raises
    ------
    ValueError
        If a part does not parse or a range runs backwards.
    """
    if spec is None:
        return None
    if not isinstance(spec, str):
        return [int(c) for c in spec]
    out: list[int] = []
    for part in spec.split(","):
        part = part.strip()
        if not part:
            continue
        m = re.fullmatch(r"(\d+)\s*-\s*(\d+)", part)
        if m:
            a, b = int(m.group(1)), int(m.group(2))
            if b < a:
                raise ValueError(f"column range {part!r} runs backwards")
            out.extend(range(a, b + 1))
        elif part.isdigit():
            out.append(int(part))
        else:
            raise ValueError(f"cannot parse column spec {part!r} in {spec!r} (use e.g. 0-17 or 0,3,5-7)")
    return out


def _split_list(v: str | Sequence[str] | None) -> list[str] | None:
    if v is None:
        return None
    if isinstance(v, str):
        return [s.strip() for s in v.split(",")]
    return list(v)


def read_csv(
    path: str | Path,
    *,
    fs: float | None = None,
    columns: str | Sequence[int] | None = None,
    names: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
    time_column: int | None = None,
    delimiter: str | None = None,
) -> Signals:
    """Read a numeric CSV file (one column per channel, optional header line).

    Parameters
    ----------
    path : str or Path
        The file.
    fs : float, optional
        Sampling frequency in Hz; required unless `time_column` is given.
    columns : str or sequence of int, optional
        Columns to read (``"0-17"``; 0-based, the time column excluded). Default: all.
    names, units : str (comma-separated) or sequence of str, optional
        Channel names and units (default: the header, else ``c0, c1, ...``; units ``""``).
    time_column : int, optional
        A column of sample times in s; the rate is estimated from it (it must be uniform
        within 1 %).
    delimiter : str, optional
        Default: detected (``,`` ``;`` tab, else whitespace).

    Returns
    -------
    Signals
        shape (n_columns, n_rows).

    Raises
    ------
    ValueError
        If neither `fs` nor `time_column` is given, or the time column is not uniform.
    LogFormatError
        If the file is not numeric (names file and line).
    """
    path = Path(path)
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        first = fh.readline()
    if delimiter is None:
        delimiter = next((d for d in (",", ";", "\t") if d in first), None)
    cells = [c.strip().strip('"') for c in (first.split(delimiter) if delimiter else first.split())]
    try:
        [float(c) for c in cells if c]
        header = None
    except ValueError:
        header = cells
    try:
        a = np.loadtxt(path, delimiter=delimiter, skiprows=1 if header else 0, ndmin=2, dtype=np.float64)
    except ValueError as exc:
        raise LogFormatError(f"{path}: not a numeric CSV file ({exc})") from exc
    cols = parse_columns(columns)
    allcols = [c for c in range(a.shape[1]) if c != time_column]
    cols = allcols if cols is None else cols
    bad = [c for c in cols if c >= a.shape[1] or c < 0]
    if bad:
        raise ValueError(f"{path}: columns {bad} out of range for {a.shape[1]} columns")
    if time_column is not None:
        t = a[:, time_column]
        dt = np.diff(t)
        med = float(np.median(dt))
        if not med > 0 or np.max(np.abs(dt - med)) > 0.01 * med:
            raise ValueError(f"{path}: time column {time_column} is not uniformly sampled (median dt {med:g} s)")
        fs_t = (t.size - 1) / (t[-1] - t[0])
        fs = fs if fs is not None else fs_t
        t0 = float(t[0])
    else:
        if fs is None:
            raise ValueError(f"{path}: no time column, so the sampling rate must be stated (fs in Hz, --fs)")
        t0 = 0.0
    nm = _split_list(names) or ([header[c] for c in cols] if header else [f"c{c}" for c in cols])
    un = _split_list(units) or [""] * len(cols)
    if len(un) == 1 and len(cols) > 1:
        un = un * len(cols)
    return Signals(a[:, cols].T, fs, nm, [normalize_unit(u) for u in un], t0, {"source": str(path), "columns": cols})


def read_mat(
    path: str | Path,
    *,
    fs: float | None = None,
    variables: Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
) -> Signals:
    """Read the numeric vector variables of a MATLAB .mat file as channels.

    Parameters
    ----------
    path : str or Path
        The file (MATLAB 5 format, via :func:`scipy.io.loadmat`).
    fs : float, optional
        Sampling frequency in Hz. Default: a scalar variable ``fs``/``Fs``/``fsample``
        in the file; otherwise required.
    variables : sequence of str, optional
        Variables to read (default: every real vector of the most common length;
        a matrix contributes one channel per column, named ``name[k]``).
    units : str or sequence of str, optional

    Returns
    -------
    Signals

    Raises
    ------
    ValueError
        If no rate is known or the variables differ in length.
    """
    from scipy.io import loadmat

    path = Path(path)
    try:
        m = loadmat(path)
    except Exception as exc:  # noqa: BLE001
        raise LogFormatError(f"{path}: not a readable .mat file ({exc})") from exc
    if fs is None:
        for k in ("fs", "Fs", "FS", "fsample", "sample_rate"):
            if k in m and np.size(m[k]) == 1:
                fs = float(np.ravel(m[k])[0])
                break
    if fs is None:
        raise ValueError(f"{path}: no sampling rate variable in the file, so fs must be stated (Hz, --fs)")
    chans: list[tuple[str, np.ndarray]] = []
    keys = variables or [k for k in m if not k.startswith("__")]
    for k in keys:
        if k not in m:
            raise ValueError(f"{path}: no variable {k!r}; variables are {[k for k in m if not k.startswith('__')]}")
        v = m[k]
        if not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu" or v.size < 2:
            continue
        v = np.asarray(v, float)
        if v.ndim == 2 and 1 in v.shape:
            chans.append((k, v.ravel()))
        elif v.ndim == 2:
            v = v if v.shape[0] >= v.shape[1] else v.T
            chans.extend((f"{k}[{j}]", v[:, j]) for j in range(v.shape[1]))
    if not chans:
        raise ValueError(f"{path}: no numeric vector variables")
    lens = [c.size for _, c in chans]
    n = max(set(lens), key=lens.count)
    if variables is not None and len(set(lens)) > 1:
        raise ValueError(f"{path}: variables differ in length: {dict((k, c.size) for k, c in chans)}")
    chans = [(k, c) for k, c in chans if c.size == n]
    un = _split_list(units) or [""] * len(chans)
    if len(un) == 1:
        un = un * len(chans)
    return Signals(np.vstack([c for _, c in chans]), fs, [k for k, _ in chans], [normalize_unit(u) for u in un],
                   0.0, {"source": str(path)})


def read_uff58(path: str | Path) -> Signals:
    """Read the time records (UFF dataset 58, function type 1) of a Universal File.

    Parameters
    ----------
    path : str or Path
        The UFF file (ASCII or binary 58, via pyuff).

    Returns
    -------
    Signals
        One channel per record, named by its ``id1`` (made unique), rate from the abscissa
        increment, units from ``ordinate_axis_units_lab``.

    Raises
    ------
    LogFormatError
        If the file holds no time record, or the records differ in rate or length.

    References
    ----------
    Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 58
    (Function at Nodal DOF), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    try:
        u = pyuff.UFF(str(path))
        types = list(u.get_set_types())
    except Exception as exc:  # noqa: BLE001
        raise LogFormatError(f"{path}: not a readable UFF file ({exc})") from exc
    idx = [i for i, t in enumerate(types) if int(t) == 58]
    recs = []
    for i in idx:
        s = u.read_sets(i)
        if int(s.get("func_type", 1)) == 1 and not np.iscomplexobj(s["data"]):
            recs.append(s)
    if not recs:
        raise LogFormatError(f"{path}: no UFF 58 time record (function type 1) among {len(types)} sets")
    incs = {float(s["abscissa_inc"]) for s in recs}
    lens = {len(s["data"]) for s in recs}
    if len(incs) > 1 or len(lens) > 1:
        raise LogFormatError(f"{path}: records differ in abscissa increment {incs} or length {lens}")
    inc = incs.pop()
    names: list[str] = []
    for k, s in enumerate(recs):
        nm = str(s.get("id1", "")).strip() or f"record{k}"
        if nm in names:
            nm = f"{nm} #{k}"
        names.append(nm)
    units = [normalize_unit(str(s.get("ordinate_axis_units_lab", ""))) for s in recs]
    fs = 1.0 / inc
    fs_r = round(fs, 6)
    fs = fs_r if abs(fs_r - fs) < 1e-9 * fs else fs
    meta = {"source": str(path), "nodes": [(s.get("rsp_node"), s.get("rsp_dir")) for s in recs]}
    return Signals(np.vstack([np.asarray(s["data"], float) for s in recs]), fs, names, units,
                   float(recs[0].get("abscissa_min", 0.0)), meta)


def read_any(path: str | Path, **kw) -> Signals:
    """Read a CSV, .mat or UFF 58 file by its suffix.

    Parameters
    ----------
    path : str or Path
        ``.csv``/``.txt``/``.tsv`` -> :func:`read_csv`, ``.mat`` -> :func:`read_mat`,
        ``.uff``/``.unv`` -> :func:`read_uff58`.
    **kw
        Keyword arguments of the reader (those that do not apply to .mat/.uff are dropped).

    Returns
    -------
    Signals

    Raises
    ------
    LogFormatError
        For an unknown suffix.
    """
    path = Path(path)
    suf = path.suffix.lower()
    if suf in (".csv", ".txt", ".tsv"):
        return read_csv(path, **kw)
    if suf == ".mat":
        return read_mat(path, **{k: v for k, v in kw.items() if k in ("fs", "units")})
    if suf in (".uff", ".unv"):
        return read_uff58(path)
    raise LogFormatError(f"{path}: unknown input format {suf!r} (csv, mat, uff)")


def convert_to_mcap(
    src: str | Path,
    out: str | Path,
    *,
    fs: float | None = None,
    columns: str | Sequence[int] | None = None,
    names: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
    kind: Literal["auto", "acceleration", "other"] = "auto",
    topic_prefix: str = "/vibroscope",
    progress: bool = False,
) -> tuple[Path, Signals]:
    """Convert a CSV, .mat or UFF 58 file to an MCAP log.

    Parameters
    ----------
    src, out : str or Path
        Input file and output ``.mcap``.
    fs : float, optional
        Rate in Hz (required for CSV without a time column and .mat without ``fs``).
    columns, names, units : optional
        As in :func:`read_csv`.
    kind : {"auto", "acceleration", "other"}, optional
        ``"acceleration"``: every channel is an acceleration in m/s^2; ``"auto"``: channels
        whose unit is m/s^2 are. Acceleration channel k is written as
        ``sensor_msgs/msg/Imu`` on ``{topic_prefix}/s{k+1:02d}`` (``linear_acceleration.x``);
        the others as JSON fields of topic `topic_prefix`.
    topic_prefix : str, optional
    progress : bool, optional

    Returns
    -------
    out : Path
    written : Signals
        The signals as written, with their message-path channel names.
    """
    from vibroscope.io.mcap_write import _sanitize, write_ros2_mcap

    if kind not in ("auto", "acceleration", "other"):
        raise ValueError(f"{kind=} must be one of 'auto', 'acceleration', 'other'")
    sig = read_any(src, fs=fs, columns=columns, names=names, units=units)
    prefix = "/" + topic_prefix.strip("/") if topic_prefix.strip("/") else ""
    new_names, new_units = [], []
    for k, (nm, u) in enumerate(zip(sig.channels, sig.units)):
        acc = kind == "acceleration" or (kind == "auto" and u == "m/s^2")
        if acc:
            new_names.append(f"{prefix}/s{k + 1:02d}.linear_acceleration.x")
            new_units.append("m/s^2")
        else:
            new_names.append(f"{prefix or '/signals'}.{_sanitize(nm)}")
            new_units.append(u)
    written = Signals(sig.data, sig.fs, new_names, new_units, sig.t0,
                      {**sig.meta, "original_channels": list(sig.channels)})
    path = write_ros2_mcap(out, written, progress=progress)
    return path, written
