"""Quality indicators of identified mode shapes: auto-MAC, modal phase collinearity (MPC), mean
phase deviation (MPD), complexity, and the co-ordinate MAC (COMAC) between two shape sets."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroscope._checks import read_only
from vibroscope.modal._results import ModalModel, mpc
from vibroscope.modal.mac import as_shapes, mac

__all__ = ["automac", "mpd", "comac", "complexity", "modal_quality", "QualityTable"]


def automac(shapes) -> np.ndarray:
    """Auto-MAC matrix of one set of mode shapes: the MAC of every pair of modes.

    Parameters
    ----------
    shapes : array_like, complex, shape (n_modes, n_points) or (n_points,), or a ModalModel
        Mode shapes, one per row (an object with a ``shapes`` attribute is accepted).

    Returns
    -------
    ndarray, shape (n_modes, n_modes)
        Symmetric, dimensionless in [0, 1], ones on the diagonal (NaN for an all-zero shape).
        Off-diagonal values near 1 flag modes that the measurement points cannot tell apart
        (spatial aliasing) or a spurious duplicate.

    See Also
    --------
    vibroscope.modal.mac.mac : The MAC between two sets.
    comac : The agreement of two paired sets per point.

    References
    ----------
    .. [1] R. J. Allemang, "The modal assurance criterion – twenty years of use and abuse",
       Sound and Vibration 37(8), 14–23, 2003.

    Examples
    --------
    >>> automac([[1, 1], [1, -1]])
    array([[1., 0.],
           [0., 1.]])
    """
    return mac(shapes)


def mpd(shapes) -> np.ndarray:
    """Mean phase deviation of complex mode shapes, in degrees.

    Parameters
    ----------
    shapes : array_like, complex, shape (n_modes, n_points) or (n_points,), or a ModalModel
        Mode shapes, one per row.

    Returns
    -------
    ndarray, shape (n_modes,)
        MPD in degrees, in [0, 90]: 0 for a real (monophase) shape, whatever its overall complex
        scale; NaN for an all-zero shape.

    See Also
    --------
    vibroscope.modal.mpc : Modal phase collinearity.
    complexity : Modal complexity, ``1 - MPC``.
    modal_quality : The shape quality indicators of every mode of a model.

    Notes
    -----
    With the real ``n_points × 2`` matrix ``[Re φ, Im φ] = U S Vᵀ``, the first right singular
    vector is the best-fit straight line through the shape's points in the complex plane. The
    phase deviation of point ``o`` from that line is
    ``δ_o = arccos(|Re φ_o V₂₂ − Im φ_o V₁₂| / (√(V₁₂² + V₂₂²) |φ_o|))`` and the MPD is their
    mean weighted by the moduli, ``Σ |φ_o| δ_o / Σ |φ_o|`` (Reynders, Houbrechts & De Roeck
    2012, eq. 16). It is the same value as ``pyoma2.functions.gen.MPD`` (which returns radians).

    References
    ----------
    .. [1] E. Reynders, J. Houbrechts and G. De Roeck, "Fully automated (operational) modal
       analysis", Mechanical Systems and Signal Processing 29, 228–250, 2012.

    Examples
    --------
    >>> float(mpd([1, 2, -3])[0])
    0.0
    >>> a = np.radians(10.0)        # two of four unit points 10° off the real axis, symmetrically
    >>> round(float(mpd([1, np.exp(1j * a), 1, np.exp(-1j * a)])[0]), 9)
    5.0
    """
    S = as_shapes(shapes)
    out = np.full(S.shape[0], np.nan)
    for r, phi in enumerate(S):
        w = np.abs(phi)
        if not np.all(np.isfinite(phi)) or w.sum() == 0:
            continue
        _, _, VT = np.linalg.svd(np.column_stack([phi.real, phi.imag]), full_matrices=True)
        V = VT.T
        num = phi.real * V[1, 1] - phi.imag * V[0, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.abs(num) / (np.hypot(V[0, 1], V[1, 1]) * w)
        c = np.clip(np.where(w > 0, c, 1.0), 0.0, 1.0)
        out[r] = np.degrees(np.sum(w * np.arccos(c)) / np.sum(w))
    return out


def complexity(shapes) -> np.ndarray:
    """Modal complexity of complex mode shapes: ``1 − MPC``.

    Parameters
    ----------
    shapes : array_like, complex, shape (n_modes, n_points) or (n_points,), or a ModalModel
        Mode shapes, one per row.

    Returns
    -------
    ndarray, shape (n_modes,)
        Dimensionless, in [0, 1]: 0 for a real (monophase) shape, 1 for a circularly complex one
        (e.g. ``[1, j]``); NaN for an all-zero shape.

    See Also
    --------
    vibroscope.modal.mpc : Modal phase collinearity.
    mpd : Mean phase deviation, in degrees.
    modal_quality : The shape quality indicators of every mode of a model.

    Notes
    -----
    With ``λ₁ ≥ λ₂`` the eigenvalues of the 2 × 2 scatter matrix of ``[Re φ, Im φ]`` (not
    centred), the MPC of Pappa, Elliott & Schenk (1993) is ``((λ₁ − λ₂) / (λ₁ + λ₂))²`` =
    ``|φᵀφ|² / (φᴴφ)²`` (:func:`~vibroscope.modal.mpc`), so the complexity
    ``1 − MPC = 4 λ₁ λ₂ / (λ₁ + λ₂)²`` is the normalised spread of the shape's points across the
    best-fit line in the complex plane. (Not the polygon-area measure.)

    References
    ----------
    .. [1] R. S. Pappa, K. B. Elliott and A. Schenk, "Consistent-mode indicator for the eigensystem
       realization algorithm", J. Guidance, Control, and Dynamics 16(5), 852–858, 1993.

    Examples
    --------
    >>> complexity([[1, -2, 3], [1, 1j, 0]])
    array([0., 1.])
    """
    return 1.0 - mpc(as_shapes(shapes))


def comac(shapes_a, shapes_b) -> np.ndarray:
    """Co-ordinate modal assurance criterion of two paired sets of mode shapes, per point.

    Parameters
    ----------
    shapes_a : array_like, complex, shape (n_modes, n_points), or a ModalModel
        First set (e.g. the reference: a model's modes), one mode per row.
    shapes_b : array_like, complex, shape (n_modes, n_points), or a ModalModel
        Second set (e.g. identified), row ``r`` paired with row ``r`` of `shapes_a` (pair them
        first with :func:`~vibroscope.modal.match_modes`), at the same points in the same order.

    Returns
    -------
    ndarray, shape (n_points,)
        Dimensionless, in [0, 1]: 1 at a point where the two sets agree (up to each mode's
        complex scale) over all modes; lower at a point whose measured values disagree (a wrong
        sensor, a swapped sign or direction). NaN at a point where a set is zero in every mode.

    Raises
    ------
    ValueError
        If the two sets differ in shape.

    See Also
    --------
    vibroscope.modal.mac.mac : The agreement per mode pair.
    automac : The MAC of every pair of modes of one set.

    Notes
    -----
    Each mode ``b_r`` is first scaled onto ``a_r`` by the modal scale factor
    ``MSF_r = b_rᴴ a_r / b_rᴴ b_r`` (least squares; Allemang 2003), which removes the arbitrary
    complex scale of each identified shape. Then for point ``j``:
    ``COMAC_j = |Σ_r a_jr conj(MSF_r b_jr)|² / (Σ_r |a_jr|² Σ_r |MSF_r b_jr|²)``.
    Lieven & Ewins (1988) define it for real shapes with ``|a_jr b_jr|`` inside the sum; the two
    coincide when the scaled shapes agree in sign at each point, and this form (the modulus of the
    sum) additionally flags a sign or phase error at a point. A grossly wrong point also biases
    the scale factors, which lowers the other points slightly (by about 0.5 % for one bad point
    of 12).

    References
    ----------
    .. [1] N. A. J. Lieven and D. J. Ewins, "Spatial correlation of mode shapes, the coordinate
       modal assurance criterion (COMAC)", Proc. 6th International Modal Analysis Conference
       (IMAC), 690–695, 1988.
    .. [2] R. J. Allemang, "The modal assurance criterion – twenty years of use and abuse",
       Sound and Vibration 37(8), 14–23, 2003.

    Examples
    --------
    >>> a = [[1, 2, 3], [1, 0, -1]]
    >>> b = [[-2, -4, -6], [1j, 0, -1j]]         # the same shapes, other complex scales
    >>> comac(a, b).round(12)
    array([1., 1., 1.])
    """
    A, B = as_shapes(shapes_a), as_shapes(shapes_b)
    if A.shape != B.shape:
        raise ValueError(f"{A.shape=} and {B.shape=} must be equal: paired modes at the same points")
    bb = np.real(np.sum(np.conj(B) * B, axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        msf = np.where(bb > 0, np.sum(np.conj(B) * A, axis=1) / np.where(bb > 0, bb, 1.0), 0.0)
        Bs = B * msf[:, None]
        num = np.abs(np.sum(A * np.conj(Bs), axis=0)) ** 2
        den = np.sum(np.abs(A) ** 2, axis=0) * np.sum(np.abs(Bs) ** 2, axis=0)
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


@dataclass(frozen=True, eq=False, kw_only=True)
class QualityTable:
    """Shape quality indicators of a :class:`~vibroscope.modal.ModalModel`, one row per mode.

    Attributes
    ----------
    natural_frequencies : ndarray, shape (n_modes,)
        Hz (copied from the model).
    damping_ratios : ndarray, shape (n_modes,)
        Dimensionless (copied from the model).
    mpc : ndarray, shape (n_modes,)
        Modal phase collinearity, in [0, 1] (1: real shape).
    mpd_deg : ndarray, shape (n_modes,)
        Mean phase deviation in degrees, in [0, 90] (0: real shape).
    complexity : ndarray, shape (n_modes,)
        ``1 − MPC``, in [0, 1].
    automac : ndarray, shape (n_modes, n_modes)
        Auto-MAC matrix.
    automac_max : ndarray, shape (n_modes,)
        Largest off-diagonal auto-MAC of each mode (NaN for a single mode).
    points : tuple of str
        Measurement points.
    method : str
        The identification method of the model.
    """

    natural_frequencies: np.ndarray
    damping_ratios: np.ndarray
    mpc: np.ndarray
    mpd_deg: np.ndarray
    complexity: np.ndarray
    automac: np.ndarray
    automac_max: np.ndarray
    points: tuple[str, ...] = ()
    method: str = ""

    def __post_init__(self) -> None:
        for name in ("natural_frequencies", "damping_ratios", "mpc", "mpd_deg", "complexity", "automac",
                     "automac_max"):
            object.__setattr__(self, name, read_only(getattr(self, name), float))
        object.__setattr__(self, "points", tuple(self.points))

    def __len__(self) -> int:
        return int(self.mpc.size)

    def __repr__(self) -> str:
        return f"QualityTable({len(self)} modes by {self.method!r} at {len(self.points)} points)"

    def to_dict(self) -> dict:
        """JSON-ready table.

        Returns
        -------
        dict
            ``{"method", "points", "modes": [{"frequency_hz", "damping_ratio", "mpc", "mpd_deg",
            "complexity", "automac_max"}, ...], "automac": [[...], ...]}``; NaN becomes None.
        """
        def num(v):
            return None if not np.isfinite(v) else float(v)

        rows = [{"frequency_hz": num(self.natural_frequencies[r]), "damping_ratio": num(self.damping_ratios[r]),
                 "mpc": num(self.mpc[r]), "mpd_deg": num(self.mpd_deg[r]), "complexity": num(self.complexity[r]),
                 "automac_max": num(self.automac_max[r])} for r in range(len(self))]
        return {"method": self.method, "points": list(self.points), "modes": rows,
                "automac": [[num(v) for v in row] for row in self.automac]}


def modal_quality(modal_model: ModalModel) -> QualityTable:
    """Shape quality indicators of every mode of an identified model.

    Parameters
    ----------
    modal_model : ModalModel
        Identified modes (any method).

    Returns
    -------
    QualityTable
        Per mode: MPC, MPD (degrees), complexity ``1 − MPC``, the largest off-diagonal auto-MAC;
        and the auto-MAC matrix. A physical, lightly and proportionally damped mode has MPC ≈ 1
        and MPD ≈ 0°; spurious (noise) modes tend to be complex (Reynders et al. 2012).

    Raises
    ------
    TypeError
        If `modal_model` has no ``shapes`` (not a ModalModel-like object).

    See Also
    --------
    vibroscope.modal.mpc : Modal phase collinearity.
    mpd : Mean phase deviation, in degrees.
    complexity : Modal complexity, ``1 - MPC``.

    References
    ----------
    .. [1] E. Reynders, J. Houbrechts and G. De Roeck, "Fully automated (operational) modal
       analysis", Mechanical Systems and Signal Processing 29, 228–250, 2012.

    Examples
    --------
    >>> m = ModalModel(natural_frequencies=[10.0, 20.0], damping_ratios=[0.01, 0.02], shapes=[[1, 1], [1, -1]],
    ...                points=["a", "b"], method="fdd")
    >>> q = modal_quality(m)
    >>> q.mpc, q.mpd_deg, q.automac_max
    (array([1., 1.]), array([0., 0.]), array([0., 0.]))
    """
    if not hasattr(modal_model, "shapes"):
        raise TypeError(f"modal_model must be a ModalModel, got {type(modal_model).__name__}")
    S = as_shapes(modal_model.shapes)
    n = S.shape[0]
    M = automac(S) if n else np.zeros((0, 0))
    off = np.where(np.eye(n, dtype=bool), np.nan, M)
    with np.errstate(invalid="ignore"):
        amax = np.full(n, np.nan) if n < 2 else np.nanmax(off, axis=1)
    return QualityTable(
        natural_frequencies=np.asarray(getattr(modal_model, "natural_frequencies", np.full(n, np.nan)), float),
        damping_ratios=np.asarray(getattr(modal_model, "damping_ratios", np.full(n, np.nan)), float),
        mpc=mpc(S) if n else np.zeros(0), mpd_deg=mpd(S), complexity=complexity(S) if n else np.zeros(0),
        automac=M, automac_max=amax,
        points=tuple(getattr(modal_model, "points", ())), method=str(getattr(modal_model, "method", "")))
