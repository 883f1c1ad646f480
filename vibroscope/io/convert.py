"""Converters from CSV, MATLAB .mat and UFF 58 files to Signals and to MCAP logs."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal, Sequence

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.signals import Signals

__all__ = [
    "read_csv", "read_mat", "read_uff58", "read_any", "convert_to_mcap", "parse_columns", "parse_units",
    "normalize_unit", "select_channels", "parse_topic", "TOPIC_TYPES",
]

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


#: the most columns a column spec may select (a typo like 0-10000000000 is an error, not a hang)
_MAX_COLUMNS = 100_000


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
        If a part does not parse (ASCII digits only), a range runs backwards, or the spec
        selects more than 100 000 columns.
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
        m = re.fullmatch(r"([0-9]+)\s*-\s*([0-9]+)", part)
        if m:
            a, b = int(m.group(1)), int(m.group(2))
            if b < a:
                raise ValueError(f"column range {part!r} runs backwards")
            if b - a >= _MAX_COLUMNS or len(out) + b - a >= _MAX_COLUMNS:
                raise ValueError(f"column spec {spec!r} selects more than {_MAX_COLUMNS} columns")
            out.extend(range(a, b + 1))
        elif part.isascii() and part.isdigit():
            out.append(int(part))
        else:
            raise ValueError(f"cannot parse column spec {part!r} in {spec!r} (use e.g. 0-17 or 0,3,5-7)")
    return out


def _split_list(v: str | Sequence[str] | None) -> list[str] | None:
    if v is None:
        return None
    if isinstance(v, str):
        out = [s.strip() for s in v.split(",")]
        return out if any(out) else None
    return [str(s) for s in v]


def _base(name: str) -> str:
    """``acc[1]`` -> ``acc`` (the .mat variable a matrix column came from)."""
    m = re.fullmatch(r"(.+)\[\d+\]", name)
    return m.group(1) if m else name


def _match(name: str, channels: Sequence[str]) -> list[int]:
    """Indices of the channels `name` selects: the channel of that name, else every column
    ``name[k]`` of a matrix variable `name`."""
    if name in channels:
        return [channels.index(name)]
    return [i for i, c in enumerate(channels) if c != name and _base(c) == name]


def parse_units(units: str | Sequence[str] | None) -> dict[str, str] | list[str] | None:
    """Parse a unit option.

    Parameters
    ----------
    units : str or sequence of str or None
        ``"N"`` (one unit for all channels), ``"N,m/s^2"`` (one per selected channel, in the
        selected order) or ``"force=N,acc=m/s^2"`` (``name=unit`` pairs); a sequence holds
        the comma-separated parts.

    Returns
    -------
    dict or list of str or None
        ``{name: unit}`` for pairs, the list of units otherwise (None for None or ``""``).

    Raises
    ------
    ValueError
        If pairs and plain units are mixed, a pair has no name, or a name repeats.
    """
    parts = _split_list(units)
    if parts is None:
        return None
    pairs = ["=" in u for u in parts]
    if not any(pairs):
        return parts
    if not all(pairs):
        raise ValueError(f"{units=}: give either name=unit pairs or plain units, not both")
    out: dict[str, str] = {}
    for u in parts:
        name, _, unit = u.rpartition("=")
        name = name.strip()
        if not name:
            raise ValueError(f"{units=}: {u!r} names no channel (use name=unit)")
        if name in out:
            raise ValueError(f"{units=}: channel {name!r} is given twice")
        out[name] = unit.strip()
    return out


def select_channels(
    signals: Signals,
    channels: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
    *,
    source: str | Path = "",
    stable_order: bool = True,
    known: Sequence[str] | None = None,
) -> Signals:
    """Select channels by name and label their units.

    Parameters
    ----------
    signals : Signals
        Every channel of a file, named as the file names them (CSV header names or
        ``c<column>``, .mat variable names, with ``name[k]`` for the columns of a matrix,
        UFF 58 record names).
    channels : str (comma-separated) or sequence of str, optional
        The channels to keep, in this order. A name selects the channel of that name, or
        every column ``name[k]`` of a .mat matrix variable ``name``. Default: all, in the
        file's order.
    units : str or sequence of str, optional
        As :func:`parse_units`: ``name=unit`` pairs (by name; channels not named keep the
        file's unit, ``""`` when it has none), one unit for every selected channel, or one
        per selected channel in the selected order. Spellings are normalised
        (:func:`normalize_unit`).
    source : str or Path, optional
        The file, named in error messages.
    stable_order : bool, optional
        False when the file's channel order is not meaningful (.mat variables): then a
        list of several units needs `channels` (or ``name=unit`` pairs), so that the same
        command labels the same channels in every file.
    known : sequence of str, optional
        Every channel name the file has, when `signals` holds only those read (CSV
        `columns`, .mat variables of one length): a ``name=unit`` pair for a known channel
        that is not read is ignored, and error messages list these names.

    Returns
    -------
    Signals
        The selected rows, with their units; ``meta["selected"]`` lists the names.

    Raises
    ------
    ValueError
        If a name is not in the file (the message lists the names it has), a channel is
        selected twice, or the number of units is neither 1 nor the number of selected
        channels.
    """
    names = list(signals.channels)
    where = f"{source}: " if str(source) else ""
    everything = list(known) if known is not None else names
    avail = f"the file's channels are {everything}"
    sel = _split_list(channels)
    if sel is None:
        idx = list(range(len(names)))
    else:
        idx = []
        for nm in sel:
            hit = _match(nm, names)
            if not hit:
                why = " (not among the columns read)" if _match(nm, everything) else ""
                raise ValueError(f"{where}no channel {nm!r}{why}; {avail}")
            dup = [names[i] for i in hit if i in idx]
            if dup:
                raise ValueError(f"{where}channel {dup[0]!r} is selected twice ({channels=})")
            idx.extend(hit)
    un = [signals.units[i] for i in idx]
    spec = parse_units(units)
    if isinstance(spec, dict):
        for nm, u in spec.items():
            hit = _match(nm, names)
            if not hit and not _match(nm, everything):
                raise ValueError(f"{where}--units names no channel {nm!r}; {avail}")
            for i in hit:
                if i in idx:
                    un[idx.index(i)] = u
    elif spec is not None:
        if len(spec) == 1:
            un = spec * len(idx)
        elif len(spec) != len(idx):
            raise ValueError(
                f"{where}{len(spec)} units {spec} for {len(idx)} channels {[names[i] for i in idx]}: give one unit "
                "for all, one per selected channel in the selected order, or name=unit pairs"
            )
        elif sel is None and not stable_order and len({_base(names[i]) for i in idx}) > 1:
            raise ValueError(
                f"{where}{len(spec)} units {spec} by position, but the order of a .mat file's variables "
                f"{[names[i] for i in idx]} is not meaningful: select the channels (--channels) or give "
                "name=unit pairs (--units force=N,acc=m/s^2)"
            )
        else:
            un = list(spec)
    return Signals(data=signals.data[idx], fs=signals.fs, channels=[names[i] for i in idx],
                   units=[normalize_unit(u) for u in un],
                   t0=signals.t0, meta={**signals.meta, "selected": [names[i] for i in idx]})


#: header names taken as a time column in s: ``time``, ``time_s``, ``time [s]``, ``seconds`` in any
#: case; ``t``, ``t_s``, ``t [s]`` in lower case only (``T`` may be a temperature)
_TIME_HEADER = re.compile(r"(?i:time|times|time_s|seconds|time\s*[\[(]\s*s\s*[\])])|t|t_s|t\s*[\[(]\s*s\s*[\])]")


def _said_non_finite(a: np.ndarray, path: Path, skip: int) -> np.ndarray:
    """`a`, with a warning when cells are NaN or ±Inf as written (``nan``, ``inf``, ``1e400``)."""
    import warnings

    bad = ~np.isfinite(a)
    if bad.any():  # missing samples, said (the reader's NaN of empty cells is said by the caller)
        rows = np.flatnonzero(bad.any(axis=1))
        warnings.warn(f"{path}: {int(bad.sum())} cells are NaN or ±Inf (written so, or beyond float64), first at "
                      f"line {rows[0] + 1 + skip}: missing samples; nothing is filled in", stacklevel=4)
    return a


def _loadtxt(path: Path, delimiter: str | None, skip: int) -> np.ndarray:
    """The numbers of a CSV file, shape (n_rows, n_columns); an empty cell is a missing
    sample: NaN, with a warning that counts them."""
    import warnings

    def fail(exc: ValueError) -> LogFormatError:
        m = re.search(r"at row (\d+)", str(exc))
        if not m:
            return LogFormatError(f"{path}: not a numeric CSV file ({exc})")
        # numpy counts data rows from 0 in a conversion error but from 1 in a column-count error
        line = int(m.group(1)) + skip + (0 if "number of columns changed" in str(exc) else 1)
        what = str(exc).replace(m.group(0), f"at line {line}")
        return LogFormatError(f"{path}: line {line}: not a numeric CSV file ({what})")

    empty = False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data": checked by the caller
        try:
            a = np.loadtxt(path, delimiter=delimiter, skiprows=skip, ndmin=2, dtype=np.float64)
        except ValueError as exc:
            if "string ''" not in str(exc) or delimiter is None:
                raise fail(exc) from None
            empty = True
        if empty:
            try:
                a = np.loadtxt(path, delimiter=delimiter, skiprows=skip, ndmin=2, dtype=np.float64,
                               converters=lambda c: float(c) if c.strip() else np.nan)
            except ValueError as exc:
                raise fail(exc) from None
    if not empty:
        return _said_non_finite(a, path, skip)
    n = int(np.isnan(a).sum())
    warnings.warn(f"{path}: {n} empty cells read as missing samples (NaN); nothing is filled in", stacklevel=3)
    return a


def _rate_from_times(path: Path, t: np.ndarray, col: int, header, fs: float | None, skip: int) -> tuple[float, float]:
    """(fs, t0) from a time column in s, which must step uniformly (within 1 %)."""
    name = repr(header[col]) if header and col < len(header) else str(col)
    if t.size < 2:
        if fs is None:
            raise ValueError(f"{path}: one row: the time column {name} gives no rate; give fs in Hz (--fs)")
        return fs, float(t[0])
    dt = np.diff(t)
    med = float(np.median(dt))
    off = np.flatnonzero(~(np.abs(dt - med) <= 0.01 * med)) if med > 0 and np.isfinite(med) else np.arange(dt.size)
    if off.size:
        k = int(off[0])
        raise ValueError(
            f"{path}: the time column {name} does not step uniformly: line {k + 1 + skip} -> {k + 2 + skip} goes "
            f"from {t[k]:g} s to {t[k + 1]:g} s (median step {med:g} s; {off.size} irregular steps). "
            "Samples are never filled in: convert the uniform segments separately, or leave the time column out "
            "(columns, --columns) and give fs (--fs)"
        )
    fs_t = (t.size - 1) / (t[-1] - t[0])
    if fs is not None and not abs(fs - fs_t) <= 0.01 * fs_t:
        raise ValueError(f"{path}: {fs=} Hz disagrees with the time column {name} ({fs_t:g} Hz); leave fs out")
    return (fs if fs is not None else fs_t), float(t[0])


def read_csv(
    path: str | Path,
    *,
    fs: float | None = None,
    columns: str | Sequence[int] | None = None,
    channels: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
    time_column: int | str | None = None,
    delimiter: str | None = None,
) -> Signals:
    """Read a numeric CSV file (one column per channel, optional header line).

    Parameters
    ----------
    path : str or Path
        The file.
    fs : float, optional
        Sampling frequency in Hz; required unless the file has a time column.
    columns : str or sequence of int, optional
        Columns to read (``"0-17"``, 0-based indices of the file's columns). Default: all
        but the time column.
    channels : str (comma-separated) or sequence of str, optional
        Channels to keep, by name, in this order (:func:`select_channels`); the names are
        the header's, or ``c0, c1, ...`` (by column index) without a header.
    units : str or sequence of str, optional
        As :func:`select_channels` (default ``""``).
    time_column : int or str, optional
        A column of sample times in s (index or header name); the rate is estimated from it
        (it must step uniformly within 1 %, and agree with `fs` if both are given). Default:
        a header column named ``t``, ``time``, ``time_s``, ``time [s]`` or ``seconds``,
        unless `columns` lists it as data.
    delimiter : str, optional
        Default: detected (``,`` ``;`` tab, else whitespace).

    Returns
    -------
    Signals
        Shape (n_channels, n_rows).

    Raises
    ------
    ValueError
        If there is neither `fs` nor a time column (the message asks for ``--fs``), the time
        column is not uniform or is selected as a channel, a column is out of range, or a
        channel name is unknown.
    LogFormatError
        If the file cannot be read, has no data rows or is not numeric (names file and
        line). An empty cell is a missing sample: NaN, with a warning.

    See Also
    --------
    read_mat : Channels from a MATLAB .mat file.
    read_uff58 : Time records from a Universal File.
    """
    path = Path(path)
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as fh:
            first = fh.readline()
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read the input file ({exc.strerror or exc})") from None
    if delimiter is None:
        delimiter = next((d for d in (",", ";", "\t") if d in first), None)
    cells = [c.strip().strip('"') for c in (first.split(delimiter) if delimiter else first.split())]
    try:
        [float(c) for c in cells if c]
        header = None
    except ValueError:
        header = cells
    a = _loadtxt(path, delimiter, 1 if header else 0)
    if a.shape[0] == 0:
        raise LogFormatError(f"{path}: no data rows")
    if isinstance(time_column, str):
        if not header or time_column not in header:
            raise ValueError(f"{path}: no column named {time_column!r}; the header is {header}")
        time_column = header.index(time_column)
    explicit = parse_columns(columns)
    if time_column is None and header:
        time_column = next((i for i, h in enumerate(header) if _TIME_HEADER.fullmatch(h.strip())), None)
        if time_column is not None and explicit is not None and time_column in explicit:
            time_column = None  # the user lists it as a data column
    if time_column is not None and not -a.shape[1] <= time_column < a.shape[1]:
        raise ValueError(f"{path}: {time_column=} out of range for {a.shape[1]} columns")
    if time_column is not None:
        time_column %= a.shape[1]
    allcols = [c for c in range(a.shape[1]) if c != time_column]
    cols = allcols if explicit is None else explicit
    bad = [c for c in cols if c >= a.shape[1] or c < 0]
    if bad:
        raise ValueError(f"{path}: columns {bad} out of range for {a.shape[1]} columns")
    if time_column is not None and time_column in cols:
        raise ValueError(f"{path}: column {time_column} is the time column; it cannot also be a channel")
    if not cols:
        raise ValueError(f"{path}: no data column to read ({a.shape[1]} columns, time column {time_column})")
    if time_column is not None:
        fs, t0 = _rate_from_times(path, a[:, time_column], time_column, header, fs, skip=1 if header else 0)
    else:
        if fs is None:
            raise ValueError(
                f"{path}: a sampling rate is needed: give it in Hz with fs (--fs), because no time column was "
                "found (no header column named t, time, time_s or 'time [s]'; name one with time_column / "
                "--time-column)"
            )
        t0 = 0.0
    nm = [header[c] if header and c < len(header) and header[c] else f"c{c}" for c in cols]
    if len(set(nm)) < len(nm):  # a header that repeats names: fall back to column indices
        nm = [f"c{c}" for c in cols]
    sig = Signals(data=a[:, cols].T, fs=fs, channels=nm, units=None, t0=t0, meta={"source": str(path), "columns": cols})
    known = [h or f"c{c}" for c, h in enumerate(header)] if header and len(set(header)) == len(header) else None
    return select_channels(sig, channels, units, source=path, known=known)


def read_mat(
    path: str | Path,
    *,
    fs: float | None = None,
    channels: str | Sequence[str] | None = None,
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
    channels : str (comma-separated) or sequence of str, optional
        Variables to read, by name, in this order (a matrix variable ``acc`` contributes one
        channel per column, named ``acc[k]``; ``acc`` selects them all, ``acc[1]`` one).
        Default: every real vector of the most common length, in the file's order (the
        others are listed, with their lengths, in ``meta["skipped_variables"]``).
    units : str or sequence of str, optional
        As :func:`select_channels`: ``name=unit`` pairs, one unit for all, or (with
        `channels`) one per selected channel in the selected order. Several units by
        position without `channels` are an error when the channels come from several
        variables, since a .mat file's variable order is not meaningful.

    Returns
    -------
    Signals

    Raises
    ------
    ValueError
        If no rate is known, a name is unknown (the message lists the variables), or the
        selected variables differ in length.
    LogFormatError
        If the file cannot be read as a .mat file.

    See Also
    --------
    read_csv : Channels from a numeric CSV file.
    read_uff58 : Time records from a Universal File.
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
                try:
                    fs = float(np.ravel(m[k])[0])
                except (TypeError, ValueError):
                    continue
                break
    if fs is None:
        raise ValueError(f"{path}: a sampling rate is needed: the file has no fs variable, so give fs in Hz (--fs)")
    chans: list[tuple[str, np.ndarray]] = []
    for k in (k for k in m if not k.startswith("__")):
        v = m[k]
        if not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu" or v.size < 2 or v.ndim != 2:
            continue
        v = np.asarray(v, float)
        if 1 in v.shape:
            chans.append((k, v.ravel()))
        else:
            v = v if v.shape[0] >= v.shape[1] else v.T
            chans.extend((f"{k}[{j}]", v[:, j]) for j in range(v.shape[1]))
    if not chans:
        raise ValueError(f"{path}: no numeric vector variables")
    names = [k for k, _ in chans]
    sel = _split_list(channels)
    skipped: dict[str, int] = {}
    if sel is None:
        lens = [c.size for _, c in chans]
        n = max(set(lens), key=lens.count)
        skipped = {k: c.size for k, c in chans if c.size != n}
        chans = [(k, c) for k, c in chans if c.size == n]
    else:
        idx: list[int] = []
        for nm in sel:
            hit = _match(nm, names)
            if not hit:
                raise ValueError(f"{path}: no channel {nm!r}; the file's numeric variables are {names}")
            idx.extend(i for i in hit if i not in idx)
        chans = [chans[i] for i in idx]
        if len({c.size for _, c in chans}) > 1:
            raise ValueError(f"{path}: variables differ in length: {dict((k, c.size) for k, c in chans)}")
    sig = Signals(data=np.vstack([c for _, c in chans]), fs=fs, channels=[k for k, _ in chans], units=None, t0=0.0,
                  meta={"source": str(path), "skipped_variables": skipped})
    return select_channels(sig, channels, units, source=path, stable_order=False, known=names)


def read_uff58(
    path: str | Path,
    *,
    channels: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
) -> Signals:
    """Read the time records (UFF dataset 58, function type 1) of a Universal File.

    Parameters
    ----------
    path : str or Path
        The UFF file (ASCII or binary 58, via pyuff).
    channels : str (comma-separated) or sequence of str, optional
        Records to keep, by name (``id1``), in this order. Default: all, in file order.
    units : str or sequence of str, optional
        Units that replace the file's, as :func:`select_channels` (``name=unit`` pairs
        replace only the named records' units).

    Returns
    -------
    Signals
        One channel per record, named by its ``id1`` (made unique), rate from the abscissa
        increment, units from ``ordinate_axis_units_lab``.

    Raises
    ------
    LogFormatError
        If the file holds no time record, or the records differ in rate or length.
    ValueError
        If a channel name is unknown (the message lists the records).

    See Also
    --------
    read_csv : Channels from a numeric CSV file.
    read_mat : Channels from a MATLAB .mat file.
    vibroscope.io.read_frf : FRF records (function type 4) of UFF 58 files.

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
    file_units = [normalize_unit(str(s.get("ordinate_axis_units_lab", ""))) for s in recs]
    fs = 1.0 / inc
    fs_r = round(fs, 6)
    fs = fs_r if abs(fs_r - fs) < 1e-9 * fs else fs
    meta = {"source": str(path), "nodes": [(s.get("rsp_node"), s.get("rsp_dir")) for s in recs]}
    sig = Signals(data=np.vstack([np.asarray(s["data"], float) for s in recs]), fs=fs, channels=names, units=file_units,
                  t0=float(recs[0].get("abscissa_min", 0.0)), meta=meta)
    return select_channels(sig, channels, units, source=path) if (channels or units) else sig


def read_any(
    path: str | Path,
    *,
    fs: float | None = None,
    columns: str | Sequence[int] | None = None,
    channels: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
    time_column: int | str | None = None,
) -> Signals:
    """Read a CSV, .mat or UFF 58 file by its suffix.

    Parameters
    ----------
    path : str or Path
        ``.csv``/``.txt``/``.tsv`` -> :func:`read_csv`, ``.mat`` -> :func:`read_mat`,
        ``.uff``/``.unv`` -> :func:`read_uff58`.
    fs : float, optional
        Rate in Hz (CSV without a time column, .mat without an ``fs`` variable); for a UFF
        file it must agree with the records' abscissa increment.
    columns : str or sequence of int, optional
        CSV columns (0-based); an error for the other formats (use `channels`).
    channels : str (comma-separated) or sequence of str, optional
        Channels by name, in this order, for every format (:func:`select_channels`).
    units : str or sequence of str, optional
        ``name=unit`` pairs, one unit, or one per selected channel (:func:`select_channels`).
    time_column : int or str, optional
        CSV only: the column of times in s (:func:`read_csv`).

    Returns
    -------
    Signals

    Raises
    ------
    LogFormatError
        For an unknown suffix or an unreadable file.
    ValueError
        For an option that does not apply to the format, an unknown channel name, or no rate.

    See Also
    --------
    read_csv, read_mat, read_uff58 : The readers it picks from.
    vibroscope.io.read_mcap : MCAP logs.
    convert_to_mcap : A file of these formats written as an MCAP log.
    """
    path = Path(path)
    suf = path.suffix.lower()
    if suf in (".csv", ".txt", ".tsv"):
        return read_csv(path, fs=fs, columns=columns, channels=channels, units=units, time_column=time_column)
    if suf not in (".mat", ".uff", ".unv"):
        raise LogFormatError(f"{path}: unknown input format {suf!r} (csv, txt, tsv, mat, uff, unv)")
    fmt = "a .mat" if suf == ".mat" else "a UFF"
    if columns is not None:
        raise ValueError(f"{path}: {columns=} selects CSV columns; select the channels of {fmt} file by name "
                         "(channels, --channels)")
    if time_column is not None:
        raise ValueError(f"{path}: {time_column=} applies to CSV files only")
    if suf == ".mat":
        return read_mat(path, fs=fs, channels=channels, units=units)
    sig = read_uff58(path, channels=channels, units=units)
    if fs is not None and not abs(fs - sig.fs) <= 1e-9 * sig.fs:
        raise ValueError(f"{path}: {fs=} Hz disagrees with the records' rate {sig.fs:g} Hz (leave fs out)")
    return sig


#: message types of ``--topic NAME=CHANNEL:TYPE``: alias -> (ROS 2 type or "json", default field)
TOPIC_TYPES = {
    "json": ("json", ""),
    "wrench": ("geometry_msgs/msg/WrenchStamped", "wrench.force.x"),
    "geometry_msgs/wrenchstamped": ("geometry_msgs/msg/WrenchStamped", "wrench.force.x"),
    "geometry_msgs/msg/wrenchstamped": ("geometry_msgs/msg/WrenchStamped", "wrench.force.x"),
    "imu": ("sensor_msgs/msg/Imu", "linear_acceleration.x"),
    "sensor_msgs/imu": ("sensor_msgs/msg/Imu", "linear_acceleration.x"),
    "sensor_msgs/msg/imu": ("sensor_msgs/msg/Imu", "linear_acceleration.x"),
}

#: units a ROS 2 message fixes for its fields (REP 103), by field prefix
_FIXED_UNITS = (("linear_acceleration.", "m/s^2"), ("angular_velocity.", "rad/s"), ("wrench.force.", "N"),
                ("wrench.torque.", "N m"))


def parse_topic(spec: str) -> tuple[str, str, str, str]:
    """Parse a ``--topic`` specification ``NAME=CHANNEL[:TYPE[:FIELD]]``.

    Parameters
    ----------
    spec : str
        ``NAME`` the topic (a leading ``/`` is added when missing), ``CHANNEL`` the input
        channel's name (as ``--channels`` names it), ``TYPE`` one of ``json``, ``wrench``
        (``geometry_msgs/WrenchStamped``), ``imu`` (``sensor_msgs/Imu``), case-insensitive, the
        ``msg/`` part optional; ``FIELD`` the field of a ROS message (default
        ``wrench.force.x`` / ``linear_acceleration.x``) or the JSON field name (default: the
        channel's name). E.g. ``/shaker/force=Force:wrench``, ``/imu/s02=s02:imu``,
        ``/imu/s02=s02z:imu:linear_acceleration.z``.

    Returns
    -------
    topic, channel, type, field : str
        `type` is the ROS 2 type name, ``"json"``, or ``""`` when not given (chosen from the
        channel's unit by :func:`convert_to_mcap`); `field` is ``""`` when not given.

    Raises
    ------
    ValueError
        If the form is wrong, the type unknown, or the field not a number field of the type.
    """
    from vibroscope.io import _ros2

    name, eq, rest = str(spec).partition("=")
    name = name.strip()
    if not eq or not name or not rest.strip():
        raise ValueError(f"--topic {spec!r}: expected NAME=CHANNEL[:TYPE[:FIELD]], e.g. /shaker/force=Force:wrench")
    parts = rest.split(":")
    if len(parts) > 3:
        raise ValueError(f"--topic {spec!r}: expected NAME=CHANNEL[:TYPE[:FIELD]] (more than three ':' parts)")
    channel = parts[0].strip()
    tname = parts[1].strip() if len(parts) > 1 else ""
    field = parts[2].strip() if len(parts) > 2 else ""
    if not channel:
        raise ValueError(f"--topic {spec!r}: no channel after '='")
    topic = "/" + name.strip("/")
    if topic == "/" or any(c.isspace() for c in topic) or "." in topic:
        raise ValueError(f"--topic {spec!r}: topic {name!r} must be a name such as /shaker/force (no '.', no spaces)")
    kind = ""
    if tname:
        key = tname.lower()
        if key not in TOPIC_TYPES:
            raise ValueError(f"--topic {spec!r}: unknown message type {tname!r}; known: json, wrench "
                             f"(geometry_msgs/WrenchStamped), imu (sensor_msgs/Imu)")
        kind = TOPIC_TYPES[key][0]
    if field and kind not in ("", "json"):
        ok = _ros2.FLOAT_FIELDS[kind]
        if field not in ok:
            near = [f for f in ok if f.split(".")[0] == field.split(".")[0]] or list(ok[:8])
            raise ValueError(f"--topic {spec!r}: {field!r} is not a number field of {kind}; e.g. {', '.join(near)}")
    return topic, channel, kind, field


def _topic_layout(specs: Sequence[str], channels: Sequence[str], units: Sequence[str],
                  src: Path) -> dict[int, tuple[str, str]]:
    """Row -> (message path, unit) written for the channels that ``--topic`` names."""
    from vibroscope.io.mcap_write import sanitize_name

    rows: dict[int, tuple[str, str]] = {}
    kinds: dict[str, str] = {}
    for spec in specs:
        topic, ch, kind, field = parse_topic(spec)
        if ch not in channels:
            raise ValueError(f"--topic {spec!r}: {src} has no channel {ch!r}; channels are {list(channels)}")
        i = list(channels).index(ch)
        if i in rows:
            raise ValueError(f"--topic {spec!r}: channel {ch!r} is already written as {rows[i][0]!r}")
        unit = normalize_unit(units[i])
        if not kind:
            kind = {"N": TOPIC_TYPES["wrench"][0], "m/s^2": TOPIC_TYPES["imu"][0]}.get(unit, "json")
        if kinds.setdefault(topic, kind) != kind:
            raise ValueError(f"--topic {spec!r}: topic {topic!r} is already a {kinds[topic]} topic, not {kind}")
        fixed = None
        if kind == "json":
            field = field or sanitize_name(ch)
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*", field):
                raise ValueError(f"--topic {spec!r}: JSON field {field!r} must be a name such as force or a.b")
        else:
            field = field or next(v[1] for v in TOPIC_TYPES.values() if v[0] == kind)
            fixed = next((u for prefix, u in _FIXED_UNITS if field.startswith(prefix)), None)
            if fixed is not None and unit not in ("", fixed):
                raise ValueError(f"--topic {spec!r}: channel {ch!r} is in {unit!r}, but {kind} {field} is in {fixed} "
                                 f"(give --units {ch}={fixed} if the values are in {fixed}, or use :json)")
        rows[i] = (f"{topic}.{field}", fixed or unit)
    return rows


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def convert_to_mcap(
    src: str | Path,
    out: str | Path,
    *,
    fs: float | None = None,
    columns: str | Sequence[int] | None = None,
    channels: str | Sequence[str] | None = None,
    units: str | Sequence[str] | None = None,
    time_column: int | str | None = None,
    kind: Literal["auto", "acceleration", "other"] = "auto",
    topic_prefix: str = "/vibroscope",
    topics: Sequence[str] | None = None,
    progress: bool = False,
) -> tuple[Path, Signals]:
    """Convert a CSV, .mat or UFF 58 file to an MCAP log.

    Parameters
    ----------
    src, out : str or Path
        Input file and output ``.mcap``. `out` is written under a temporary name in its
        directory and renamed when complete; it must not be `src`.
    fs : float, optional
        Rate in Hz (required for CSV without a time column and .mat without ``fs``).
    columns : str or sequence of int, optional
        CSV columns (:func:`read_csv`).
    channels : str (comma-separated) or sequence of str, optional
        Channels by name, in this order, for every format (:func:`select_channels`).
    units : str or sequence of str, optional
        ``name=unit`` pairs (``"force=N,acc=m/s^2"``), one unit for all, or one per selected
        channel in the selected order (:func:`select_channels`). Stored in the MCAP
        (Channel metadata ``"vibroscope.units"``).
    time_column : int or str, optional
        CSV column of times in s (:func:`read_csv`).
    kind : {"auto", "acceleration", "other"}, optional
        ``"acceleration"``: every channel is an acceleration in m/s^2; ``"auto"``: channels
        whose unit is m/s^2 are. Acceleration channel k is written as
        ``sensor_msgs/msg/Imu`` on ``{topic_prefix}/s{k+1:02d}`` (``linear_acceleration.x``);
        the others as JSON fields of topic `topic_prefix`.
    topic_prefix : str, optional
        Topic prefix (default ``/vibroscope``).
    topics : sequence of str, optional
        ``NAME=CHANNEL[:TYPE[:FIELD]]`` specifications (:func:`parse_topic`) that name the topic
        and message type of channels: ``/shaker/force=Force:wrench`` writes channel ``Force``
        as ``wrench.force.x`` of ``geometry_msgs/msg/WrenchStamped`` messages on
        ``/shaker/force``; ``/imu/s02=s02:imu`` channel ``s02`` as ``linear_acceleration.x`` of
        ``sensor_msgs/msg/Imu`` on ``/imu/s02``; ``:json`` a JSON field. Without a type, a
        channel in N is a wrench, one in m/s^2 an Imu, others JSON. Several channels may share
        a topic (distinct fields). Channels not named keep the layout of `kind`/`topic_prefix`.
    progress : bool, optional
        Show a progress bar.

    Returns
    -------
    out : Path
        The MCAP written.
    written : Signals
        The signals as written, with their message-path channel names.

    Raises
    ------
    ValueError
        If `out` is `src` or a directory, `kind` is unknown, a `topics` entry is malformed, names
        no channel, or gives a ROS type whose field unit contradicts the channel's, or as
        :func:`read_any`.
    LogFormatError
        If `src` does not exist or cannot be read.
    """
    from vibroscope.io.mcap_write import sanitize_name, write_ros2_mcap

    if kind not in ("auto", "acceleration", "other"):
        raise ValueError(f"{kind=} must be one of 'auto', 'acceleration', 'other'")
    src_p, out_p = Path(src), Path(out)
    if _same_file(src_p, out_p):
        raise ValueError(f"output {str(out_p)!r} is the input file; choose another output name (the input is kept)")
    if out_p.is_dir() or not out_p.parent.is_dir():
        raise ValueError(f"output {str(out_p)!r} is a directory, or its directory does not exist; name an output file")
    if not src_p.is_file():
        raise LogFormatError(f"{src_p}: no such input file" + (" (a directory)" if src_p.is_dir() else ""))
    sig = read_any(src_p, fs=fs, columns=columns, channels=channels, units=units, time_column=time_column)
    prefix = "/" + topic_prefix.strip("/") if topic_prefix.strip("/") else ""
    for spec in topics or ():
        parse_topic(spec)  # the form first, before any channel is looked at
    named = _topic_layout(list(topics or ()), sig.channels, sig.units, src_p)
    new_names, new_units = [], []
    for k, (nm, u) in enumerate(zip(sig.channels, sig.units)):
        if k in named:
            new_names.append(named[k][0])
            new_units.append(named[k][1])
            continue
        if kind == "acceleration" and u not in ("", "m/s^2"):
            raise ValueError(f"{src_p}: channel {nm!r} has unit {u!r}, but {kind=} writes every channel as an "
                             "acceleration in m/s^2 (use kind 'auto' or 'other', or fix --units)")
        acc = kind == "acceleration" or (kind == "auto" and u == "m/s^2")
        if acc:
            new_names.append(f"{prefix}/s{k + 1:02d}.linear_acceleration.x")
            new_units.append("m/s^2")
        else:
            new_names.append(f"{prefix or '/signals'}.{sanitize_name(nm)}")
            new_units.append(u)
    written = Signals(data=sig.data, fs=sig.fs, channels=new_names, units=new_units, t0=sig.t0,
                      meta={**sig.meta, "original_channels": list(sig.channels)})
    path = write_ros2_mcap(out_p, written, progress=progress)
    return path, written
