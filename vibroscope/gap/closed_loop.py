"""The gap diagnosis of a model inside its controllers (closed loop).

A model with ``controllers`` (:mod:`vibroscope.models.controller`) is driven by the logged
rows of :func:`~vibroscope.models.closed_loop.loop_inputs` (references, feed-forwards, then
the forces of the inputs no controller drives); its measured channels are the plant's
outputs and then the command of each controller that names an ``output_channel`` (the
logged controller output, e.g. the EMPS ``vir``), compared like any output. An open-loop
model keeps its ``[[input]]`` and ``[[output]]`` channels: every helper here reduces to the
open-loop behaviour for a model without controllers.

The effects of the vocabulary sit in the plant (elements at its connections) or at the
plant ``[[input]]`` a controller drives (offset, saturation, and ``time_delay``: the command
applied ``delay`` s late, interpolated between controller ticks). :data:`CLOSED_LOOP_EXCLUDED`
names effects left out of a closed-loop diagnosis (none at present).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vibroscope.models.lumped import Input, LumpedModel

__all__ = [
    "CLOSED_LOOP_EXCLUDED",
    "actuator_force",
    "basis_model",
    "basis_rows",
    "command_channels",
    "is_closed_loop",
    "log_channels",
    "measured_rows",
]

#: effects left out of a closed-loop diagnosis, with the reason (the report's meta says it)
CLOSED_LOOP_EXCLUDED: dict[str, str] = {}


def is_closed_loop(model) -> bool:
    """True when `model` has controllers.

    Parameters
    ----------
    model : LumpedModel or any model
        Models without a ``controllers`` attribute are open loop.

    Returns
    -------
    bool
    """
    return bool(getattr(model, "controllers", ()))


def command_channels(model: LumpedModel) -> list[str]:
    """The logged command channels of `model`: each controller's ``output_channel`` that is set.

    Parameters
    ----------
    model : LumpedModel

    Returns
    -------
    list of str
        In controller order (empty for an open-loop model).
    """
    return [c.output_channel for c in getattr(model, "controllers", ()) if c.output_channel]


def log_channels(model: LumpedModel) -> tuple[list[str], list[str]]:
    """The log channels the gap diagnosis reads: ``(inputs, outputs)``.

    Parameters
    ----------
    model : LumpedModel

    Returns
    -------
    inputs : list of str
        Open loop: :meth:`LumpedModel.input_channels`; closed loop: the rows of
        :func:`~vibroscope.models.closed_loop.loop_inputs` (references, feed-forwards,
        forces of the undriven inputs).
    outputs : list of str
        :meth:`LumpedModel.output_channels`, then (closed loop) the controllers' named
        ``output_channel`` s.
    """
    if not is_closed_loop(model):
        return list(model.input_channels()), list(model.output_channels())
    from vibroscope.models.closed_loop import loop_inputs

    return [r[0] for r in loop_inputs(model)], list(model.output_channels()) + command_channels(model)


def measured_rows(model: LumpedModel, sim) -> np.ndarray:
    """The rows of a simulation result `sim` (:func:`~vibroscope.models.simulate.simulate`)
    that match :func:`log_channels`' outputs, shape (n_outputs, n_samples).

    Open loop: the rows after the inputs. Closed loop: the plant outputs (after the
    :func:`~vibroscope.models.closed_loop.loop_inputs` rows), then the commands of the
    controllers with an ``output_channel`` (``simulate`` returns every controller's command
    last, in controller order).

    Parameters
    ----------
    model : LumpedModel
        The simulated model.
    sim : Signals
        Its simulation result.

    Returns
    -------
    ndarray, shape (n_outputs, n_samples)
    """
    data = np.asarray(sim.data)
    if not is_closed_loop(model):
        return data[len(model.inputs):]
    from vibroscope.models.closed_loop import loop_inputs

    n_u, n_y = len(loop_inputs(model)), len(model.outputs)
    cmd = [n_u + n_y + i for i, c in enumerate(model.controllers) if c.output_channel]
    return np.vstack([data[n_u:n_u + n_y], data[cmd]]) if cmd else data[n_u:n_u + n_y]


def actuator_force(model: LumpedModel, u: np.ndarray, y: np.ndarray, fs: float) -> np.ndarray:
    """The force (N) at the plant's first actuated input over a log, shape (n_samples,).

    The scales of the input-side effects and of the friction starts are forces: open loop,
    the logged first input; closed loop, a controller's command times its ``gain`` (``gtau
    vir`` on EMPS): the logged command of the first controller that names an
    ``output_channel``, else the first controller's command simulated with `model`.

    Parameters
    ----------
    model : LumpedModel
    u : ndarray, shape (n_inputs, n_samples)
        The log's input rows (:func:`log_channels`).
    y : ndarray, shape (n_outputs, n_samples)
        The log's output rows (:func:`log_channels`).
    fs : float
        Sampling frequency, Hz.

    Returns
    -------
    ndarray, shape (n_samples,)
    """
    if not is_closed_loop(model):
        return np.asarray(u[0], float)
    named = command_channels(model)
    for c in model.controllers:
        if c.output_channel:
            return c.gain * np.asarray(y[len(model.outputs) + named.index(c.output_channel)], float)
    from vibroscope.models.simulate import simulate

    s = simulate(model, u, fs)
    c = model.controllers[0]
    return c.gain * np.asarray(s.data[list(s.channels).index(c.command_channel)], float)


def basis_model(model: LumpedModel, dofs) -> LumpedModel:
    """`model` driven by unit force inputs at `dofs` (channels ``/basis/<dof>``).

    Open loop: the inputs are replaced by them. Closed loop: they are added as inputs no
    controller drives (the loop stays closed: the response is the closed loop's to a force
    at `dofs`, a disturbance the controller fights), fed by :func:`basis_rows`.

    Parameters
    ----------
    model : LumpedModel
    dofs : sequence of str
        DOF (or point) names, one unit force input each.

    Returns
    -------
    LumpedModel
    """
    ins = tuple(Input(dof=d, channel=f"/basis/{d}") for d in dofs)
    if not is_closed_loop(model):
        return replace(model, inputs=ins)
    return replace(model, inputs=tuple(model.inputs) + ins)


def basis_rows(model: LumpedModel, forces: np.ndarray) -> np.ndarray:
    """The simulation rows of a :func:`basis_model` for the basis `forces` (n_basis, n).

    Open loop: `forces`. Closed loop: zero references, feed-forwards and other undriven
    inputs, then `forces` (the basis inputs are the last rows of ``loop_inputs``).

    Parameters
    ----------
    model : LumpedModel
        A :func:`basis_model`.
    forces : array_like, shape (n_basis, n_samples)
        The basis forces, N.

    Returns
    -------
    ndarray, shape (n_rows, n_samples)
    """
    forces = np.atleast_2d(np.asarray(forces, float))
    if not is_closed_loop(model):
        return forces
    from vibroscope.models.closed_loop import loop_inputs

    n_rows = len(loop_inputs(model))
    u = np.zeros((n_rows, forces.shape[1]))
    u[n_rows - forces.shape[0]:] = forces
    return u
