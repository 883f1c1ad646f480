"""Helpers shared by the matplotlib figures and the rerun recording (no heavy imports)."""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["sensor_geometry", "real_shape", "mode_label", "nearest_frequencies", "pyplot", "short_label", "distinct_labels",
           "sigint_held"]

_AXES = {"1": (1.0, 0.0, 0.0), "2": (0.0, 1.0, 0.0), "3": (0.0, 0.0, 1.0),
         "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def _direction(d: Any) -> np.ndarray | None:
    if d is None:
        return None
    if isinstance(d, (str, int, np.integer)):
        key = str(d).strip().lower().lstrip("+")
        if key not in _AXES:
            raise ValueError(f"unknown sensor direction {d!r}; use 1/2/3, x/y/z or a 3-vector")
        return np.array(_AXES[key])
    v = np.asarray(d, dtype=float).reshape(3)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n == 0:
        raise ValueError(f"sensor direction {d!r} has no length")
    return v / n


def sensor_geometry(points: Sequence[str], coords: Mapping[str, Any] | None = None,
                    spacing: float = 1.0) -> tuple[np.ndarray, np.ndarray, bool]:
    """Positions and measuring directions of the points of a mode shape.

    Parameters
    ----------
    points : sequence of str
        Measurement point (channel) names, the columns of the mode shapes.
    coords : mapping, optional
        ``point -> {"xyz": (x, y, z), "direction": (dx, dy, dz) or 'x'/'y'/'z'/1/2/3}`` (the
        form of ``SensorCoords.as_mapping()``), or ``point -> (x, y, z)`` or
        ``point -> (x, y, z, direction)``. Points missing from it are an error. None lays the
        points on the x axis, `spacing` m apart, measuring along z.
    spacing : float, optional
        Distance in m between points laid out on a line.

    Returns
    -------
    positions : ndarray, shape (n_points, 3)
        Coordinates in m.
    directions : ndarray, shape (n_points, 3)
        Unit measuring directions. Where a point gives none: z, or x when the points spread
        mostly along z (a tower measured sideways).
    from_coords : bool
        Whether the geometry came from `coords` (False: laid out on a line).

    Raises
    ------
    ValueError
        If a point has no coordinates in `coords`, or a direction is malformed.
    """
    n = len(points)
    if coords is None:
        pos = np.zeros((n, 3))
        pos[:, 0] = spacing * np.arange(n)
        dirs = np.tile([0.0, 0.0, 1.0], (n, 1))
        return pos, dirs, False
    pos = np.zeros((n, 3))
    dirs: list[np.ndarray | None] = []
    missing = [p for p in points if p not in coords]
    if missing:
        raise ValueError(f"no coordinates for points {missing}; coords has {list(coords)[:6]}")
    for k, p in enumerate(points):
        c = coords[p]
        if isinstance(c, Mapping):
            pos[k] = np.asarray(c.get("xyz", c.get("position")), dtype=float).reshape(3)
            dirs.append(_direction(c.get("direction")))
        else:
            c = list(c)
            pos[k] = np.asarray(c[:3], dtype=float)
            dirs.append(_direction(c[3]) if len(c) > 3 else None)
    spread = np.ptp(pos, axis=0) if n else np.zeros(3)
    default = np.array([1.0, 0.0, 0.0]) if n and np.argmax(spread) == 2 and spread[2] > 0 else np.array([0.0, 0.0, 1.0])
    d = np.array([default if v is None else v for v in dirs]).reshape(n, 3)
    return pos, d, True


def real_shape(shape: np.ndarray) -> np.ndarray:
    """The real, signed version of a complex mode shape.

    The shape is rotated so that its largest-modulus entry is real and positive; its real part
    is returned (exact for a normal mode, the in-phase part otherwise).

    Parameters
    ----------
    shape : array_like, complex, shape (n_points,)

    Returns
    -------
    ndarray, shape (n_points,)
    """
    s = np.asarray(shape, dtype=complex)
    if s.size == 0:
        return np.zeros(0)
    k = int(np.argmax(np.abs(s)))
    if s[k] == 0:
        return np.real(s)
    return np.real(s * np.exp(-1j * np.angle(s[k])))


def mode_label(natural_frequency: float, zeta: float) -> str:
    """``"f = 2.82 Hz, ζ = 1.20 %"`` (ζ shown as ``n/a`` when NaN).

    Parameters
    ----------
    natural_frequency : float
        Natural frequency in Hz (4 significant digits).
    zeta : float
        Damping ratio, dimensionless (shown in % with 2 decimals).

    Returns
    -------
    str
    """
    z = "n/a" if not np.isfinite(zeta) else f"{100 * zeta:.2f} %"
    return f"f = {natural_frequency:.4g} Hz, ζ = {z}"


def nearest_frequencies(f_est: np.ndarray, f_true: np.ndarray) -> np.ndarray:
    """Index of the nearest true frequency for each estimated one (−1 when no true modes).

    Parameters
    ----------
    f_est : array_like, shape (n_est,)
        Estimated natural frequencies in Hz.
    f_true : array_like, shape (n_true,)
        True natural frequencies in Hz.

    Returns
    -------
    ndarray of int, shape (n_est,)
        Index into `f_true` of the nearest frequency (several estimates may share one).
    """
    f_est = np.asarray(f_est, dtype=float)
    f_true = np.asarray(f_true, dtype=float)
    if f_true.size == 0:
        return np.full(f_est.shape, -1)
    return np.argmin(np.abs(f_est[:, None] - f_true[None, :]), axis=1)


def pyplot():
    """Import pyplot, choosing Agg when no display is available and no backend was chosen.

    Returns
    -------
    module
        ``matplotlib.pyplot``.
    """
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules and sys.platform.startswith("linux") \
            and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) \
            and "MPLBACKEND" not in os.environ:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def short_label(name: str, n: int = 38, *, keep: str = "end") -> str:
    """`name` cut to `n` characters with an ellipsis when longer: its last ones (a channel's
    field and axis), or with ``keep="start"`` its first ones (a candidate's effect).

    Parameters
    ----------
    name : str
        A channel or file name, or a label.
    n : int, optional
        Most characters kept (default 38).
    keep : {'end', 'start'}, optional
        Which end of `name` is kept (default ``'end'``).

    Returns
    -------
    str
    """
    if len(name) <= n:
        return name
    return name[: n - 1] + "…" if keep == "start" else "…" + name[-(n - 1):]


def distinct_labels(names: Sequence[str], n: int = 16) -> list[str]:
    """Short tick labels: the names less the prefix and suffix they all share (cut at ``/`` or
    ``.``), e.g. ``/imu/m1.linear_acceleration.x`` -> ``m1``.

    Parameters
    ----------
    names : sequence of str
        Channel or point names.
    n : int, optional
        Most characters per label (:func:`short_label`; default 16).

    Returns
    -------
    list of str
        One label per name; the names themselves (shortened) when the cut labels would not be
        distinct.
    """
    names = [str(x) for x in names]
    if len(names) < 2:
        return [short_label(x, n) for x in names]
    pre = os.path.commonprefix(names)
    cut = max(pre.rfind("/"), pre.rfind(".")) + 1
    rev = [x[::-1] for x in names]
    suf = os.path.commonprefix(rev)
    cut_s = max(suf.rfind("/"), suf.rfind(".")) + 1
    out = [x[cut:len(x) - cut_s] if len(x) - cut_s > cut else x for x in names]
    if len(set(out)) < len(out) or not all(out):
        out = names
    return [short_label(x, n) for x in out]


@contextlib.contextmanager
def sigint_held():
    """Hold back Ctrl-C (SIGINT) in this block; one that came meanwhile is handed to the handler that
    was in place (``KeyboardInterrupt`` by default) as the block ends.

    A ``KeyboardInterrupt`` inside ``Pool()`` would leave a started worker that nobody terminates
    (``Pool`` cleans up after an ``Exception`` only), and a worker forked from the drawing server
    (:mod:`vibroscope.viewers.drawing_server`) holds the server's lifeline: neither would ever end.
    The Python-level handler is swapped for one that records the signal (a mask would not do: the
    signal may be delivered to any thread, and Python raises it in the main thread all the same).
    Only the main thread may set handlers: elsewhere this does nothing.

    Yields
    ------
    None
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = signal.signal(signal.SIGINT, lambda s, f: got.append(s))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if got:
            if callable(old):
                old(signal.SIGINT, None)
            elif old != signal.SIG_IGN:
                raise KeyboardInterrupt
