"""Time simulation of a lumped model inside its discrete controllers (closed loop).

:func:`simulate_closed_loop` is what :func:`vibroscope.models.simulate.simulate` runs for a
model with ``controllers``. The controllers (:mod:`vibroscope.models.controller`) run on
the ticks of the fastest one's ``rate_hz`` (an integer multiple ``m >= 1`` of the log's
`fs`); a slower controller (its rate the fastest divided by a whole number) updates on every
so many ticks. Between its updates a command is held (ZOH), and so are the logged rows (references,
feed-forwards, open-loop forces: each log sample is held for ``m`` ticks). The plant is
stepped between ticks by

* a linear model (``method="auto"`` or ``"linear"``): the exact ZOH discretisation
  ``Phi = exp(A T)``, ``Gamma = int_0^T exp(A s) ds B`` [1]_ (no error but the ZOH itself);
* otherwise (``"nonlinear"``, or nonlinear elements): ``oversample`` sub-steps of the
  compiled trapezoidal rule of :mod:`vibroscope.models.integrate` (friction, backlash,
  hysteresis... act inside the loop).

All of it runs in one compiled kernel (:func:`vibroscope.models.integrate.closed_loop_kernel`).

References
----------
.. [1] K. J. Åström, B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., Prentice Hall,
   1997, sec. 2.3 (sampling a continuous system with a zero-order hold).
.. [2] N. M. Newmark, "A method of computation for structural dynamics", J. Eng. Mech.
   Div. ASCE 85(EM3):67-94, 1959.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from typing import Literal

import numpy as np
from scipy.linalg import expm

from vibroscope.models.controller import GAIN_ORDER, LAWS
from vibroscope.models.integrate import closed_loop_kernel, flatten_model
from vibroscope.models.lumped import UNITS, LumpedModel, Output
from vibroscope.signals import Signals

__all__ = ["loop_inputs", "simulate_closed_loop", "zoh_matrices"]


def loop_inputs(model: LumpedModel) -> list[tuple[str, str, str]]:
    """The rows ``u`` of a closed-loop simulation, in order.

    Parameters
    ----------
    model : LumpedModel
        A model with controllers.

    Returns
    -------
    list of (channel, kind, unit)
        First each controller's ``reference`` (kind ``"reference"``, m), then each
        ``feedforward`` (kind ``"feedforward"``, the command's unit), in controller order;
        then the inputs no controller drives (kind ``"input"``, N), in input order.
    """
    rows = [(c.reference, "reference", "m") for c in model.controllers if c.reference is not None]
    rows += [(c.feedforward, "feedforward", c.output_unit) for c in model.controllers if c.feedforward is not None]
    driven = {model.driven_input(c) for c in model.controllers}
    chans = model.input_channels()
    rows += [(chans[j], "input", "N") for j in range(len(model.inputs)) if j not in driven]
    return rows


def zoh_matrices(A: np.ndarray, B: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of ``qdot = A q + B u`` over a period `T`.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix (1/s).
    B : ndarray, shape (n, n_in)
        Input matrix.
    T : float
        Period in s, > 0.

    Returns
    -------
    Phi : ndarray, shape (n, n)
        ``exp(A T)``.
    Gamma : ndarray, shape (n, n_in)
        ``int_0^T exp(A s) ds B``, from one exponential of the block matrix
        ``[[A, B], [0, 0]] T`` (Van Loan 1978).

    Raises
    ------
    ValueError
        If `T` is not positive.

    References
    ----------
    .. [1] C. F. Van Loan, "Computing integrals involving the matrix exponential", IEEE
       Trans. Autom. Control 23(3):395-404, 1978.
    """
    if not np.isfinite(T) or T <= 0:
        raise ValueError(f"{T=} must be positive")
    n, k = A.shape[0], B.shape[1]
    Mx = np.zeros((n + k, n + k))
    Mx[:n, :n] = A * T
    Mx[:n, n:] = B * T
    E = expm(Mx)
    return E[:n, :n], E[:n, n:]


def _rate(model: LumpedModel, fs: float) -> tuple[float, int, np.ndarray]:
    """The tick rate (the fastest controller's), ticks per sample of `fs`, and each
    controller's ticks per update."""
    rates = [float(c.rate_hz) for c in model.controllers]
    rate = max(rates)
    every = []
    for c, r in zip(model.controllers, rates):
        e = rate / r
        ei = int(round(e))
        if abs(e - ei) > 1e-9 * e:
            raise ValueError(f"controller {c.name!r}: rate_hz={r} must divide the fastest controller's rate "
                             f"{rate} Hz by a whole number (controllers at several rates run on its ticks)")
        every.append(ei)
    m = rate / fs
    mi = int(round(m))
    if mi < 1 or abs(m - mi) > 1e-9 * m:
        raise ValueError(f"the fastest controller's rate_hz={rate} must be an integer multiple of {fs=}")
    return rate, mi, np.array(every, dtype=np.int64)


def _hold_rows(model: LumpedModel, u: np.ndarray, m: int, rate: float):
    """References, feed-forwards (per controller) and open-loop forces (per input) on the tick grid."""
    n_c, n_in = len(model.controllers), len(model.inputs)
    Nt = u.shape[1] * m
    held = np.repeat(u, m, axis=1) if m > 1 else u
    Ref, FF, Uol = np.zeros((n_c, Nt)), np.zeros((n_c, Nt)), np.zeros((n_in, Nt))
    r = 0
    for c, ctl in enumerate(model.controllers):
        if ctl.reference is not None:
            Ref[c] = held[r]
            r += 1
    for c, ctl in enumerate(model.controllers):
        if ctl.feedforward is not None:
            FF[c] = held[r]
            r += 1
    driven = {model.driven_input(c) for c in model.controllers}
    for j, inp in enumerate(model.inputs):
        if j in driven:
            continue
        row = held[r]
        r += 1
        if inp.delay:
            shift = inp.delay * rate
            s = int(round(shift))
            if abs(shift - s) > 1e-9 * max(1.0, shift):
                raise ValueError(f"input {j} delay={inp.delay} s must be a whole number of controller ticks "
                                 f"(1/{rate} s) in a closed-loop simulation")
            row = np.concatenate([np.zeros(min(s, Nt)), row[: max(Nt - s, 0)]])
        row = row + inp.offset
        if inp.saturation is not None:
            row = inp.saturate(row)
        Uol[j] = row
    return Ref, FF, Uol


def simulate_closed_loop(
    model: LumpedModel,
    u,
    fs: float,
    *,
    t0: float = 0.0,
    method: Literal["auto", "linear", "nonlinear"] = "auto",
    oversample: int | None = None,
    noise: float = 0.0,
    seed: int | None = None,
    tol: float = 1e-13,
    max_iter: int = 50,
) -> Signals:
    """Simulate `model` inside its controllers, from rest, driven by the logged rows `u`.

    Parameters
    ----------
    model : LumpedModel
        A model with at least one controller (the fastest one's ``rate_hz`` an integer
        multiple of `fs`, every other ``rate_hz`` that rate divided by a whole number).
    u : array_like, shape (n_rows, n_samples) or (n_samples,)
        The logged rows of :func:`loop_inputs`: references (m), feed-forwards (command
        unit), then the forces (N) of the inputs no controller drives, sampled at `fs`.
    fs : float
        Sampling frequency of `u` and of the result, Hz.
    t0 : float
        Time of the first sample, s.
    method : {"auto", "linear", "nonlinear"}
        ``"linear"`` (default for a model whose elements are all linear): exact ZOH
        discretisation at the controller period; ``"nonlinear"``: `oversample`
        trapezoidal sub-steps per controller period.
    oversample : int, optional
        Trapezoidal sub-steps per controller period (nonlinear path); default
        ``max(4, ceil(40 f_max / rate_hz))`` with ``f_max`` the highest natural frequency of
        the open plant's linear part (the held command is constant within a period, so the
        sub-steps only resolve the plant; on the EMPS drive with friction at 1 kHz, 4
        sub-steps differ from 80 by 2e-3 % in the command).
    noise : float
        Gaussian noise of ``noise x RMS`` added to each output and command row.
    seed : int, optional
        Seed of the noise.
    tol, max_iter
        Newton settings of the trapezoidal path (see
        :func:`vibroscope.models.integrate.integrate`).

    Returns
    -------
    Signals
        The rows of `u` (their channels and units from :func:`loop_inputs`), then the model's
        outputs (m, m/s, m/s^2), then each controller's command (channel
        :attr:`Controller.command_channel`, unit ``output_unit``). Sample ``k`` is the tick
        at ``t0 + k / fs``: outputs at the state of that instant with the force held
        over the previous period (an acceleration is its left limit), commands computed
        from that instant's measurement and held until the next tick. ``meta`` holds
        ``simulator`` (``"closed-loop-zoh-exact"`` or ``"closed-loop-trapezoidal"``),
        ``rate_hz``, ``oversample``, ``newton_failures``, ``model``.

    Raises
    ------
    ValueError
        If `model` has no controllers, `u` has the wrong shape or non-finite values, the
        fastest rate is not an integer multiple of `fs` or another rate does not divide it,
        ``method="linear"`` is asked for a model
        with nonlinear elements, or `oversample` < 1.

    Warns
    -----
    RuntimeWarning
        If Newton's iteration failed at some sub-steps.
    """
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be positive")
    if not getattr(model, "controllers", ()):
        raise ValueError("simulate_closed_loop needs a LumpedModel with controllers")
    rows = loop_inputs(model)
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[np.newaxis]
    if u.ndim != 2 or u.shape[0] != len(rows):
        raise ValueError(f"u must have shape (n_rows={len(rows)}, n_samples) with rows {[r[0] for r in rows]}, "
                         f"got {u.shape=}")
    if u.shape[1] < 2:
        raise ValueError(f"need at least 2 samples, got {u.shape[1]=}")
    if not np.all(np.isfinite(u)):
        raise ValueError("u contains non-finite values")
    linear = all(e.is_linear for e in model.elements)
    if method == "auto":
        method = "linear" if linear else "nonlinear"
    if method not in ("linear", "nonlinear"):
        raise ValueError(f"{method=} must be 'auto', 'linear' or 'nonlinear'")
    if method == "linear" and not linear:
        raise ValueError("method='linear' needs a model with only linear elements")
    rate, m, every = _rate(model, fs)
    T = 1.0 / rate
    if method == "linear":
        R = 1
    elif oversample is not None:
        R = int(oversample)
    else:
        try:
            fmax = float(np.max(model.modes().natural_frequencies))
        except ValueError:
            fmax = 0.0
        R = max(4, int(math.ceil(40.0 * fmax / rate)))
    if R < 1:
        raise ValueError(f"{oversample=} must be >= 1")
    Ref, FF, Uol = _hold_rows(model, u, m, rate)
    ctls = model.controllers
    n_c = len(ctls)
    fm = flatten_model(model, T / R)
    if method == "linear":
        A, Bq, _, _ = model.state_matrices()
        Phi, Gam = zoh_matrices(A, Bq, T)
        fm = replace(fm, P=np.ascontiguousarray(Phi), Gu=np.ascontiguousarray(0.5 * Gam.reshape(A.shape[0], -1)))
    meas = tuple(Output(c.dof, q) for c in ctls for q in ("displacement", "velocity", "acceleration"))
    fmm = flatten_model(model.replace(outputs=meas), T / R)
    maxt = max(len(c.taps) for c in ctls)
    taps = np.zeros((n_c, maxt))
    for c, ctl in enumerate(ctls):
        taps[c, : len(ctl.taps)] = ctl.taps
    for c in ctls:
        inp = model.inputs[model.driven_input(c)]
        if inp.saturation is not None and inp.saturation_law != "clip":
            raise ValueError(f"input {model.driven_input(c)} (driven by controller {c.name!r}): saturation_law="
                             f"{inp.saturation_law!r}; a closed loop's driven input clips (saturation_law = 'clip')")
    in_sat = np.array([i.saturation if i.saturation is not None else np.inf for i in model.inputs])
    in_off = np.array([i.offset for i in model.inputs], dtype=float)
    # a driven input's delay acts on the command (in controller ticks, fractional: linear
    # interpolation between the two held commands around t - delay); open-loop inputs are
    # shifted on the tick grid by _hold_rows
    in_delay = np.zeros(len(model.inputs))
    for c in ctls:
        j = model.driven_input(c)
        in_delay[j] = float(model.inputs[j].delay) * rate
    Nt = Ref.shape[1]
    Y = np.empty((len(model.outputs), Nt))
    Cout = np.empty((n_c, Nt))
    fails, iters = closed_loop_kernel(
        fm.P, fm.Gu, fm.Gf, fm.Sd, fm.Sv, fm.L, fm.codes, fm.params, fm.k_lin, fm.c_lin, fm.state_offsets,
        fm.Cy, fm.Dy, fm.Hy, fmm.Cy, fmm.Dy, fmm.Hy,
        np.array([LAWS[c.law].code for c in ctls], dtype=np.int64),
        np.array([[c.g(k) for k in GAIN_ORDER] for c in ctls], dtype=float),
        np.array([[("velocity" in c.measures), ("acceleration" in c.measures)] for c in ctls], dtype=np.int64),
        taps, np.array([len(c.taps) for c in ctls], dtype=np.int64),
        np.array([model.driven_input(c) for c in ctls], dtype=np.int64),
        np.array([c.saturation if c.saturation is not None else np.inf for c in ctls]),
        np.array([c.gain for c in ctls], dtype=float),
        in_off, in_sat, in_delay, Ref, FF, np.ascontiguousarray(Uol), T, R, float(tol), int(max_iter), Y, Cout,
        every,
    )  # fmt: skip
    fails, iters = int(fails), int(iters)
    if fails:
        warnings.warn(
            f"Newton's iteration did not converge at {fails} of {(Nt - 1) * R} integration steps; "
            "the simulated response may be inaccurate there (try a larger oversample)",
            RuntimeWarning,
            stacklevel=2,
        )
    y = np.vstack([Y[:, ::m], Cout[:, ::m]])
    if noise:
        rng = np.random.default_rng(seed)
        rms = np.sqrt(np.mean(y**2, axis=1, keepdims=True))
        y = y + noise * rms * rng.standard_normal(y.shape)
    channels = [r[0] for r in rows] + model.output_channels() + [c.command_channel for c in ctls]
    units = [r[2] for r in rows] + [UNITS[o.quantity] for o in model.outputs] + [c.output_unit for c in ctls]
    meta = {
        "simulator": "closed-loop-zoh-exact" if method == "linear" else "closed-loop-trapezoidal",
        "rate_hz": rate,
        "oversample": R,
        "newton_failures": fails,
        "model": model.name,
    }
    return Signals(data=np.vstack([u, y]), fs=fs, channels=channels, units=units, t0=t0, meta=meta)
