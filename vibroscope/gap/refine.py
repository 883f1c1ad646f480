"""Output-error refinement of a parameterised model on whole logs, with optional offsets.

:func:`refine_model` is the long, accurate counterpart of the gap diagnosis' screening fits
(:func:`vibroscope.gap.fit.fit_time_domain`): all fitting samples, the simulator's full
integration accuracy, a tight finite-difference step and enough function evaluations to
converge, and optionally a constant offset on each input and each output (the DC bias of
the measurement chain), fitted jointly with the model's parameters.

Why the offsets: on the Silverbox benchmark the logged input has a DC bias of about
5.3 mV (the circuit sees ``u - u0``). Through the cubic spring a bias shifts the operating
point, i.e. it acts as an asymmetric (quadratic) stiffness; without it a cubic model is
left at 5.3 mV RMS simulation error on the arrow test part, with it at about 0.4 mV (see
``examples/gap/silverbox_limits.py``).

References
----------
.. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999 (output-error
   fitting, simulation error).
.. [2] T. Wigren, J. Schoukens, "Three free data sets for development and benchmarking in
   nonlinear system identification", European Control Conference, 2013 (Silverbox).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from vibroscope.gap.fit import SCHEME, LogSimulator, oversample_for
from vibroscope.models.lumped import LumpedModel
from vibroscope.models.simulate import reconstruct_input
from vibroscope.models.simulate import simulate as _sim

__all__ = ["RefineResult", "refine_model", "simulate_with_offsets"]


@dataclass(frozen=True, kw_only=True)
class RefineResult:
    """Result of :func:`refine_model`.

    Attributes
    ----------
    x : ndarray
        Fitted model parameters (the vector `build` takes).
    model : LumpedModel
        ``build(x)``.
    input_offset : ndarray, shape (n_inputs,)
        Fitted input bias in the inputs' units (N): the model is driven by ``u - input_offset``
        (zeros when not fitted).
    output_offset : ndarray, shape (n_outputs,)
        Fitted output bias in the outputs' units: the prediction is
        ``simulate(model, u - input_offset) + output_offset`` (zeros when not fitted).
    nrmse : float
        ``||y - y_hat|| / ||y||`` over the fitting samples of all logs.
    nfev : int
        Residual evaluations counted by :func:`scipy.optimize.least_squares` (the
        finite-difference Jacobian's evaluations not included).
    n_sims : int
        Simulations run (Jacobian columns included): about ``(nfev) (1 + n_params)`` per log.
    seconds : float
        Wall time of the fit.
    status : int
        ``least_squares``' status (0: `max_nfev` reached, > 0: converged).
    """

    x: np.ndarray
    model: LumpedModel
    input_offset: np.ndarray
    output_offset: np.ndarray
    nrmse: float
    nfev: int
    n_sims: int
    seconds: float
    status: int


def _r_for(model: LumpedModel, fs: float, fast: bool) -> int:
    # the sub-steps LogSimulator.run uses
    return 8 if all(e.is_linear for e in model.elements) else oversample_for(model, fs, fast)


def simulate_with_offsets(sim: LogSimulator, model: LumpedModel, n: int | None = None, *, input_offset=None,
                          output_offset=None, fast: bool = False, _ones: dict | None = None) -> np.ndarray:
    """Outputs of `model` driven by ``u - input_offset``, plus ``output_offset``.

    The input reconstruction is linear, so the biased input's fine-grid force is the cached
    reconstruction of ``u`` minus ``input_offset`` times the reconstruction of a constant
    (exactly what reconstructing ``u - input_offset`` gives, edges included). The model
    starts from rest: the bias is a step at the first sample, whose transient the fitting
    masks should leave out.

    Parameters
    ----------
    sim : LogSimulator
        The log's input.
    model : LumpedModel
    n : int, optional
        Leading samples to simulate; default all.
    input_offset : array_like, shape (n_inputs,), optional
        Input bias (N); default none.
    output_offset : array_like, shape (n_outputs,), optional
        Output bias; default none.
    fast : bool, optional
        Screening oversampling as in :meth:`LogSimulator.run`; default False.

    Returns
    -------
    ndarray, shape (n_outputs, n)
        All NaN when the simulation fails or is not finite.
    """
    n = sim.u.shape[1] if n is None else int(n)
    u0 = None if input_offset is None else np.asarray(input_offset, float).reshape(-1, 1)
    if u0 is None or not np.any(u0):
        y = sim.run(model, n, fast=fast)
    else:
        R = _r_for(model, sim.fs, fast)
        u_ = sim.input(n)
        key = (R, u_.shape[1])
        ones = _ones if _ones is not None else {}
        if key not in ones:
            ones[key] = reconstruct_input(np.ones((1, u_.shape[1])), sim.fs, R)
        U = sim.fine_input(R, n) - u0 * ones[key]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = _sim(model, u_ - u0, sim.fs, fine_input=U, scheme=SCHEME,
                         output_sampling=sim.output_sampling)
            y = sim.trim(s.data[len(model.inputs):])
        except (ValueError, FloatingPointError, ZeroDivisionError, OverflowError):
            y = np.full((len(model.outputs), n), np.nan)
        if not np.all(np.isfinite(y)):
            y = np.full_like(y, np.nan)
    if output_offset is not None:
        y = y + np.asarray(output_offset, float).reshape(-1, 1)
    return y


def refine_model(build, x0, lower, upper, sims, ys, masks, ns=None, *, input_offset: bool = False,
                 output_offset: bool = False, max_nfev: int = 200, x_scale=1.0, diff_step: float = 1e-6,
                 fast: bool = False, ftol: float = 1e-10, xtol: float = 1e-10) -> RefineResult:
    """Output-error fit of ``build(x) -> LumpedModel`` (and offsets) to whole logs.

    Minimises ``sum ||(y - y_hat)[mask]||^2 / sum ||y[mask]||^2`` over the fitting samples of
    all logs with :func:`scipy.optimize.least_squares` (trust region reflective,
    finite-difference Jacobian), simulating every log in full at the simulator's default
    integration accuracy. Unlike the screening fit
    :func:`~vibroscope.gap.fit.fit_time_domain` (coarse integration, a few evaluations,
    ``diff_step=1e-3``) it is meant to converge: on the Silverbox estimation part (86 750
    samples) the cubic model (mass, damping, linear and cubic stiffness, input offset),
    started from the diagnosis' cubic model, converges (``status`` 1) after 6 evaluations
    (36 simulations).

    Parameters
    ----------
    build : callable
        Parameter vector (shape like `x0`) -> :class:`LumpedModel`.
    x0, lower, upper : array_like
        Start and bounds of the model parameters. Choose the parameterisation so that the
        parameters are of order 1 (log-factors, or values divided by their start), or pass
        `x_scale`.
    sims : list of LogSimulator
        The logs' inputs.
    ys : list of ndarray, shape (n_outputs, n_samples)
        Measured outputs per log.
    masks : list of ndarray of bool
        Fitting samples per log (leave out the start transient; with `input_offset` the
        bias is a step at the first sample).
    ns : list of int, optional
        Samples to simulate per log (0 skips the log); default all.
    input_offset : bool, optional
        Also fit a constant bias per input, the model being driven by ``u - u0``; default
        False. Fitted as a fraction of each input's RMS, within +- 1 RMS.
    output_offset : bool, optional
        Also fit a constant bias per output added to the prediction; default False. Fitted
        as a fraction of each output's RMS, within +- 1 RMS.
    max_nfev : int, optional
        Residual evaluations allowed to ``least_squares`` (the finite-difference Jacobian's
        are not counted: each iteration costs about ``1 + n_params`` simulations of every
        log); default 200.
    x_scale : float, array_like or "jac", optional
        ``least_squares``' ``x_scale`` of the model parameters (the offsets' entries are 1);
        default 1.0.
    diff_step : float, optional
        Relative finite-difference step (``least_squares``' ``diff_step``); default 1e-6.
    fast : bool, optional
        Screening integration accuracy (:meth:`LogSimulator.run`); default False.
    ftol, xtol : float, optional
        ``least_squares``' tolerances; default 1e-10.

    Returns
    -------
    RefineResult

    Examples
    --------
    Mass, damping, stiffness and cubic stiffness as multiples of their start values, with an
    input bias (``model0`` holding a ``CubicSpring``, ``u``, ``y`` a log's rows)::

        sims = [LogSimulator(u, fs)]
        mask = np.ones(u.shape[1], bool); mask[:200] = False
        r = refine_model(lambda x: scaled(model0, x), np.ones(4), np.full(4, 0.1), np.full(4, 10.0),
                         sims, [y], [mask], input_offset=True)
        r.model, r.input_offset
    """
    x0 = np.asarray(x0, float).ravel()
    lower = np.broadcast_to(np.asarray(lower, float), x0.shape)
    upper = np.broadcast_to(np.asarray(upper, float), x0.shape)
    ns = [s.u.shape[1] for s in sims] if ns is None else list(ns)
    n_in = sims[0].u.shape[0]
    n_out = ys[0].shape[0]
    live = [i for i, n in enumerate(ns) if n]
    su = np.sqrt(np.mean(np.concatenate([sims[i].u[:, :ns[i]] for i in live], axis=1) ** 2, axis=1))
    sy = np.sqrt(np.mean(np.concatenate([ys[i][:, :ns[i]] for i in live], axis=1) ** 2, axis=1))
    su = np.where(su > 0, su, 1.0)
    sy = np.where(sy > 0, sy, 1.0)
    nx = x0.size
    n_u = n_in if input_offset else 0
    n_y = n_out if output_offset else 0
    den = math.sqrt(sum(float(np.sum(ys[i][:, :ns[i]][:, masks[i][:ns[i]]] ** 2)) for i in live))
    count = [0]
    ones: dict = {}

    def split(z):
        x = z[:nx]
        u0 = z[nx:nx + n_u] * su if n_u else None
        y0 = z[nx + n_u:] * sy if n_y else None
        return x, u0, y0

    def res(z):
        x, u0, y0 = split(z)
        try:
            m = build(x)
        except (ValueError, np.linalg.LinAlgError):
            m = None
        out = []
        for i in live:
            n, mk = ns[i], masks[i][:ns[i]]
            if m is None:
                r = np.full(int(mk.sum()) * n_out, 10.0 / math.sqrt(max(mk.sum() * n_out, 1)))
            else:
                yh = simulate_with_offsets(sims[i], m, n, input_offset=u0, output_offset=y0, fast=fast, _ones=ones)
                count[0] += 1
                r = ((ys[i][:, :n] - yh)[:, mk] / den).ravel()
                if not np.all(np.isfinite(r)):
                    r = np.full_like(r, 10.0 / math.sqrt(r.size))
            out.append(r)
        return np.concatenate(out)

    z0 = np.concatenate([np.clip(x0, lower + 1e-12 * np.maximum(1, abs(lower)), upper - 1e-12 * np.maximum(1, abs(upper))),
                         np.zeros(n_u + n_y)])
    lo = np.concatenate([lower, np.full(n_u + n_y, -1.0)])
    hi = np.concatenate([upper, np.full(n_u + n_y, 1.0)])
    xs = x_scale if isinstance(x_scale, str) else np.concatenate(
        [np.broadcast_to(np.asarray(x_scale, float), x0.shape), np.ones(n_u + n_y)])
    t = time.perf_counter()
    sol = least_squares(res, z0, bounds=(lo, hi), method="trf", x_scale=xs, diff_step=diff_step,
                        max_nfev=max_nfev, ftol=ftol, xtol=xtol)
    secs = time.perf_counter() - t
    x, u0, y0 = split(sol.x)
    return RefineResult(
        x=x,
        model=build(x),
        input_offset=np.zeros(n_in) if u0 is None else u0,
        output_offset=np.zeros(n_out) if y0 is None else y0,
        nrmse=float(math.sqrt(2 * sol.cost)),
        nfev=int(sol.nfev),
        n_sims=count[0],
        seconds=secs,
        status=int(sol.status),
    )
