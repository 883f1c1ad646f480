"""Peak helpers shared by the spectral-peak methods of :mod:`vibroscope.modal` (peak picking, FDD,
EFDD, resonance comparison): the analysis band and parabolic interpolation between lines."""

from __future__ import annotations

import numpy as np

__all__ = ["band_indices", "parabolic_vertex", "parabolic_peak"]

#: fewest lines a band must hold for a peak search
MIN_BAND_LINES = 5


def band_indices(frequencies: np.ndarray, fmin: float | None, fmax: float | None) -> np.ndarray:
    """Indices of the lines with ``f > 0``, ``f >= fmin`` and ``f <= fmax`` (Hz; None: no bound).

    Parameters
    ----------
    frequencies : array_like, shape (n_freqs,)
        The frequency axis in Hz.
    fmin, fmax : float or None
        Band edges in Hz, both included; None for no bound.

    Returns
    -------
    ndarray of int
        Ascending indices into `frequencies`.

    Raises
    ------
    ValueError
        If the band holds fewer than 5 lines.
    """
    f = np.asarray(frequencies)
    band = f > 0
    if fmin is not None:
        band &= f >= fmin
    if fmax is not None:
        band &= f <= fmax
    idx = np.flatnonzero(band)
    if idx.size < MIN_BAND_LINES:
        lo = "0" if fmin is None else f"{float(fmin):.6g}"
        hi = f"{f[-1]:.6g}" if fmax is None else f"{float(fmax):.6g}"
        raise ValueError(f"the band {lo}–{hi} Hz holds {idx.size} frequency lines (spacing {f[1] - f[0]:.4g} Hz); at "
                         f"least {MIN_BAND_LINES} are needed: widen the band or lengthen nperseg")
    return idx


def parabolic_vertex(y: np.ndarray, k: int) -> tuple[float, float]:
    """Vertex of the parabola through ``y[k-1], y[k], y[k+1]`` (a maximum or a minimum).

    Parameters
    ----------
    y : ndarray, shape (n,)
        Values on equally spaced lines (e.g. a magnitude in dB).
    k : int
        The centre line, ``1 <= k <= n - 2``.

    Returns
    -------
    offset : float
        Position of the vertex in lines relative to `k`, clipped to ``[-0.5, 0.5]``; 0 when the
        three values lie on a line.
    value : float
        The parabola's value there, ``y[k] − (y[k-1] − y[k+1]) · offset / 4``.
    """
    a, b, c = y[k - 1], y[k], y[k + 1]
    den = a - 2 * b + c
    p = 0.5 * (a - c) / den if den != 0 else 0.0
    p = float(np.clip(p, -0.5, 0.5))
    return p, float(b - 0.25 * (a - c) * p)


def parabolic_peak(frequencies: np.ndarray, y: np.ndarray, k: int) -> float:
    """Frequency of a peak of `y` at line `k`, refined by the parabola through its neighbours.

    Parameters
    ----------
    frequencies : ndarray, shape (n,)
        Frequencies in Hz.
    y : ndarray, shape (n,)
        The curve (e.g. in dB).
    k : int
        Index of the peak line.

    Returns
    -------
    float
        ``f[k] + offset · Δf`` with the offset of :func:`parabolic_vertex` and the local line
        spacing ``Δf = (f[k+1] − f[k-1]) / 2``; ``f[k]`` itself at the ends of the axis, next to a
        non-finite value, or where the parabola does not open downwards (no maximum).
    """
    if k <= 0 or k >= len(y) - 1 or not np.all(np.isfinite(y[k - 1 : k + 2])):
        return float(frequencies[k])
    if y[k - 1] - 2 * y[k] + y[k + 1] >= 0:
        return float(frequencies[k])
    p, _ = parabolic_vertex(y, k)
    return float(frequencies[k] + p * (frequencies[k + 1] - frequencies[k - 1]) / 2)
