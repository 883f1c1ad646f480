"""Lumped models in modal coordinates: a modal model with physical points, so that elements
(springs, dampers, friction, cubic springs, ...) can act between measured points.

A mode ``r`` is one DOF ``q_r`` of unit modal mass on a spring ``omega_r^2`` and a damper
``2 zeta_r omega_r`` to ground; the displacement of measured point ``p`` is
``x_p = sum_r phi_p,r q_r`` with mass-normalised real mode shapes ``phi`` (1/sqrt(kg)). An
element between points ``a`` and ``b`` sees ``d = (phi_a - phi_b) q`` and its force ``f``
acts on the modes as ``(phi_a - phi_b)^T f``; a force input at point ``p`` as ``phi_p^T u``.
This is the standard "modal model + localised nonlinearity" form [1]_ [2]_.

The mode shapes come from a driving-point FRF: for the receptance (displacement per force)
pole-residue form ``R_r,qp = phi_q,r phi_p,r / (2 j omega_d,r)`` (real modes), so the modal
constants ``A_r,qp = 2 j omega_d,r R_r,qp`` at the driving point ``p`` give
``phi_p,r = sqrt(A_r,pp)`` and at every other point ``phi_q,r = A_r,qp / phi_p,r`` [3]_.
Residues of a velocity or acceleration output (``H = (jw)^k x receptance``) are divided by
``lambda_r^k`` first.

References
----------
.. [1] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research
   Studies Press, 2000, sec. 2.3 and 6.2 (modal constants, mass-normalised shapes from a
   driving-point FRF).
.. [2] G. Kerschen, K. Worden, A. F. Vakakis, J.-C. Golinval, "Past, present and future of
   nonlinear system identification in structural dynamics", MSSP 20(3):505-592, 2006,
   sec. 5 (modal models with localised nonlinearities).
.. [3] W. Heylen, S. Lammens, P. Sas, *Modal Analysis Theory and Testing*, KU Leuven, 1997,
   ch. A.2 (residues and modal constants).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from vibroscope.models.elements import GROUND, Damper, Spring
from vibroscope.models.lumped import Dof, LumpedModel
from vibroscope.models.modal_model import QUANTITY_ORDER, PoleResidueModel

__all__ = ["ModalCoordinatesModel", "from_pole_residue", "from_transfer_function"]

#: a mode whose modal constants have an imaginary part above this share of their modulus
#: (non-proportional damping, identification noise) is warned about: the real part is kept
COMPLEXITY_WARN = 0.1

#: a residual term smaller than this share of the in-band modes' own scale at the driving point
#: (their static compliance ``sum A / omega^2`` for the upper residual, their mass line
#: ``sum A`` for the lower) has no sign that can be read: noise of either sign
RESIDUAL_SIGN_MIN = 0.05
#: the frequency of the pseudo-mode that carries a positive upper residual, as a multiple of the
#: highest identified mode's (its in-band FRF is the residual's to within ``(f/f_u)^2``, 6 %
#: at the highest mode's frequency)
UPPER_PSEUDO_FACTOR = 4.0
#: the DOF name of that pseudo-mode
UPPER_PSEUDO_NAME = "upper_residual"


@dataclass(frozen=True, kw_only=True)
class ModalCoordinatesModel(LumpedModel):
    """A :class:`LumpedModel` whose DOFs are modal coordinates, with measured points.

    Parameters
    ----------
    dofs, elements, inputs, outputs, name
        As :class:`LumpedModel`; elements, inputs and outputs may also name a point.
    controllers : tuple of Controller, optional
        As :class:`LumpedModel`: discrete controllers closing loops around the model; default
        none.
    points : tuple of str
        The names of the measured points (not DOF names, not ``"ground"``).
    shapes : tuple of tuple of float, shape (n_points, n_shape)
        ``shapes[p][r] = phi_p,r``: the displacement of point ``p`` is
        ``x_p = sum_r phi_p,r x_r`` over the first ``n_shape <= n_dofs`` DOFs (1/sqrt(kg) for
        mass-normalised modes of unit modal mass); further DOFs (an added extra mode) do not
        move the points.

    Raises
    ------
    ValueError
        If points repeat, clash with a DOF name or ``"ground"``, `shapes` has not one row
        per point of equal length ``<= n_dofs``, or a value is not finite; and as
        :class:`LumpedModel`.

    Notes
    -----
    Every method of :class:`LumpedModel` (``M``, ``K``, ``C``, ``B``, :meth:`frf`,
    :meth:`modes`, :meth:`state_matrices`) and the time simulation work through
    :meth:`point_vector`.
    """

    points: tuple[str, ...] = ()
    shapes: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        pts = tuple(str(p) for p in self.points)
        rows = tuple(tuple(float(x) for x in row) for row in self.shapes)
        if len(set(pts)) != len(pts) or GROUND in pts:
            raise ValueError(f"points={list(pts)} must be distinct names other than {GROUND!r}")
        if len(rows) != len(pts) or len({len(r) for r in rows}) > 1:
            raise ValueError(f"shapes must have one row per point ({len(pts)=}), all of one length")
        if not all(np.isfinite(x) for r in rows for x in r):
            raise ValueError("shapes must be finite")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "shapes", rows)
        super().__post_init__()
        clash = set(pts) & set(self.dof_names)
        if clash:
            raise ValueError(f"points {sorted(clash)} are also DOF names")
        if rows and len(rows[0]) > self.n_dofs:
            raise ValueError(f"shapes have {len(rows[0])} columns, more than {self.n_dofs=}")

    def point_names(self) -> tuple[str, ...]:
        """The measured points."""
        return tuple(self.points)

    def point_vector(self, name: str) -> np.ndarray:
        """``v`` with ``x_name = v @ x``: the mode-shape row of a point, zeros beyond it; a
        unit vector for a DOF.

        Parameters
        ----------
        name : str
            A point or DOF name.

        Returns
        -------
        ndarray, shape (n_dofs,)

        Raises
        ------
        KeyError
            If `name` is neither a point nor a DOF.
        """
        if name in self.points:
            row = self.shapes[self.points.index(name)]
            v = np.zeros(self.n_dofs)
            v[: len(row)] = row
            return v
        return super().point_vector(name)

    @property
    def shape_matrix(self) -> np.ndarray:
        """``Phi``, shape (n_points, n_shape): mode shapes at the points (1/sqrt(kg))."""
        return np.array(self.shapes, dtype=float).reshape(len(self.points), -1)


def _mode_dofs(natural_frequencies, damping_ratios, names):
    w = 2 * np.pi * np.asarray(natural_frequencies, float)
    dofs, els = [], []
    for nm, wr, zr in zip(names, w, damping_ratios):
        dofs.append(Dof(nm, 1.0))
        els.append(Spring((nm, GROUND), k=float(wr**2)))
        if zr > 0:
            els.append(Damper((nm, GROUND), c=float(2 * zr * wr)))
    return dofs, els


def modal_constants(model: PoleResidueModel) -> np.ndarray:
    """Complex modal constants ``A_r,oi = 2 j omega_d,r R_r,oi / lambda_r^p_o`` (receptance).

    Parameters
    ----------
    model : PoleResidueModel

    Returns
    -------
    ndarray of complex, shape (n_modes, n_outputs, n_inputs)
        In m/N * (rad/s)^2 = 1/kg; real (``phi_o,r phi_i,r``) for real modes.
    """
    lam = model.eigenvalues
    p = np.array(model.output_orders)
    Rrec = model.residues / lam[:, None, None] ** p[None, :, None]
    return 2j * lam.imag[:, None, None] * Rrec


def from_pole_residue(model: PoleResidueModel, *, source: str = "") -> ModalCoordinatesModel:
    """The modal-coordinates model of a pole-residue model with a driving point.

    Parameters
    ----------
    model : PoleResidueModel
        Must contain a driving point: an ``[[input]]`` and an ``[[output]]`` with the same
        ``dof`` label (the same physical point; an output's ``quantity`` sets how its
        residues are read). Every output's ``dof`` label names a measured point (outputs with
        one label are one point, the first sets its shape); every input must act at a
        measured point.
    source : str, optional
        The file the model came from, named in error messages.

    Returns
    -------
    ModalCoordinatesModel
        DOFs ``mode1`` ... ``moden`` (unit modal mass, spring ``omega_r^2`` and damper
        ``2 zeta_r omega_r`` to ground), and ``upper_residual`` where the upper residual is
        carried (Notes); points = the outputs' ``dof`` labels, shapes from the
        driving-point column; the inputs and outputs of `model` on those points.

    Raises
    ------
    ValueError
        If there is no driving point, an input acts at no measured point, a driving-point
        modal constant is not positive (the residues do not describe a driving point), or a
        point label is ``mode<k>``/``ground``.

    Warns
    -----
    RuntimeWarning
        If a mode's modal constants are markedly complex (imaginary part above
        :data:`COMPLEXITY_WARN` of the modulus): the real-mode approximation keeps their
        real part.

    Notes
    -----
    The upper residual (the compliance of the modes above the band) is carried as a pseudo-mode
    (DOF :data:`UPPER_PSEUDO_NAME`) at :data:`UPPER_PSEUDO_FACTOR` times the highest mode's
    frequency, with modal constants ``UR_o omega_u^2`` (its static compliance is the residual's)
    and the median damping ratio, when it is positive at the driving point beyond
    :data:`RESIDUAL_SIGN_MIN` of the in-band modes' static compliance (a driving point's upper
    residual is ``sum phi_p^2 / omega^2 > 0``; a smaller one, or one of the wrong sign, is
    noise and dropped) [Ewins, *Modal Testing*, 2000, sec. 4.4: residual terms, and the
    pseudo-mode that stands for the modes out of range]. An identified model whose band ends
    below a mode it did not fit (a ground vibration test's band) needs it: dropped, a residual of
    half the in-band compliance leaves a 10 % FRF error. The lower residual is not carried
    (modes below the band); for an acceleration output the realisation has its own
    high-frequency limit ``sum_r phi_o,r phi_i,r``. With real modal constants and no upper
    residual the realisation's FRF equals the pole-residue sum exactly. The gap diagnosis places
    the pseudo-mode from its logs (``vibroscope.gap.diagnosis._place_upper_residual``): a
    constant residual identified over a band is the modes above it as amplified inside the band,
    so as a static compliance it is too large when such a mode lies close above the band.
    """
    where = f"{source}: " if source else ""
    out_labels = [o.dof for o in model.outputs]
    points = list(dict.fromkeys(out_labels))
    drive = next(((i, out_labels.index(inp.dof)) for i, inp in enumerate(model.inputs) if inp.dof in out_labels), None)
    if drive is None:
        raise ValueError(
            f"{where}modal model {model.name!r} has no driving point: the gap diagnosis places "
            f"elements on mass-normalised mode shapes, which need an output at the input's point; "
            f"give one [[input]] and one [[output]] the same `dof` label (inputs: "
            f"{[i.dof for i in model.inputs]}, outputs: {out_labels})")
    for inp in model.inputs:
        if inp.dof not in points:
            raise ValueError(f"{where}input {inp.channel!r} acts at {inp.dof!r}, which no output measures; "
                             f"points are {points}")
    names = [f"mode{r + 1}" for r in range(model.n_modes)]
    bad = set(points) & (set(names) | {GROUND, UPPER_PSEUDO_NAME})
    if bad:
        raise ValueError(f"{where}output labels {sorted(bad)} are reserved (modal DOF names or ground)")
    A = modal_constants(model)
    i0, o0 = drive
    cplx = np.abs(A.imag) > COMPLEXITY_WARN * np.maximum(np.abs(A), 1e-300)
    if np.any(cplx):
        modes = sorted({int(r) + 1 for r in np.nonzero(cplx)[0]})
        warnings.warn(f"{where}modes {modes} of {model.name!r} have complex modal constants; the real "
                      f"parts are kept (real-mode approximation)", RuntimeWarning, stacklevel=2)
    A = A.real
    a_pp = A[:, o0, i0]
    if np.any(a_pp <= 0):
        r = int(np.nonzero(a_pp <= 0)[0][0])
        raise ValueError(
            f"{where}driving-point modal constant A={a_pp[r]:.4g} 1/kg of mode {r + 1} "
            f"({model.natural_frequencies[r]:.4g} Hz) at {points[points.index(out_labels[o0])]!r} must be > 0: "
            f"the output {model.outputs[o0].channel!r} is not at the input's point")
    fr, zr = list(model.natural_frequencies), list(model.damping_ratios)
    # the upper residual (the receptance compliance of the modes above the band, whatever the
    # output's quantity) as a pseudo-mode well above the band, when it is positive at the
    # driving point beyond noise: A_o = UR_o omega_u^2
    ur = np.real(np.asarray(model.upper_residual)[:, i0])
    w2 = (2 * np.pi * np.asarray(model.natural_frequencies, float)) ** 2
    if ur[o0] > RESIDUAL_SIGN_MIN * float(np.sum(a_pp / w2)):
        fu = UPPER_PSEUDO_FACTOR * float(np.max(model.natural_frequencies))
        A = np.concatenate([A[:, :, i0:i0 + 1], (ur * (2 * np.pi * fu) ** 2)[None, :, None]])  # shapes: column i0 only
        i0 = 0
        a_pp = A[:, o0, i0]
        fr.append(fu)
        zr.append(float(np.median(model.damping_ratios)))
        names.append(UPPER_PSEUDO_NAME)
    phi_p = np.sqrt(a_pp)
    shapes = []
    for pt in points:
        o = out_labels.index(pt)
        shapes.append(tuple((A[:, o, i0] / phi_p).tolist()))
    dofs, els = _mode_dofs(fr, zr, names)
    return ModalCoordinatesModel(dofs=tuple(dofs), elements=tuple(els), inputs=tuple(model.inputs),
                                 outputs=tuple(model.outputs), name=model.name, points=tuple(points),
                                 shapes=tuple(shapes))


def from_transfer_function(model, *, rtol: float = 1e-6) -> ModalCoordinatesModel:
    """A SISO transfer function ``num(s)/den(s)`` of any order as modes in modal coordinates.

    Parameters
    ----------
    model : TransferFunctionModel
        Of the mechanical form ``H(s) = s^p sum_r A_r / (s^2 + 2 zeta_r omega_r s +
        omega_r^2)`` with real ``A_r`` (``p`` = 0, 1, 2 for a displacement, velocity or
        acceleration output): ``den`` of degree ``2 n`` with ``n`` distinct lightly damped
        (``0 <= zeta < 1``) pole pairs.
    rtol : float, optional
        The realisation's FRF must match ``num/den`` to this relative tolerance.

    Returns
    -------
    ModalCoordinatesModel
        One point ``p1`` with the input and output when every ``A_r > 0`` (a driving point),
        else two points ``in`` (input) and ``out`` (output) with shapes ``sqrt|A_r|`` and
        ``sign(A_r) sqrt|A_r|``.

    Raises
    ------
    ValueError
        If ``den`` has a real, unstable or repeated pole, or ``num/den`` is not of that form.
    """
    from scipy import signal

    num = np.asarray(model.num, float)
    den = np.asarray(model.den, float)
    p = QUANTITY_ORDER[model.output.quantity]
    form = (f"the gap diagnosis needs a second-order transfer function or one of the modal form s^{p} sum_r A_r / (s^2 + 2 zeta_r w_r s + w_r^2) "
            f"with real A_r ({model.output.quantity} output)")
    poles = np.roots(den)
    if den.size < 3 or np.any(np.abs(poles.imag) <= 1e-12 * np.maximum(np.abs(poles), 1.0)) or np.any(poles.real > 0):
        raise ValueError(f"{form}: den={den.tolist()} must have only complex pole pairs in the left half-plane, "
                         f"got poles {np.round(poles, 6).tolist()}")
    r, pl, _ = signal.residue(num, den)
    up = pl.imag > 0
    lam, R = pl[up], r[up]
    if lam.size * 2 != den.size - 1 or np.unique(np.round(lam, 9)).size != lam.size:
        raise ValueError(f"{form}: repeated poles {np.round(pl, 6).tolist()}")
    order = np.argsort(np.abs(lam))
    lam, R = lam[order], R[order]
    wn = np.abs(lam)
    A = (2j * lam.imag * R / lam**p).real
    if np.any(A == 0):
        raise ValueError(f"{form}: a mode has a zero modal constant")
    names = [f"mode{k + 1}" for k in range(lam.size)]
    dofs, els = _mode_dofs(wn / (2 * np.pi), -lam.real / wn, names)
    if np.all(A > 0):
        points, shapes = ("p1",), (tuple(np.sqrt(A).tolist()),)
        io = ("p1", "p1")
    else:
        s = np.sqrt(np.abs(A))
        points, shapes = ("in", "out"), (tuple(s.tolist()), tuple((np.sign(A) * s).tolist()))
        io = ("in", "out")
    out = ModalCoordinatesModel(dofs=tuple(dofs), elements=tuple(els),
                                inputs=(replace(model.input, dof=io[0]),),
                                outputs=(replace(model.output, dof=io[1]),), name=model.name, points=points,
                                shapes=shapes)
    f = np.unique(np.concatenate([wn / (2 * np.pi) * k for k in (0.3, 0.9, 1.0, 1.1, 3.0)]))
    H0 = np.polyval(num, 2j * np.pi * f) / np.polyval(den, 2j * np.pi * f)
    H1 = out.frf(f, quantity=None)[:, 0, 0]
    if model.input.delay:
        H1 = H1 * np.exp(2j * np.pi * f * model.input.delay)
    err = float(np.max(np.abs(H1 - H0)) / np.max(np.abs(H0)))
    if not err <= rtol:
        raise ValueError(f"{form} (e.g. no direct term beyond that form, no complex modal constants): "
                         f"the modal realisation differs from num/den by {err:.3g} relative; "
                         f"num={num.tolist()}, den={den.tolist()}")
    return out
