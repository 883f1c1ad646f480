"""Sensor coordinates files: where each measurement point sits and which way it measures."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from vibroscope.errors import VibroscopeError

__all__ = ["SensorCoords", "read_coords", "line_coords"]

_AXES = {"1": (1.0, 0.0, 0.0), "2": (0.0, 1.0, 0.0), "3": (0.0, 0.0, 1.0),
         "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class SensorCoords:
    """Positions (m) and measuring directions (unit vectors) of measurement points.

    Attributes
    ----------
    points : tuple of str
        Channel names (message paths), in the order of `positions`.
    positions : ndarray, shape (n_points, 3)
        x, y, z in m.
    directions : ndarray, shape (n_points, 3)
        Unit vector of each sensor's measuring axis.
    source : str
        The file they came from ("line" when laid out on a line).
    """

    points: tuple[str, ...]
    positions: np.ndarray
    directions: np.ndarray
    source: str = ""

    def as_mapping(self) -> dict[str, dict]:
        """``{point: {"xyz": (x, y, z), "direction": (dx, dy, dz)}}``."""
        return {p: {"xyz": tuple(map(float, x)), "direction": tuple(map(float, d))}
                for p, x, d in zip(self.points, self.positions, self.directions)}


def read_coords(path: str | Path, channels: Sequence[str]) -> SensorCoords:
    """Read a sensor coordinates CSV and match its rows to `channels`.

    Accepted layouts (header row required, comma separated):

    - a ``channel`` column naming the message path, with ``x, y, z`` (m) and optional
      ``direction`` (``1``/``2``/``3`` or ``x``/``y``/``z``) or ``dx, dy, dz``;
    - a ``sensor number`` column (1-based), as in the LUMO data set's ``coords_lumo.csv``: sensor k
      is the k-th of `channels`; rows with direction 0 (reference nodes) are ignored.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    channels : sequence of str
        The analysed response channels.

    Returns
    -------
    SensorCoords

    Raises
    ------
    VibroscopeError
        If the file lacks x, y, z columns, a value does not parse (names file, line and column),
        or a channel has no coordinates.
    """
    path = Path(path)
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise VibroscopeError(f"{path}: no rows")
    cols = {c.strip().lower(): c for c in rows[0].keys() if c}
    for c in ("x", "y", "z"):
        if c not in cols:
            raise VibroscopeError(f"{path}: no {c!r} column (columns: {list(rows[0].keys())})")
    key = cols.get("channel") or cols.get("sensor number") or cols.get("sensor")
    if key is None:
        raise VibroscopeError(f"{path}: needs a 'channel' or 'sensor number' column")
    found: dict[str, tuple] = {}
    for line, r in enumerate(rows, start=2):
        try:
            xyz = tuple(float(r[cols[c]]) for c in ("x", "y", "z"))
            if "dx" in cols:
                d = np.array([float(r[cols[c]]) for c in ("dx", "dy", "dz")])
            else:
                dv = (r.get(cols.get("direction", ""), "") or "3").strip().lower()
                if dv in ("0", ""):
                    continue
                if dv not in _AXES:
                    raise ValueError(f"direction {dv!r}")
                d = np.array(_AXES[dv])
        except (ValueError, TypeError) as exc:
            raise VibroscopeError(f"{path}: line {line}: {exc}") from None
        ident = r[key].strip()
        if key == cols.get("channel"):
            name = ident
        else:
            k = int(float(ident)) - 1
            if not 0 <= k < len(channels):
                continue
            name = channels[k]
        found[name] = (xyz, d / np.linalg.norm(d))
    missing = [c for c in channels if c not in found]
    if missing:
        raise VibroscopeError(f"{path}: no coordinates for channels {missing}")
    pos = np.array([found[c][0] for c in channels], float)
    dirs = np.array([found[c][1] for c in channels], float)
    return SensorCoords(tuple(channels), pos, dirs, str(path))


def line_coords(channels: Sequence[str], spacing: float = 1.0) -> SensorCoords:
    """Points laid out on the x axis, `spacing` m apart, measuring along z (no coordinates file)."""
    n = len(channels)
    pos = np.zeros((n, 3))
    pos[:, 0] = spacing * np.arange(n)
    dirs = np.tile([0.0, 0.0, 1.0], (n, 1))
    return SensorCoords(tuple(channels), pos, dirs, "line")
