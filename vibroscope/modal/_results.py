"""Result containers of modal identification: :class:`ModalModel` and :class:`Mode`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np

from vibroscope._checks import read_only

__all__ = ["Mode", "ModalModel", "normalize_shapes", "mpc", "ods_as_modal_model", "with_operating_shapes"]


def normalize_shapes(shapes: np.ndarray) -> np.ndarray:
    """Scale each mode shape to unit maximum modulus with a real positive reference entry.

    Parameters
    ----------
    shapes : array_like, complex, shape (n_modes, n_points) or (n_points,)
        Mode shapes, one per row.

    Returns
    -------
    ndarray, complex, shape like `shapes`
        Each row divided by its largest-modulus entry, which thereby becomes exactly ``1 + 0j``.
        Rows that are all zero or all NaN are returned unchanged; NaN entries are ignored.
    """
    s = np.array(shapes, dtype=complex)
    one = s.ndim == 1
    s = np.atleast_2d(s)
    for r in range(s.shape[0]):
        a = np.abs(s[r])
        if not np.any(np.isfinite(a)):
            continue
        k = int(np.nanargmax(a))
        if s[r, k] != 0:
            s[r] = s[r] / s[r, k]
    return s[0] if one else s


def mpc(shapes: np.ndarray) -> np.ndarray:
    """Modal phase collinearity of complex shapes (Pappa, Elliott & Schenk 1993).

    ``MPC = |φᵀφ|² / (φᴴφ)²``: 1 for a real (monophase) mode, 0 for a circularly complex one.

    Parameters
    ----------
    shapes : array_like, complex, shape (n_modes, n_points) or (n_points,)

    Returns
    -------
    ndarray, shape (n_modes,)
        Dimensionless, in [0, 1].

    See Also
    --------
    vibroscope.modal.mpd : Mean phase deviation, in degrees.
    vibroscope.modal.complexity : Modal complexity, ``1 - MPC``.
    vibroscope.modal.modal_quality : The shape quality indicators of every mode of a model.

    References
    ----------
    .. [1] R. S. Pappa, K. B. Elliott and A. Schenk, "Consistent-mode indicator for the eigensystem
       realization algorithm", J. Guidance, Control, and Dynamics 16(5), 852–858, 1993.
    """
    s = np.atleast_2d(np.asarray(shapes, dtype=complex))
    num = np.abs(np.sum(s * s, axis=1)) ** 2
    den = np.sum(np.abs(s) ** 2, axis=1) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / den


@dataclass(frozen=True, eq=False, kw_only=True)
class Mode:
    """One identified mode (an item of :class:`ModalModel`).

    Attributes
    ----------
    natural_frequency : float
        Natural frequency in Hz (the `natural_frequencies` entry of its model; the JSON key is
        ``frequency_hz``).
    damping_ratio : float
        Viscous damping ratio ζ (dimensionless, e.g. 0.01 for 1 %); NaN when not estimated.
    shape : ndarray, complex, shape (n_points,)
        Mode shape at `points`, normalised to unit maximum modulus (real positive reference).
    points : tuple of str
        Measurement point (channel) names.
    index : int
        Position in the parent model.
    method : str
        Identification method.
    """

    natural_frequency: float
    damping_ratio: float
    shape: np.ndarray
    points: tuple[str, ...]
    index: int = 0
    method: str = ""

    def to_dict(self) -> dict:
        """JSON-ready entry ``{"frequency_hz", "damping_ratio", "shape": {point: [re, im]}, "method"}``."""
        return {
            "frequency_hz": float(self.natural_frequency),
            "damping_ratio": None if not np.isfinite(self.damping_ratio) else float(self.damping_ratio),
            "shape": {p: [float(v.real), float(v.imag)] for p, v in zip(self.points, self.shape)},
            "method": self.method,
        }


@dataclass(frozen=True, eq=False, kw_only=True)
class ModalModel:
    """Identified modal parameters of a structure.

    Attributes
    ----------
    natural_frequencies : ndarray, shape (n_modes,)
        Natural frequencies in Hz, ascending.
    damping_ratios : ndarray, shape (n_modes,)
        Viscous damping ratios ζ (dimensionless); NaN where not estimated.
    shapes : ndarray, complex, shape (n_modes, n_points)
        Mode shapes, one per row, at `points`, as the method normalised them, which
        ``extra["normalisation"]`` states: ``"unit_maximum"`` (the default when absent: largest
        modulus exactly ``1 + 0j``, see :func:`normalize_shapes`; every method without a driving
        point) or ``"unit_modal_mass"`` (LSCF + LSFD with a driving point: ``φᵀ M φ = 1``, mass-normalised
        shapes in kg^-½ for FRFs in SI units per newton, see
        :meth:`vibroscope.modal.lsfd.LSFDResult.modal_model`). The constructor stores the shapes as
        given.
    points : tuple of str
        Channel names of the measurement points (the columns of `shapes`).
    method : str
        How they were identified (``"peak_picking"``, ``"fdd"``, ``"efdd"``, ``"ssi_cov"``).
    extra : dict
        Per-mode diagnostics as arrays of shape (n_modes,) (e.g. ``"mpc"``, ``"peak_value"``,
        ``"damping_half_power"``) and the settings used.

    Examples
    --------
    >>> m = ModalModel(natural_frequencies=[10.0], damping_ratios=[0.02], shapes=[[1.0, 0.5]], points=["a", "b"],
    ...                method="peak_picking")
    >>> len(m), m[0].natural_frequency
    (1, 10.0)
    """

    natural_frequencies: np.ndarray
    damping_ratios: np.ndarray
    shapes: np.ndarray
    points: tuple[str, ...]
    method: str
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        f = np.atleast_1d(np.asarray(self.natural_frequencies, dtype=float))
        z = np.atleast_1d(np.asarray(self.damping_ratios, dtype=float))
        s = np.asarray(self.shapes, dtype=complex)
        if s.ndim == 1 and s.size == 0:
            s = s.reshape(0, len(self.points))
        s = np.atleast_2d(s)
        if f.ndim != 1 or z.shape != f.shape or s.shape[0] != f.size:
            raise ValueError(
                f"inconsistent sizes: {f.shape=} frequencies, {z.shape=} damping ratios, {s.shape=} shapes"
            )
        if s.shape[1] != len(self.points):
            raise ValueError(f"{s.shape=} shapes for {len(self.points)} points")
        object.__setattr__(self, "natural_frequencies", read_only(f, float))
        object.__setattr__(self, "damping_ratios", read_only(z, float))
        object.__setattr__(self, "shapes", read_only(s, complex))
        object.__setattr__(self, "points", tuple(str(p) for p in self.points))
        object.__setattr__(self, "extra", dict(self.extra))

    def __len__(self) -> int:
        return int(self.natural_frequencies.size)

    def __getitem__(self, r: int) -> Mode:
        r = range(len(self))[r]
        return Mode(natural_frequency=float(self.natural_frequencies[r]), damping_ratio=float(self.damping_ratios[r]),
                    shape=self.shapes[r], points=self.points, index=r, method=self.method)

    def __iter__(self) -> Iterator[Mode]:
        return (self[r] for r in range(len(self)))

    def to_dict(self) -> dict:
        """JSON-ready summary.

        Returns
        -------
        dict
            ``{"method": str, "points": [str], "modes": [entry, ...]}`` where each entry is
            :meth:`Mode.to_dict`: ``{"frequency_hz", "damping_ratio", "shape": {point: [re, im]},
            "method"}`` (a NaN damping ratio becomes ``None``).
        """
        return {"method": self.method, "points": list(self.points), "modes": [m.to_dict() for m in self]}

    def plot(self, *args: Any, **kwargs: Any):
        """Plot the mode shapes; imports matplotlib lazily through
        :func:`vibroscope.viewers.figures.plot_mode_shapes` (arguments passed on)."""
        from vibroscope._plotting import draw

        return draw("plot_mode_shapes", self, *args, **kwargs)

    def __repr__(self) -> str:
        fs = ", ".join(f"{f:.4g}" for f in self.natural_frequencies[:6])
        return (f"ModalModel({len(self)} modes by {self.method!r} at {len(self.points)} points; "
                f"f = [{fs}{', ...' if len(self) > 6 else ''}] Hz)")


def ods_as_modal_model(ods_result) -> ModalModel:
    """An operating deflection shape as a one-mode :class:`vibroscope.modal.ModalModel`.

    So that everything that draws or animates modes (:func:`vibroscope.viewers.figures.plot_mode_shapes`,
    :func:`vibroscope.viewers.rerun_view.log_analysis`) shows the ODS like a mode (built here, in the
    modal room, not in a viewer).

    Parameters
    ----------
    ods_result : OperatingShape
        From :func:`vibroscope.spectral.integration.ods`.

    Returns
    -------
    ModalModel
        ``natural_frequencies = [frequency]``, ``damping_ratios = [nan]``,
        ``shapes = [shape]``, ``points``, ``method = 'ods'``; ``extra`` holds ``source``,
        ``reference``, ``requested_hz``, ``input``, ``units`` and ``values`` (shape (1, n_points)).
    """
    o = ods_result
    extra = {"source": o.source, "reference": o.reference, "requested_hz": np.array([o.requested_frequency]),
             "input": o.input, "units": o.units, "values": np.asarray(o.values)[None, :]}
    return ModalModel(natural_frequencies=[o.frequency], damping_ratios=[np.nan], shapes=[o.shape], points=o.points,
                      method="ods", extra=extra)


def with_operating_shapes(model: ModalModel, shapes: list[ModalModel]) -> ModalModel:
    """The modes of `model` followed by operating deflection shapes (animated alike in rerun).

    Parameters
    ----------
    model : ModalModel
        The identified modes, shapes ``(n_modes, n_points)``.
    shapes : list of ModalModel
        One-mode models of the same points (:func:`ods_as_modal_model`), at least one.

    Returns
    -------
    ModalModel
        ``n_modes + len(shapes)`` entries, the shapes' damping ratios NaN, ``method``
        ``model.method + "+ods"`` (its ``extra`` not carried).
    """
    f = np.concatenate([model.natural_frequencies, [o.natural_frequencies[0] for o in shapes]])
    z = np.concatenate([model.damping_ratios, [np.nan] * len(shapes)])
    s = np.concatenate([np.reshape(model.shapes, (len(model), shapes[0].shapes.shape[-1])), *[o.shapes for o in shapes]])
    return ModalModel(natural_frequencies=f, damping_ratios=z, shapes=s, points=model.points,
                      method=model.method + "+ods")
