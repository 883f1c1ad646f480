"""Sensor coordinates: where each channel measures, and along which direction."""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vibroscope.errors import ChannelError, LogFormatError

__all__ = ["SensorCoords", "read_coords", "line_coords"]

_AXES = {"1": (1.0, 0.0, 0.0), "2": (0.0, 1.0, 0.0), "3": (0.0, 0.0, 1.0),
         "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True, eq=False)
class SensorCoords:
    """Positions and measuring directions of channels.

    Attributes
    ----------
    points : tuple of str
        Channel names (message paths), one per row.
    xyz : ndarray, shape (n_points, 3)
        Positions in m.
    directions : ndarray, shape (n_points, 3)
        Unit measuring directions.
    from_file : bool
        False for the default layout on a line (:func:`line_coords`).
    source : str
        The file read, or ``""``.
    """

    points: tuple[str, ...]
    xyz: np.ndarray
    directions: np.ndarray
    from_file: bool = True
    source: str = ""

    def as_mapping(self) -> dict[str, dict[str, Any]] | None:
        """``{point: {"xyz": (x, y, z), "direction": (dx, dy, dz)}}``, or None for the
        default line layout (so viewers lay the points out themselves)."""
        if not self.from_file:
            return None
        return {p: {"xyz": tuple(map(float, self.xyz[k])), "direction": tuple(map(float, self.directions[k]))}
                for k, p in enumerate(self.points)}


def line_coords(channels: Sequence[str], spacing: float = 1.0) -> SensorCoords:
    """Channels laid out on the x axis, `spacing` m apart, measuring along z.

    Parameters
    ----------
    channels : sequence of str
        Channel names.
    spacing : float, optional
        Distance between points in m.

    Returns
    -------
    SensorCoords
        With ``from_file=False``.
    """
    n = len(channels)
    xyz = np.zeros((n, 3))
    xyz[:, 0] = spacing * np.arange(n)
    return SensorCoords(tuple(channels), xyz, np.tile([0.0, 0.0, 1.0], (n, 1)), False, "")


def _direction(v: str, path: Path, line: int) -> np.ndarray:
    key = v.strip().lower().lstrip("+")
    if key in _AXES:
        return np.array(_AXES[key])
    if key.startswith("-") and key[1:] in _AXES:
        return -np.array(_AXES[key[1:]])
    raise LogFormatError(f"{path}: line {line}: direction {v!r} is not 1/2/3 or x/y/z")


#: a channel that names its sensor's number: ``/lumo/s07.linear_acceleration.x``
_SENSOR = re.compile(r"/s(\d+)(?:[./\[]|$)")


def _sensor_number(channel: str) -> int | None:
    m = _SENSOR.search(channel) or re.search(r"(\d+)(?!.*\d)", channel)
    return int(m.group(1)) if m else None


def read_coords(path: str | Path, channels: Sequence[str]) -> SensorCoords:
    """Read sensor coordinates from a CSV file and match them to channels.

    Parameters
    ----------
    path : str or Path
        A UFF geometry (datasets 15 / 2411, matched by the node of DOF-like channel names such
        as ``"12+Z"``, the direction from the name), or a
        CSV with a header naming ``x``, ``y``, ``z`` (m), optionally ``direction``
        (1/2/3 or x/y/z, a sign allowed) and either ``channel`` (names) or
        ``sensor``/``sensor number`` (1-based numbers), e.g. the LUMO ``coords_lumo.csv``.
    channels : sequence of str
        The channels to place. With a ``channel`` column they are matched by name; with
        sensor numbers by the number in the channel name (``/lumo/s07.linear_acceleration.x``
        -> 7) when every channel has a distinct one in the table (and, when the table has more
        rows than there are channels, every channel names its sensor as ``/sNN``), else in order
        (the k-th channel is the k-th row: as many rows as channels).

    Returns
    -------
    SensorCoords

    Raises
    ------
    LogFormatError
        If the file lacks x/y/z columns or a value does not parse (names file and line).
    ChannelError
        If a channel has no row, or the rows taken in order are more or fewer than the
        channels (names both counts).
    """
    path = Path(path)
    if path.suffix.lower() in (".uff", ".unv", ".uf"):
        return _uff_coords(path, channels)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise LogFormatError(f"{path}: cannot read ({exc})") from None
    if not rows:
        raise LogFormatError(f"{path}: empty coordinates file")
    head = [h.strip().lower() for h in rows[0]]

    def col(*names: str) -> int | None:
        for nm in names:
            if nm in head:
                return head.index(nm)
        return None

    ix, iy, iz = col("x"), col("y"), col("z")
    if None in (ix, iy, iz):
        raise LogFormatError(f"{path}: line 1: header needs x, y, z columns, got {rows[0]}")
    idir = col("direction", "dir")
    ich = col("channel", "name", "path")
    isn = col("sensor number", "sensor", "sensor_number")
    table: list[tuple[str, int | None, np.ndarray, np.ndarray]] = []
    for ln, r in enumerate(rows[1:], start=2):
        if not r or all(not c.strip() for c in r):
            continue
        try:
            xyz = np.array([float(r[ix]), float(r[iy]), float(r[iz])])
            sn = int(float(r[isn])) if isn is not None else None
            name = r[ich].strip() if ich is not None else ""
        except (ValueError, IndexError, OverflowError) as exc:
            raise LogFormatError(f"{path}: line {ln}: {type(exc).__name__}: {exc}") from None
        if not np.all(np.isfinite(xyz)):
            raise LogFormatError(f"{path}: line {ln}: coordinates must be finite numbers, got {r}")
        if idir is not None and idir < len(r) and r[idir].strip() == "0":
            continue  # a node without a sensor (e.g. LUMO's base node, direction 0)
        d = _direction(r[idir], path, ln) if idir is not None and idir < len(r) and r[idir].strip() else np.array([0.0, 0.0, 1.0])
        table.append((name, sn, xyz, d))
    chosen: list[tuple] = []
    if ich is not None:
        by = {t[0]: t for t in table}
        missing = [c for c in channels if c not in by]
        if missing:
            raise ChannelError(f"{path}: no coordinates for channels {missing}")
        chosen = [by[c] for c in channels]
    else:
        nums = [_sensor_number(c) for c in channels]
        by_sn = {t[1]: t for t in table if t[1] is not None}
        # a subset of the rows by number only where every channel names its sensor (/lumo/s07...):
        # another digit in a name (/imu/m1) picks a row by chance
        named = all(_SENSOR.search(c) for c in channels) or len(table) == len(channels)
        if all(n in by_sn for n in nums) and len(set(nums)) == len(nums) and named:
            chosen = [by_sn[n] for n in nums]
        elif len(table) == len(channels):
            chosen = table
        else:
            raise ChannelError(f"{path}: {len(table)} coordinate rows for {len(channels)} channels: give one row per "
                               "channel, or a 'channel' column naming them")
    return SensorCoords(tuple(channels), np.array([t[2] for t in chosen]).reshape(-1, 3),
                        np.array([t[3] for t in chosen]).reshape(-1, 3), True, str(path))


def _uff_coords(path: Path, channels: Sequence[str]) -> SensorCoords:
    """Channels named like UFF DOFs (``"12+Z"``) placed at the nodes of a UFF geometry file."""
    from vibroscope.io.uff import parse_dof
    from vibroscope.io.uff_geometry import read_geometry

    ids, xyz = read_geometry(path)
    where = {int(i): k for k, i in enumerate(ids)}
    pos, dirs = [], []
    for ch in channels:
        dof = parse_dof(ch)
        if dof is None or dof[0] not in where:
            raise ChannelError(f"{path}: channel {ch!r} is not a DOF of a node in the geometry "
                               f"({len(ids)} nodes, e.g. {int(ids[0])})")
        node, code = dof
        d = np.zeros(3)
        if 1 <= abs(code) <= 3:
            d[abs(code) - 1] = np.sign(code)
        else:
            d[2] = 1.0
        pos.append(xyz[where[node]])
        dirs.append(d)
    return SensorCoords(tuple(channels), np.array(pos, float), np.array(dirs, float), True, str(path))
