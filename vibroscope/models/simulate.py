"""Time simulation of lumped models: input reconstruction and input physics (delay,
offset, saturation) on a fine grid, then either the exact first-order-hold discretisation of a
linear model (:mod:`vibroscope.models.linear_sim`) or the compiled implicit trapezoidal
(Newmark average-acceleration) integrator (:mod:`vibroscope.models.integrate`), and the
assembly of the outputs.

Conventions
-----------
* The input is sampled at `fs`; between samples it is *not* held constant: it is
  reconstructed on a grid ``oversample`` times finer (band-limited by default,
  :func:`reconstruct_input`). Input delay, offset and saturation act on that continuous
  (fine-grid) force, as an actuator does.
* Output sample ``k`` belongs to input sample ``k`` (no half-sample delay).
* The returned :class:`~vibroscope.signals.Signals` holds the input channels first (N),
  then the outputs (m/s^2, m/s or m).

Module layout: :mod:`~vibroscope.models.resample` (:func:`upsample`,
:func:`decimate_fir`), :mod:`~vibroscope.models.linear_sim` (FOH path),
:mod:`~vibroscope.models.integrate` (numba kernel); their public names are re-exported here.
The Bouc-Wen benchmark [3]_ (:mod:`~vibroscope.models.boucwen_benchmark`, which simulates with
this module) is offered by :mod:`vibroscope.models`.

References
----------
.. [1] N. M. Newmark, "A method of computation for structural dynamics", J. Eng. Mech. Div.
   ASCE 85(EM3):67-94, 1959.
.. [2] G. F. Franklin, J. D. Powell, M. L. Workman, *Digital Control of Dynamic Systems*,
   3rd ed., 1998, sec. 6.3.2 (triangle-hold equivalent).
.. [3] J. P. Noël, M. Schoukens, "Hysteretic benchmark with a dynamic nonlinearity",
   Workshop on Nonlinear System Identification Benchmarks, Brussels, 2016.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from scipy import signal

from vibroscope.models.integrate import integrate
from vibroscope.models.linear_sim import dlsim_modal, foh_equivalent, triangle_hold_compensation
from vibroscope.models.lumped import UNITS, LumpedModel
from vibroscope.models.resample import decimate_fir, decimate_sharp, upsample
from vibroscope.signals import Signals

__all__ = [
    "simulate",
    "simulate_periodic",
    "reconstruct_input",
    "default_oversample",
    "upsample",
    "decimate_fir",
    "decimate_sharp",
]

#: the ways the nonlinear path brings its fine-grid outputs back to the sample rate, the default first
OUTPUT_SAMPLINGS = ("filtered", "sharp", "point")
#: linear path's default oversampling factor
LINEAR_OVERSAMPLE = 8
#: half-length (taps each side) and Kaiser beta of the fine-grid fractional-delay filter
_FRAC_TAPS, _FRAC_BETA = 24, 10.0


# --------------------------------------------------------------------------------------------
# input preparation
# --------------------------------------------------------------------------------------------
def _check_u(model: LumpedModel, u) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[np.newaxis]
    if u.ndim != 2 or u.shape[0] != len(model.inputs):
        raise ValueError(f"u must have shape (n_inputs={len(model.inputs)}, n_samples), got {u.shape=}")
    if u.shape[1] < 2:
        raise ValueError(f"need at least 2 input samples, got {u.shape[1]=}")
    if not np.all(np.isfinite(u)):
        raise ValueError("u contains non-finite values")
    return u


def default_oversample(model: LumpedModel, fs: float) -> int:
    """Default sub-steps per sample of the nonlinear (trapezoidal) path.

    ``max(20, ceil(40 f_max / fs))`` with ``f_max`` the highest natural frequency of the
    linear part (nonlinear elements' small-motion stiffness ignored): the integration rate is
    >= 20 x ``fs`` and >= 40 x ``f_max``.

    Parameters
    ----------
    model : LumpedModel
    fs : float
        Sampling frequency of the input in Hz.

    Returns
    -------
    int
    """
    try:
        fmax = float(np.max(model.modes().natural_frequencies))
    except ValueError:
        fmax = 0.0
    return max(20, int(math.ceil(40.0 * fmax / float(fs))))


_default_oversample = default_oversample  # former private name


def reconstruct_input(
    u, fs: float, oversample: int, *, upsampling: Literal["poly", "fft", "linear"] = "poly"
) -> np.ndarray:
    """Reconstruction of sampled inputs on the integration grid ``fs * oversample``.

    The raw reconstruction (:func:`upsample`, non-periodic), before any model-specific input
    delay or saturation, which :func:`simulate` applies. Compute it once and pass it as
    ``simulate(..., fine_input=...)`` to simulate one input record with many models.

    Parameters
    ----------
    u : array_like, shape (n_inputs, n) or (n,)
        Input forces in N sampled at `fs`.
    fs : float
        Sampling frequency in Hz.
    oversample : int
        Fine-grid points per sample, >= 1.
    upsampling : {"poly", "fft", "linear"}
        Reconstruction method (see :func:`upsample`).

    Returns
    -------
    ndarray, shape (n_inputs, n * oversample)
        Sample ``k`` of `u` lands on fine sample ``k * oversample``.

    Raises
    ------
    ValueError
        If `fs` is not positive, `oversample` < 1, `u` is not finite or `upsampling` is
        unknown.
    """
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be positive")
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[np.newaxis]
    if u.ndim != 2:
        raise ValueError(f"u must have shape (n_inputs, n_samples), got {u.shape=}")
    if not np.all(np.isfinite(u)):
        raise ValueError("u contains non-finite values")
    R = int(oversample)
    if R < 1:
        raise ValueError(f"{oversample=} must be >= 1")
    if upsampling not in ("poly", "fft", "linear"):
        raise ValueError(f"{upsampling=} must be 'poly', 'fft' or 'linear'")
    return upsample(u, R, method=upsampling)


def _fractional_delay_taps(frac: float, cutoff: float = 1.0) -> np.ndarray:
    """Kaiser-windowed (beta 10) sinc ``h[j] = c sinc(c (j - frac)) w(j - frac)``,
    ``j = -K+1 .. K`` (K = 24), unit DC gain: ``y[i] = sum_j h[j] x[i - j]`` delays `x` by
    ``frac`` in (0, 1) samples, low-passed at ``c`` (`cutoff`) x Nyquist. On a grid
    oversampled >= 8x with ``c = 1/2`` its error on a sine below the coarse Nyquist is
    about 1e-6 of the amplitude."""
    K = _FRAC_TAPS
    t = np.arange(-K + 1, K + 1) - frac
    w = np.i0(_FRAC_BETA * np.sqrt(np.clip(1.0 - (t / K) ** 2, 0.0, None))) / np.i0(_FRAC_BETA)
    h = cutoff * np.sinc(cutoff * t) * w
    return h / h.sum()


def _delay_fine(x: np.ndarray, shift: float, periodic: bool = False, cutoff: float = 1.0) -> np.ndarray:
    """`x` (N,) delayed by `shift` >= 0 fine samples: integer part by indexing (zeros before the
    start, or circular), fractional part by :func:`_fractional_delay_taps` (the record taken
    as zero outside, or periodic)."""
    N = x.shape[0]
    m = int(math.floor(shift + 1e-9))
    frac = shift - m
    if abs(frac) < 1e-9:
        frac = 0.0
    y = x
    if frac:
        h = _fractional_delay_taps(frac, cutoff)
        K = _FRAC_TAPS
        if periodic:
            y = sum(hj * np.roll(x, j) for j, hj in zip(range(-K + 1, K + 1), h))
        else:
            y = signal.oaconvolve(x, h, mode="full")[K - 1 : K - 1 + N]
    if periodic:
        return np.roll(y, m)
    out = np.zeros(N)
    if m < N:
        out[m:] = y[: N - m]
    return out


def _apply_input_physics(
    model: LumpedModel, U: np.ndarray, fs_fine: float, fs: float, periodic: bool = False
) -> np.ndarray:
    """The applied force on the fine grid: each input's reconstruction delayed by its
    ``delay`` (pure time shift, zero before the start; circular if `periodic`), plus its
    ``offset``, then limited at its ``saturation`` (:meth:`Input.saturate`). Returns `U` itself when
    no input has any of the three, else a new array."""
    if not any(i.delay or i.offset or i.saturation is not None for i in model.inputs):
        return U
    U = np.array(U, dtype=float)
    for j, inp in enumerate(model.inputs):
        if inp.delay:
            R = fs_fine / fs if fs else 1.0
            U[j] = _delay_fine(U[j], inp.delay * fs_fine, periodic, cutoff=0.5 if R >= 4 else 1.0)
        if inp.offset:
            U[j] += inp.offset
        if inp.saturation is not None:
            U[j] = inp.saturate(U[j])
    return U


def _applied_samples(model: LumpedModel, u: np.ndarray, U_app: np.ndarray, fs: float, R: int) -> np.ndarray:
    """The input rows returned with the outputs: the logged samples as applied. Undelayed
    inputs: the logged samples (clipped at the saturation); an integer-sample delay shifts the
    logged samples exactly (zeros before); a fractional one takes the delayed fine-grid
    reconstruction at the sample instants (already offset and clipped). Then the ``offset``
    added and clipped at the saturation."""
    out = u.copy()
    n = u.shape[1]
    for j, inp in enumerate(model.inputs):
        if inp.delay:
            shift = inp.delay * fs
            m = int(round(shift))
            if abs(shift - m) < 1e-9 * max(1.0, shift):
                out[j] = 0.0
                if m < n:
                    out[j, m:] = u[j, : n - m]
            else:
                out[j] = U_app[j, ::R][:n]
                continue
        if inp.offset:
            out[j] += inp.offset
        if inp.saturation is not None:
            out[j] = inp.saturate(out[j])
    return out


def _wrap(model, u, y, fs, t0, noise, seed, meta):
    if noise:
        rng = np.random.default_rng(seed)
        rms = np.sqrt(np.mean(y**2, axis=1, keepdims=True))
        y = y + noise * rms * rng.standard_normal(y.shape)
    data = np.vstack([u, y])
    units = ["N"] * len(model.inputs) + [UNITS[o.quantity] for o in model.outputs]
    return Signals(data=data, fs=fs, channels=model.input_channels() + model.output_channels(), units=units, t0=t0,
                   meta=meta)


def _bring_back(y: np.ndarray, R: int, output_sampling: str) -> np.ndarray:
    """Fine-grid outputs ``(n_out, n R)`` brought back to the sample rate by `output_sampling`
    ('point': every `R`-th sample; 'sharp': :func:`decimate_sharp`; 'filtered':
    :func:`decimate_fir`)."""
    if output_sampling == "point":
        return np.ascontiguousarray(y[:, ::R])
    if output_sampling == "sharp":
        return decimate_sharp(y, R)
    return decimate_fir(y, R)


def _is_linear(model: LumpedModel) -> bool:
    return all(e.is_linear for e in model.elements)


# --------------------------------------------------------------------------------------------
# simulation
# --------------------------------------------------------------------------------------------
def simulate(
    model: LumpedModel,
    u,
    fs: float,
    *,
    t0: float = 0.0,
    method: Literal["auto", "linear", "nonlinear"] = "auto",
    oversample: int | None = None,
    upsampling: Literal["poly", "fft", "linear"] = "poly",
    noise: float = 0.0,
    seed: int | None = None,
    fine_input=None,
    scheme: Literal["trapezoid", "exponential"] = "trapezoid",
    output_sampling: Literal["filtered", "sharp", "point"] = "filtered",
) -> Signals:
    """Simulate `model` driven by the sampled inputs `u`, from rest.

    Steps: (1) the inputs are reconstructed on the fine grid ``fs * oversample``
    (:func:`reconstruct_input`, or `fine_input`); (2) each input's ``delay`` shifts its
    fine-grid force in time (integer fine samples by indexing, the fractional rest by a
    48-tap Kaiser-windowed-sinc fractional-delay filter, low-passed at half the fine
    Nyquist for ``oversample >= 4``; zero before the start), then its ``offset`` (N) is
    added (from ``t = 0``) and its ``saturation`` clips the sum, ``clip(u(t - delay) +
    offset)``: the actuator limits the continuous force, not the logged samples; (3) the
    model is integrated over that applied fine-grid force; (4) the outputs are brought back
    to `fs`.

    A model with ``controllers`` is simulated in closed loop instead
    (:func:`vibroscope.models.closed_loop.simulate_closed_loop`): `u` then holds the logged
    references (m), feed-forwards and the forces of the inputs no controller drives
    (:func:`~vibroscope.models.closed_loop.loop_inputs`), the controllers tick at their
    ``rate_hz`` with a zero-order hold on their commands, the plant is stepped by its exact
    ZOH discretisation (linear) or by trapezoidal sub-steps (`oversample`, nonlinear), and
    the result adds each controller's command as a channel; `upsampling` and `fine_input`
    do not apply.

    Parameters
    ----------
    model : LumpedModel, TransferFunctionModel or PoleResidueModel
        The model; its inputs are the rows of `u`, its outputs the simulated channels.
        Transfer-function and pole-residue models (no elements) take the linear path
        through their ``state_matrices()`` (a pole-residue model's realisation leaves out
        the residual terms it cannot realise, with a warning:
        :meth:`~vibroscope.models.modal_model.PoleResidueModel.state_matrices`).
    u : array_like, shape (n_inputs, n_samples) or (n_samples,)
        Input forces in N sampled at `fs`.
    fs : float
        Sampling frequency in Hz.
    t0 : float
        Time of the first sample in s.
    method : {"auto", "linear", "nonlinear"}
        ``"linear"``: exact first-order-hold (triangle-hold) discretisation of the linear
        part at ``fs * oversample`` [2]_, run as decoupled modal recursions, on the applied
        fine-grid input pre-emphasised against the hold's ``sinc^2`` roll-off (flat within
        1e-4 up to 0.25 fs for band-limited inputs; with ``upsampling="linear"`` no
        pre-emphasis, exact for inputs linear between fine samples). ``oversample=1`` is the
        plain FOH equivalent (input linear between samples, whose response rolls off as
        ``sinc^2(f / fs)`` against the band-limited interpretation: 1 % at 0.055 fs).
        Saturated and delayed inputs use this path too: the FOH recursion runs on the
        clipped / shifted fine-grid force (the clipped force is not band-limited; the FOH
        treats it as linear between fine samples, without pre-emphasis correction of its
        corners beyond the ``[-1/12, 7/6, -1/12]`` filter). Outputs are the responses at
        the sample instants, except for a saturated input with `output_sampling`
        'filtered' or 'sharp': an acceleration output of a driven DOF contains the
        feedthrough ``M^-1 B u`` of the clipped force, whose harmonics above ``fs / 2``
        would alias, so the fine-grid outputs are brought back to `fs` as on the nonlinear
        path (the two paths then agree to ~2e-4).
        ``"nonlinear"``: the compiled trapezoidal rule (Newmark average acceleration,
        ``a = 1/2``, ``b = 1/4``, internal states ``c = 1/2``; second order, A-stable) [1]_
        (:func:`vibroscope.models.integrate.integrate`) at ``fs * oversample`` on the applied
        fine-grid force, the outputs low-passed and decimated (:func:`decimate_fir`).
        ``"auto"``: linear when every element is linear (whatever the inputs' saturation,
        delay and offset; an offset is a constant force, whose response is the static
        deflection plus the transient of its onset at ``t = 0``), else nonlinear.
    oversample : int, optional
        Sub-steps per sample: linear path default 8, nonlinear path default
        :func:`default_oversample`. With `fine_input` it defaults to
        ``fine_input.shape[1] // n_samples`` and must equal that if given.
    upsampling : {"poly", "fft", "linear"}
        Input reconstruction between samples (see :func:`upsample`); with `fine_input`, the
        method that made it (it decides the linear path's pre-emphasis and is recorded in
        the metadata).
    noise : float
        Add Gaussian noise of standard deviation ``noise x RMS`` of each output channel.
    seed : int, optional
        Seed of the noise generator.
    fine_input : array_like, shape (n_inputs, n_samples * R), optional
        A precomputed :func:`reconstruct_input` ``(u, fs, R, upsampling=...)`` of the same
        `u` (raw: delay, offset and saturation are applied here). Skips the reconstruction;
        the results are identical to passing none. It is not modified.
    scheme : {'trapezoid', 'exponential'}, optional
        The nonlinear path's discretisation of the linear part
        (:func:`vibroscope.models.integrate.flatten_model`): 'trapezoid' (default) or
        'exponential' (exact linear free response: no frequency warping, so fewer sub-steps
        reach the same accuracy). Not used on the linear path or in closed loop.
    output_sampling : {'filtered', 'sharp', 'point'}, optional
        How the nonlinear path brings its fine-grid outputs back to `fs`: 'filtered'
        (default) low-passes and decimates them (:func:`decimate_fir`, MATLAB's order-30
        stages, which roll off from about 0.3 `fs`), as a digitally decimated record such as
        the Bouc-Wen benchmark's was made; 'sharp' low-passes them flat to about 0.46 `fs`
        and decimates (:func:`decimate_sharp`), as a sigma-delta converter's or a
        recorder's sharp anti-aliasing filter does; 'point' takes them at the sample
        instants, as a sampling ADC with no anti-aliasing filter (and a reference integrator
        sampled at the log's times) would, so a nonlinearity's harmonics above ``fs / 2``
        alias into the band as they do there. The linear path samples at the instants (its
        outputs have no content above ``fs / 2``) but for a saturated input, whose clipped
        force's harmonics it treats the same way. Not used in closed loop.

    Returns
    -------
    Signals
        Inputs then outputs, ``n_samples`` each; output sample ``k`` is the response at the
        time of input sample ``k``. The input rows are the logged samples as applied:
        delayed, offset and clipped at the saturation (an integer-sample delay shifts the
        logged samples exactly, zeros before; a fractional one takes the delayed fine-grid
        reconstruction at the sample instants). ``meta`` holds ``simulator``
        (``"foh-exact"`` or ``"trapezoidal"``), ``oversample``, ``upsampling``, ``model``
        and, for the trapezoidal path, ``newton_failures`` (steps whose Newton iteration did
        not converge).

    Raises
    ------
    ValueError
        If `u` has the wrong shape or non-finite values, `fs` is not positive,
        ``method="linear"`` is asked for a nonlinear model, ``method="nonlinear"`` for a
        model that is not a :class:`LumpedModel`, `oversample` < 1, or
        `fine_input` has the wrong shape, non-finite values or disagrees with `oversample`,
        or `output_sampling` is not 'filtered', 'sharp' or 'point'.

    Warns
    -----
    RuntimeWarning
        Once, if the Newton iteration of the trapezoidal path failed to converge at some
        steps (count in ``meta["newton_failures"]``).

    See Also
    --------
    vibroscope.load_model : A model from a model file.
    vibroscope.models.closed_loop.simulate_closed_loop : The same with controllers closing a loop.

    Examples
    --------
    >>> import numpy as np
    >>> from vibroscope.models.lumped import LumpedModel
    >>> m = LumpedModel.chain([1.0], [1e4], [0.0], output_quantity="displacement")
    >>> s = simulate(m, np.full(2000, 1.0), fs=1000.0)   # step of 1 N
    >>> round(float(s.data[1].max() * 1e4), 3)            # peak 2 F/k
    2.0
    """
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be positive")
    if output_sampling not in OUTPUT_SAMPLINGS:
        raise ValueError(f"{output_sampling=} must be 'filtered', 'sharp' or 'point'")
    if getattr(model, "controllers", ()):
        if fine_input is not None:
            raise ValueError("fine_input is not used in a closed-loop simulation (the model has controllers)")
        from vibroscope.models.closed_loop import simulate_closed_loop

        return simulate_closed_loop(model, u, fs, t0=t0, method=method, oversample=oversample, noise=noise, seed=seed)
    u = _check_u(model, u)
    n = u.shape[1]
    linear = _is_linear(model)
    if method == "auto":
        method = "linear" if linear else "nonlinear"
    if method not in ("linear", "nonlinear"):
        raise ValueError(f"{method=} must be 'auto', 'linear' or 'nonlinear'")
    if method == "linear" and not linear:
        raise ValueError("method='linear' needs a model with only linear elements")
    if method == "nonlinear" and not isinstance(model, LumpedModel):
        raise ValueError(f"method='nonlinear' needs a LumpedModel; a {type(model).__name__} runs on the linear path")
    if fine_input is not None:
        U = np.asarray(fine_input, dtype=float)
        if U.ndim == 1:
            U = U[np.newaxis]
        if U.ndim != 2 or U.shape[0] != u.shape[0] or U.shape[1] % n or U.shape[1] < n:
            raise ValueError(
                f"fine_input must have shape (n_inputs={u.shape[0]}, n_samples * R) with n_samples={n}, got {U.shape}"
            )
        R = U.shape[1] // n
        if oversample is not None and int(oversample) != R:
            raise ValueError(f"{oversample=} disagrees with fine_input ({R} fine samples per sample)")
        if not np.all(np.isfinite(U)):
            raise ValueError("fine_input contains non-finite values")
    else:
        if oversample is not None:
            R = int(oversample)
        else:
            R = LINEAR_OVERSAMPLE if method == "linear" else default_oversample(model, fs)
        if R < 1:
            raise ValueError(f"{oversample=} must be >= 1")
        U = reconstruct_input(u, fs, R, upsampling=upsampling)
    U_app = _apply_input_physics(model, U, fs * R, fs)
    u_app = _applied_samples(model, u, U_app, fs, R)
    if method == "linear":
        A, B, C, D = model.state_matrices()
        Uc = triangle_hold_compensation(U_app) if R > 1 and upsampling != "linear" else U_app
        disc = foh_equivalent(A, B, C, D, 1.0 / (fs * R))
        clipped = R > 1 and output_sampling != "point" and any(i.saturation is not None for i in model.inputs)
        if clipped:
            # a clipped force carries harmonics above fs / 2: filter the fine-grid outputs
            y = _bring_back(dlsim_modal(*disc, Uc, D, U_app, 1), R, output_sampling)[:, :n]
        else:
            y = dlsim_modal(*disc, Uc, D, U_app[:, ::R], R)
        meta = {"simulator": "foh-exact", "oversample": R, "upsampling": upsampling, "model": model.name}
        if clipped:
            meta["output_sampling"] = output_sampling
    else:
        res = integrate(model, U_app, 1.0 / (fs * R), warn=False, scheme=scheme)
        _warn_newton(res.newton_failures, U_app.shape[1] - 1)
        if R == 1:
            y = res.y
        else:
            y = _bring_back(res.y, R, output_sampling)[:, :n]
        meta = {
            "simulator": "trapezoidal" if scheme == "trapezoid" else "exponential-trapezoidal",
            "oversample": R,
            "output_sampling": output_sampling,
            "upsampling": upsampling,
            "model": model.name,
            "newton_failures": res.newton_failures,
        }
    return _wrap(model, u_app, y, fs, t0, noise, seed, meta)


def _warn_newton(failures: int, steps: int) -> None:
    if failures:
        import warnings

        warnings.warn(
            f"Newton's iteration did not converge at {failures} of {steps} integration steps; "
            "the simulated response may be inaccurate there (try a larger oversample)",
            RuntimeWarning,
            stacklevel=3,
        )


def simulate_periodic(
    model: LumpedModel,
    u_period,
    fs: float,
    *,
    n_periods: int = 3,
    oversample: int | None = None,
    noise: float = 0.0,
    seed: int | None = None,
) -> Signals:
    """Steady-state response to a periodic input: simulate `n_periods` periods and return the last.

    Models with nonlinear elements, saturated or delayed inputs: the input period is
    upsampled by ideal band-limited (FFT) interpolation, delayed circularly, offset and
    clipped on the fine grid (as in :func:`simulate`), the model is integrated over
    `n_periods` periods from rest with the compiled trapezoidal kernel, and the fine-grid
    outputs of the last period are low-passed circularly and decimated
    (:func:`decimate_fir`). Other linear models (an input offset included) use the exact
    discretisation (:func:`simulate`) on `n_periods` periods.

    Parameters
    ----------
    model : LumpedModel
    u_period : array_like, shape (n_inputs, n) or (n,)
        One period of the input in N.
    fs : float
        Sampling frequency in Hz.
    n_periods : int
        Periods simulated (transients must have died out by the last one).
    oversample, noise, seed
        As in :func:`simulate`.

    Returns
    -------
    Signals
        One steady-state period, inputs (the logged period) then outputs.

    Raises
    ------
    ValueError
        If the model has controllers (closed loops run in :func:`simulate` only).

    Warns
    -----
    RuntimeWarning
        Once, if Newton's iteration failed at some steps (``meta["newton_failures"]``).
    """
    fs = float(fs)
    if getattr(model, "controllers", ()):
        raise ValueError("simulate_periodic does not run closed loops (the model has controllers); use simulate")
    u = _check_u(model, u_period)
    n = u.shape[1]
    linear = _is_linear(model) and all(i.saturation is None and not i.delay for i in model.inputs)
    if linear:
        s = simulate(model, np.tile(u, n_periods), fs)
        y = s.data[len(model.inputs) :, -n:]
        meta = {"simulator": "foh-exact", "n_periods": n_periods}
    else:
        R = int(oversample or default_oversample(model, fs))
        U = upsample(u, R, method="fft", periodic=True)
        U = _apply_input_physics(model, U, fs * R, fs, periodic=True)
        Ut = np.tile(U, n_periods)
        Ut = np.concatenate([Ut, U[:, :1]], axis=1)
        res = integrate(model, Ut, 1.0 / (fs * R), warn=False)
        _warn_newton(res.newton_failures, Ut.shape[1] - 1)
        last = slice(-n * R - 1, -1)
        y = decimate_fir(res.y[:, last], R, periodic=True)
        meta = {"simulator": "trapezoidal", "oversample": R, "n_periods": n_periods,
                "newton_failures": res.newton_failures}  # fmt: skip
    return _wrap(model, u, y, fs, 0.0, noise, seed, meta)
