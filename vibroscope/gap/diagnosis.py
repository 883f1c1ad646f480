"""The sim-to-real gap diagnosis: measure, localise, attribute, quantify.

:func:`diagnose` drives a nominal model with the logged input, measures where the
simulation and the log disagree (channels, frequency bands, excitation levels, state
regimes) against a noise floor estimated from the data, runs signature tests on the
residual of the re-estimated linear model, fits the model augmented with every candidate
effect of the vocabulary (:data:`~vibroscope.gap.effects.EFFECT_TABLE`), ranks the candidates
by the share of the gap they close on held-out data, and adds further effects while they
close significantly more (forward selection).

This module prepares the logs, simulates the nominal model, refits the linear parameters (steps
1-4 below) and builds the report. Every stage works on one :class:`~vibroscope.gap._run.Run` (the
working state, beside the tuning constants, which this module exposes too); the others live in private
modules: the evidence and the start values in :mod:`vibroscope.gap._evidence` (the level tests in
:mod:`vibroscope.gap._level_evidence`), the candidates' fits in :mod:`vibroscope.gap._candidates`,
their scores and the verdict in :mod:`vibroscope.gap._ranking`, the forward selection in
:mod:`vibroscope.gap._selection`.

Procedure
---------
1. **Split** (:func:`~vibroscope.gap.measure.make_split`): one log: a time split that keeps
   every excitation level on both sides; several logs at one level: the last one is held
   out; several logs at different levels: each is split in time (every level is fitted and
   held out: a held-out level the fit never saw would test an extrapolation). A sine sweep
   (an input whose spectrum changes over the record) is split in blocks across it, not at
   its end, where the held-out part would be a band the fit never saw.
2. **Nominal**: simulate the model with the logged input (band-limited reconstruction,
   output sample k aligned with input sample k); gap = held-out nrmse (each channel
   normalised by its own energy, :func:`~vibroscope.gap.measure.nrmse`).
3. **Noise floor** (:func:`~vibroscope.gap.measure.noise_floor`).
4. **Refit**: the nominal structure's masses, stiffnesses and dampings re-estimated on the
   fitting data, on the measured H1 (segment length from the record:
   :func:`~vibroscope.gap.levels.frf_segment_length`) and then on the time response, started
   from the FRF fit or from the nominal, whichever fits better; the refit is never worse on
   the fitting data than the nominal itself (both are reported in ``meta["refit"]``).
5. **Level evidence**: the BLA per log and excitation level; its change from the lowest to
   the highest level is tested line by line against the H1 uncertainty (Bendat & Piersol),
   and the resonances' natural frequency and damping per level are estimated
   (:func:`~vibroscope.gap.levels.level_blas`); a natural frequency that moves beyond its
   uncertainty (less the refitted model's own change) makes the BLA level dependent too.
6. **Candidates**: start values derived from the data (the residual regressed on each element
   law's force computed from the refitted motion; clearance and limit levels from the
   distributions of the relative displacement and of the input); linear effects (time
   delay, extra mode) fitted jointly with the linear parameters on the FRF, then in time;
   nonlinear effects probed from the refitted and from the nominal linear parameters at
   every location, the most promising locations refined (a short prefix of the fitting
   data, coarser integration), the best classes fitted jointly with the linear parameters.
7. **Score**: every candidate simulated on the held-out data; with ``e(g) = sqrt(g^2 -
   floor^2)`` the excess over the noise floor, candidates are ranked by
   ``max(e(gap_after), 0.15 floor) (1 + 0.1 n)`` with ``n`` the number of effect parameters
   and ``score = 1 - that / e(gap_before)``. A candidate whose fitted parameters make the
   effect vanish (:meth:`~vibroscope.gap.effects.EffectSpec.vanishes`, or an effect that
   changes the held-out outputs by less than the noise floor; the linear refit as
   ``parameter_mismatch`` by the same output test, whatever the size of its changes) is never
   the verdict; nor is a
   linear explanation (parameter mismatch, delay, extra mode) when the BLA depends on the
   level; without that evidence a nonlinear effect must beat the best linear explanation by
   :data:`NL_MARGIN`. The verdict is ``none`` when the nominal gap is within
   :data:`NONE_FACTOR` times the noise floor (no effect is fitted), ``unexplained`` when the
   best admissible candidate's score is below :data:`UNEXPLAINED_SCORE`, else that candidate,
   polished jointly with the linear parameters at full accuracy.
8. **Forward selection**: each other class is added to the verdict's model (its own
   parameters fitted, then jointly with the linear ones; a promising addition is fitted
   further before the decision); the best is kept when the penalised excess falls below
   :data:`ADD_FACTOR` times the current one, up to three effects, then the combination is
   polished jointly; each effect's share of the shrink is reported. An input delay that
   joined only later is fitted first too (:func:`~vibroscope.gap._selection.delay_first`);
   when nothing joins it and the combination is not significantly better than the delay
   alone by the same test, the delay alone is the verdict. A ``parameter_mismatch`` verdict
   that nothing joined and that still leaves more than :data:`PM_UNEXPLAINED` times the noise
   floor becomes ``unexplained`` (a refit of every linear parameter reaches the noise where the
   truth is linear; the refit stays first among the candidates).
9. **An unexplained gap not coherent with the input** (:func:`_check_incoherent`): the floor
   assumes white noise; coloured sensor noise or an unlogged disturbance leaves a gap no model
   of the logged input can close. An ``unexplained`` verdict becomes ``none``, the candidate
   that leaves no part coherent with the input, or ``parameter_mismatch``, when the residuals
   say so (:func:`~vibroscope.gap.measure.coherent_gap`), with the reason in
   ``meta["incoherent_gap"]``.

References
----------
.. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999 (simulation
   error, residual analysis, validation on fresh data).
.. [2] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*,
   2nd ed., 2012 (best linear approximation, level dependence, noise floor).
.. [3] G. Kerschen, K. Worden, A. F. Vakakis, J.-C. Golinval, "Past, present and future of
   nonlinear system identification in structural dynamics", MSSP 20(3):505-592, 2006.
.. [4] J. S. Bendat, A. G. Piersol, *Random Data: Analysis and Measurement Procedures*, 4th
   ed., Wiley, 2010, sec. 9.2 (random error of H1 and coherence estimates).
"""

from __future__ import annotations

import math
import time

import numpy as np

from vibroscope.errors import ChannelError
from vibroscope.gap._candidates import fit_candidates, recheck_output_sampling
from vibroscope.gap._evidence import gather_evidence, states_model
from vibroscope.gap._ranking import held_out_gain, rank_candidates
from vibroscope.gap._run import MismatchFit, Run, frf_data, pow2
from vibroscope.gap._run import (  # the tuning constants live with the run state; exposed here too
    ADD_FACTOR,
    CLEARANCE_HOLDERS,
    CONN_JOINT_GAIN,
    HELD_CLEARANCE_CONNECTIONS,
    HELD_CLEARANCE_NFEV,
    HELD_CLEARANCE_STALL,
    HELD_CLEARANCE_STARTS,
    JOINT_TOP,
    LEVEL_FRACTION,
    LEVEL_MODE_CHANGE,
    LEVEL_MODE_MATCH,
    LEVEL_MODE_Z,
    LIN_EFFECT_NFEV,
    LINEAR_STOP_FACTOR,
    NESTED_FAMILIES,
    NESTED_T,
    NL_MARGIN,
    NONE_FACTOR,
    N_LOCATIONS,
    OTHER_BASE_FACTOR,
    PENALTY,
    PM_FURTHER,
    PM_UNEXPLAINED,
    POLISH_FLOOR_FACTOR,
    POLISH_GAIN,
    POLISH_ROUNDS,
    POLISH_S,
    PREDICT_SHARE,
    REFINE_FACTOR,
    RESIDUAL_GROWTH,
    STAND_IN_FACTOR,
    TREND_MARGIN,
    TREND_SHARE,
    UNEXPLAINED_SCORE,
)
from vibroscope.gap._selection import select_further_effects
from vibroscope.gap.closed_loop import CLOSED_LOOP_EXCLUDED, is_closed_loop, log_channels
from vibroscope.gap.effects import EFFECT_TABLE, LinearParams
from vibroscope.gap.fit import LogSimulator, fit_linear_frf, fit_time_domain
from vibroscope.gap.levels import aperiodic_logs, frf_segment_length, period_floor, steady_state_start
from vibroscope.gap.measure import (LOG_LEVEL_RATIO, coherent_gap, coherent_power, input_levels, locate_bands, make_split, masked_csd,
                                    noise_floor, nrmse, regime_gaps, residual_growth, welch_starts)
from vibroscope.gap.report import ChannelGap, GapReport, GapSpectrum, GapTraces
from vibroscope.modal.automatic import one_blas_thread
from vibroscope.models.lumped import LumpedModel
from vibroscope.models.simulate import OUTPUT_SAMPLINGS
from vibroscope.signals import Signals, true_runs

__all__ = ["diagnose", "fit_linear_model", "as_lumped"]


def as_lumped(model) -> LumpedModel:
    """`model` as a :class:`LumpedModel` (:func:`vibroscope.gap.physical.as_lumped`).

    Parameters
    ----------
    model : LumpedModel, TransferFunctionModel or PoleResidueModel
        A lumped model, a transfer function (second order: one mass; higher: modes), or a
        modal model with a driving point.

    Returns
    -------
    LumpedModel
        `model`, one mass, or a modal-coordinates model with the measured points.

    Raises
    ------
    ValueError
        For a transfer function not of the modal form or a modal model with no driving point.
    """
    from vibroscope.gap.physical import as_lumped as _as_lumped

    return _as_lumped(model)


def _split_at_gaps(model, sigs: list, nperseg: int | None) -> list:
    """Logs with missing samples (NaN) cut into their gap-free stretches, each taken as a log.

    A stretch counts when every model channel is present over at least ``4 nperseg`` samples
    (8 s without `nperseg`); shorter ones are left out. The simulation restarts at rest at each
    stretch, so nothing is bridged across a gap. Raises ValueError naming the channels with
    missing samples when no stretch is long enough.
    """
    import warnings

    chans = sum(log_channels(model), [])
    out = []
    for sig in sigs:
        rows = [list(sig.channels).index(c) for c in chans if c in sig.channels]
        if len(rows) < len(chans):
            out.append(sig)  # _split_channels names the missing channel
            continue
        data = np.asarray(sig.data)[rows]
        present = np.isfinite(data).all(axis=0)
        if present.all():
            out.append(sig)
            continue
        bad = [c for c, r in zip(chans, data) if not np.isfinite(r).all()]
        min_len = 4 * int(nperseg) if nperseg else int(8 * sig.fs)
        starts, stops = true_runs(present)
        keep = [(a, b) for a, b in zip(starts, stops) if b - a >= min_len]
        if not keep:
            longest = int((stops - starts).max()) if starts.size else 0
            src = sig.meta.get("source")
            raise ValueError(f"{src + ': ' if src else ''}missing samples (NaN) in channel(s) {bad}: the longest "
                             f"stretch without one is {longest} samples ({longest / sig.fs:.3g} s), the gap "
                             f"diagnosis needs {min_len} ({min_len / sig.fs:.3g} s): give a log with fewer gaps "
                             f"(or, in the API, a smaller nperseg)")
        used = sum(b - a for a, b in keep)
        warnings.warn(f"missing samples (NaN) in channel(s) {bad}: the log is diagnosed as {len(keep)} "
                      f"gap-free stretches ({used} of {sig.n_samples} samples; stretches shorter than "
                      f"{min_len / sig.fs:.3g} s left out)", UserWarning, stacklevel=4)
        for a, b in keep:
            out.append(Signals(data=sig.data[:, a:b], fs=sig.fs, channels=sig.channels, units=sig.units, t0=sig.t0 + a / sig.fs,
                               meta={**sig.meta, "stretch": [int(a), int(b)]}))
    return out


def _split_channels(model: LumpedModel, sig: Signals):
    idx = {c: i for i, c in enumerate(sig.channels)}
    rows = []
    ins, outs = log_channels(model)  # closed loop: references... in, plant outputs and commands out
    for ch in ins + outs:
        if ch not in idx:
            src = sig.meta.get("source", "the log") if hasattr(sig, "meta") else "the log"
            raise ChannelError(f"{src}: channel {ch!r} of the model is not in the log; channels: {list(sig.channels)}")
        rows.append(idx[ch])
    data = np.asarray(sig.data)[rows]
    n_in = len(ins)
    u, y = data[:n_in], data[n_in:]
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        bad = [ch for ch, r in zip(ins + outs, data) if not np.all(np.isfinite(r))]
        raise ValueError(f"non-finite samples in channel(s) {bad}: the gap diagnosis needs gap-free records")
    return u, y


def _skip_samples(model: LumpedModel, fs: float, u: np.ndarray, y: np.ndarray, transient_s) -> tuple[int, str, int]:
    """Samples at the start of one log left out of every metric, why (one line), and the
    simulations' lead-in in whole periods: ``(skip, reason, lead_periods)`` (with a lead-in the
    skip is one period).

    Given `transient_s`: that, no lead-in. A periodic input whose log is in steady state from
    its first sample (:func:`~vibroscope.gap.levels.steady_state_start`): one period, since the
    simulation from rest has a transient there that the data lack; where three time constants
    ``1 / (zeta omega_n)`` of the nominal model's slowest mode outlast that period, the
    simulations also start enough whole periods before the log (its periodic continuation,
    at most the log's length; :class:`~vibroscope.gap.fit.LogSimulator`) for that transient to
    have decayed where the log begins (the blind suite's harder variant, seed 13 case 026: a
    2.18 Hz mode damped 0.79 %, a time constant of 9.3 s, behind a 5 s period: the simulations
    from rest carried 58 % of their transient into the fitting data). Otherwise three time
    constants of the slowest mode, at most 5 % of the record."""
    n = u.shape[1]
    if transient_s is not None:
        k = int(round(float(transient_s) * fs))
        return k, f"given: {float(transient_s):g} s", 0
    try:
        md = model.modes()
        tau = float(np.max(1.0 / np.maximum(md.damping_ratios * 2 * np.pi * md.natural_frequencies, 1e-9)))
    except Exception:  # noqa: BLE001
        tau = 0.0
    k = int(min(3 * tau * fs, 0.05 * n))
    T = steady_state_start(u, y, fs)
    if T is not None and T > k:
        why = (f"one period ({T} samples, {T / fs:.4g} s): the log is in periodic steady state from its start, "
               "the simulation from rest is not")
        lead = int(min(math.ceil(3 * tau * fs / T) - 1, n // T)) if 3 * tau * fs > T else 0
        if lead > 0:
            why += (f"; the simulations start {lead} period(s) ({lead * T / fs:.4g} s) before the log, so that three "
                    f"time constants of the nominal model's slowest mode ({3 * tau:.3g} s) have passed where it begins")
        return T, why, lead
    return k, f"three time constants of the nominal model's slowest mode ({3 * tau:.3g} s), at most 5 % of the record", 0


def fit_linear_model(model, signals, *, nperseg: int | None = None, time_polish: bool = True) -> LumpedModel:
    """Re-estimate the masses, stiffnesses and dampings of `model` on the logs.

    The FRF (H1, the best linear approximation) of all samples is fitted first, then the
    simulated time response (output error) is polished with
    :func:`scipy.optimize.least_squares`.

    Parameters
    ----------
    model : LumpedModel or second-order TransferFunctionModel
        Start values and structure (elements' linear parts).
    signals : Signals or list of Signals
        Logs holding the model's input and output channels.
    nperseg : int, optional
        Welch segment length for the FRF (default about 4 s).
    time_polish : bool

    Returns
    -------
    LumpedModel
    """
    model = as_lumped(model)
    sigs = [signals] if isinstance(signals, Signals) else list(signals)
    fs = float(sigs[0].fs)
    us, ys = zip(*(_split_channels(model, s) for s in sigs))
    masks = [np.ones(u.shape[1], bool) for u in us]
    nps = nperseg or pow2(min(4 * fs, min(u.shape[1] for u in us) / 4))
    fd = frf_data(us, ys, masks, fs, nps)
    lin = LinearParams(model)
    f, H, coh = fd[0], fd[1], fd[2]
    sel, w = _frf_weights(f, coh, us, fs, nps)
    if is_closed_loop(model):  # the open plant's FRF is not what the loop's log measures: fit in time
        m1, theta = model, np.zeros(len(lin))
    else:
        m1, theta, _, _ = fit_linear_frf(model, lin, f[sel], H[sel], w[sel])
    if not time_polish:
        return m1
    sims = [LogSimulator(u, fs) for u in us]
    x, _, _ = fit_time_domain(lambda x: lin.apply(model, x), theta, np.full(len(lin), -2.5), np.full(len(lin), 2.5),
                              sims, list(ys), masks, [u.shape[1] for u in us], fast=False, max_nfev=10)
    return lin.apply(model, x)


def _frf_weights(f, coh, us, fs, nps, thin: bool = True):
    """The FRF lines a linear fit is made on (in the excited band, coherence above 0.3; with
    `thin`, every n-th of them, at most 600) and each line's weights per output,
    ``sqrt(coh / (1 - coh))`` capped at 10: ``(sel, w)``."""
    from vibroscope.gap.measure import excited_band

    fb = excited_band(np.concatenate(us, axis=1), fs, nps)
    inb = (f >= fb[0]) & (f <= fb[1]) & (f > 0)
    c = np.clip(coh, 0.0, 0.999)
    w = np.sqrt(c / (1 - c))
    w = np.minimum(w, 10.0) * (c > 0.3)
    sel = inb & np.any(w > 0, axis=1)
    return (_thinned(sel) if thin else sel), w


def _thinned(sel):
    """Every n-th line of mask `sel`, at most 600 of them (for the fits' speed)."""
    idx = np.nonzero(sel)[0]
    if idx.size <= 600:
        return sel
    keep = np.zeros_like(sel)
    keep[idx[:: int(math.ceil(idx.size / 600))]] = True
    return keep


def diagnose(
    model,
    signals,
    *,
    effects=None,
    transient_s: float | None = None,
    nperseg: int | None = None,
    workers: int = 2,
    n_full: int = 2,
    progress: bool = False,
    holdout: str = "auto",
    output_sampling: str = "auto",
) -> GapReport:
    """Diagnose the gap between `model` and the logged behaviour.

    Parameters
    ----------
    model : LumpedModel or TransferFunctionModel
        The nominal model. Its ``[[input]]`` channels are the logged command (N), its
        ``[[output]]`` channels the measured responses.
    signals : Signals or list of Signals
        The log(s), each holding the model's input and output channels on one grid (read
        with ``read_mcap(path, channels=model.input_channels() + model.output_channels())``).
        With several logs at one input level the last is held out for validation; logs at
        different levels are each split in time (:func:`~vibroscope.gap.measure.make_split`).
        A log of a periodic input whose response stops repeating with it at a higher level
        than the others (chaos, a subharmonic: :func:`~vibroscope.gap.levels.aperiodic_logs`)
        is left out (with ``holdout='auto'``); ``meta["aperiodic_logs"]`` and the report's
        validation line say which and why.
    effects : sequence of str, optional
        Restrict the candidates (default: the whole vocabulary).
    transient_s : float, optional
        Seconds at the start of each log left out of every metric. Default: one period for a
        log of a periodic input that is in steady state from its first sample
        (:func:`~vibroscope.gap.levels.steady_state_start`: the simulation from rest is not),
        else three time constants of the nominal model's slowest mode, at most 5 % of the
        record; the report's ``meta["transient_reasons"]`` says which, per log.
    nperseg : int, optional
        Welch segment length (samples) for FRFs and spectra. Default
        (:func:`~vibroscope.gap.levels.frf_segment_length`): one period of a periodic input
        (rectangular window, no overlap), else a line spacing of a quarter of the nominal
        model's narrowest half-power bandwidth ``2 zeta f_n`` (at least 8 averages), else
        about 4 s; the report's ``meta["nperseg_reason"]`` says which.
    workers : int
        Threads for the candidate fits (the simulation kernel releases the GIL). The whole
        diagnosis runs with every BLAS pool limited to one thread (threadpoolctl): the
        parallelism is these threads, and a BLAS pool beside them only spins against them. The
        limit is the process's: diagnoses run at once on threads of one process share it, and
        the first to finish restores the pools' threads.
    n_full : int
        Number of nonlinear effect classes fitted jointly with the linear parameters after
        screening.
    progress : bool
        Show a progress bar over the candidates.
    holdout : {'auto', 'last'}, optional
        Several logs: ``'auto'`` (default) holds out the last log when every log is at one
        input level, else the end of each log; ``'last'`` always holds out the last log (a
        validation log the user has chosen, such as a benchmark's test part).
    output_sampling : {'auto', 'filtered', 'sharp', 'point'}, optional
        How the nonlinear simulations bring their outputs to the log's rate
        (:func:`~vibroscope.models.simulate.simulate`): low-passed and decimated by MATLAB's FIR
        stages ('filtered': a digitally decimated record), by a filter flat to 0.46 fs ('sharp':
        a sigma-delta converter's anti-aliasing filter) or taken at the sample instants
        ('point': a sampling ADC without one, where a nonlinearity's harmonics above ``fs / 2``
        alias). ``'auto'`` (default) chooses the one that fits the best screened nonlinear
        candidate best
        (:func:`~vibroscope.gap._candidates.choose_output_sampling`); the report's
        ``meta["output_sampling"]`` says which and why.

    Returns
    -------
    GapReport

    Raises
    ------
    ChannelError
        If a model channel is missing from a log.
    ValueError
        If `output_sampling` is not one of its three values, the logs have different sampling
        rates, ±Inf samples, too little left between
        missing samples, or the model cannot be diagnosed (see :func:`as_lumped`).

    Warns
    -----
    UserWarning
        When a log with missing samples (NaN) is cut into its gap-free stretches: each stretch
        of at least ``4 nperseg`` samples (8 s by default) is diagnosed as a log of its own
        (the simulation restarts at rest; the last stretch of the last log is held out for
        validation), shorter ones are left out; nothing is interpolated across a gap.

    See Also
    --------
    vibroscope.models.simulate.simulate : The nominal model's response to the logged input.
    vibroscope.modal.compare.frequency_shift : Measured against model natural frequencies only.

    Examples
    --------
    A 2-DOF chain logged through itself (20 s of random force at 1 kHz, 2 % output noise): no
    effect is found, and the gap before any fit is the added noise, 0.02. Skipped as a doctest
    (the candidate fits take 10-20 s); a like case runs as
    ``tests/gap/test_diagnose.py::test_none_when_the_model_is_right``.

    >>> import numpy as np
    >>> from vibroscope import Signals, diagnose, simulate
    >>> from vibroscope.models import Damper, Dof, Input, LumpedModel, Output, Spring
    >>> model = LumpedModel(
    ...     dofs=(Dof("m1", 1.0), Dof("m2", 0.5)),
    ...     elements=(Spring(("m1", "ground"), k=4e4), Damper(("m1", "ground"), c=8.0),
    ...               Spring(("m2", "m1"), k=3e4), Damper(("m2", "m1"), c=4.0)),
    ...     inputs=(Input(dof="m1", channel="/f.x"),),
    ...     outputs=(Output("m1", "acceleration", "/a1.x"), Output("m2", "acceleration", "/a2.x")),
    ...     name="chain")
    >>> u = 5 * np.random.default_rng(1).standard_normal(20_000)
    >>> sim = simulate(model, u, 1000.0, noise=0.02, seed=2)
    >>> report = diagnose(model, sim)  # doctest: +SKIP
    >>> report.verdict, round(float(report.gap_before), 2)  # doctest: +SKIP
    ('none', 0.02)
    """
    import warnings

    with warnings.catch_warnings():
        # candidates far from the truth can make the kernel's Newton steps struggle; their
        # (bad) held-out gap is what counts, so the per-simulation warning is not repeated
        warnings.filterwarnings("ignore", message="Newton's iteration did not converge", category=RuntimeWarning)
        # a trial step of a far-off candidate can overflow least_squares' reduction ratio; the
        # optimiser rejects that step by itself
        warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"scipy\.optimize")
        # one BLAS thread for the whole diagnosis, not per probe: the linear simulations' modal
        # recursion ran 2.7x slower with OpenBLAS's two threads than with one (42.6 against 15.8 ms
        # a call, seed 16 case 001 of the harder blind variant), and that case's diagnosis took
        # 105.9 s against 76.6 s with the same report; the per-probe limit (prefix_gap) left the
        # time-domain fits' simulations at two threads, and it restored two threads on leaving
        # while the other worker was still inside it
        return one_blas_thread(_diagnose)(model, signals, effects=effects, transient_s=transient_s,
                                          nperseg=nperseg, workers=workers, n_full=n_full, progress=progress,
                                          holdout=holdout, output_sampling=output_sampling)


def _diagnose(model, signals, *, effects, transient_s, nperseg, workers, n_full, progress, holdout,
              output_sampling) -> GapReport:
    if output_sampling not in ("auto", *OUTPUT_SAMPLINGS):
        raise ValueError(f"{output_sampling=} must be 'auto', 'filtered', 'sharp' or 'point'")
    run = _prepare_logs(model, signals, effects=effects, transient_s=transient_s, nperseg=nperseg, holdout=holdout)
    run.output_sampling = output_sampling
    _place_upper_residual(run)
    _simulate_nominal(run)
    _refit_linear(run)
    gather_evidence(run)
    fit_candidates(run, workers=workers, n_full=n_full, progress=progress)
    rank_candidates(run, workers=workers)
    if recheck_output_sampling(run):
        # the winner says the other output sampling: every candidate is evaluated and ranked again under it
        rank_candidates(run, workers=workers)
    select_further_effects(run, workers=workers)
    _check_incoherent(run)
    return _build_report(run)


def _prepare_logs(model, signals, *, effects, transient_s, nperseg, holdout) -> Run:
    """The logs split at their gaps and into input and output rows, the transient to skip, the
    fit / held-out split, one simulator per log, the FRF segment length (and window) and the
    effects to try (closed loop: less those that do not apply). Returns a new :class:`Run`."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    model = as_lumped(model)
    sigs = [signals] if isinstance(signals, Signals) else list(signals)
    if not sigs:
        raise ValueError("no log given")
    sigs = _split_at_gaps(model, sigs, nperseg)
    fs = float(sigs[0].fs)
    for s in sigs[1:]:
        if abs(float(s.fs) - fs) > 1e-9 * fs:
            raise ValueError(f"logs have different sampling rates: {fs} Hz and {s.fs} Hz")
    pairs = [_split_channels(model, s) for s in sigs]
    us = [p[0] for p in pairs]
    out_ch = log_channels(model)[1]
    ys, accel_means = _remove_acceleration_means(model, out_ch, [p[1] for p in pairs])
    closed = is_closed_loop(model)
    units = [sigs[0].units[list(sigs[0].channels).index(c)] if sigs[0].units else "" for c in out_ch]
    in_ch0 = log_channels(model)[0][0]
    in_unit = (sigs[0].units[list(sigs[0].channels).index(in_ch0)] if sigs[0].units else "") or "N"
    skip_why = [_skip_samples(model, fs, u, y, transient_s) for u, y in zip(us, ys)]
    # a log at a higher level whose response no longer repeats with its periodic input (chaos, a
    # subharmonic) is a trajectory no model reproduces sample by sample: left out (not with
    # holdout="last": the user's validation log is kept as given)
    aper = (aperiodic_logs(ys, us, [np.arange(u.shape[1]) >= k for u, (k, _, _) in zip(us, skip_why)], fs)
            if holdout == "auto" else None)
    if aper is not None:
        keep = [i for i in range(len(sigs)) if i not in aper.logs]
        sigs, pairs, skip_why = [sigs[i] for i in keep], [pairs[i] for i in keep], [skip_why[i] for i in keep]
        us = [p[0] for p in pairs]
        ys, accel_means = _remove_acceleration_means(model, out_ch, [p[1] for p in pairs])
    skips = [k for k, _, _ in skip_why]
    split = make_split(us, fs, skip=skips, holdout=holdout)
    sims = [LogSimulator(u, fs, period=k, lead_periods=lead) for u, (k, _, lead) in zip(us, skip_why)]
    n_min = min(u.shape[1] for u in us)
    window = "hann"
    if nperseg:
        nps, nps_reason = int(nperseg), f"given: nperseg = {int(nperseg)} samples"
    else:
        # the FRF resolves the modes it fits: whole periods of a periodic input, else a line
        # spacing of a quarter of the nominal model's narrowest half-power bandwidth
        try:
            md = model.modes()
            bw = 2 * np.asarray(md.damping_ratios) * np.asarray(md.natural_frequencies)
        except Exception:  # noqa: BLE001 - no modes (a free body): the default length
            bw = None
        n_fit = max(int(np.sum(m)) for m in split.fit)
        nps, nps_reason = frf_segment_length(us[0], fs, mode_bandwidths_hz=bw, n_samples=n_fit)
        if nps_reason.startswith("one period"):
            window = "boxcar"
        nps = min(nps, max(n_min // 2, 64))
        # Welch segments lie wholly inside a fitting stretch (an interleaved split's are blocks)
        run_max = max((int(np.max(b - a)) for m in split.fit for a, b in [true_runs(m)] if len(a)), default=nps)
        if nps > run_max >= 64:
            nps, nps_reason = run_max, nps_reason + f"; capped at the longest fitting stretch, {run_max} samples"
            if window == "boxcar":  # no longer whole periods: a rectangular window would leak
                window, nps_reason = "hann", nps_reason + ", Hann window"
        # Welch segments (placed as masked_csd places them) wholly inside the fitting stretches: one
        # whole period at least, else MIN_WELCH_SEGMENTS (fitting stretches cut in blocks by the
        # split can hold none of a length the record as a whole allows)
        n0, k0 = nps, _welch_segments(split.fit, nps, window)
        while nps > 64 and _welch_segments(split.fit, nps, window) < (1 if window == "boxcar" else MIN_WELCH_SEGMENTS):
            nps, window = max(64, nps // 2), "hann"  # half a period is not whole periods
        if nps < n0:
            nps_reason += (f"; halved to {nps} samples ({_welch_segments(split.fit, nps, window)} segments): "
                           f"{k0} of {n0} lie wholly inside the fitting stretches at the Welch positions")
    effect_set = set(EFFECT_TABLE) if effects is None else set(effects)
    excluded = {e: why for e, why in CLOSED_LOOP_EXCLUDED.items() if e in effect_set} if closed else {}
    effect_set -= set(excluded)
    return Run(t_start=t_start, timings=timings, model=model, sigs=sigs, fs=fs, us=us, ys=ys, out_ch=out_ch,
                closed=closed, units=units, in_unit=in_unit, skips=skips, skip_reasons=[w for _, w, _ in skip_why], split=split,
                sims=sims, nps=nps, aperiodic=aper,
                nps_reason=nps_reason, window=window, effect_set=effect_set, excluded=excluded,
                accel_means=accel_means)


#: the fewest Hann-windowed Welch segments inside the fitting stretches before the segment length is
#: halved: one segment is no average (seed 7002 case 010, --input-kind sweep: 6000 samples, one
#: segment; 3000, eleven); more is not asked for, since resolution costs more than averages on a
#: lightly damped mode (seed 3737 case 006, 2 s blocks: 4554 samples in two segments name the
#: asymmetric friction within 10 %, 2277 in eleven move its smaller force 34 % off)
MIN_WELCH_SEGMENTS = 2


def _welch_segments(masks: list, nperseg: int, window: str) -> int:
    """Welch segments of `nperseg` samples wholly inside `masks` (one mask per log), at the
    positions :func:`~vibroscope.gap.measure.masked_csd` uses
    (:func:`~vibroscope.gap.measure.welch_starts`)."""
    return sum(len(welch_starts(m, nperseg, window)) for m in masks)


def _remove_acceleration_means(model: LumpedModel, out_ch: list, ys: list) -> tuple[list, dict]:
    """Each log's acceleration outputs less their mean over the log, and the means removed
    (``{channel: [mean per log]}``, m/s^2).

    A model's acceleration has no mean over a record that starts and ends at rest or in
    periodic steady state (the mean is the change of velocity over the record's length), so a
    measured mean is the sensor's: an accelerometer's bias, or gravity along an inertial
    sensor's axis (``sensor_msgs/msg/Imu``'s ``linear_acceleration`` holds it). Left in, it
    counts as a gap no model can close (gravity on one and 0.35 m/s^2 on the other
    accelerometer of a 2-DOF chain with a hidden friction: the friction named, but the
    augmented model left 0.197 held-out against a floor of 0.021). Displacement and velocity
    outputs keep their means (a force offset or a drive's travel shows there), and so do all
    outputs of a model with a rigid-body mode (a zero eigenvalue of its state matrix), which a
    constant force accelerates on average, and of a closed loop (left as they are; its plant is
    usually such a body)."""
    rows = [i for i, o in enumerate(model.outputs) if o.quantity == "acceleration"]  # out_ch starts with them
    if not rows or is_closed_loop(model):
        return ys, {}
    lam = np.abs(np.linalg.eigvals(model.state_matrices()[0]))
    if np.any(lam <= 1e-9 * max(float(lam.max(initial=0.0)), 1.0)):  # a free body: its acceleration can have a mean
        return ys, {}
    out, means = [], {out_ch[i]: [] for i in rows}
    for y in ys:
        y = np.array(y, float)
        for i in rows:
            mu = float(np.mean(y[i]))
            y[i] -= mu
            means[out_ch[i]].append(mu)
        out.append(y)
    return out, means


#: the pseudo-mode that carries a modal model's upper residual is placed from the data when that
#: fits the lowest level's FRF better than the convention (4 times the highest mode) by this factor
UPPER_PLACE_GAIN = 0.9


def _place_upper_residual(run: Run) -> None:
    """Stage 0, a modal model whose upper residual is carried as a pseudo-mode
    (:data:`~vibroscope.models.modal_coordinates.UPPER_PSEUDO_NAME`): its frequency and static
    compliance fitted to the FRF of the logs at the lowest input level (within 1.5 times the
    lowest RMS; their fitting samples), its shape kept.

    A modal test's band ends below modes it did not fit, and its upper residual is a constant
    that stands for their FRF *inside the band*, where they are amplified ``1 / (1 - (f /
    f_r)^2)``: a mode 1.4 times above the band's top counts twice there. Realised at the
    convention's frequency (4 times the highest mode) with that constant as its static
    compliance, the pseudo-mode carries too much static flexibility between the measured points
    (2.4 times the true third mode's across the joint of ``examples/gap/gvt_joint.py``), and an
    element placed between them acts on the wrong stiffness. The data's FRF at the lowest level
    (the least nonlinear) places it: the frequency between 1.02 and 4 times the highest mode,
    the compliance within a factor ``e^2.5`` of the residual's. Kept when it fits that FRF
    better than the convention by :data:`UPPER_PLACE_GAIN` and the lowest level's fitting data
    in time no worse; ``run.upper_placement`` records what was done (the report's
    ``meta["upper_residual"]``). Ewins, *Modal Testing*, 2000, sec. 4.4 (residual terms and the
    pseudo-modes that stand for the modes out of range)."""
    from scipy.optimize import least_squares

    from vibroscope.gap.fit import frf_residual
    from vibroscope.models.modal_coordinates import UPPER_PSEUDO_FACTOR, UPPER_PSEUDO_NAME

    model = run.model
    names = [d.name for d in model.dofs]
    if run.closed or UPPER_PSEUDO_NAME not in names or not model.point_names():
        return
    lin = LinearParams(model, which=[f"m:{UPPER_PSEUDO_NAME}", f"k:{UPPER_PSEUDO_NAME}-ground",
                                     f"c:{UPPER_PSEUDO_NAME}-ground"])
    if len(lin) < 2 or lin.names[0] != f"m:{UPPER_PSEUDO_NAME}":
        return
    i_u = names.index(UPPER_PSEUDO_NAME)
    f_u0 = float(np.sqrt(model.K[i_u, i_u] / model.M[i_u, i_u]) / (2 * np.pi))
    f_top = float(f_u0 / UPPER_PSEUDO_FACTOR)
    rms = [float(np.sqrt(np.mean(u[0, m] ** 2))) if m.any() else np.inf for u, m in zip(run.us, run.split.fit)]
    low = [i for i, r in enumerate(rms) if np.isfinite(r) and r <= 1.5 * min(rms)]
    if not low:
        return
    us, ys, masks = [run.us[i] for i in low], [run.ys[i] for i in low], [run.split.fit[i] for i in low]
    fd = frf_data(us, ys, masks, run.fs, run.nps, run.window)
    if fd is None:
        return
    f, H, coh, _, _ = fd
    sel, w = _frf_weights(f, coh, us, run.fs, run.nps)
    if int(sel.sum()) < 10:
        return
    f, H, w = f[sel], H[sel], w[sel]
    has_c = len(lin) == 3

    def theta(x):
        # x = (log f_u / f_u0, log compliance factor): k / k0 = 1 / c, m / m0 = k / k0 (f_u0 / f_u)^2,
        # the damper keeps the pseudo-mode's damping ratio (c ~ sqrt(k m))
        tk = -x[1]
        tm = tk - 2 * x[0]
        return np.array([tm, tk] + ([0.5 * (tk + tm)] if has_c else []))

    def build(x):
        return lin.apply(model, theta(x))

    def res(x):
        try:
            return frf_residual(build(x), f, H, w)
        except (ValueError, np.linalg.LinAlgError):
            return np.full(2 * w.size, 1e3)

    lo = np.array([np.log(1.02 * f_top / f_u0), -2.5])
    hi = np.array([0.0, 2.5])
    r0 = res(np.zeros(2))
    best = None
    for a in (0.25, 0.5, 0.75):  # starts spread over the frequency range (a log scale)
        x0 = np.array([lo[0] + a * (hi[0] - lo[0]), 0.0])
        sol = least_squares(res, x0, bounds=(lo, hi), method="trf", max_nfev=60)
        if best is None or sol.cost < best.cost:
            best = sol
    c0, c1 = float(np.sum(r0 ** 2)), float(2 * best.cost)
    placed = build(best.x)
    info = {"method": "the pseudo-mode of the upper residual: frequency and static compliance fitted to the "
                      "FRF of the lowest input level (logs " + ", ".join(str(i) for i in low) + "), shape kept",
            "convention_hz": f_u0, "frequency_hz": float(f_u0 * np.exp(best.x[0])),
            "compliance_factor": float(np.exp(best.x[1])), "frf_cost_convention": c0, "frf_cost_placed": c1}

    def low_gap(m_):
        return nrmse(ys, [run.sims[i].run(m_) for i in low], masks)

    keep = c1 < UPPER_PLACE_GAIN * c0
    if keep:
        g0, g1 = low_gap(model), low_gap(placed)
        info.update(gap_fit_convention=g0, gap_fit_placed=g1)
        keep = bool(np.isfinite(g1) and g1 <= g0)
    info["kept"] = bool(keep)
    if keep:
        run.model = placed
    run.upper_placement = info


def _simulate_nominal(run: Run) -> None:
    """Stage 1: the nominal model simulated on every log, its held-out gap, the non-transient
    sample masks, the noise floor beyond the band and the floor a periodic input measures in it
    (:func:`~vibroscope.gap.levels.period_floor`). Sets ``y_nom``, ``gap_before``, ``all_masks``,
    ``nf``, ``floor``, ``period``."""
    model, sims, ys, us, split, fs, nps = run.model, run.sims, run.ys, run.us, run.split, run.fs, run.nps
    t = time.perf_counter()
    y_nom = [sim.run(model) for sim in sims]
    gap_before = nrmse(ys, y_nom, split.validation)
    all_masks = []
    for u, sk in zip(us, run.skips):
        m = np.ones(u.shape[1], bool)
        m[:sk] = False
        all_masks.append(m)
    # normalised on the held-out samples, where the gaps it is compared with are measured
    nf = noise_floor(ys, us, all_masks, fs, nps, norm_masks=split.validation)
    floor = nf.nrmse
    run.timings["nominal"] = time.perf_counter() - t
    run.y_nom, run.gap_before, run.all_masks, run.nf, run.floor = y_nom, gap_before, all_masks, nf, floor
    run.period = period_floor(ys, us, all_masks, fs)


def _refit_linear(run: Run) -> None:
    """Stage 2: the H1 of the fitting data and the nominal structure's linear parameters
    re-estimated on it, then in time; started from the FRF fit and from the nominal, the better
    on the fitting data is kept, and the refit is never worse there than the nominal model
    itself. Sets ``fd``, ``sel``, ``w``, ``lin``, the parameter bounds and sample counts,
    ``theta``, ``refit``, ``y_ref``, ``gap_refit`` and the fitting gaps."""
    model, sims, ys, us, split, fs, nps = run.model, run.sims, run.ys, run.us, run.split, run.fs, run.nps
    closed, window = run.closed, run.window
    t = time.perf_counter()
    fd = frf_data(us, ys, split.fit, fs, nps, window)
    if fd is None:
        raise ValueError(f"too little fitting data for nperseg={nps}")
    f, H, coh, _, _ = fd
    dense, w = _frf_weights(f, coh, us, fs, nps, thin=False)
    sel = _thinned(dense)
    lin = LinearParams(model)
    # closed loop: the open plant's FRF is not the loop's (reference to outputs): time domain only
    theta0 = None if closed else fit_linear_frf(model, lin, f[sel], H[sel], w[sel])[1]
    ns_fit = split.fit_prefix
    lo_l, hi_l = np.full(len(lin), -2.5), np.full(len(lin), 2.5)
    # time-domain polish on up to 20 s of the fitting data (the FRF fit is biased by leakage)
    ns_pol = [min(n, max(s_, int(20 * fs))) if n else 0 for n, s_ in zip(ns_fit, split.screen_prefix)]
    run.ns_pol = ns_pol

    def fit_gap(x):
        return run.fit_gap(lin.apply(model, x))

    zeros = np.zeros(len(lin))
    g_nom_fit = fit_gap(zeros)
    g_frf_fit = fit_gap(theta0) if theta0 is not None else float("inf")
    x_start = theta0 if g_frf_fit <= g_nom_fit else zeros
    theta, _, _ = fit_time_domain(lambda x: lin.apply(model, x), x_start, lo_l, hi_l, sims, ys, split.fit, ns_pol,
                                  fast=False, max_nfev=6)
    g_ref_fit = fit_gap(theta)
    refit_note = "FRF fit then time-domain polish" if x_start is theta0 else "time-domain fit from the nominal"
    if closed:
        refit_note += " (closed loop: the open plant's FRF does not apply)"
    if not g_ref_fit <= g_nom_fit:
        theta, g_ref_fit, refit_note = zeros, g_nom_fit, "the nominal parameters (no refit was better on the fitting data)"
    refit = lin.apply(model, theta)
    y_ref = [sim.run(refit) for sim in sims]
    gap_refit = nrmse(ys, y_ref, split.validation)
    run.fd, run.sel, run.w, run.lin = fd, sel, w, lin
    # every line, for the searches of narrow features (the extra-mode starts): thinned to every
    # 13th line of 0.1 Hz, a 3.87 Hz absorber below a 7.08 Hz host fell between lines (the blind
    # suite's harder variant, seed 13 case 020)
    run.sel_dense = dense
    run.ns_fit, run.lo_l, run.hi_l, run.ns_pol = ns_fit, lo_l, hi_l, ns_pol
    run.g_nom_fit, run.g_ref_fit, run.theta, run.refit_note = g_nom_fit, g_ref_fit, theta, refit_note
    run.refit, run.y_ref, run.gap_refit = refit, y_ref, gap_refit
    if model.point_names() and not closed:
        _refit_physical(run, f[sel], H[sel], w[sel])
    run.timings["refit"] = time.perf_counter() - t


def _refit_physical(run: Run, f, H, w) -> None:
    """Stage 2b, a model with measured points (modal coordinates): the ``parameter_mismatch``
    explanation refitted with physical stiffness and damping changes at the connections as well
    (:class:`~vibroscope.gap.effects.LinearParams` with ``physical=True``: they couple the modes
    and change their shapes, as a physical spring or damper that differs from the identified
    one does),
    FRF fit then time-domain polish from the better of it and the per-mode refit; kept as
    ``run.pm`` when better on the fitting data. The nonlinear candidates stay on the per-mode
    refit: a stiffness change taken there would take the share of a joint or a clearance."""
    model, sims, ys, split, ns_pol = run.model, run.sims, run.ys, run.split, run.ns_pol
    lin_p = LinearParams(model, physical=True)
    if len(lin_p) == len(run.lin):
        return

    def fit_gap(x):
        return run.fit_gap(lin_p.apply(model, x))

    x_ref = np.concatenate([run.theta, np.zeros(len(lin_p) - len(run.lin))])
    x_frf = fit_linear_frf(model, lin_p, f, H, w)[1]
    g_frf = fit_gap(x_frf)
    x_start = x_frf if g_frf < run.g_ref_fit else x_ref
    lo, hi = np.full(len(lin_p), -2.5), np.full(len(lin_p), 2.5)
    theta_p, _, _ = fit_time_domain(lambda x: lin_p.apply(model, x), x_start, lo, hi, sims, ys, split.fit, ns_pol,
                                    fast=False, max_nfev=6)
    g_fit = fit_gap(theta_p)
    if not g_fit < run.g_ref_fit:
        return
    refit_p = lin_p.apply(model, theta_p)
    y_p = [sim.run(refit_p) for sim in sims]
    run.pm = MismatchFit(lin=lin_p, theta=theta_p, model=refit_p, outputs=y_p, gap=nrmse(ys, y_p, split.validation),
                         gap_fit=g_fit)
    run.refit_note += ("; parameter_mismatch refitted with physical stiffness and damping changes at the measured points' "
                       f"connections as well (fitting gap {g_fit:.4g})")


def _check_incoherent(run: Run) -> None:
    """Stage 5b: an ``unexplained`` gap that is not a linear function of the input.

    The noise floor assumes white noise seen beyond the excited band; a sensor whose
    anti-aliasing filter shapes its noise, or a force the log does not hold (an unlogged
    disturbance, the part of a shaker's force its load cell misses), puts more in the band than
    beyond it, and the nominal's gap stays above that floor whatever model is fitted. The
    nominal's residual is split into its part coherent with the logged input(s) and the rest
    (:func:`~vibroscope.gap.measure.coherent_gap`, every non-transient sample). When the verdict
    is ``unexplained`` and the coherent part is within :data:`NONE_FACTOR` times the noise floor
    (plus three times the estimate's own scatter, and never beyond :data:`PM_UNEXPLAINED` times
    the floor: over few averages the scatter allows any part), the nominal is the best linear approximation
    of the data. First, the admissible candidate with the lowest held-out gap whose own
    residual's coherent part is so, significantly better than the nominal and explaining more
    than the linear refit, is the verdict (:func:`_best_beyond_refit`: it explains what a model
    can; a friction fitted to its true force under a disturbance 8 % of the input's RMS lost to
    the refit on the parameter penalty, fresh seed 7102 case 004). Else, unless the linear refit
    is significantly better than the nominal on held-out data (batch-means t of
    :func:`~vibroscope.gap.measure.nested_gain` at least :data:`NESTED_T`), the verdict is
    ``none`` and the report says what the gap is (``meta["incoherent_gap"]``); not where the input
    is periodic and the residual's incoherent part exceeds :data:`PERIOD_NONE_FACTOR` times the
    larger of the outputs' variation from period to period and the white floor (it repeats with
    the period: a distortion, not noise; ``meta["incoherent_gap"]["repeats"]`` says so; not
    applied when that variation grows with the level, :attr:`PeriodFloor.grows_with_level
    <vibroscope.gap.levels.PeriodFloor.grows_with_level>`: then the response itself stops
    repeating and the variation is no floor to compare with). Else, when the refit's own residual is so (on the held-out
    samples; the nominal's is not, or the refit is significantly better) and the BLA does not
    change with the excitation level, the verdict is ``parameter_mismatch``. Neither ``none``
    nor ``parameter_mismatch`` is given so when the residual repeats with a periodic input's
    period (above), nor when its share of the measured power grows
    with the input level by more than :data:`RESIDUAL_GROWTH` over levels at least
    :data:`~vibroscope.gap.measure.LOG_LEVEL_RATIO` apart
    (:func:`~vibroscope.gap.measure.residual_growth`): noise and a disturbance grow at most like
    the signal, a hardening spring's or a clipped force's distortion faster. A nonlinearity whose BLA is the
    nominal's, and that no candidate fits, is called ``none`` by this rule when the input is
    not periodic (a random input gives no measure of what repeats).

    Every verdict: ``meta["incoherent_gap"]["period_floor"]`` holds the floor a periodic input
    measures in the band (:func:`~vibroscope.gap.levels.period_floor`, the outputs' variation
    from period to period; None without enough alike periods) beside the white floor (the
    candidates were ranked against it when it is the larger by
    :data:`~vibroscope.gap._ranking.PERIOD_RANK_FACTOR`: :func:`~vibroscope.gap._ranking.ranking_floor`).
    """
    fs, nps, window = run.fs, run.nps, run.window
    cg_nom = coherent_gap(run.ys, run.y_nom, run.us, run.all_masks, fs, nps, window=window)
    cg_ref = coherent_gap(run.ys, run.y_ref, run.us, run.split.validation, fs, nps, window=window)

    def within(cg):
        # within NONE_FACTOR x the floor, allowing three times the estimate's scatter -- but never
        # beyond PM_UNEXPLAINED x the floor: over few averages the scatter allows any coherent part
        # (fresh seed 17 case 007 of the harder blind variant, a dead-zone spring, one 5 Hz mode:
        # the refit's coherent part 0.164 over 3 averages, scatter 0.021, passed against a floor of
        # 0.045, and a refit at 7.4x the floor was named parameter_mismatch)
        return bool(np.isfinite(cg.coherent) and cg.coherent ** 2 <= (NONE_FACTOR * run.floor) ** 2 + 3 * cg.spread
                    and cg.coherent <= PM_UNEXPLAINED * run.floor)

    def strictly_within(cg):
        return bool(np.isfinite(cg.coherent) and cg.coherent <= NONE_FACTOR * run.floor)

    info = {"method": ("each model's residual split into its part coherent with the logged input(s) (multiple "
                       "coherence, its estimate's bias removed) and the rest (noise of any colour, an unlogged "
                       "disturbance, a nonlinearity's distortion); the nominal's on every non-transient sample, "
                       "the linear refit's on the held-out samples"),
            "nominal": cg_nom.to_dict(), "refit": cg_ref.to_dict(),
            "threshold_coherent": float(NONE_FACTOR * run.floor),
            "cap_coherent": float(PM_UNEXPLAINED * run.floor), "changed": None}
    # the in-band floor a periodic input measures, the outputs' variation from period to period,
    # beside the white floor seen beyond the band (the ranking's, ranking_floor)
    pf = run.period
    info["period_floor"] = (None if pf is None else
                            pf.to_dict() | {"white_floor": float(run.floor),
                                            "ratio_to_white_floor": float(pf.nrmse / run.floor) if run.floor > 0
                                            else None})
    vetoed = {}

    def repeats(cg, which: str) -> bool:
        # a residual whose incoherent part is far beyond the period-to-period variation repeats
        # with the input's period: the response of the system to the input, not noise or a
        # disturbance (a distortion is incoherent with the input, not with its period)
        if pf is None or pf.grows_with_level or not np.isfinite(cg.incoherent):
            return False
        thr = PERIOD_NONE_FACTOR * max(pf.nrmse, run.floor)
        if cg.incoherent > thr:
            vetoed.setdefault(which, (cg.incoherent, thr))
            return True
        return False

    if run.verdict == "unexplained" and run.gap_before > NONE_FACTOR * run.floor:
        level_flagged = bool(run.level.get("flagged")) if isinstance(run.level, dict) else False

        def steady(y_model, masks, logs=None) -> bool:
            # the residual does not grow with the input level (noise, a disturbance), or no levels
            # (`logs`: the logs of `y_model` and `masks` when not all of them)
            ys_, us_ = (run.ys, run.us) if logs is None else ([run.ys[i] for i in logs], [run.us[i] for i in logs])
            g, ratio = residual_growth(ys_, y_model, us_, masks, fs)
            info.setdefault("residual_growth", []).append({"growth": g, "input_ratio": ratio})
            return not (np.isfinite(g) and ratio >= LOG_LEVEL_RATIO and g > RESIDUAL_GROWTH)

        pm = next((c for c in run.ordered if c[0].effect == "parameter_mismatch"), None)
        # the refit's held-out gain over the nominal, significant or not (batch means)
        t_ref = held_out_gain(run.ys, run.y_nom, run.y_ref, run.split, range(len(run.ys)), fs)
        info["refit_gain_t"], info["threshold_t"] = t_ref, NESTED_T
        # whether the nominal's residual repeats with a periodic input's period, read whichever
        # test stops `none` first, so that the report says so (seed 12 case 007: its coherent part
        # beyond PM_UNEXPLAINED x the floor now stops `none` before this test is reached)
        nom_repeats = repeats(cg_nom, "none")
        # a refit whose coherent part passes only on the scatter allowance is not known to explain
        # all a linear model can: a candidate whose own coherent part is within NONE_FACTOR x the
        # floor without that allowance explains more (seed 7353 case 002, an extra mode of 16 Hz
        # under a disturbance: the refit's coherent part 0.029 over 4 averages, the extra mode's
        # 0.012, floor 0.016)
        ref_within, ref_strict = within(cg_ref), strictly_within(cg_ref)
        info["refit_within"], info["refit_strictly_within"] = ref_within, ref_strict
        on_allowance = ref_within and not ref_strict
        if (best := _best_beyond_refit(run, strictly_within if on_allowance else within, ref_within, steady,
                                       linear_yields=on_allowance)) is not None:
            b, cg_b, t_b = best
            run.ordered = [b] + [c for c in run.ordered if c is not b]
            run.chosen, run.shares, run.verdict = [b], [1.0], b[0].effect
            info["best"] = {"effect": b[0].effect, "where": dict(b[0].where), "coherent_gap": cg_b.to_dict(),
                            "gain_over_refit_t": t_b}
            info["changed"] = (f"unexplained -> {b[0].effect}: its held-out gap {cg_b.total:.4g} is {cg_b.incoherent:.4g} "
                               f"not coherent with the input and {cg_b.coherent:.4g} coherent, within {NONE_FACTOR:g} x "
                               f"the noise floor {run.floor:.4g}, and it explains more than the linear refit (whose "
                               f"coherent part is {cg_ref.coherent:.4g}; held-out gain t {t_b:.3g}, {NESTED_T:g} asked "
                               "when that is within): it explains what a model can, the rest is coloured noise or an "
                               "unlogged disturbance")
        elif within(cg_nom) and t_ref < NESTED_T and steady(run.y_nom, run.all_masks) and not nom_repeats:
            none_c = next(c for c in run.ordered if c[0].effect == "none")
            run.ordered = [none_c] + [c for c in run.ordered if c is not none_c]
            run.chosen, run.shares, run.verdict = [], [], "none"
            info["changed"] = (f"unexplained -> none: the nominal's gap {cg_nom.total:.4g} is {cg_nom.incoherent:.4g} "
                               f"not coherent with the input and {cg_nom.coherent:.4g} coherent, within "
                               f"{NONE_FACTOR:g} x the noise floor {run.floor:.4g} (white noise assumed beyond the "
                               f"band), and the linear refit is not significantly better on held-out data (t "
                               f"{t_ref:.3g} < {NESTED_T:g}): the model is the data's best linear approximation; the "
                               "rest is coloured noise or an unlogged disturbance that no candidate explained on "
                               "held-out data")
        elif (pm is not None and not level_flagged and not pm[0].vanished and within(cg_ref)
              and steady(run.y_ref, run.split.validation) and not repeats(cg_ref, "parameter_mismatch")):
            run.ordered = [pm] + [c for c in run.ordered if c is not pm]
            run.chosen, run.shares, run.verdict = [pm], [1.0], "parameter_mismatch"
            info["changed"] = (f"unexplained -> parameter_mismatch: the refit's held-out gap {cg_ref.total:.4g} is "
                               f"{cg_ref.incoherent:.4g} not coherent with the input and {cg_ref.coherent:.4g} "
                               f"coherent, within {NONE_FACTOR:g} x the noise floor {run.floor:.4g}, the nominal's "
                               f"coherent part {cg_nom.coherent:.4g} is not (or the refit is significantly better "
                               f"on held-out data: t {t_ref:.3g}), no other candidate explains more, and the BLA does "
                               "not change with the level: the rest is coloured noise or an unlogged disturbance")
    if run.verdict == "unexplained" and info["changed"] is None and vetoed:
        which, (inc, thr) = next(iter(vetoed.items()))
        whose = {"none": "the nominal's", "parameter_mismatch": "the refit's"}[which]
        info["repeats"] = (f"not {which}: {whose} residual is {inc:.4g} not coherent with the input, more than {thr:.4g} "
                           f"({PERIOD_NONE_FACTOR:g} x the larger of the outputs' variation from period to period, "
                           f"{pf.nrmse:.4g}, and the white floor): it repeats with the input's period, a response to "
                           "the input that no candidate explained, not noise or a disturbance")
    run.incoherent = info


#: a residual not coherent with a periodic input is noise or an unlogged disturbance only while it
#: is within this many times the outputs' variation from period to period (the in-band floor,
#: :func:`~vibroscope.gap.levels.period_floor`); beyond it, it repeats with the period, and is the
#: system's response to the input (a nonlinear distortion), so the ``unexplained`` verdict stands
#: (the blind suite's harder variant, seed 12 case 007: a clearance replacing a spring to ground,
#: 0.196 incoherent against a period-to-period 0.067, named ``none`` at 13x the white floor)
PERIOD_NONE_FACTOR = 2.0


def _best_beyond_refit(run: Run, cg_thr, refit_within: bool, steady=None, *, linear_yields: bool = False):
    """For :func:`_check_incoherent`: the admissible candidate (an effect of the vocabulary other
    than the linear refit, not vanished) of the lowest held-out gap below the refit's and the
    nominal's whose held-out residual's coherent part passes `cg_thr`, whose held-out gain over
    the nominal is significant (batch-means t of :func:`~vibroscope.gap.measure.nested_gain` at
    least :data:`NESTED_T`; not its score, which is measured against the white floor) and that
    explains more than the refit: the refit's own coherent part does not pass (`refit_within`
    False: it lacks a linear term the candidate has, an extra mode) or the candidate's held-out
    gain over it is significant too (a nonlinear term, or a constant force: an input offset's
    response is not coherent with a zero-mean input, fresh seed 7105 case 005). `linear_yields`
    True: the refit's coherent part passes only on the scatter allowance of few averages, and
    `cg_thr` is then the strict bound (NONE_FACTOR x the floor, no allowance); a linear candidate
    (an extra mode, a delay) passing it explains more than the refit without a t over it, a
    nonlinear one still needs that t (``benchmarks/gap`` seed 7353 case 002 and seed 7355 case 011,
    extra modes under an unlogged disturbance with t 3.63 and 3.12 over the refit, were named
    ``parameter_mismatch``; seed 7353 case 009, a mismatch whose refit passes the same way, would
    have been named ``backlash`` with a nonlinear candidate let through at t 0.49). With `steady`
    (``steady(outputs, masks, logs) -> bool``, the residual-growth test of :func:`_check_incoherent`
    on the logs `logs` of the held-out outputs),
    a candidate whose residual's share of the measured power grows with the input level is not
    taken: what it leaves is a distortion, not noise or a disturbance (the blind suite's harder
    variant, seed 16 case 000: a hardening cubic + quintic spring whose true model is chaotic
    and itself leaves 0.63; a hysteresis at 0.66, 17x the floor, passed the coherent-part test
    on a spread of 0.05 over nine averages and was named; its residual's share grows 3.1x over
    the logs' level ratio of 5.2).
    Returns ``(candidate, its CoherentGap, t over the refit)`` or None (of the ten best at most)."""
    adm = sorted((c for c in run.ordered if c[0].effect not in ("none", "parameter_mismatch") and c[3] is not None
                  and not c[0].vanished and isinstance(c[2], dict)
                  and c[0].gap_after < min(run.gap_refit, run.gap_before)), key=lambda c: c[0].gap_after)
    for b in adm[:10]:
        logs = [i for i in run.val_logs if i in b[2]]
        if not logs:
            continue
        ys, yb = [run.ys[i] for i in logs], [b[2][i] for i in logs]
        masks = [run.split.validation[i] for i in logs]
        cg_b = coherent_gap(ys, yb, [run.us[i] for i in logs], masks, run.fs, run.nps, window=run.window)
        if not cg_thr(cg_b):
            continue
        if held_out_gain(run.ys, run.y_nom, b[2], run.split, logs, run.fs) < NESTED_T:
            continue  # not significantly better than the nominal itself
        t_b = held_out_gain(run.ys, run.y_ref, b[2], run.split, logs, run.fs)
        # a refit within only on the scatter allowance (linear_yields) yields to a linear
        # candidate strictly within; a nonlinear one must still be significantly better than it
        lin = EFFECT_TABLE[b[0].effect].kind == "linear"
        if not refit_within or (linear_yields and lin) or t_b >= NESTED_T:
            if steady is not None and not steady(yb, masks, logs):
                continue
            return b, cg_b, t_b
    return None


def _build_report(run: Run) -> GapReport:
    """Stage 6: the localisation (channels, bands and regimes of the nominal model on the last
    log's held-out samples), the figures' data (spectra, FRFs, traces) and the
    :class:`~vibroscope.gap.report.GapReport` of the whole run."""
    model, sims, ys, us, split, fs, nps = run.model, run.sims, run.ys, run.us, run.split, run.fs, run.nps
    sigs, out_ch, units, nf, all_masks = run.sigs, run.out_ch, run.units, run.nf, run.all_masks
    y_nom, y_ref = run.y_nom, run.y_ref
    chosen, ordered, verdict, val_logs, timings = run.chosen, run.ordered, run.verdict, run.val_logs, run.timings
    t_start, floor, gap_before, gap_refit = run.t_start, run.floor, run.gap_before, run.gap_refit
    shares, closed = run.shares, run.closed
    sigs_tests, level, level_ev = run.sigs_tests, run.level, run.level_ev
    scales, trend_shifts = run.scales, run.trend_shifts
    in_unit, nps_reason, window, skips, excluded = run.in_unit, run.nps_reason, run.window, run.skips, run.excluded
    floor_rank, floor_rank_method, refit_note = run.floor_rank, run.floor_rank_method, run.refit_note
    g_nom_fit, g_ref_fit, not_tried = run.g_nom_fit, run.g_ref_fit, run.not_tried
    verdicts = [c[0].effect for c in chosen] if chosen else [verdict]
    last = chosen[-1] if chosen else ordered[0]
    best_c, best_m, best_y = last[0], last[1], last[2]
    gap_after = best_c.gap_after

    t = time.perf_counter()
    tr = val_logs[-1] if val_logs else 0
    vmask = split.validation[tr]
    y_aug_full = best_y.get(tr) if best_y.get(tr) is not None else sims[tr].run(best_m)

    def _rms(a):
        return float(np.sqrt(np.mean(a[vmask] ** 2))) if vmask.any() else float("nan")

    channels = tuple(
        ChannelGap(channel=ch, gap=nrmse(ys[tr][c:c + 1], y_nom[tr][c:c + 1], vmask),
                   gap_after=nrmse(ys[tr][c:c + 1], y_aug_full[c:c + 1], vmask),
                   rms_error=_rms(ys[tr][c] - y_nom[tr][c]), rms_error_after=_rms(ys[tr][c] - y_aug_full[c]),
                   unit=units[c])
        for c, ch in enumerate(out_ch))
    # bands: residual of the nominal on every (non-transient) sample of every log, normalised per channel
    # the inputs first: the nominal residual's part coherent with them is read from the same spectra
    m_in = us[tr].shape[0]
    fr, Gm, _ = masked_csd(np.vstack([us[tr], ys[tr], ys[tr] - y_nom[tr], ys[tr] - y_ref[tr], ys[tr] - y_aug_full]),
                           all_masks[tr], fs, nps)
    nc = len(out_ch)
    P = np.real(np.einsum("fii->if", Gm))[m_in:]
    Pm, Pb, Pr, Pa = P[:nc], P[nc:2 * nc], P[2 * nc:3 * nc], P[3 * nc:]
    var = np.maximum(np.array([np.mean(ys[tr][c, all_masks[tr]] ** 2) for c in range(nc)]), 1e-300)
    noise_psd = np.repeat(nf.psd_level[:, None], fr.size, axis=1)
    bands = locate_bands(fr, np.sum(Pb / var[:, None], axis=0), np.sum(noise_psd / var[:, None], axis=0))
    st_nom = sims[tr].run(states_model(model))
    regimes = regime_gaps(ys[tr], y_nom[tr], vmask, {"displacement": st_nom[:model.n_dofs],
                                                      "velocity": st_nom[model.n_dofs:2 * model.n_dofs]},
                          us[tr], input_levels(us[tr], fs)[0])
    fdt = frf_data([us[tr]], [ys[tr]], [all_masks[tr]], fs, nps)
    fdn = frf_data([us[tr]], [y_nom[tr]], [all_masks[tr]], fs, nps)
    fda = frf_data([us[tr]], [y_aug_full], [all_masks[tr]], fs, nps)
    # the lines that carry no input (frf_data gives them no coherence) have no FRF to show: their
    # H1 is a ratio of residues (+250 dB beyond a multisine's band edge)
    dead = ~np.any(fdt[2] > 0, axis=1)
    fdt, fdn, fda = ((d[0], np.where(dead[:, None], np.nan, d[1])) + tuple(d[2:]) for d in (fdt, fdn, fda))
    # the nominal residual's part coherent with the input(s), per line (the figure's evidence for
    # a gap that is not a linear function of the input: _check_incoherent)
    sub = np.r_[np.arange(m_in), m_in + nc + np.arange(nc)]
    Pc = coherent_power(Gm[:, sub][:, :, sub], m_in)[2]
    spectrum = GapSpectrum(frequencies=fr, measured=Pm, residual_before=Pb, residual_refit=Pr,
                           residual_after=Pa, noise=noise_psd, frf_frequencies=fdt[0], frf_measured=fdt[1],
                           frf_nominal=fdn[1], frf_augmented=fda[1], coherence=fdt[2],
                           residual_before_coherent=Pc)
    traces = GapTraces(fs=fs, t0=float(sigs[tr].t0), channels=tuple(out_ch), units=tuple(units),
                       measured=ys[tr], nominal=y_nom[tr], refit=y_ref[tr], augmented=y_aug_full,
                       validation=vmask, input=us[tr][0],
                       log=str(sigs[tr].meta.get("source", "")) if sigs[tr].meta else "")
    timings["report"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start
    shrink = 1.0 - gap_after / gap_before if gap_before > 0 else 0.0
    return GapReport(
        metric="nrmse",
        validation=split.description + ("" if run.aperiodic is None else
                                        f"; {len(run.aperiodic.logs)} of {len(sigs) + len(run.aperiodic.logs)} logs "
                                        f"left out: {run.aperiodic.describe()}"),
        noise_floor=floor,
        noise_floor_method=nf.method,
        gap_before=gap_before,
        gap_refit=gap_refit,
        gap_after=gap_after,
        shrink=shrink,
        bands=bands,
        channels=channels,
        regimes=regimes,
        candidates=tuple(c[0] for c in ordered),
        signatures=sigs_tests,
        verdict=verdict if len(verdicts) == 1 else verdicts[0],
        verdicts=tuple(verdicts),
        shares=tuple(shares),
        model_name=model.name,
        augmented_model_toml=best_c.model_toml,
        traces=traces,
        spectrum=spectrum,
        timings=timings,
        level_evidence=level_ev,
        meta={"fs_hz": fs, "input_unit": in_unit, "nperseg": nps, "nperseg_reason": nps_reason, "output_sampling": run.sampling_choice, "window": window, "extra_mode_starts_hz": scales.get("f_extra", []), "n_logs": len(sigs),
              "aperiodic_logs": None if run.aperiodic is None else run.aperiodic.to_dict() | {"why": run.aperiodic.describe()},
              "transient_samples": skips, "transient_reasons": run.skip_reasons,
              "acceleration_means_removed": {"method": "each log's mean of each acceleration output, removed "
                                             "before any comparison (a sensor bias or gravity: a model's "
                                             "acceleration has no mean over a record from rest or in steady "
                                             "state), m/s^2 per log", "means": run.accel_means or {}},
              "levels": split.levels, "excited_band_hz": list(nf.excited_band),
              "noise_floor_ranking": {"nrmse": floor_rank, "method": floor_rank_method},
              "nested_tests": {"t": dict(run.nested_t), "threshold": NESTED_T},
              "selection": {"method": "forward selection, one entry per round: the additions tried on the current "
                                      "model (held-out gap, penalised excess gap), kept when the best one's "
                                      f"penalised excess is below {ADD_FACTOR} of the current one's (the threshold); "
                                      "an entry with 'stopped' says why a selection ended without trying "
                                      "(within the noise floor, three effects, no class left, an "
                                      "unpredictable model, a linear refit far above the floor: unexplained); "
                                      "an addition that vanishes into the simpler member of its family "
                                      "(an asymmetric friction with equal forces) is tried as that member "
                                      "('reduced'); a held-clearance trial, kept when significantly better "
                                      f"(not tried, 'stopped', where the current model leaves at most {PM_FURTHER:g} "
                                      "x the noise floor); a stand-in retry from another class at the chosen "
                                      "effect's connection ('trial', 'trial_gap'), kept when significantly better "
                                      "or, one effect against one, simpler with a held-out gain beyond the noise "
                                      "('simpler_gain_t')",
                            "rounds": list(run.selection)},
              "predictability": {
                  "method": "held-out nrmse between the model's outputs at its default and at twice its "
                            "integration sub-steps; forward selection does not start from a model where it "
                            f"exceeds the noise floor and {PREDICT_SHARE} of the model's excess gap",
                  "models": {k: {a: b for a, b in v.items() if not a.startswith("_")}
                             for k, v in run.predictability.items()}},
              "upper_residual": run.upper_placement,
              "incoherent_gap": run.incoherent,
              "refit": {"method": refit_note, "gap_fit_nominal": g_nom_fit, "gap_fit_refit": g_ref_fit},
              "level_dependence": {k: (v if not isinstance(v, float) or np.isfinite(v) else None)
                                   for k, v in level.items()} | {"simulated_shifts": trend_shifts},
              "start_values": {f"{k[0]}@{k[1]}" if k[1] else k[0]: (list(v) if isinstance(v, tuple) else v)
                               for k, v in scales.get("regress", {}).items()},
              "start_values_nominal": {f"{k[0]}@{k[1]}" if k[1] else k[0]: (list(v) if isinstance(v, tuple) else v)
                                       for k, v in scales.get("regress_nominal", {}).items()},
              "not_tried": not_tried,
              "closed_loop": ({"inputs": log_channels(model)[0], "outputs": out_ch,
                               "excluded_effects": excluded,
                               "delay_from_command_s": scales.get("delay0_loop")} if closed else None),
              "localisation": "bands, channels and regimes of the nominal model on the last log's held-out samples "
                              "(the nominal model is fitted on nothing)"},
    )


