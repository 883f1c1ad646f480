"""Simulation of a log in-process, and the fits of the gap diagnosis.

* :class:`LogSimulator` drives model variants with one log's input: the input is
  reconstructed band-limited once per oversampling factor and reused.
* :func:`fit_linear_frf`: the linear parameters (and a linear effect: delay, extra mode)
  fitted to the measured H1 FRF (the best linear approximation, BLA) of the fitting data by
  :func:`scipy.optimize.least_squares` on the relative complex error.
* :func:`fit_time_domain`: effect (and linear) parameters fitted to the fitting samples'
  time response by :func:`scipy.optimize.least_squares` (trust region reflective,
  finite-difference Jacobian).

References
----------
.. [1] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*,
   2nd ed., 2012 (BLA, frequency-domain fitting).
.. [2] L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999 (output-error
   fitting, simulation error).
"""

from __future__ import annotations

import math
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.optimize import least_squares

from vibroscope.gap.closed_loop import is_closed_loop, log_channels, measured_rows
from vibroscope.models.lumped import LumpedModel
from vibroscope.models.simulate import reconstruct_input
from vibroscope.models.simulate import simulate as _sim

__all__ = ["LogSimulator", "best_start", "fit_linear_frf", "fit_time_domain", "frf_residual"]


#: the nonlinear simulations of the diagnosis discretise the linear part exactly
#: (:func:`vibroscope.models.integrate.flatten_model`): no frequency warping, so fewer sub-steps
#: than the trapezoidal rule reach the same accuracy (a 2-DOF cubic spring, modes to 80 Hz at
#: 1 kHz: 8e-4 nrmse at 5 sub-steps against 5e-3 for the trapezoidal rule at 8)
SCHEME = "exponential"


def oversample_for(model: LumpedModel, fs: float, fast: bool) -> int:
    """Sub-steps of the exponential scheme: ``max(10, 20 f_max / fs)``, or a coarser
    ``max(5, 8 f_max / fs)`` for screening."""
    try:
        fmax = float(np.max(model.modes().natural_frequencies))
    except Exception:  # noqa: BLE001 - no modes (free body)
        fmax = 0.0
    if not fast:
        return max(10, int(math.ceil(20.0 * fmax / fs)))
    return max(5, int(math.ceil(8.0 * fmax / fs)))


class LogSimulator:
    """Simulate model variants under one log's input.

    Parameters
    ----------
    u : ndarray, shape (n_inputs, n_samples)
        Logged input (N); for a model with controllers, the rows of
        :func:`~vibroscope.models.closed_loop.loop_inputs` (references first).
    fs : float
        Hz.
    output_sampling : {'filtered', 'sharp', 'point'}, optional
        How nonlinear simulations are brought back to `fs`
        (:func:`~vibroscope.models.simulate.simulate`); the diagnosis chooses it from the data
        (:func:`~vibroscope.gap._candidates.choose_output_sampling`). Default 'filtered'.
    period : int, optional
        Samples of one period of a periodic input whose log is in periodic steady state from
        its first sample (:func:`~vibroscope.gap.levels.steady_state_start`); with
        `lead_periods` the simulations start that many periods before the log.
    lead_periods : int, optional
        Whole periods of the input (its periodic continuation, ``u[:, :period]`` repeated)
        simulated before the log and dropped from every output, so that a model's transient
        from rest has decayed where the log begins, as the logged system's had; default 0.
    """

    def __init__(self, u: np.ndarray, fs: float, output_sampling: str = "filtered", *,
                 period: int | None = None, lead_periods: int = 0):
        self.u = np.ascontiguousarray(u, float)
        self.fs = float(fs)
        self.output_sampling = output_sampling
        self.lead = int(period) * int(lead_periods) if period and lead_periods > 0 else 0
        self._u_sim = (np.ascontiguousarray(np.concatenate([np.tile(self.u[:, :int(period)], int(lead_periods)), self.u],
                                                           axis=1)) if self.lead else self.u)
        self._fine: dict[tuple[int, int], np.ndarray] = {}

    def input(self, n: int) -> np.ndarray:
        """The input the simulations of the first `n` samples of the log take.

        Parameters
        ----------
        n : int
            Samples of the log.

        Returns
        -------
        ndarray, shape (n_inputs, lead + n)
            The lead-in periods (``lead`` samples), then ``u[:, :n]`` (N).
        """
        return self._u_sim[:, :self.lead + int(n)]

    def trim(self, y: np.ndarray) -> np.ndarray:
        """Outputs simulated on :meth:`input` without the lead-in.

        Parameters
        ----------
        y : array_like, shape (n_outputs, lead + n)
            Simulated outputs.

        Returns
        -------
        ndarray, shape (n_outputs, n)
            `y` from the log's first sample on.
        """
        return np.asarray(y)[:, self.lead:] if self.lead else np.asarray(y)

    def fine_input(self, R: int, n: int) -> np.ndarray:
        """:meth:`input` of the first `n` samples reconstructed at `R` times the rate (cached).

        Parameters
        ----------
        R : int
            Oversampling factor of the integrator.
        n : int
            Samples of the log's input.

        Returns
        -------
        ndarray, shape (n_inputs, R * (lead + n))
            :func:`~vibroscope.models.simulate.reconstruct_input` of ``input(n)`` (N).
        """
        key = (int(R), int(n))
        if key not in self._fine:
            self._fine[key] = reconstruct_input(self.input(n), self.fs, R)
        return self._fine[key]

    def run(self, model: LumpedModel, n: int | None = None, *, fast: bool = False,
            oversample: int | None = None) -> np.ndarray:
        """Outputs of `model` (n_outputs, n) for the first `n` samples of the input.

        Non-finite results (an unstable candidate) are returned as NaN rows.

        Parameters
        ----------
        model : LumpedModel
            The model variant; its inputs take the rows of the logged input.
        n : int, optional
            Number of leading samples to simulate; default all.
        fast : bool, optional
            For nonlinear models, integrate with the coarser screening sub-steps
            ``max(5, ceil(8 f_max / fs))`` instead of ``max(10, ceil(20 f_max / fs))``
            (both with the exponential scheme, :data:`SCHEME`); default False. Linear models
            always take the exact linear path at 8 sub-steps.
        oversample : int, optional
            For nonlinear open-loop models, this many sub-steps instead of the default (the
            predictability check integrates at twice the default,
            :func:`~vibroscope.gap._selection.self_disagreement`); default None.

        Returns
        -------
        ndarray, shape (n_outputs, n)
            Simulated outputs in their units; all NaN when the simulation fails or is not
            finite. For a model with controllers: the plant outputs, then the commands of
            the controllers with an ``output_channel``
            (:func:`~vibroscope.gap.closed_loop.measured_rows`), simulated in closed loop
            at the controllers' rate (`fast` is not used).
        """
        n = self.u.shape[1] if n is None else int(n)
        u = self.input(n)
        if is_closed_loop(model):
            # the loop runs at the controllers' ticks (ZOH): no band-limited reconstruction
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    y = self.trim(measured_rows(model, _sim(model, u, self.fs)))
            except (ValueError, FloatingPointError, ZeroDivisionError, OverflowError):
                y = np.full((len(log_channels(model)[1]), n), np.nan)
            return y if np.all(np.isfinite(y)) else np.full_like(y, np.nan)
        linear = all(e.is_linear for e in model.elements)
        kw = {}
        # linear models: the exact FOH path at 8 sub-steps; nonlinear: the compiled kernel
        R = 8 if linear else (int(oversample) if oversample else oversample_for(model, self.fs, fast))
        kw["fine_input"] = self.fine_input(R, n)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = _sim(model, u, self.fs, scheme=SCHEME, output_sampling=self.output_sampling, **kw)
            y = self.trim(s.data[len(model.inputs):])
        except (ValueError, FloatingPointError, ZeroDivisionError, OverflowError):
            y = np.full((len(model.outputs), n), np.nan)
        if not np.all(np.isfinite(y)):
            y = np.full_like(y, np.nan)
        return y


def frf_residual(model: LumpedModel, frequencies: np.ndarray, H: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted relative complex FRF error ``w (H_model - H) / |H|``, stacked [re, im].

    Parameters
    ----------
    model : LumpedModel
        The model; its FRF to the first input is taken in each output's own quantity.
    frequencies : ndarray, shape (n_f,)
        Frequencies in Hz.
    H : ndarray of complex, shape (n_f, n_outputs)
        Measured FRF to the first input.
    w : ndarray, shape (n_f, n_outputs)
        Weights.

    Returns
    -------
    ndarray, shape (2 n_f n_outputs,)
        Real parts, then imaginary parts, each raveled.
    """
    f = frequencies
    Hm = model.frf(f, quantity=None)[:, :, 0]
    r = w * (Hm - H) / np.maximum(np.abs(H), 1e-300)
    return np.concatenate([r.real.ravel(), r.imag.ravel()])


def _frf_parts(model: LumpedModel):
    """What :meth:`LumpedModel.frf` to the first input is made of: ``(M, K, C, b, rows, tau)``,
    ``b`` the first input's force distribution (n_dofs,), ``rows`` the outputs' point vectors
    (n_outputs, n_dofs) and ``tau`` the first input's delay (s)."""
    return (np.asarray(model.M), np.asarray(model.K), np.asarray(model.C), model.point_vector(model.inputs[0].dof),
            model.output_rows(), float(model.inputs[0].delay))


def frf_residual_jacobian(build, x, frequencies, H, w, upper=None, rel_step: float = 1e-7):
    """Jacobian of :func:`frf_residual` of ``build(x)`` with respect to `x`, shape (2 w.size, x.size).

    The model's matrices are differenced along each parameter (one model build and assembly per
    parameter, no solve); the FRF's derivative then follows from two factorisations per
    frequency: with ``Z = K - w^2 M + j w C``, ``G = Z^-1 b`` and ``L = R Z^-1`` (``R`` the
    output rows),

    ``dH = s e (dR G + L db - L dZ G) + s (R G) de``, ``e = exp(-j w tau)``, ``de = -j w dtau e``,

    ``s`` the output quantity's factor (``-w^2``, ``j w`` or 1). Exact up to the matrices'
    difference quotient (they are linear in the element values, which are smooth in `x`),
    where a finite-difference Jacobian of the residual solves the whole model once per
    parameter (Pintelon & Schoukens [1]_, sec. 9.7: the analytic Jacobian of a
    frequency-domain fit).

    Parameters
    ----------
    build : callable
        Parameter vector -> LumpedModel (the same number of DOFs for every `x`).
    x : ndarray, shape (n_x,)
    frequencies : ndarray, shape (n_f,)
        Hz.
    H : ndarray of complex, shape (n_f, n_outputs)
        Measured FRF to the first input.
    w : ndarray, shape (n_f, n_outputs)
        Weights.
    upper : ndarray, shape (n_x,), optional
        Upper bounds: a (forward) step that would leave them is taken backwards.
    rel_step : float, optional
        Relative step of the matrices' difference quotient, times ``max(1, |x_i|)``.

    Returns
    -------
    ndarray, shape (2 n_f n_outputs, n_x)
        Rows as :func:`frf_residual` stacks them (real parts, then imaginary parts).

    Raises
    ------
    ValueError
        If a parameter changes the model's number of DOFs or outputs.
    """
    x = np.asarray(x, float)
    f = np.asarray(frequencies, float)
    om = 2 * np.pi * f
    m0 = build(x)
    M, K, C, b, R, tau = _frf_parts(m0)
    Z = m0.dynamic_stiffness(f)
    G = np.linalg.solve(Z, np.broadcast_to(b[:, None], (len(f),) + b[:, None].shape))[..., 0]  # (n_f, n_d)
    Lt = np.linalg.solve(np.swapaxes(Z, 1, 2), np.broadcast_to(R.T, (len(f),) + R.T.shape))  # (n_f, n_d, n_o)
    L = np.swapaxes(Lt, 1, 2)  # (n_f, n_o, n_d)
    S = m0.output_factors(f)
    e = np.exp(-1j * om * tau)
    RG = np.einsum("od,fd->fo", R, G)
    scale = w / np.maximum(np.abs(H), 1e-300)
    J = np.empty((2 * w.size, x.size))
    for i in range(x.size):
        h = rel_step * max(1.0, abs(x[i]))
        if upper is not None and x[i] + h > upper[i]:
            h = -h
        xi = x.copy()
        xi[i] += h
        M2, K2, C2, b2, R2, tau2 = _frf_parts(build(xi))
        if M2.shape != M.shape or R2.shape != R.shape:
            raise ValueError(f"parameter {i} changes the model's size ({M.shape} -> {M2.shape})")
        dZ = ((K2 - K)[None] - (om**2)[:, None, None] * (M2 - M)[None]
              + 1j * om[:, None, None] * (C2 - C)[None]) / h
        dG = -np.einsum("fde,fe->fd", dZ, G)
        if np.any(b2 != b):
            dG = dG + (b2 - b)[None, :] / h
        dH = np.einsum("fod,fd->fo", L, dG)
        if np.any(R2 != R):
            dH = dH + np.einsum("od,fd->fo", (R2 - R) / h, G)
        dH = S * e[:, None] * dH
        if tau2 != tau:
            dH = dH + S * RG * (-1j * om * (tau2 - tau) / h * e)[:, None]
        d = scale * dH
        J[:, i] = np.concatenate([d.real.ravel(), d.imag.ravel()])
    return J


def fit_linear_frf(model: LumpedModel, lin, frequencies, H, w, *, spec=None, p_starts=None, prior: float = 0.02,
                   max_nfev: int = 200, jacobian: str = "analytic"):
    """Fit linear log-factors `lin` (and a linear effect `spec`'s parameters) to the FRF.

    Parameters
    ----------
    model : LumpedModel
        Start model (nominal).
    lin : LinearParams
    frequencies : ndarray, shape (n_f,)
        Hz.
    H : ndarray of complex, shape (n_f, n_outputs)
        Measured H1 to the (first) input.
    w : ndarray, shape (n_f, n_outputs)
        Weights (coherence-based).
    spec : EffectSpec, optional
        A linear effect to fit jointly.
    p_starts : list of array_like, optional
        Start vectors for `spec`'s parameters, one fit per start, the best kept; default
        ``spec.starts[0]`` only (none without `spec`). A one-parameter `spec` with a
        :attr:`~vibroscope.gap.effects.EffectSpec.profile` adds the best value of its grid, the
        linear parameters at the base.
    prior : float
        Weight of a small pull of the log-factors towards 0 (keeps unidentifiable
        parameters at their nominal values).
    max_nfev : int, optional
        Function evaluations per start (:func:`scipy.optimize.least_squares`); default 200.
    jacobian : {"analytic", "2-point"}, optional
        ``"analytic"`` (default): :func:`frf_residual_jacobian`; ``"2-point"``: scipy's forward
        differences of the whole residual (the baseline of ``benchmarks/gap/frf_fit.py``).

    Returns
    -------
    (model, theta, p, cost)
    """
    f = frequencies
    nl = len(lin)
    scale = math.sqrt(max(w.size, 1))

    def build(x):
        m = lin.apply(model, x[:nl])
        return spec.apply(m, x[nl:]) if spec is not None else m

    def res(x):
        try:
            r = frf_residual(build(x), f, H, w)
        except (ValueError, np.linalg.LinAlgError):
            return np.full(2 * w.size + nl, 1e3)
        return np.concatenate([r, prior * scale * x[:nl]])

    n_x = nl + (spec.n if spec is not None else 0)
    prior_rows = np.zeros((nl, n_x))  # the pull towards 0: constant rows of the Jacobian
    prior_rows[:, :nl] = prior * scale * np.eye(nl)

    def jac(x):
        # analytic through the model's matrices (one build per parameter, two solves), not one
        # whole-model FRF per parameter
        try:
            J = frf_residual_jacobian(build, x, f, H, w, upper=hi)
        except (ValueError, np.linalg.LinAlgError):
            J = np.zeros((2 * w.size, x.size))
        return np.vstack([J, prior_rows])

    if jacobian not in ("analytic", "2-point"):
        raise ValueError(f"jacobian={jacobian!r} must be 'analytic' or '2-point'")
    starts = p_starts if p_starts is not None else ([spec.starts[0]] if spec is not None else [np.zeros(0)])
    if spec is not None and spec.n == 1 and spec.profile is not None:
        # the FRF cost profiled over the effect's parameter with the linear ones at the base: its
        # best value is a further start (a delay's cost has a valley every period of the top line)
        grid = np.clip(np.asarray(spec.profile(f), float), spec.lower[0], spec.upper[0])
        if grid.size:
            costs = [float(np.sum(res(np.concatenate([np.zeros(nl), [g]]))[:2 * w.size] ** 2)) for g in grid]
            starts = list(starts) + [np.array([grid[int(np.argmin(costs))]])]
    best = None
    for p0 in starts:
        x0 = np.concatenate([np.zeros(nl), np.asarray(p0, float)])
        lo = np.concatenate([np.full(nl, -2.5), spec.lower if spec is not None else []])
        hi = np.concatenate([np.full(nl, 2.5), spec.upper if spec is not None else []])
        x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
        sol = least_squares(res, x0, jac=jac if jacobian == "analytic" else "2-point", bounds=(lo, hi),
                            method="trf", x_scale="jac", max_nfev=max_nfev)
        if best is None or sol.cost < best.cost:
            best = sol
    x = best.x
    return build(x), x[:nl], x[nl:], float(best.cost)


def fit_time_domain(build, x0, lower, upper, sims, ys, masks, ns, *, fast=True, max_nfev=30, diff_step=1e-3,
                    jac_workers=2, callback=None):
    """Least-squares fit of parameters `x` of ``build(x) -> LumpedModel`` to the outputs.

    Parameters
    ----------
    build : callable
        Parameter vector -> model.
    x0, lower, upper : ndarray
    sims : list of LogSimulator
    ys : list of ndarray, shape (n_outputs, n_samples)
        Measured outputs per log.
    masks : list of ndarray of bool
        Fitting samples per log.
    ns : list of int
        Samples to simulate per log (0 skips the log).
    fast : bool, optional
        Simulate with the coarser screening oversampling (:meth:`LogSimulator.run`);
        default True.
    max_nfev : int, optional
        Function evaluations allowed to :func:`scipy.optimize.least_squares`; default 30.
    diff_step : float, optional
        Relative finite-difference step of the Jacobian (``least_squares``'s
        ``diff_step``); default 1e-3.
    jac_workers : int, optional
        Threads evaluating the finite-difference Jacobian's columns (``least_squares``'s
        ``workers``, scipy >= 1.16); default 2. The simulation kernels release the GIL, so
        the columns run on several cores; the result does not depend on it.
    callback : callable, optional
        ``least_squares``'s ``callback(intermediate_result)`` (scipy >= 1.16), called after each
        iteration; raising :class:`StopIteration` ends the fit at the current point.

    Returns
    -------
    (x, nrmse on the fitting samples, number of simulations)
    """
    # each channel normalised by its own energy (the metric of vibroscope.gap.measure.nrmse)
    den_c = sum(np.sum(y[:, :n][:, m[:n]] ** 2, axis=1) for y, m, n in zip(ys, masks, ns) if n)
    den = np.sqrt(np.maximum(np.asarray(den_c, float), 1e-300) * len(np.atleast_1d(den_c)))[:, None]
    calls: list = []  # one entry per simulation (list.append is atomic across threads)

    def res(x):
        m = build(x)
        out = []
        for sim, y, mk, n in zip(sims, ys, masks, ns):
            if not n:
                continue
            yh = sim.run(m, n, fast=fast)
            calls.append(1)
            r = (y[:, :n] - yh)[:, mk[:n]] / den
            if not np.all(np.isfinite(r)):
                r = np.full_like(r, 10.0 / math.sqrt(r.size))
            out.append(r.ravel())
        return np.concatenate(out)

    x0 = np.clip(np.asarray(x0, float), lower + 1e-9, upper - 1e-9)
    n_thr = max(1, min(jac_workers, x0.size))
    # the Jacobian's columns in parallel threads (the simulation kernels release the GIL)
    with ThreadPoolExecutor(n_thr) as ex:
        sol = least_squares(res, x0, bounds=(lower, upper), method="trf", x_scale=1.0, diff_step=diff_step,
                            max_nfev=max_nfev, workers=ex.map if n_thr > 1 else None, callback=callback)
    return sol.x, float(math.sqrt(2 * sol.cost)), len(calls)


def best_start(build, starts, sims, ys, masks, ns):
    """The start vector of `starts` whose model ``build(p)`` fits the outputs best.

    Used where no FRF fit gives a start (a model inside its controllers: the measured FRF
    is the loop's, not the open plant's).

    Parameters
    ----------
    build : callable
        Parameter vector -> model.
    starts : list of array_like
        Candidate start vectors.
    sims : list of LogSimulator
    ys : list of ndarray, shape (n_outputs, n_samples)
        Measured outputs per log.
    masks : list of ndarray of bool
        Samples that count, per log.
    ns : list of int
        Samples to simulate per log (0 skips the log).

    Returns
    -------
    (p, nrmse)
        The best start (``starts[0]`` when none simulates) and its nrmse (inf then).
    """
    from vibroscope.gap.measure import nrmse

    best = (np.asarray(starts[0], float), float("inf"))
    for p0 in starts:
        try:
            m = build(np.asarray(p0, float))
        except (ValueError, TypeError):
            continue
        yh = [sim.run(m, n, fast=True) if n else None for sim, n in zip(sims, ns)]
        g = nrmse([y[:, :n] for y, n in zip(ys, ns) if n], [h for h in yh if h is not None],
                  [mk[:n] for mk, n in zip(masks, ns) if n])
        if np.isfinite(g) and g < best[1]:
            best = (np.asarray(p0, float), float(g))
    return best
