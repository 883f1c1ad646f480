"""Universal Files through pyuff: the list of a file's datasets, each record read with the file
and record named in its error, and the node-DOF names (``"12+Z"``) and ID lines that every UFF
reader and writer of the package shares (:mod:`vibroscope.io.uff58`, :mod:`vibroscope.io.uff55`,
:mod:`vibroscope.io.uff_geometry`).

References
----------
.. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15, 55, 58,
   164 and 2411, University of Cincinnati.
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any, Sequence

from vibroscope.errors import LogFormatError

__all__ = ["uff_datasets"]

AXIS = {1: "X", 2: "Y", 3: "Z", 4: "RX", 5: "RY", 6: "RZ"}
_AXIS_CODE = {v: k for k, v in AXIS.items()}
_DOF_RE = re.compile(r"^\s*(\d+)\s*(?:([+-]?)\s*(RX|RY|RZ|X|Y|Z))?\s*$", re.I)
UFF_SUFFIXES = (".uff", ".unv", ".uf")


def dof_name(node: int, direction: int) -> str:
    """``"12+Z"`` for node 12, direction +3; ``"12"`` for a scalar (direction 0)."""
    if direction == 0 or abs(direction) not in AXIS:
        return f"{node}"
    return f"{node}{'+' if direction > 0 else '-'}{AXIS[abs(direction)]}"


def parse_dof(name: str) -> tuple[int, int] | None:
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


def read_label(v: Any) -> str:
    """An ID line or label as read by pyuff, with ``NONE`` as empty."""
    s = str(v if v is not None else "").strip()
    return "" if s.upper() == "NONE" else s


def id_line(s: str) -> str:
    """A UFF ID line: one line, at most 80 characters, ``NONE`` when empty."""
    s = " ".join(str(s).split())[:80]
    return s or "NONE"


def open_uff(path: Path):
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
    return open_uff(Path(path))[1]


def read_set(u, path: Path, i: int, header_only: bool = False) -> dict:
    try:
        return u.read_sets(i, header_only=header_only)
    except Exception as exc:  # noqa: BLE001
        raise LogFormatError(f"{path}: data set #{i + 1} cannot be read by pyuff ({exc})") from exc


def dataset_summary(types: Sequence[int]) -> str:
    from collections import Counter

    return ", ".join(f"{n}× dataset {t}" for t, n in Counter(types).items())


def remove_existing(path: Path) -> None:
    if path.exists():
        path.unlink()


def date_line() -> str:
    return time.strftime("%d-%b-%y %H:%M:%S")

