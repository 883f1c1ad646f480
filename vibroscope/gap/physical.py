"""The nominal model of the gap diagnosis in physical form: a :class:`LumpedModel` whose
connections, inputs and outputs are points where effects can act.

* a :class:`~vibroscope.models.LumpedModel` is used as it is;
* a second-order transfer function ``b / (a2 s^2 + a1 s + a0)`` (times ``s^p`` for a
  velocity or acceleration output) becomes one mass ``a2 / b``, damper ``a1 / b`` and spring
  ``a0 / b`` (DOF ``m1``);
* a transfer function of higher order ``s^p sum_r A_r / (s^2 + 2 zeta_r w_r s + w_r^2)``
  and a ``kind = "modal"`` pole-residue model with a driving point become a
  :class:`~vibroscope.models.modal_coordinates.ModalCoordinatesModel`: one DOF per mode
  (``mode1`` ...) and the measured points on mass-normalised mode shapes, so that an element
  between two points (or a point and ground) acts through the shapes.

What a modal model must contain: one ``[[input]]`` and one ``[[output]]`` with the same
``dof`` label (the driving point; ``vibroscope modal --export-model`` writes the labels when
it finds the driving point), every input at a labelled output's point, and driving-point
modal constants ``2 j omega_d R_r / lambda_r^p > 0`` (real part).

References
----------
.. [1] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research
   Studies Press, 2000, sec. 2.3 and 6.2.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vibroscope.models.elements import Damper, Spring
from vibroscope.models.lumped import Dof, LumpedModel
from vibroscope.models.modal_coordinates import from_pole_residue, from_transfer_function
from vibroscope.models.modal_model import PoleResidueModel

__all__ = ["as_lumped"]


def as_lumped(model, *, source: str = "") -> LumpedModel:
    """`model` as a :class:`LumpedModel` the diagnosis can augment with effects.

    Parameters
    ----------
    model : LumpedModel, TransferFunctionModel or PoleResidueModel
        The nominal model (see the module docstring for the forms accepted).
    source : str, optional
        The model's file, named in error messages.

    Returns
    -------
    LumpedModel
        `model` itself; one DOF ``m1`` for a second-order transfer function; a
        :class:`~vibroscope.models.modal_coordinates.ModalCoordinatesModel` for a higher
        order transfer function or a modal model.

    Raises
    ------
    ValueError
        For a transfer function not of the modal form, a modal model with no driving point
        (the message says what to add), or another model type.
    """
    if isinstance(model, LumpedModel):
        return model
    if isinstance(model, PoleResidueModel):
        return from_pole_residue(model, source=source)
    if not hasattr(model, "num") or not hasattr(model, "den"):
        raise ValueError(f"the gap diagnosis needs a lumped, transfer-function or modal model, got {type(model).__name__}")
    num = np.trim_zeros(np.asarray(model.num, float), "f")
    den = np.trim_zeros(np.asarray(model.den, float), "f")
    q = model.output.quantity
    lead = {"displacement": 0, "velocity": 1, "acceleration": 2}[q]
    if den.size == 3 and num.size == 1 + lead and not np.any(num[1:] != 0) and num[0] != 0:
        b = num[0]
        m, c, k = den / b
        if m > 0:
            return LumpedModel(
                dofs=(Dof("m1", m),),
                elements=(Spring(("m1", "ground"), k=k), Damper(("m1", "ground"), c=c)),
                inputs=(replace(model.input, dof="m1"),),
                outputs=(replace(model.output, dof="m1"),),
                name=model.name,
            )
    return from_transfer_function(model)
