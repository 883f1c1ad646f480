"""Modal Assurance Criterion and mode pairing."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.optimize

__all__ = ["mac", "mac_matrix", "match_modes", "ModeMatch"]


def as_shapes(x) -> np.ndarray:
    """Mode shapes as a complex array (n_modes, n_points): `x` itself or its ``shapes`` (a 1-D array
    is one mode); raises ValueError for another number of dimensions."""
    s = getattr(x, "shapes", x)
    s = np.asarray(s, dtype=complex)
    if s.ndim == 1:
        s = s[np.newaxis]
    if s.ndim != 2:
        raise ValueError(f"shapes must be 1-D (n_points,) or 2-D (n_modes, n_points), got {s.shape=}")
    return s


def mac(a, b=None) -> np.ndarray:
    """Modal Assurance Criterion between two sets of (complex) mode shapes.

    ``MAC(φ, ψ) = |φᴴψ|² / ((φᴴφ)(ψᴴψ))`` (Allemang & Brown 1982): 1 for collinear shapes (any complex
    scale), 0 for orthogonal ones.

    Parameters
    ----------
    a : array_like, complex, shape (n_a, n_points) or (n_points,), or a ModalModel / Modes
        First set of shapes (one per row); an object with a ``shapes`` attribute is accepted.
    b : same as `a`, optional
        Second set; default `a` (the auto-MAC).

    Returns
    -------
    ndarray, shape (n_a, n_b)
        Dimensionless values in [0, 1]; NaN where a shape is all zero.

    Raises
    ------
    ValueError
        If the shapes have different numbers of points.

    See Also
    --------
    match_modes : Pairs of modes by MAC and frequency.
    compare_mode_sets : Two mode sets compared (MAC matrix, pairs, frequency differences).
    vibroscope.modal.quality.automac : The MAC of every pair of modes of one set.
    vibroscope.modal.quality.comac : The agreement of two paired sets per point.

    References
    ----------
    .. [1] R. J. Allemang and D. L. Brown, "A correlation coefficient for modal vector analysis",
       Proc. 1st International Modal Analysis Conference (IMAC), 110–116, 1982.

    Examples
    --------
    >>> mac([1, 2, 3], [-2j, -4j, -6j])
    array([[1.]])
    """
    A = as_shapes(a)
    B = A if b is None else as_shapes(b)
    if A.shape[1] != B.shape[1]:
        raise ValueError(f"shapes have {A.shape[1]} and {B.shape[1]} points; they must match")
    num = np.abs(A.conj() @ B.T) ** 2
    den = np.real(np.sum(A.conj() * A, axis=1))[:, None] * np.real(np.sum(B.conj() * B, axis=1))[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


#: alias of :func:`mac`
mac_matrix = mac


class ModeMatch(NamedTuple):
    """Pairs of estimated and reference modes (see :func:`match_modes`).

    Attributes
    ----------
    pairs : ndarray of int, shape (n_pairs, 2)
        ``(index in est, index in ref)``, sorted by the reference index.
    frequency_errors : ndarray, shape (n_pairs,)
        Relative frequency errors ``(f_est − f_ref) / f_ref`` (dimensionless).
    mac : ndarray, shape (n_pairs,)
        MAC of each pair.
    """

    pairs: np.ndarray
    frequency_errors: np.ndarray
    mac: np.ndarray


def match_modes(est, ref, *, mac_min: float = 0.0, max_frequency_error: float = np.inf,
                frequency_weight: float = 1.0) -> ModeMatch:
    """Pair estimated modes with reference modes by MAC and frequency proximity.

    The assignment minimises ``Σ (1 − MAC) + w |f_est − f_ref| / f_ref`` over one-to-one pairings
    (Hungarian algorithm, :func:`scipy.optimize.linear_sum_assignment`); pairs below `mac_min` or
    beyond `max_frequency_error` are then dropped.

    Parameters
    ----------
    est, ref : ModalModel, vibroscope.models.Modes or tuple (frequencies, shapes)
        Frequencies in Hz, shape (n_modes,); shapes (n_modes, n_points) with the same points in the
        same order.
    mac_min : float, optional
        Smallest MAC accepted for a pair (default 0: keep all).
    max_frequency_error : float, optional
        Largest relative frequency error of a kept pair (default: no limit).
    frequency_weight : float, optional
        Weight ``w`` of the relative frequency distance in the cost (default 1).

    Returns
    -------
    ModeMatch
        ``(pairs, frequency_errors, mac)``.

    Raises
    ------
    ValueError
        If the shapes have different numbers of points.

    See Also
    --------
    mac : The criterion it pairs by.
    compare_mode_sets : Pairs, MAC matrix and frequency differences of two mode sets, with a report.
    """

    def unpack(m):
        if isinstance(m, tuple):
            f, s = m
        else:
            f, s = m.natural_frequencies, m.shapes
        return np.atleast_1d(np.asarray(f, dtype=float)), as_shapes(s)

    fe, se = unpack(est)
    fr, sr = unpack(ref)
    M = mac(se, sr)
    if M.size == 0:
        return ModeMatch(np.zeros((0, 2), int), np.zeros(0), np.zeros(0))
    dfrel = np.abs(fe[:, None] - fr[None, :]) / fr[None, :]
    cost = (1 - np.nan_to_num(M)) + frequency_weight * dfrel
    ie, ir = scipy.optimize.linear_sum_assignment(cost)
    keep = (np.nan_to_num(M[ie, ir]) >= mac_min) & (dfrel[ie, ir] <= max_frequency_error)
    ie, ir = ie[keep], ir[keep]
    order = np.argsort(ir)
    ie, ir = ie[order], ir[order]
    return ModeMatch(np.column_stack([ie, ir]).astype(int), (fe[ie] - fr[ir]) / fr[ir], M[ie, ir])
