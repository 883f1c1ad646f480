"""The sim-to-real gap diagnosis: measure, localise, attribute, quantify.

:func:`diagnose` drives a nominal model with the logged input, measures where the
simulation and the log disagree (channels, frequency bands, excitation levels, state
regimes) against a noise floor estimated from the data, runs signature tests on the
residual of the re-estimated linear model, fits the model augmented with every candidate
effect of the vocabulary (:data:`~vibroscope.gap.effects.EFFECT_TABLE`), ranks the candidates
by the share of the gap they close on held-out data, and adds further effects while they
close significantly more (forward selection).

Procedure
---------
1. **Split** (:func:`~vibroscope.gap.measure.make_split`): one log: a time split that keeps
   every excitation level on both sides; several logs at one level: the last one is held
   out; several logs at different levels: each is split in time (every level is fitted and
   held out: a held-out level the fit never saw would test an extrapolation).
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
   changes the held-out outputs by less than the noise floor) is never the verdict; nor is a
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
   polished jointly; each effect's share of the shrink is reported.

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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from scipy import signal as sps

from vibroscope.errors import ChannelError
from vibroscope.gap.closed_loop import (
    CLOSED_LOOP_EXCLUDED,
    actuator_force,
    basis_model,
    basis_rows,
    is_closed_loop,
    log_channels,
    measured_rows,
)
from vibroscope.gap.effects import (
    EFFECT_TABLE,
    FRICTION_V_EPS,
    LinearParams,
    candidate_specs,
    connections,
    pair_name,
)
from vibroscope.gap.fit import LogSimulator, best_start, fit_linear_frf, fit_time_domain
from vibroscope.gap.levels import frf_segment_length, level_blas
from vibroscope.gap.measure import (
    input_levels,
    locate_bands,
    LOG_LEVEL_RATIO,
    make_split,
    masked_csd,
    nested_gain,
    noise_floor,
    nrmse,
    regime_gaps,
)
from vibroscope.gap.report import Candidate, ChannelGap, GapReport, GapSpectrum, GapTraces
from vibroscope.gap.signatures import run_signatures
from vibroscope.modal.automatic import one_blas_thread
from vibroscope.models.elements import GROUND
from vibroscope.models.lumped import Input, LumpedModel, Output
from vibroscope.models.elements import Spring
from vibroscope.signals import Signals, true_runs

__all__ = ["diagnose", "fit_linear_model", "as_lumped"]

#: the nominal gap must exceed the noise floor by this factor before any effect is named
NONE_FACTOR = 1.3
#: complexity penalty: the held-out excess gap is scored as e * (1 + PENALTY * n_effect_parameters)
PENALTY = 0.1
#: the BLA depends on the level when more than this fraction of its well-excited lines changes by
#: more than 3 standard deviations between the lowest and the highest level
LEVEL_FRACTION = 0.01
#: the best admissible candidate must explain at least this share of the excess gap (its score),
#: else the verdict is ``unexplained``
UNEXPLAINED_SCORE = 0.3
#: a richer candidate moves ahead of one it nests when the t statistic of its held-out gain
#: (batch means, see :func:`~vibroscope.gap.measure.nested_gain`) exceeds this
NESTED_T = 4.0
#: forward selection keeps a further effect when the penalised held-out excess gap falls below
#: this factor times the current one
ADD_FACTOR = 0.5
#: an addition within REFINE_FACTOR (but not ADD_FACTOR) times the current penalised excess is
#: fitted further (jointly with the linear parameters) before the decision
REFINE_FACTOR = 0.8
#: without level dependence of the BLA, a nonlinear verdict needs a penalised held-out excess gap
#: below this factor times the best linear explanation's
NL_MARGIN = 0.8
#: with a measured resonance shift between the lowest and the highest level (hardening or
#: softening), a nonlinear verdict whose own simulation does not shift the resonance the same way
#: (by at least TREND_SHARE of the measured shift) yields to the best candidate that does, when
#: that one's penalised held-out excess gap is within TREND_MARGIN times it
TREND_MARGIN = 1.5
TREND_SHARE = 0.3
#: a resonance's natural frequency that moves from the lowest to the highest level by more than
#: LEVEL_MODE_Z standard deviations and LEVEL_MODE_CHANGE (relative), beyond the model's own
#: estimate on the same groups, makes the BLA level dependent (:func:`_modal_level_test`)
LEVEL_MODE_Z = 3.0
LEVEL_MODE_CHANGE = 0.005
#: effects of which forward selection names one member only (asymmetric friction contains Coulomb
#: friction; a Jenkins joint is a Bouc-Wen element)
NESTED_FAMILIES = ({"coulomb_friction", "asymmetric_friction"}, {"hysteresis", "joint_friction"})
#: locations of each nonlinear class refined after probing the start values (the best ones by
#: their best start, whatever its gap: a hysteresis at the loaded link of a 3-DOF chain probed at
#: 0.218 against 0.136 for a start that changes nothing elsewhere, and refined to 0.027)
N_LOCATIONS = 3
#: a location's best start on the other linear base (nominal or refit) is refined too when its
#: screening gap is within this factor of the best start's
OTHER_BASE_FACTOR = 2.0
#: seconds of fitting data per log on which the winner is polished at full accuracy
POLISH_S = 30.0
#: the polish's evaluations in fours, the share of its fitting gap every four iterations must
#: close to go on, and the multiple of the noise floor at which it stops (the Bouc-Wen
#: benchmark's loop shape needs about twenty evaluations)
POLISH_ROUNDS = 5
POLISH_GAIN = 0.02
POLISH_FLOOR_FACTOR = 1.5
#: function evaluations of a linear effect's FRF fit per start (its best start is then polished in
#: time; on a 3-DOF parameter-mismatch case the median fit took 20, a few ran to the old limit of 200)
LIN_EFFECT_NFEV = 60


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


def _frf_data(us, ys, masks, fs, nperseg, window="hann"):
    """H1 (n_f, n_out) and coherence from the masked samples of several logs (pooled spectra)."""
    G = None
    tot = 0
    f = None
    for u, y, m in zip(us, ys, masks):
        if not m.any():
            continue
        f, g, n_avg = masked_csd(np.vstack([u[:1], y]), m, fs, nperseg, window)
        if n_avg:
            G = g * n_avg if G is None else G + g * n_avg
            tot += n_avg
    if G is None or tot == 0:
        return None
    G = G / tot
    Guu = G[:, 0, 0].real
    Guy = G[:, 0, 1:]
    Gyy = np.real(np.einsum("fii->fi", G[:, 1:, 1:]))
    H = Guy / np.maximum(Guu, 1e-300)[:, None]
    coh = np.abs(Guy) ** 2 / np.maximum(Guu[:, None] * Gyy, 1e-300)
    return f, H, np.clip(coh, 0, 1), Gyy, tot


def _pow2(x: float) -> int:
    return int(2 ** max(6, int(math.floor(math.log2(max(x, 64))))))


def _states_model(model: LumpedModel) -> LumpedModel:
    outs = tuple(Output(d.name, "displacement", f"/state/{d.name}.x") for d in model.dofs) + tuple(
        Output(d.name, "velocity", f"/state/{d.name}.v") for d in model.dofs)
    return replace(model, outputs=outs)


def _relative(model: LumpedModel, X: np.ndarray, V: np.ndarray) -> dict:
    out = {}
    for pair in connections(model):
        lv = model.element_vector(Spring(pair, k=0.0))
        out[pair_name(pair)] = (lv @ X, lv @ V)
    return out


def _excess(g: float, floor: float) -> float:
    return math.sqrt(max(g * g - floor * floor, 0.0))


def _skip_samples(model: LumpedModel, fs: float, n: int, transient_s) -> int:
    if transient_s is not None:
        return int(round(float(transient_s) * fs))
    try:
        md = model.modes()
        tau = float(np.max(1.0 / np.maximum(md.damping_ratios * 2 * np.pi * md.natural_frequencies, 1e-9)))
    except Exception:  # noqa: BLE001
        tau = 0.0
    return int(min(3 * tau * fs, 0.05 * n))


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
    nps = nperseg or _pow2(min(4 * fs, min(u.shape[1] for u in us) / 4))
    fd = _frf_data(us, ys, masks, fs, nps)
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


def _frf_weights(f, coh, us, fs, nps):
    from vibroscope.gap.measure import excited_band

    fb = excited_band(np.concatenate(us, axis=1), fs, nps)
    inb = (f >= fb[0]) & (f <= fb[1]) & (f > 0)
    c = np.clip(coh, 0.0, 0.999)
    w = np.sqrt(c / (1 - c))
    w = np.minimum(w, 10.0) * (c > 0.3)
    sel = inb & np.any(w > 0, axis=1)
    idx = np.nonzero(sel)[0]
    if idx.size > 600:  # thin the lines for speed
        keep = np.zeros_like(sel)
        keep[idx[:: int(math.ceil(idx.size / 600))]] = True
        sel = keep
    return sel, w


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
    effects : sequence of str, optional
        Restrict the candidates (default: the whole vocabulary).
    transient_s : float, optional
        Seconds at the start of each log left out of every metric (default: three time
        constants of the slowest mode, at most 5 % of the record).
    nperseg : int, optional
        Welch segment length (samples) for FRFs and spectra. Default
        (:func:`~vibroscope.gap.levels.frf_segment_length`): one period of a periodic input
        (rectangular window, no overlap), else a line spacing of a quarter of the nominal
        model's narrowest half-power bandwidth ``2 zeta f_n`` (at least 8 averages), else
        about 4 s; the report's ``meta["nperseg_reason"]`` says which.
    workers : int
        Threads for the candidate fits (the simulation kernel releases the GIL).
    n_full : int
        Number of nonlinear effect classes fitted jointly with the linear parameters after
        screening.
    progress : bool
        Show a progress bar over the candidates.
    holdout : {'auto', 'last'}, optional
        Several logs: ``'auto'`` (default) holds out the last log when every log is at one
        input level, else the end of each log; ``'last'`` always holds out the last log (a
        validation log the user has chosen, such as a benchmark's test part).

    Returns
    -------
    GapReport

    Raises
    ------
    ChannelError
        If a model channel is missing from a log.
    ValueError
        If the logs have different sampling rates, ±Inf samples, too little left between
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
        return _diagnose(model, signals, effects=effects, transient_s=transient_s, nperseg=nperseg,
                         workers=workers, n_full=n_full, progress=progress, holdout=holdout)


def _level_groups(us, masks, fs):
    """Excitation-level groups across logs: ``(log, sample mask, input RMS)``, lowest first.

    Within a log, the levels of :func:`~vibroscope.gap.measure.input_levels`; across logs, a
    log's groups are taken as they are (several logs at different levels are levels)."""
    groups = []
    for i, (u, m) in enumerate(zip(us, masks)):
        if not m.any():
            continue
        labels, lv = input_levels(u, fs)
        for k in range(len(lv)):
            mk = m & (labels == k)
            if mk.sum() > 0:
                groups.append((i, mk, float(np.sqrt(np.mean(u[0, mk] ** 2)))))
    groups.sort(key=lambda g: g[2])
    return groups


def _bla_levels(us, ys, groups, fs, nperseg, f_sel):
    """H1 (n_sel, n_out), coherence and averages per level group, interpolated on `f_sel`."""
    out = []
    for i, mk, rms in groups:
        runs = np.diff(np.nonzero(np.diff(np.concatenate([[False], mk, [False]]).astype(int)) != 0)[0])[::2]
        # segments of about half a typical stretch of the level: more averages, a tighter H1
        typical = int(np.median(runs)) if runs.size else 0
        nps = _pow2(min(nperseg, max(typical // 2, 256)))
        d = _frf_data([us[i]], [ys[i]], [mk], fs, nps)
        if d is None:
            continue
        f, H, coh, _, n_avg = d
        Hi = np.array([np.interp(f_sel, f, H[:, c].real) + 1j * np.interp(f_sel, f, H[:, c].imag)
                       for c in range(H.shape[1])]).T
        ci = np.array([np.interp(f_sel, f, coh[:, c]) for c in range(H.shape[1])]).T
        out.append((rms, Hi, ci, n_avg))
    return out


def _level_test(f, blas, blas_model=None):
    """Does the BLA change with the excitation level beyond its own uncertainty (and beyond what
    the model itself predicts)?

    Per line and output, ``z^2 = |H_hi - H_lo - (M_hi - M_lo)|^2 / (var_hi + var_lo)``, where
    ``M`` is the BLA of the model's own simulation on the same level groups (`blas_model`; zero
    when not given): the change a known nonlinearity of the model (a controller's saturation)
    or the estimator's leakage at each level explains is not evidence. The H1 variance is
    ``|H|^2 (1 - gamma^2) / (n_d gamma^2)`` (Bendat & Piersol, *Random Data*, 4th ed., eq.
    9.90: nonlinear distortion counts as noise there, so the test is conservative); the
    statistic is the fraction of the well-excited lines (coherence >= 0.5 at both levels)
    with ``z > 3`` (about 1e-4 for a linear system: ``z^2`` is ``chi^2_2 / 2``). Flagged when
    at least 5 lines and :data:`LEVEL_FRACTION` of them are. The trend compares the frequency of the
    largest peak of ``sum |H|`` at the lowest and highest level.

    Returns dict: ``stat``, ``flagged``, ``trend`` (``hardening``, ``softening``, ``none``),
    ``shift`` (relative frequency change), ``levels_rms``."""
    if len(blas) < 2:
        return {"stat": float("nan"), "flagged": False, "trend": "none", "shift": 0.0,
                "levels_rms": [b[0] for b in blas]}
    lo, hi = blas[0], blas[-1]
    if hi[0] < 1.5 * lo[0]:
        return {"stat": float("nan"), "flagged": False, "trend": "none", "shift": 0.0,
                "levels_rms": [b[0] for b in blas]}
    (_, H0, c0, n0), (_, H1, c1, n1) = lo, hi
    c0c = np.clip(c0, 1e-6, 1 - 1e-9)
    c1c = np.clip(c1, 1e-6, 1 - 1e-9)
    v0 = np.abs(H0) ** 2 * (1 - c0c) / (max(n0, 1) * c0c)
    v1 = np.abs(H1) ** 2 * (1 - c1c) / (max(n1, 1) * c1c)
    ok = (c0 >= 0.5) & (c1 >= 0.5)
    dM = 0.0
    if blas_model is not None and len(blas_model) == len(blas):
        dM = blas_model[-1][1] - blas_model[0][1]
        dM = np.where(np.isfinite(dM), dM, 0.0)  # an unstable model simulation predicts nothing
    z2 = np.abs(H1 - H0 - dM) ** 2 / np.maximum(v0 + v1, 1e-300)
    n_ok = int(ok.sum())
    n_out = int(np.sum(z2[ok] > 9.0))
    stat = n_out / n_ok if n_ok >= 20 else float("nan")
    flagged = bool(np.isfinite(stat) and n_out >= max(5, LEVEL_FRACTION * n_ok))
    a0 = np.sum(np.abs(H0), axis=1)
    a1 = np.sum(np.abs(H1), axis=1)
    k0, k1 = int(np.argmax(a0)), int(np.argmax(a1))
    shift = 0.0
    if f.size > 2:
        f0, f1 = float(f[k0]), float(f[k1])
        # compare near the low-level peak: the high-level peak within 30 %
        win = np.abs(f - f0) <= 0.3 * f0
        if win.any():
            k1w = int(np.nonzero(win)[0][np.argmax(a1[win])])
            f1 = float(f[k1w])
        shift = (f1 - f0) / f0 if f0 > 0 else 0.0
    dfl = float(np.median(np.diff(f))) if f.size > 1 else 0.0
    trend = "none"
    if flagged and abs(shift) * (f[k0] if f.size else 0) > 1.5 * dfl and abs(shift) > 0.005:
        trend = "hardening" if shift > 0 else "softening"
    return {"stat": stat, "flagged": flagged, "trend": trend, "shift": float(shift),
            "levels_rms": [b[0] for b in blas], "lines": n_ok, "lines_beyond_3_sigma": n_out}


def _mode_change(ev, f_hz: float):
    """Relative natural-frequency change, lowest to highest level where fitted, of the mode of
    `ev` (:class:`~vibroscope.gap.levels.LevelEvidence`) nearest `f_hz` (within 5 %), with the
    indices of those two levels; None without one."""
    if ev is None or len(ev.levels) < 2 or not ev.modes:
        return None
    j = int(np.argmin([abs(m.natural_frequency - f_hz) for m in ev.modes]))
    if abs(ev.modes[j].natural_frequency - f_hz) > 0.05 * f_hz:
        return None
    fn = np.array([lv.natural_frequencies[j] for lv in ev.levels])
    sf = np.array([lv.natural_frequency_std[j] for lv in ev.levels])
    ok = np.flatnonzero(np.isfinite(fn) & np.isfinite(sf))
    if ok.size < 2:
        return None
    a, b = int(ok[0]), int(ok[-1])
    return float((fn[b] - fn[a]) / fn[a]), a, b


def _modal_level_test(ev, ev_model) -> dict | None:
    """The level dependence of the resonances (:func:`~vibroscope.gap.levels.level_blas`):
    each mode's relative natural-frequency change from the lowest to the highest level, less
    the change the model's own simulation shows on the same groups (`ev_model`, noise-free:
    the estimator's bias at each level), over the measured standard deviation. A mode fits
    many lines at once, so this sees a shift of a narrow or weakly observed resonance that
    the line-wise test of :func:`_level_test` cannot (a 1 % softening of a mode whose
    half-power bandwidth is one or two lines). Damping changes are not used: their estimates
    scatter more than their standard deviations say.

    Returns None without a significant mode (``|z|`` above :data:`LEVEL_MODE_Z` and a change
    above :data:`LEVEL_MODE_CHANGE`), else a dict: ``trend``, ``shift`` (relative change of
    the mode with the largest ``|z|``), ``z``, ``frequency_hz``."""
    if ev is None or len(ev.levels) < 2:
        return None
    best = None
    for j, md in enumerate(ev.modes):
        ch = _mode_change(ev, md.natural_frequency)
        if ch is None:
            continue
        change, a, b = ch
        if ev.levels[b].rms < LOG_LEVEL_RATIO * ev.levels[a].rms:
            continue
        sf = float(np.hypot(ev.levels[a].natural_frequency_std[j], ev.levels[b].natural_frequency_std[j]))
        chm = _mode_change(ev_model, md.natural_frequency)
        d = change - (chm[0] if chm is not None else 0.0)
        z = d * float(ev.levels[a].natural_frequencies[j]) / sf if sf > 0 else 0.0
        if abs(z) > LEVEL_MODE_Z and abs(d) > LEVEL_MODE_CHANGE and (best is None or abs(z) > abs(best["z"])):
            best = {"trend": "hardening" if d > 0 else "softening", "shift": float(d), "z": float(z),
                    "frequency_hz": float(md.natural_frequency)}
    return best


def _pair_force_model(model: LumpedModel, pair) -> LumpedModel:
    """`model` with its inputs replaced by a force pair at the ends of `pair`: ``-f`` on the
    first end, ``+f`` on the second (an element's force); ground ends are left out."""
    return basis_model(model, [d for d in pair if d != GROUND])


def _regression_starts(refit, rel, ys, y_ref, fit_log, n, fs, effects):
    """Start values from the residual: each element law's force, computed on the refitted
    model's relative motion, is applied to the refitted model, and the residual (measured -
    refitted) is regressed on the responses (a linear-in-the-parameters estimate, Kerschen et
    al. 2006, sec. 5; NARMAX-like). Returns ``{(effect, pair or None): estimate}``."""
    from vibroscope.models.simulate import simulate

    out = {}
    # each channel weighted by its own RMS (the metric of nrmse: channels of any unit alike)
    wc = 1.0 / np.maximum(np.sqrt(np.mean(ys[fit_log][:, :n] ** 2, axis=1)), 1e-300)[:, None]
    r = ((ys[fit_log][:, :n] - y_ref[fit_log][:, :n]) * wc).ravel()
    if not np.all(np.isfinite(r)) or n < 16:
        return out

    def resp(m, forces):
        try:
            s = simulate(m, basis_rows(m, forces), fs)
            y = measured_rows(m, s) * wc
            return y.ravel() if np.all(np.isfinite(y)) else None
        except Exception:  # noqa: BLE001 - a start value only
            return None

    def ls(cols):
        A = np.vstack(cols).T
        sol, *_ = np.linalg.lstsq(A, r, rcond=None)
        return sol

    for pair in connections(refit):
        key = pair_name(pair)
        if key not in rel:
            continue
        d, v = rel[key]
        d, v = d[:n], v[:n]
        m = _pair_force_model(refit, pair)
        sgn = np.array([-1.0 if e == pair[0] else 1.0 for e in pair if e != GROUND])[:, None]
        t = np.tanh(v / FRICTION_V_EPS)
        cols = {}
        for name, g in (("t", t), ("t2", t * t), ("d3", d**3)):
            y = resp(m, sgn * g[None, :])
            if y is not None:
                cols[name] = y
        if "t" in cols and ({"coulomb_friction"} & effects):
            out[("coulomb_friction", key)] = abs(float(ls([cols["t"]])[0]))
        if "t" in cols and "t2" in cols and ({"asymmetric_friction"} & effects):
            fa, fd = ls([cols["t"], cols["t2"]])
            out[("asymmetric_friction", key)] = (abs(fa + fd), abs(fa - fd))
        if "d3" in cols and ({"cubic_stiffness"} & effects):
            out[("cubic_stiffness", key)] = float(ls([cols["d3"]])[0])
    if "offset" in effects and refit.inputs:
        m = (basis_model(refit, [refit.inputs[0].dof]) if is_closed_loop(refit)
             else replace(refit, inputs=refit.inputs[:1]))
        y = resp(m, np.ones((1, n)))
        if y is not None:
            out[("offset", None)] = float(ls([y])[0])
    return out


@dataclass(kw_only=True, eq=False)
class _Run:
    """The working state of one :func:`_diagnose` call, filled stage by stage.

    Set by :func:`_prepare_logs`: the model, the logs and their split, the simulators, the
    FRF segment length and the effects to try; by each later stage: what it found (the
    comments below name the stage). Mutable and private: a stage reads what the earlier
    ones left and adds its own results; ``timings`` collects each stage's seconds."""

    # the logs and their split (_prepare_logs)
    t_start: float
    timings: dict
    model: LumpedModel
    sigs: list
    fs: float
    us: list
    ys: list
    out_ch: list
    closed: bool
    units: list
    in_unit: str
    skips: list
    split: object
    sims: list
    nps: int
    nps_reason: str
    window: str
    effect_set: set
    excluded: dict
    # the nominal model and the noise floor (_simulate_nominal)
    y_nom: list | None = None
    gap_before: float | None = None
    all_masks: list | None = None
    nf: object = None
    floor: float | None = None
    # the FRF of the fitting data and the linear refit (_refit_linear)
    fd: tuple | None = None
    sel: np.ndarray | None = None
    w: np.ndarray | None = None
    lin: LinearParams | None = None
    ns_fit: list | None = None
    lo_l: np.ndarray | None = None
    hi_l: np.ndarray | None = None
    ns_pol: list | None = None
    g_nom_fit: float | None = None
    g_ref_fit: float | None = None
    theta: np.ndarray | None = None
    refit_note: str | None = None
    refit: LumpedModel | None = None
    y_ref: list | None = None
    gap_refit: float | None = None
    # scales, signatures and level evidence (_gather_evidence)
    f_s: np.ndarray | None = None
    H_s: np.ndarray | None = None
    scales: dict | None = None
    groups: list | None = None
    blas: list | None = None
    level: dict | None = None
    level_ev: object = None
    level_ev_ref: object = None
    sigs_tests: tuple | None = None
    # the candidates' fits (_fit_candidates)
    val_logs: list | None = None
    none_ok: bool | None = None
    specs: list | None = None
    not_tried: dict | None = None
    lin_later: dict | None = None
    results: list | None = None
    pre_eval: dict | None = None
    keep_ids: set | None = None
    per_class: dict | None = None
    screened: list = field(default_factory=list)
    nested_t: dict = field(default_factory=dict)
    # held-out evaluation and ranking (_rank_candidates)
    floor_rank: float | None = None
    floor_rank_method: str | None = None
    k_before: float | None = None
    cands: list | None = None
    best_i: int | None = None
    trend_shifts: dict | None = None
    polish: dict | None = None
    verdict: str | None = None
    ordered: list | None = None
    chosen: list | None = None
    # forward selection (_select_further_effects)
    shares: list | None = None

    def held_out(self, m_, fast=False):
        """Held-out nrmse of model `m_` (inf when not finite) and its outputs per held-out log."""
        val_logs, sims, ys, split = self.val_logs, self.sims, self.ys, self.split
        yh = {i: sims[i].run(m_, fast=fast) for i in val_logs}
        g = nrmse([ys[i] for i in val_logs], [yh[i] for i in val_logs], [split.validation[i] for i in val_logs])
        return (g if np.isfinite(g) else float("inf")), yh

    def key(self, g, n):
        """Penalised held-out excess gap (lower is better)."""
        floor_rank = self.floor_rank
        return max(_excess(g, floor_rank), 0.15 * floor_rank) * (1 + PENALTY * n)


@one_blas_thread  # the fits run in a thread pool: a BLAS pool per thread only spins against it
def _prefix_gap(run: _Run, m) -> float:
    """nrmse of model `m` on the screening prefix of the fitting data (coarse integration):
    the measure every start is probed by. May be non-finite."""
    sp = run.split.screen_prefix
    yh = [sim.run(m, n, fast=True) if n else None for sim, n in zip(run.sims, sp)]
    return nrmse([y[:, :n] for y, n in zip(run.ys, sp) if n], [h for h in yh if h is not None],
                 [mk[:n] for mk, n in zip(run.split.fit, sp) if n])


def _diagnose(model, signals, *, effects, transient_s, nperseg, workers, n_full, progress, holdout) -> GapReport:
    run = _prepare_logs(model, signals, effects=effects, transient_s=transient_s, nperseg=nperseg, holdout=holdout)
    _simulate_nominal(run)
    _refit_linear(run)
    _gather_evidence(run)
    _fit_candidates(run, workers=workers, n_full=n_full, progress=progress)
    _rank_candidates(run, workers=workers)
    _select_further_effects(run, workers=workers)
    return _build_report(run)


def _prepare_logs(model, signals, *, effects, transient_s, nperseg, holdout) -> _Run:
    """The logs split at their gaps and into input and output rows, the transient to skip, the
    fit / held-out split, one simulator per log, the FRF segment length (and window) and the
    effects to try (closed loop: less those that do not apply). Returns a new :class:`_Run`."""
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
    ys = [p[1] for p in pairs]
    out_ch = log_channels(model)[1]
    closed = is_closed_loop(model)
    units = [sigs[0].units[list(sigs[0].channels).index(c)] if sigs[0].units else "" for c in out_ch]
    in_ch0 = log_channels(model)[0][0]
    in_unit = (sigs[0].units[list(sigs[0].channels).index(in_ch0)] if sigs[0].units else "") or "N"
    skips = [_skip_samples(model, fs, u.shape[1], transient_s) for u in us]
    split = make_split(us, fs, skip=skips, holdout=holdout)
    sims = [LogSimulator(u, fs) for u in us]
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
    effect_set = set(EFFECT_TABLE) if effects is None else set(effects)
    excluded = {e: why for e, why in CLOSED_LOOP_EXCLUDED.items() if e in effect_set} if closed else {}
    effect_set -= set(excluded)
    return _Run(t_start=t_start, timings=timings, model=model, sigs=sigs, fs=fs, us=us, ys=ys, out_ch=out_ch,
                closed=closed, units=units, in_unit=in_unit, skips=skips, split=split, sims=sims, nps=nps,
                nps_reason=nps_reason, window=window, effect_set=effect_set, excluded=excluded)


def _simulate_nominal(run: _Run) -> None:
    """Stage 1: the nominal model simulated on every log, its held-out gap, the non-transient
    sample masks and the noise floor. Sets ``y_nom``, ``gap_before``, ``all_masks``, ``nf``,
    ``floor``."""
    model, sims, ys, us, split, fs, nps = run.model, run.sims, run.ys, run.us, run.split, run.fs, run.nps
    t = time.perf_counter()
    y_nom = [sim.run(model) for sim in sims]
    gap_before = nrmse(ys, y_nom, split.validation)
    all_masks = []
    for u, sk in zip(us, run.skips):
        m = np.ones(u.shape[1], bool)
        m[:sk] = False
        all_masks.append(m)
    nf = noise_floor(ys, us, all_masks, fs, nps)
    floor = nf.nrmse
    run.timings["nominal"] = time.perf_counter() - t
    run.y_nom, run.gap_before, run.all_masks, run.nf, run.floor = y_nom, gap_before, all_masks, nf, floor


def _refit_linear(run: _Run) -> None:
    """Stage 2: the H1 of the fitting data and the nominal structure's linear parameters
    re-estimated on it, then in time; started from the FRF fit and from the nominal, the better
    on the fitting data is kept, and the refit is never worse there than the nominal model
    itself. Sets ``fd``, ``sel``, ``w``, ``lin``, the parameter bounds and sample counts,
    ``theta``, ``refit``, ``y_ref``, ``gap_refit`` and the fitting gaps."""
    model, sims, ys, us, split, fs, nps = run.model, run.sims, run.ys, run.us, run.split, run.fs, run.nps
    closed, window = run.closed, run.window
    t = time.perf_counter()
    fd = _frf_data(us, ys, split.fit, fs, nps, window)
    if fd is None:
        raise ValueError(f"too little fitting data for nperseg={nps}")
    f, H, coh, _, _ = fd
    sel, w = _frf_weights(f, coh, us, fs, nps)
    lin = LinearParams(model)
    # closed loop: the open plant's FRF is not the loop's (reference to outputs): time domain only
    theta0 = None if closed else fit_linear_frf(model, lin, f[sel], H[sel], w[sel])[1]
    ns_fit = split.fit_prefix
    lo_l, hi_l = np.full(len(lin), -2.5), np.full(len(lin), 2.5)
    # time-domain polish on up to 20 s of the fitting data (the FRF fit is biased by leakage)
    ns_pol = [min(n, max(s_, int(20 * fs))) if n else 0 for n, s_ in zip(ns_fit, split.screen_prefix)]

    def fit_gap(x):
        m_ = lin.apply(model, x)
        yh = [sim.run(m_, n) if n else None for sim, n in zip(sims, ns_pol)]
        g = nrmse([y[:, :n] for y, n in zip(ys, ns_pol) if n], [h for h in yh if h is not None],
                  [mk[:n] for mk, n in zip(split.fit, ns_pol) if n])
        return g if np.isfinite(g) else float("inf")

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
    run.timings["refit"] = time.perf_counter() - t
    run.fd, run.sel, run.w, run.lin = fd, sel, w, lin
    run.ns_fit, run.lo_l, run.hi_l, run.ns_pol = ns_fit, lo_l, hi_l, ns_pol
    run.g_nom_fit, run.g_ref_fit, run.theta, run.refit_note = g_nom_fit, g_ref_fit, theta, refit_note
    run.refit, run.y_ref, run.gap_refit = refit, y_ref, gap_refit


def _gather_evidence(run: _Run) -> None:
    """Stage 3: the scales of the candidates' start values (motion and input distributions,
    extra-mode start frequencies, residual regressions), the BLA's level dependence (line-wise
    and per resonance) and the signature tests of the refit's residual. Sets ``f_s``, ``H_s``,
    ``scales``, ``groups``, ``blas``, ``level``, ``level_ev``, ``level_ev_ref``,
    ``sigs_tests``."""
    model, sims, ys, us, split, fs, nps = run.model, run.sims, run.ys, run.us, run.split, run.fs, run.nps
    closed, window, refit, y_ref, y_nom = run.closed, run.window, run.refit, run.y_ref, run.y_nom
    ns_fit, fd, sel, w, nf, all_masks, in_unit = run.ns_fit, run.fd, run.sel, run.w, run.nf, run.all_masks, run.in_unit
    f, H, coh, _, _ = fd
    t = time.perf_counter()
    # the scales, start values and signatures come from the fitting log of the highest input
    # level (several logs at different levels): an effect that grows with the level shows most there
    fit_logs = [i for i, n in enumerate(ns_fit) if n]
    fit_log = max(fit_logs, key=lambda i: float(np.mean(us[i][0, split.fit[i]] ** 2)) if split.fit[i].any() else 0.0)
    n_sc = ns_fit[fit_log]
    scales: dict = {"fs": fs}
    rels = []
    for base in (refit, model):
        st = sims[fit_log].run(_states_model(base), n_sc)
        nd = base.n_dofs
        rels.append(_relative(base, st[:nd], st[nd:2 * nd]))
    rel = rels[0]
    # the input-side scales are forces (closed loop: the actuator's, gain x command)
    u_force = [actuator_force(model, u, y, fs) for u, y in zip(us, ys)]
    u_fit = u_force[fit_log][:n_sc]
    # the input's distribution over every fitting sample of every log (several logs at different
    # levels: a limit is sought among all the levels the fit sees)
    au = np.abs(np.concatenate([uf[m_[:uf.size]] for uf, m_ in zip(u_force, split.fit) if m_.any()]))
    mfit0 = split.fit[fit_log][:n_sc]
    scales.update({
        "u_rms": float(np.sqrt(np.mean(u_fit**2))),
        "u_max": float(au.max()),
        "u_quantiles": [float(np.quantile(au, q)) for q in (0.999, 0.99, 0.95, 0.85, 0.7, 0.5)],
        "u_abs_sorted": np.sort(np.abs(np.concatenate(u_force))),
        # the larger of the refitted and the nominal model's motion (a strong nonlinearity makes
        # the refit's the wrong scale)
        "d_rms": {k: float(max(np.std(d[mfit0]), np.std(rels[1][k][0][mfit0]))) for k, (d, v) in rel.items()},
        "v_rms": {k: float(max(np.std(v[mfit0]), np.std(rels[1][k][1][mfit0]))) for k, (d, v) in rel.items()},
        "d_quantiles": {k: [float(np.quantile(np.abs(d[mfit0]), q)) for q in (0.5, 0.8, 0.95)] for k, (d, v) in rel.items()},
    })
    f_s, H_s, coh_s = f[sel], H[sel], coh[sel]

    def model_frf(m_, y_m):
        """The model's FRF to the first input: the open plant's, or (closed loop) the H1 of its
        simulation `y_m` under the logged references on the fitting samples."""
        if closed:
            return _frf_data(us, y_m, split.fit, fs, nps, window)[1][sel]
        return m_.frf(f_s, quantity=None)[:, :, 0]

    H_refit = model_frf(refit, y_ref)
    # start frequencies of an extra mode: where measured / model deviates most significantly
    # (deviation in dB times the coherence weight), against the refitted and the nominal model
    starts: list[float] = []
    for ref_m, y_m in ((refit, y_ref), (model, y_nom)):
        Hr = model_frf(ref_m, y_m)
        rt = H_s / np.where(np.abs(Hr) > 0, Hr, 1)
        dev = np.mean(np.abs(20 * np.log10(np.maximum(np.abs(rt), 1e-300))) * w[sel], axis=1)
        pk, props = sps.find_peaks(dev, prominence=0.05 * max(float(dev.max()), 1e-12))
        order = np.argsort(props["prominences"])[::-1] if pk.size else []
        for i in order[:3]:
            fc = float(f_s[pk[i]])
            if all(abs(fc - o) > 0.03 * o for o in starts):
                starts.append(fc)
    scales["f_extra"] = starts
    # levels (within and across logs) and level-wise H1: the BLA's level dependence
    groups = _level_groups(us, all_masks, fs)
    blas = _bla_levels(us, ys, groups, fs, nps, f_s)
    # against the refitted model's own level dependence on the same groups (noise-free)
    level = _level_test(f_s, blas, _bla_levels(us, y_ref, groups, fs, nps, f_s))
    level["evidence"] = "lines" if level["flagged"] else None
    # the resonances per level (the report's level evidence), against the refitted model's own
    level_ev, level_ev_ref = None, None
    if len(groups) >= 2:
        np_ev = _pow2(min(nps, max(min(int(np.sum(g[1])) for g in groups) // 4, 256)))
        try:
            level_ev = level_blas(us, ys, all_masks, fs, np_ev, f_band=tuple(nf.excited_band), input_unit=in_unit)
            level_ev_ref = level_blas(us, y_ref, all_masks, fs, np_ev, f_band=tuple(nf.excited_band),
                                      window=level_ev.window, input_unit=in_unit)
        except (ValueError, np.linalg.LinAlgError):  # evidence only: the diagnosis goes on without it
            pass
    modal_level = _modal_level_test(level_ev, level_ev_ref)
    if modal_level is not None:
        level["modal"] = modal_level
        if not level["flagged"] or level["trend"] == "none":
            level.update(flagged=True, trend=modal_level["trend"], shift=modal_level["shift"],
                         evidence=level["evidence"] or "modes")
    scales["level_trend"] = level["trend"]
    H_lv = [b[1] for b in blas]
    lv_rms = [b[0] for b in blas]
    # coherence that the noise floor alone would leave (output PSDs of the fitting data, fd[3])
    noise_coh = np.clip(1 - nf.psd_level[None, :] / np.maximum(fd[3][sel], 1e-300), 0, 1)
    resid = ys[fit_log][:, :n_sc] - y_ref[fit_log][:, :n_sc]
    rel_fit = {k: (d[mfit0], v[mfit0]) for k, (d, v) in rel.items()}
    sigs_tests = run_signatures(
        frequencies=f_s, H_levels=H_lv if len(H_lv) >= 2 else [], level_rms=lv_rms, H_meas=H_s, H_refit=H_refit, coh=coh_s,
        noise_coh=noise_coh, resid=resid[:, mfit0], u=u_fit[mfit0], states={"relative": rel_fit}, fs=fs,
        out_channels=run.out_ch, level_stat=level, input_unit=in_unit, u_unit="N" if closed else in_unit)
    tau = next((s.value for s in sigs_tests if s.name == "phase_slope"), 0.0)
    scales["delay0"] = float(min(max(tau, 1e-4), 0.05))
    n_reg = min(n_sc, int(20 * fs))
    scales["regress"] = _regression_starts(refit, rel, ys, y_ref, fit_log, n_reg, fs, run.effect_set)
    if np.any(run.theta):  # the nominal's residual too: a strong nonlinearity bends the refit
        scales["regress_nominal"] = _regression_starts(model, rels[1], ys, y_nom, fit_log, n_reg, fs,
                                                       run.effect_set & {"coulomb_friction", "cubic_stiffness"})
    run.timings["signatures"] = time.perf_counter() - t
    run.f_s, run.H_s, run.scales, run.groups, run.blas, run.level = f_s, H_s, scales, groups, blas, level
    run.level_ev, run.level_ev_ref, run.sigs_tests = level_ev, level_ev_ref, sigs_tests


def _fit_candidates(run: _Run, *, workers, n_full, progress) -> None:
    """Stage 4: the candidate effects' fits. Linear effects fitted jointly with the linear
    parameters on the FRF, then in time; nonlinear effects probed at every location from the
    refitted and the nominal linear parameters, the most promising locations refined, the best
    classes fitted jointly with the linear parameters (a family refitted from its member's
    solution where the member fits better). Sets ``val_logs``, ``none_ok``, ``specs``,
    ``not_tried``, ``lin_later``, ``results`` (``(spec, augmented model, p, gap_fit, base)``),
    ``pre_eval``, ``keep_ids``, ``per_class``."""
    from tqdm.auto import tqdm

    t = time.perf_counter()
    lin_specs, nl_specs = _candidate_specs(run)

    def n_steps():
        """Progress steps: every linear and nonlinear spec, and the joint fits of the best classes."""
        return len(lin_specs) + len(nl_specs) + min(n_full, len({s.effect for s in nl_specs}))

    bar = tqdm(total=n_steps(), desc="gap candidates", disable=not progress, leave=False)
    results = _fit_linear_effects(run, lin_specs, bar, workers)
    nl_left, pre_eval = _stop_at_linear_floor(run, results, nl_specs, workers)
    if nl_left is not nl_specs:
        nl_specs = nl_left
        bar.total = n_steps()
        bar.refresh()
    screened = _screen_nonlinear(run, nl_specs, bar, workers)
    per_class, keep_ids = _fit_best_classes_jointly(run, screened, results, bar, workers, n_full)
    done = {r[0].effect for r in results}
    for s, p, g, base in screened:  # the other classes and locations as screened
        if s.effect not in done or s is not per_class[s.effect][0]:
            results.append((s, s.apply(base, p), p, g, base))
    bar.close()
    run.timings["candidates"] = time.perf_counter() - t
    run.results, run.pre_eval, run.keep_ids, run.per_class = results, pre_eval, keep_ids, per_class
    run.screened = screened


def _candidate_specs(run: _Run) -> tuple[list, list]:
    """The candidates to fit: none when the nominal's gap is within the noise, else every
    effect's specs split into linear and nonlinear; linear effects of a linear model whose BLA
    changes with the level are not fitted alone (left to the forward selection). Sets
    ``val_logs``, ``none_ok``, ``specs``, ``not_tried``, ``lin_later``; returns
    ``(linear specs, nonlinear specs)``."""
    level, refit = run.level, run.refit
    run.val_logs = [i for i, m in enumerate(run.split.validation) if m.any()]
    none_ok = run.gap_before <= NONE_FACTOR * run.floor
    # within the noise: nothing to explain
    specs = [] if none_ok else candidate_specs(refit, run.scales, run.effect_set)
    lin_specs = [s for s in specs if s.linear]
    nl_specs = [s for s in specs if not s.linear]
    not_tried: dict[str, str] = {}  # effect -> why its candidates were not fitted
    lin_later: dict[str, object] = {}  # linear effects not fitted alone, tried by the forward selection
    if lin_specs and level["flagged"] and not run.closed and refit.is_linear:
        # a linear effect in a linear model cannot change the BLA with the level: it would be
        # inadmissible (see _admissible()), so it is not fitted
        for s in lin_specs:
            not_tried[s.effect] = "the BLA changes with the level, which no linear effect of a linear model does"
        # alone it cannot be the verdict, but beside a nonlinear effect it can be a second one: the
        # forward selection tries each such effect's first candidate
        for s in lin_specs:
            lin_later.setdefault(s.effect, s)
        lin_specs = []
    run.none_ok, run.specs, run.not_tried, run.lin_later = none_ok, specs, not_tried, lin_later
    return lin_specs, nl_specs


def _fit_linear_effects(run: _Run, lin_specs: list, bar, workers) -> list:
    """The linear effects fitted on the FRF jointly with the linear parameters (closed loop: the
    best start on the screening prefix), from the refit and, where the refit closes less than half
    of the nominal's fitting gap, from the nominal too; the best per effect polished in time
    (:func:`_polish_linear_effect`). Returns the results ``(spec, model, p, gap_fit, base)``."""
    model, refit, lin, sims, ys, split = run.model, run.refit, run.lin, run.sims, run.ys, run.split
    best_lin: dict[str, tuple] = {}
    sp = split.screen_prefix
    # when the refit closes less than half of the nominal's fitting gap, the refit has bent the
    # linear parameters towards something they cannot express (a long delay): the linear effects
    # are fitted from the nominal too
    lin_bases = [refit] + ([model] if np.any(run.theta) and run.g_ref_fit > 0.5 * run.g_nom_fit else [])
    for s in lin_specs:
        for b_ in lin_bases:
            if run.closed:  # no FRF of the loop to fit: the start that fits the screening prefix best
                p_s, cost = best_start(lambda p, s=s, b_=b_: s.apply(b_, p), s.starts, sims, ys, split.fit, sp)
                th_s = np.zeros(len(lin))
            else:
                m_s, th_s, p_s, cost = fit_linear_frf(b_, lin, run.f_s, run.H_s, run.w[run.sel], spec=s,
                                                      p_starts=s.starts, max_nfev=LIN_EFFECT_NFEV)
            if s.effect not in best_lin or cost < best_lin[s.effect][3]:
                best_lin[s.effect] = (s, th_s, p_s, cost, b_)
        bar.update(1)
    with ThreadPoolExecutor(max(1, workers)) as ex:
        return list(ex.map(partial(_polish_linear_effect, run), best_lin.values()))


def _polish_linear_effect(run: _Run, item):
    """A linear effect's FRF fit polished in time with the linear parameters, on the same
    (at most 20 s per log) samples as the linear refit."""
    lin = run.lin
    s, th_s, p_s, _, b_ = item
    nl = len(lin)

    def build(x, s=s):
        return s.apply(lin.apply(b_, x[:nl]), x[nl:])

    x0 = np.concatenate([th_s, p_s])
    lo = np.concatenate([run.lo_l, s.lower])
    hi = np.concatenate([run.hi_l, s.upper])
    x, gfit, _ = fit_time_domain(build, x0, lo, hi, run.sims, run.ys, run.split.fit, run.ns_pol, fast=False,
                                 max_nfev=6)
    return s, build(x), x[nl:], gfit, lin.apply(b_, x[:nl])


def _stop_at_linear_floor(run: _Run, results: list, nl_specs: list, workers) -> tuple[list, dict]:
    """The linear fits checked on the held-out data when there are nonlinear candidates and the
    BLA does not change with the level: a linear explanation already at the noise floor leaves a
    level-dependent nonlinear effect nothing it could be told by (the search stops, as 'none'
    stops it for the nominal model), so those effects are not tried (``not_tried``). Returns
    ``(the nonlinear specs left, {id(result): (held-out gap, outputs)})``; the list is `nl_specs`
    itself when nothing was dropped."""
    pre_eval: dict[int, tuple] = {}  # id(result) -> (held-out gap, outputs), reused in _evaluate()
    if results and nl_specs and not run.level["flagged"]:
        with ThreadPoolExecutor(max(1, workers)) as ex:
            for r, ev in zip(results, ex.map(lambda r: run.held_out(r[1], fast=True), results)):
                pre_eval[id(r)] = ev
        g_lin = min([run.gap_refit] + [pre_eval[id(r)][0] for r in results if r[0].vanishes(r[2]) is None])
        floor = run.floor
        if g_lin <= NONE_FACTOR * floor:
            for s in nl_specs:
                if EFFECT_TABLE[s.effect].level_dependent:
                    run.not_tried[s.effect] = (f"a linear explanation leaves a held-out gap of {g_lin:.3g}, within "
                                               f"{NONE_FACTOR} x the noise floor {floor:.3g}, and the BLA does not "
                                               f"change with the level")
            nl_specs = [s for s in nl_specs if not EFFECT_TABLE[s.effect].level_dependent]
    return nl_specs, pre_eval


def _screen_nonlinear(run: _Run, nl_specs: list, bar, workers) -> list:
    """The nonlinear effects screened at every location with the linear parameters at the refit
    (and the nominal): each location's best start (:func:`_probe`), the :data:`N_LOCATIONS` best
    locations of each class refined (:func:`_refine_on_either_base`, the others keep their best
    start), and a family refined again from its member's solution where the member fits a
    location better. Returns the screened items ``(spec, p, fitting gap, base)``."""
    other_base: dict[int, tuple] = {}  # id(best start) -> the best start on the other linear base
    with ThreadPoolExecutor(max(1, workers)) as ex:
        probed = []
        for res in ex.map(partial(_probe, run, other_base), nl_specs):
            if res is not None:
                probed.append(res)
            bar.update(1)
        # only the most promising locations of each class (of each form of a class: the Jenkins and
        # the Iwan joint) are refined (the others keep their best start)
        by_class: dict[tuple, list] = {}
        for item in probed:
            by_class.setdefault((item[0].effect, item[0].where.get("form")), []).append(item)
        to_refine, kept = [], []
        for eff, items in by_class.items():
            items.sort(key=lambda r: r[2])
            # the probe ranks start values, not locations: at the effect's own connection every
            # start may still fit worse than none (its valley lies far from the starts), so the
            # N_LOCATIONS best locations are refined whatever their probed gaps
            to_refine += items[:N_LOCATIONS]
            kept += items[N_LOCATIONS:]
        screened = list(ex.map(partial(_refine_on_either_base, run, other_base), to_refine)) + kept
        # a family never fits worse than a member it contains: where the member (Coulomb friction)
        # fits a location better than the family (asymmetric friction), the family is refined again
        # from the member's solution there
        at = {(it[0].effect, _where_key(it[0].where)): it for it in screened}
        lifts = []
        for i, (s, p, g, base) in enumerate(screened):
            mem = at.get((s.lifts_from[0], _where_key(s.where))) if s.lifts_from is not None else None
            if mem is not None and mem[2] < g:
                p0 = np.clip(s.lifts_from[1](mem[1]), s.lower + 1e-9, s.upper - 1e-9)
                lifts.append((i, (s, p0, mem[2], mem[3])))
        for (i, _), res in zip(lifts, ex.map(partial(_refine, run), [x[1] for x in lifts])):
            screened[i] = res
    return screened


def _probe(run: _Run, other_base: dict, s):
    """The best start of `s` on the screening prefix, from the refitted and from the nominal
    linear parameters (a nonlinearity shifts the BLA, so the refit can be the wrong base);
    the best start on the other base is kept aside in `other_base` (by the id of the best)."""
    per_base = {}
    for base in ((run.refit, run.model) if run.theta.any() else (run.refit,)):
        for p0 in s.starts:
            try:
                m0 = s.apply(base, p0)
            except ValueError:
                continue
            g = _prefix_gap(run, m0)
            g = g if np.isfinite(g) else 1e9
            if id(base) not in per_base or g < per_base[id(base)][2]:
                per_base[id(base)] = (s, np.asarray(p0, float), g, base)
    if not per_base:
        return None
    best, *alt = sorted(per_base.values(), key=lambda r: r[2])
    if alt:
        other_base[id(best)] = alt[0]
    return best


def _refine(run: _Run, item):
    """The probed start refined on the screening prefix (effect parameters only)."""
    s, p0, g0, base = item

    def build(p, s=s, base=base):
        return s.apply(base, p)

    p, g, _ = fit_time_domain(build, p0, s.lower, s.upper, run.sims, run.ys, run.split.fit, run.split.screen_prefix,
                              fast=True, max_nfev=4 + 2 * s.n)
    return (s, p, g, base) if g <= g0 else item


def _refine_on_either_base(run: _Run, other_base: dict, item):
    """`item` refined, and the best start on the other linear base too when it probed within
    :data:`OTHER_BASE_FACTOR` of it: the better of the two. (A joint that slips at every level
    of the logs softens the refit, from which the joint then seems to do nothing; from the
    nominal its narrow valley is found, as for a modal model identified at a low level.)"""
    res = _refine(run, item)
    alt = other_base.get(id(item))
    if alt is not None and alt[2] <= OTHER_BASE_FACTOR * item[2]:
        res2 = _refine(run, alt)
        if res2[2] < res[2]:
            return res2
    return res


def _fit_best_classes_jointly(run: _Run, screened: list, results: list, bar, workers, n_full) -> tuple[dict, set]:
    """The best location of each class, and the `n_full` best classes fitted jointly with the
    linear parameters (:func:`_fit_joint`); where a member's joint fit is better than its
    family's (or the family had none), the family is fitted jointly again from the member's
    joint solution. Appends to `results` (and replaces a family's fit there); returns
    ``(per_class, ids of the results to keep)``."""
    lin, model = run.lin, run.model
    per_class: dict[str, tuple] = {}
    for s, p, g, base in screened:
        if s.effect not in per_class or g < per_class[s.effect][2]:
            per_class[s.effect] = (s, p, g, base)
    ranked = sorted(per_class.values(), key=lambda r: r[2])
    full = ranked[:n_full]
    joint_n = [min(n, max(s_, int(20 * run.fs))) if n else 0 for n, s_ in zip(run.ns_fit, run.split.screen_prefix)]
    keep_ids = {id(r) for r in results}  # the linear fits
    with ThreadPoolExecutor(max(1, workers)) as ex:
        for res in ex.map(partial(_fit_joint, run, joint_n), full):
            results.append(res)
            keep_ids.add(id(res))
            bar.update(1)
        # the same after the joint fits: where the member's joint fit (effect and linear parameters)
        # is better than the family's, or the family had none, the family is fitted jointly again
        # from the member's joint solution
        jfit = {(r[0].effect, _where_key(r[0].where)): r for r in results if id(r) in keep_ids and not r[0].linear}
        families = {(s_.lifts_from[0], _where_key(s_.where)): s_ for s_, *_ in screened if s_.lifts_from is not None}
        lifts = []
        for (eff, wk), r in jfit.items():
            fam = families.get((eff, wk))
            if fam is None:
                continue
            own = jfit.get((fam.effect, wk))
            if own is None or own[3] > r[3]:
                p0 = np.clip(fam.lifts_from[1](r[2]), fam.lower + 1e-9, fam.upper - 1e-9)
                lifts.append((own, (fam, p0, r[3], r[4]), lin.theta_between(model, r[4])))
        for (own, _, _), res in zip(lifts, ex.map(lambda a: _fit_joint(run, joint_n, a[1], a[2]), lifts)):
            if own is None or res[3] < own[3]:
                results[:] = [r for r in results if r is not own]
                results.append(res)
                keep_ids.add(id(res))
    return per_class, keep_ids


def _fit_joint(run: _Run, joint_n: list, item, x_lin=None):
    """`item` fitted jointly with the linear parameters on `joint_n` samples per log (from
    `x_lin`, default the refit's or the nominal's, as its base)."""
    lin, model = run.lin, run.model
    s, p, _, base = item
    nl = len(lin)

    def build(x, s=s):
        return s.apply(lin.apply(model, x[:nl]), x[nl:])

    x0 = np.concatenate([x_lin if x_lin is not None else (run.theta if base is run.refit else np.zeros(nl)), p])
    lo = np.concatenate([run.lo_l, s.lower])
    hi = np.concatenate([run.hi_l, s.upper])
    x, g, _ = fit_time_domain(build, x0, lo, hi, run.sims, run.ys, run.split.fit, joint_n, fast=True, max_nfev=6)
    return s, build(x), x[nl:], g, lin.apply(model, x[:nl])


def _rank_candidates(run: _Run, *, workers) -> None:
    """Stage 5: every candidate (and the refit as ``parameter_mismatch``) evaluated on the
    held-out data, the ranking floor, the penalised ranking, the admissible best (level
    evidence, the margin a nonlinear effect needs, the measured trend reproduced), the winner
    polished, and the verdict (``none``, ``unexplained`` or the winner). Sets ``floor_rank``,
    ``floor_rank_method``, ``k_before``, ``cands``, ``best_i``, ``trend_shifts``, ``polish``
    (the arguments of :func:`_polish`), ``verdict``, ``ordered``, ``chosen``."""
    t = time.perf_counter()
    results = _results_to_evaluate(run)
    evaluated = _evaluate_candidates(run, results, workers)
    cands = _ranked_candidates(run, evaluated)
    bla_cache: dict[int, list | None] = {}
    best_i = _admissible_best(run, cands, bla_cache)
    best_i, trend_shifts = _best_reproducing_trend(run, cands, best_i, bla_cache)
    polish = _polish_winner(run, cands, best_i)
    verdict, ordered, chosen = _verdict(run, cands, best_i)
    run.timings["validation"] = time.perf_counter() - t
    run.cands, run.best_i = cands, best_i
    run.trend_shifts, run.polish, run.verdict, run.ordered, run.chosen = trend_shifts, polish, verdict, ordered, chosen


def _results_to_evaluate(run: _Run) -> list:
    """The fits worth a held-out evaluation: a fit that vanishes into a simpler member of its
    family (asymmetric friction with equal forces) added as that simpler effect at the same
    location (to ``results`` and ``keep_ids``); every linear and jointly fitted result, and of the
    screened ones those within 1.5 times their class's best fitting gap (the rest cannot win)."""
    results, keep_ids, specs = run.results, run.keep_ids, run.specs
    for r in list(results):
        s_, m_, p_, g_, b_ = r
        red = s_.reduces_to(p_) if s_.reduces_to is not None else None
        if red is None:
            continue
        s2 = next((x for x in specs if x.effect == red[0] and x.where == s_.where), None)
        if s2 is not None:
            r2 = (s2, s2.apply(b_, red[1]), np.asarray(red[1], float), g_, b_)
            results.append(r2)
            keep_ids.add(id(r2))
    cls_best: dict[str, float] = {}
    for r in results:
        if id(r) not in keep_ids:
            cls_best[r[0].effect] = min(cls_best.get(r[0].effect, np.inf), r[3])
    return [r for r in results if id(r) in keep_ids or r[3] <= 1.5 * cls_best[r[0].effect]]


def _evaluate_candidates(run: _Run, results: list, workers) -> list:
    """Each result evaluated on the held-out data (:func:`_evaluate`), then the floor the
    candidates are ranked against (:func:`_ranking_floor`: the data's out-of-band level, or a
    good candidate's held-out residual out of band when lower). Sets ``floor_rank``,
    ``floor_rank_method``; returns the evaluated items."""
    with ThreadPoolExecutor(max(1, workers)) as ex:
        evaluated = list(ex.map(partial(_evaluate, run), results))
    run.floor_rank, run.floor_rank_method = _ranking_floor(run.floor, run.nf, evaluated, run.ys, run.us, run.split,
                                                           run.val_logs, run.fs, run.nps)
    return evaluated


def _evaluate(run: _Run, item):
    """One result's held-out gap and outputs (fast integration; the winner is re-run at full
    accuracy by :func:`_polish`) and how much the effect itself changes the held-out outputs
    against its own linear base: ``(spec, model, p, gap_fit, gap, outputs, contribution, base)``."""
    val_logs, split = run.val_logs, run.split
    s, m_aug, p, gfit, base = item
    g, yh = run.pre_eval[id(item)] if id(item) in run.pre_eval else run.held_out(m_aug, fast=True)
    if base is run.refit or base is run.model:  # already simulated
        yb = {i: (run.y_ref if base is run.refit else run.y_nom)[i] for i in val_logs}
    else:
        yb = {i: run.sims[i].run(base) for i in val_logs}
    contrib = nrmse([yh[i] for i in val_logs], [yb[i] for i in val_logs],
                    [split.validation[i] for i in val_logs]) if np.isfinite(g) else float("nan")
    return s, m_aug, p, gfit, g, yh, contrib, base


def _ranked_candidates(run: _Run, evaluated: list) -> list:
    """The evaluated results as candidates (vanished when their effect changes the held-out
    outputs less than the ranking floor), the refit as ``parameter_mismatch``, ranked by the
    penalised held-out gap, a richer candidate moved ahead of one it nests when its gain is
    significant (:func:`_nested_order`). Sets ``k_before``, ``nested_t``; returns the list of
    ``(Candidate, model, held-out outputs, spec, p, base)``."""
    key, floor_rank, lin, refit = run.key, run.floor_rank, run.lin, run.refit
    k_before = key(run.gap_before, 0)
    run.k_before = k_before
    cands = []  # (Candidate, model, held-out outputs, spec, p)
    for s, m_aug, p, gfit, g, yh, contrib, base in evaluated:
        reason = s.vanishes(p)
        if reason is None and np.isfinite(contrib) and np.isfinite(floor_rank) and contrib < floor_rank:
            reason = (f"the effect changes the held-out outputs by nrmse {contrib:.3g}, within the noise floor "
                      f"{floor_rank:.3g}")
        where = dict(s.where) | s.qualifiers(p)
        if s.effect == "extra_mode":
            where["frequency_hz"] = s.describe(p).get("frequency_hz")
        expl = 1.0 - key(g, s.n) / k_before if k_before > 0 else 0.0
        c = Candidate(effect=s.effect, where=where, parameters=s.describe(p), gap_after=g, score=expl,
                      gap_fit=gfit, n_parameters=s.n, model_toml=_dumps(m_aug), vanished=reason or "")
        cands.append((c, m_aug, yh, s, p, base))
    changed = lin.changed(run.theta)
    pm_params = {k: v for k, v in lin.values(refit).items() if k in changed}
    expl_pm = 1.0 - key(run.gap_refit, 0) / k_before if k_before > 0 else 0.0
    cands.append((Candidate(effect="parameter_mismatch", where={"parameters": changed}, parameters=pm_params,
                            gap_after=run.gap_refit, score=expl_pm, gap_fit=run.g_ref_fit, n_parameters=0,
                            model_toml=_dumps(refit),
                            vanished="" if changed else "no linear parameter changed by more than 3 %"),
                  refit, {i: run.y_ref[i] for i in run.val_logs}, None, None, refit))
    # rank by the penalised held-out gap (the score saturates at 1 once a gap reaches the floor)
    cands.sort(key=lambda c: (key(c[0].gap_after, c[0].n_parameters), c[0].n_parameters, c[0].gap_after))
    run.nested_t = _nested_order(cands, run.ys, run.split, run.val_logs, run.fs)
    return cands


def _bla_of(run: _Run, cache: dict, c):
    """The BLA per level of a candidate's own simulation on the measured level groups
    (cached in `cache`); None when its held-out outputs do not cover every level (multi-log)."""
    if id(c[0]) not in cache:
        cache[id(c[0])] = (_bla_levels(run.us, [c[2].get(i) for i in range(len(run.ys))], run.groups, run.fs,
                                       run.nps, run.f_s)
                           if {g[0] for g in run.groups} <= set(c[2]) else None)
    return cache[id(c[0])]


def _admissible(run: _Run, cache: dict, c) -> bool:
    """Not vanished, and not a linear explanation of a BLA that changes with the level -
    unless the candidate's own simulation changes with the level the same way (a linear
    effect inside a nominal with nonlinear parts, such as a controller's saturation)."""
    if c[0].vanished:
        return False
    kind = EFFECT_TABLE[c[0].effect].kind
    if not (run.level["flagged"] and kind in ("linear", "reference")):
        return True
    if c[0].effect in ("parameter_mismatch", "none") or _bla_of(run, cache, c) is None:
        return False
    return not _level_test(run.f_s, run.blas, _bla_of(run, cache, c))["flagged"]


def _admissible_best(run: _Run, cands: list, cache: dict) -> int | None:
    """The index of the first admissible candidate (:func:`_admissible`); without level evidence
    a nonlinear effect must beat the best admissible linear explanation by :data:`NL_MARGIN`,
    else that one is the best. None when no candidate is admissible."""
    key = run.key
    best_i = next((i for i, c in enumerate(cands) if _admissible(run, cache, c)), None)
    if best_i is not None and not run.level["flagged"] and EFFECT_TABLE[cands[best_i][0].effect].kind == "nonlinear":
        # without level evidence a nonlinear effect must beat the best linear explanation clearly
        j = next((i for i, c in enumerate(cands) if _admissible(run, cache, c)
                  and EFFECT_TABLE[c[0].effect].kind in ("linear", "reference")), None)
        if j is not None and (key(cands[best_i][0].gap_after, cands[best_i][0].n_parameters)
                              > NL_MARGIN * key(cands[j][0].gap_after, cands[j][0].n_parameters)):
            best_i = j
    return best_i


def _reproduces_trend(run: _Run, cache: dict, trend_shifts: dict, c) -> bool:
    """Whether candidate `c`'s own simulation moves the resonance the way the measured level
    evidence does (the same mode's shift when the evidence is a mode's, else the line-wise BLA
    shift), by at least :data:`TREND_SHARE` of it; the simulated shift is recorded in
    `trend_shifts`. True without evidence (outputs not covering every level)."""
    if _bla_of(run, cache, c) is None:  # its outputs do not cover every level (multi-log): no evidence
        return True
    level, level_ev = run.level, run.level_ev
    sm = float(level["shift"])
    md = level.get("modal")
    if md is not None and md["trend"] == level["trend"]:
        # the evidence is a mode's shift: the candidate's own simulation, the same mode
        try:
            ev_c = level_blas(run.us, [c[2].get(i) for i in range(len(run.ys))], run.all_masks, run.fs,
                              level_ev.nperseg, f_band=level_ev.f_band, window=level_ev.window)
        except (ValueError, np.linalg.LinAlgError):
            return True
        ch, chm = _mode_change(ev_c, md["frequency_hz"]), _mode_change(run.level_ev_ref, md["frequency_hz"])
        sc = (ch[0] - (chm[0] if chm else 0.0)) if ch else 0.0
    else:
        sc = float(_level_test(run.f_s, _bla_of(run, cache, c))["shift"])
    trend_shifts[f"{c[0].effect}@{_where_key(c[0].where)}"] = sc
    return sc * sm > 0 and abs(sc) >= TREND_SHARE * abs(sm)


def _best_reproducing_trend(run: _Run, cands: list, best_i, cache: dict) -> tuple[int | None, dict]:
    """The level evidence enters the ranking: a measured hardening / softening must be reproduced
    by a nonlinear best's own simulation (its BLA per level, on the same level groups), else the
    first admissible nonlinear candidate within :data:`TREND_MARGIN` of it that does is the best.
    Returns ``(best index, the report's record effect@location -> simulated shift)``."""
    key = run.key
    trend_shifts: dict[str, float] = {}

    def reproduces(c):
        return _reproduces_trend(run, cache, trend_shifts, c)

    if (best_i is not None and run.level["trend"] in ("hardening", "softening")
            and EFFECT_TABLE[cands[best_i][0].effect].kind == "nonlinear" and not reproduces(cands[best_i])):
        kb = key(cands[best_i][0].gap_after, cands[best_i][0].n_parameters)
        j = next((i for i, c in enumerate(cands) if _admissible(run, cache, c)
                  and EFFECT_TABLE[c[0].effect].kind == "nonlinear"
                  and key(c[0].gap_after, c[0].n_parameters) <= TREND_MARGIN * kb and reproduces(c)), None)
        if j is not None:
            best_i = j
    return best_i, trend_shifts


def _polish_winner(run: _Run, cands: list, best_i) -> dict:
    """A nonlinear best polished at full accuracy (:func:`_polish`), replaced in `cands`; returns
    the polishing arguments (used again for a combination)."""
    polish = dict(model=run.model, lin=run.lin, lo_l=run.lo_l, hi_l=run.hi_l, sims=run.sims, ys=run.ys,
                  split=run.split, fs=run.fs, held_out=run.held_out, key=run.key, k_before=run.k_before,
                  floor=run.floor_rank)
    if best_i is not None and cands[best_i][3] is not None and not cands[best_i][3].linear:
        cands[best_i] = _polish(cands[best_i], [(cands[best_i][3], cands[best_i][4])], **polish)
    return polish


def _verdict(run: _Run, cands: list, best_i) -> tuple[str, list, list]:
    """``none`` (the nominal's gap within the noise), ``unexplained`` (no admissible candidate, or
    the best's score below :data:`UNEXPLAINED_SCORE`) or the best candidate's effect (taken out of
    `cands`): ``(verdict, every candidate in the report's order, the chosen ones)``."""
    model = run.model
    none_c = (Candidate(effect="none", where={}, parameters={}, gap_after=run.gap_before, score=0.0,
                        gap_fit=run.g_nom_fit, n_parameters=0, model_toml=_dumps(model)), model,
              {i: run.y_nom[i] for i in run.val_logs}, None, None, model)
    chosen = []
    if run.none_ok:
        verdict = "none"
        ordered = [none_c] + cands
    elif best_i is None or cands[best_i][0].score < UNEXPLAINED_SCORE:
        verdict = "unexplained"
        ordered = cands + [none_c]
    else:
        first = cands.pop(best_i)
        ordered = [first] + cands + [none_c]
        chosen = [first]
        verdict = first[0].effect
    return verdict, ordered, chosen


def _nests(rich, simple) -> bool:
    """Whether candidate `rich` contains `simple` as a special case: a family and its member at
    the same connection (``EffectSpec.lifts_from``: asymmetric friction and Coulomb friction), or
    an extra mode and the linear refit it is built on (the mode's mass going to zero)."""
    s_r, s_s = rich[3], simple[3]
    if s_r is None:
        return False
    if s_r.lifts_from is not None and s_s is not None:
        return simple[0].effect == s_r.lifts_from[0] and _where_key(s_s.where) == _where_key(s_r.where)
    return rich[0].effect == "extra_mode" and simple[0].effect == "parameter_mismatch"


def _nested_order(cands: list, ys, split, val_logs, fs) -> dict:
    """Move a richer candidate ahead of one it nests (:func:`_nests`) that ranks before it when
    its held-out gain is significant (:func:`~vibroscope.gap.measure.nested_gain` above
    :data:`NESTED_T`): the complexity penalty of the ranking judges a gain by its size against
    the signal, this test by its size against the noise [Schmeiser 1982]. `cands` is reordered
    in place; returns ``{"rich@where over simple@where": t}`` for the report."""
    out = {}
    for r in list(cands):
        if r[0].vanished:
            continue
        i = next(k for k, c in enumerate(cands) if c is r)  # by identity: the tuples hold arrays
        for j in range(i):
            s_ = cands[j]
            if not _nests(r, s_) or not set(val_logs) <= set(r[2]) or not set(val_logs) <= set(s_[2]):
                continue
            t = nested_gain([ys[k] for k in val_logs], [s_[2][k] for k in val_logs], [r[2][k] for k in val_logs],
                            [split.validation[k] for k in val_logs], fs)
            out[f"{r[0].effect}@{_where_key(r[0].where)} over {s_[0].effect}@{_where_key(s_[0].where)}"] = t
            if t > NESTED_T:
                cands.insert(j, cands.pop(i))
            break
    return out


def _select_further_effects(run: _Run, *, workers) -> None:
    """Stage 5b: forward selection from the verdict (or, when unexplained, from the best
    admissible candidate): a second (third) effect is kept when it closes significantly more,
    and a combination is polished jointly. Where an input delay joins only later, or nothing
    joins an unexplained gap while the phase slope measures a delay, the selection is run once
    more from the delay fitted alone, with the nonlinear candidates screened again on it
    (:func:`_delay_first`, :func:`_screen_on`), and the combination that explains more is kept.
    Updates ``chosen``, ``verdict``, ``ordered``; sets ``shares``."""
    per_class, polish = run.per_class, run.polish
    chosen, cands, best_i, verdict, ordered = run.chosen, run.cands, run.best_i, run.verdict, run.ordered
    t = time.perf_counter()
    shares = []

    def select_from(first, screening=None):
        """Forward selection from `first` (with the nonlinear candidates as `screening`
        ``(per_class, screened)`` has them, default as first screened); a combination is
        polished jointly with the linear parameters at full accuracy. Returns ``(chosen, shares)``."""
        pc, scr = screening if screening is not None else (per_class, run.screened)
        ch, sh = _forward_selection(run, first, pc, scr, workers)
        if len(ch) > 1:
            ch[-1] = _polish(ch[-1], [(c[3], c[4]) for c in ch], **polish)
        return ch, sh

    def or_from_delay(trial, trial_shares, alone_ok=False):
        """`trial`, or the selection from the delay fitted alone when that explains more: tried
        when a delay joined `trial` only later (its first effect was then screened on a linear
        base bent by the delay) or, with `alone_ok` (no verdict yet), when `trial` found no
        combination and the phase slope measures a delay (the delay was not fitted alone: the BLA
        changes with the level)."""
        d_later = [float(c[4][0]) for c in trial[1:] if c[0].effect == "time_delay"]
        if not d_later and (len(trial) > 1 or not alone_ok):
            return trial, trial_shares
        d_first = _delay_first(run, workers, tau=d_later[0] if d_later else None)
        if d_first is None:
            return trial, trial_shares
        trial2, shares2 = select_from(d_first, _screen_on(run, d_first[1], workers))
        if len(trial2) > 1 and trial2[-1][0].score > trial[-1][0].score:
            return trial2, shares2
        return trial, trial_shares

    if chosen and chosen[0][3] is not None:
        chosen, shares = or_from_delay(*select_from(chosen[0]))
        if len(chosen) > 1:
            verdict = chosen[0][0].effect
            added = {c[0].effect for c in chosen}
            ordered = chosen + [c for c in ordered if c[0].effect not in added]
    elif verdict == "unexplained" and best_i is not None and cands[best_i][3] is not None:
        # no effect explains the gap alone; two together may (a clearance and a delay, each of
        # which alone leaves most of it): the forward selection from the best admissible
        # candidate, and the combination is the verdict only if it explains enough itself
        trial, trial_shares = or_from_delay(*select_from(cands[best_i]), alone_ok=True)
        if len(trial) > 1 and trial[-1][0].score >= UNEXPLAINED_SCORE:
            chosen, shares, verdict = trial, trial_shares, trial[0][0].effect
            added = {c[0].effect for c in chosen}
            ordered = chosen + [c for c in ordered if c[0].effect not in added]
    run.timings["forward_selection"] = time.perf_counter() - t
    run.chosen, run.shares, run.verdict, run.ordered = chosen, shares, verdict, ordered


def _delay_first(run: _Run, workers, tau: float | None = None) -> tuple | None:
    """The input delay fitted alone (with the linear parameters, from the refit and from the
    nominal) as a start of the forward selection, when the phase slope of the measured FRF
    against the refit's (:func:`~vibroscope.gap.signatures.run_signatures`) measures a delay of
    at least half a sample and the delay was not fitted alone (``lin_later``: the BLA changes with
    the level). `tau`: the delay to start from (s), default the phase slope's. Returns a candidate
    tuple ``(Candidate, model, held-out outputs, spec, p, base)`` or None."""
    s = run.lin_later.get("time_delay")
    if tau is None:
        tau = next((t.value for t in (run.sigs_tests or ()) if t.name == "phase_slope"), 0.0)
    if s is None or not tau >= 0.5 / run.fs:
        return None
    model, lin, sims, ys, split = run.model, run.lin, run.sims, run.ys, run.split
    nl = len(lin)

    def build(x):
        return s.apply(lin.apply(model, x[:nl]), x[nl:])

    lo = np.concatenate([run.lo_l, s.lower])
    hi = np.concatenate([run.hi_l, s.upper])
    tau0 = float(min(max(tau, s.lower[0]), s.upper[0]))
    starts = [np.concatenate([np.clip(th, run.lo_l, run.hi_l), [tau0]])
              for th in ([run.theta] + ([np.zeros(nl)] if np.any(run.theta) else []))]

    def fit(x0):
        try:
            x, g, _ = fit_time_domain(build, x0, lo, hi, sims, ys, split.fit, split.screen_prefix, fast=True,
                                      max_nfev=8)
        except (ValueError, TypeError):
            return None
        return x, g

    with ThreadPoolExecutor(max(1, min(workers, len(starts)))) as ex:
        fits = [r for r in ex.map(fit, starts) if r is not None and np.isfinite(r[1])]
    if not fits:
        return None
    x, gfit = min(fits, key=lambda r: r[1])
    p = x[nl:]
    if s.vanishes(p) is not None:
        return None
    m_aug, base = build(x), lin.apply(model, x[:nl])
    g, yh = run.held_out(m_aug, fast=True)
    if not np.isfinite(g):
        return None
    k_before = run.k_before
    c = Candidate(effect=s.effect, where=dict(s.where) | s.qualifiers(p), parameters=s.describe(p), gap_after=g,
                  score=1.0 - run.key(g, s.n) / k_before if k_before > 0 else 0.0, gap_fit=gfit, n_parameters=s.n,
                  model_toml=_dumps(m_aug))
    return c, m_aug, yh, s, p, base


def _screen_on(run: _Run, base, workers) -> tuple[dict, list]:
    """The nonlinear candidates screened again on another base model (the delay fitted alone):
    every location's best start on the screening prefix, the best location of each class
    refined (effect parameters only). Returns ``(per_class, screened)`` as
    :func:`_fit_candidates` makes them (``(spec, p, fitting gap, base)``)."""
    sims, ys, split = run.sims, run.ys, run.split
    sp = split.screen_prefix
    nl_specs = [s for s in run.specs if not s.linear]

    def gap_of(m):
        g = _prefix_gap(run, m)
        return g if np.isfinite(g) else 1e9

    def probe(s):
        best = None
        for p0 in s.starts:
            try:
                g = gap_of(s.apply(base, p0))
            except ValueError:
                continue
            if best is None or g < best[2]:
                best = (s, np.asarray(p0, float), g, base)
        return best

    def refine(item):
        s, p0, g0, _ = item
        p, g, _ = fit_time_domain(lambda p, s=s: s.apply(base, p), p0, s.lower, s.upper, sims, ys, split.fit, sp,
                                  fast=True, max_nfev=4 + 2 * s.n)
        return (s, p, g, base) if g <= g0 else item

    with ThreadPoolExecutor(max(1, workers)) as ex:
        probed = [r for r in ex.map(probe, nl_specs) if r is not None]
        best: dict[str, tuple] = {}
        for r in probed:
            if r[0].effect not in best or r[2] < best[r[0].effect][2]:
                best[r[0].effect] = r
        refined = dict(zip(best, ex.map(refine, best.values())))
    screened = [refined.get(r[0].effect) if best.get(r[0].effect) is r else r for r in probed]
    per_class = {e: r for e, r in refined.items()}
    return per_class, screened


def _build_report(run: _Run) -> GapReport:
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
    fr, Gm, _ = masked_csd(np.vstack([ys[tr], ys[tr] - y_nom[tr], ys[tr] - y_ref[tr], ys[tr] - y_aug_full]),
                           all_masks[tr], fs, nps)
    nc = len(out_ch)
    P = np.real(np.einsum("fii->if", Gm))
    Pm, Pb, Pr, Pa = P[:nc], P[nc:2 * nc], P[2 * nc:3 * nc], P[3 * nc:]
    var = np.maximum(np.array([np.mean(ys[tr][c, all_masks[tr]] ** 2) for c in range(nc)]), 1e-300)
    noise_psd = np.repeat(nf.psd_level[:, None], fr.size, axis=1)
    bands = locate_bands(fr, np.sum(Pb / var[:, None], axis=0), np.sum(noise_psd / var[:, None], axis=0))
    st_nom = sims[tr].run(_states_model(model))
    regimes = regime_gaps(ys[tr], y_nom[tr], vmask, {"displacement": st_nom[:model.n_dofs],
                                                      "velocity": st_nom[model.n_dofs:2 * model.n_dofs]},
                          us[tr], input_levels(us[tr], fs)[0])
    fdt = _frf_data([us[tr]], [ys[tr]], [all_masks[tr]], fs, nps)
    fdn = _frf_data([us[tr]], [y_nom[tr]], [all_masks[tr]], fs, nps)
    fda = _frf_data([us[tr]], [y_aug_full], [all_masks[tr]], fs, nps)
    spectrum = GapSpectrum(frequencies=fr, measured=Pm, residual_before=Pb, residual_refit=Pr,
                           residual_after=Pa, noise=noise_psd, frf_frequencies=fdt[0], frf_measured=fdt[1],
                           frf_nominal=fdn[1], frf_augmented=fda[1], coherence=fdt[2])
    traces = GapTraces(fs=fs, t0=float(sigs[tr].t0), channels=tuple(out_ch), units=tuple(units),
                       measured=ys[tr], nominal=y_nom[tr], refit=y_ref[tr], augmented=y_aug_full,
                       validation=vmask, input=us[tr][0],
                       log=str(sigs[tr].meta.get("source", "")) if sigs[tr].meta else "")
    timings["report"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start
    shrink = 1.0 - gap_after / gap_before if gap_before > 0 else 0.0
    return GapReport(
        metric="nrmse",
        validation=split.description,
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
        meta={"fs_hz": fs, "input_unit": in_unit, "nperseg": nps, "nperseg_reason": nps_reason, "window": window, "extra_mode_starts_hz": scales.get("f_extra", []), "n_logs": len(sigs),
              "transient_samples": skips, "levels": split.levels, "excited_band_hz": list(nf.excited_band),
              "noise_floor_ranking": {"nrmse": floor_rank, "method": floor_rank_method},
              "nested_tests": {"t": dict(run.nested_t), "threshold": NESTED_T},
              "refit": {"method": refit_note, "gap_fit_nominal": g_nom_fit, "gap_fit_refit": g_ref_fit},
              "level_dependence": {k: (v if not isinstance(v, float) or np.isfinite(v) else None)
                                   for k, v in level.items()} | {"simulated_shifts": trend_shifts},
              "start_values": {f"{k[0]}@{k[1]}" if k[1] else k[0]: (list(v) if isinstance(v, tuple) else v)
                               for k, v in scales.get("regress", {}).items()},
              "start_values_nominal": {f"{k[0]}@{k[1]}" if k[1] else k[0]: (list(v) if isinstance(v, tuple) else v)
                                       for k, v in scales.get("regress_nominal", {}).items()},
              "not_tried": not_tried,
              "closed_loop": ({"inputs": log_channels(model)[0], "outputs": out_ch,
                               "excluded_effects": excluded} if closed else None),
              "localisation": "bands, channels and regimes of the nominal model on the last log's held-out samples "
                              "(the nominal model is fitted on nothing)"},
    )


def _ranking_floor(floor, nf, evaluated, ys, us, split, val_logs, fs, nps, n_best: int = 3):
    """The noise floor the candidates are ranked against, and how it was found.

    The data's out-of-band output level (:func:`~vibroscope.gap.measure.noise_floor`) bounds
    the noise from above; a nonlinearity's harmonics beyond the excited band (friction, a
    clearance) raise it, and every candidate then looks as good as the noise. The held-out
    residual of a candidate, measured minus simulated, holds the noise plus that model's own
    error: its out-of-band level is another upper bound. The lowest of the data's and the
    `n_best` best candidates' (by held-out gap) is returned; it is never above the data's.
    Evaluated items are ``(spec, model, p, gap_fit, gap_held_out, outputs, contrib, base)``.
    """
    if not (np.isfinite(floor) and nf.method.startswith("out-of-band") and val_logs):
        return floor, "the data's floor"
    best, how = floor, "the data's floor (no candidate's held-out residual is lower out of band)"
    good = sorted((e for e in evaluated if np.isfinite(e[4])), key=lambda e: e[4])[:n_best]
    for e in good:
        yh = e[5]
        if any(yh.get(i) is None for i in val_logs):
            continue
        r = noise_floor([ys[i] - yh[i] for i in val_logs], [us[i] for i in val_logs],
                        [split.validation[i] for i in val_logs], fs, nps, reference=[ys[i] for i in val_logs])
        if r.method.startswith("out-of-band") and np.isfinite(r.nrmse) and r.nrmse < best:
            best = r.nrmse
            how = (f"out-of-band level of the held-out residual of {e[0].effect} @ {_where_key(e[0].where)} "
                   f"(below the data's {floor:.3g})")
    return float(best), how


def _where_key(where: dict) -> str:
    """A candidate's location as a short key (``m1-ground``, ``input``, ``m2``)."""
    if "between" in where:
        return "-".join(str(x) for x in where["between"])
    return str(where.get("dof") or where.get("side") or "model")


def _forward_selection(run: _Run, first, per_class: dict, screened: list, workers):
    """Forward selection of further effects on top of the winner [Ljung 1999, sec. 16.4].

    Each other effect class (its best screened location, and the two best classes screened at
    a chosen effect's connection: a joint has friction and a stiffness nonlinearity at once) is
    added to the current augmented model and its own parameters are fitted (screening prefix,
    coarse integration), then again jointly with the linear parameters and the chosen
    effects' parameters: a first effect fitted alone bends the linear parameters and its own to
    mimic the second (a spring softened for a clearance, a friction force raised for a stiffening
    spring), and only a joint fit can undo that; the better on the fitting data is kept (the
    joint fit only when no chosen effect vanishes in it) (:func:`_try_addition`). The
    best addition is kept when its penalised held-out excess gap falls below
    :data:`ADD_FACTOR` times the current one (beyond what the extra parameters and the noise
    floor explain) (:func:`_accepted_addition`); then the next, up to three effects. Returns the
    chosen candidates (cumulative: the last holds the combined model) and each effect's share of
    the shrink. Besides the four best screened classes of `per_class` (and those of `screened` at
    a chosen connection), the linear effects that were not fitted alone because the BLA changes
    with the level (``lin_later``) are tried as additions, from their own starts."""
    key, k_before, floor = run.key, run.k_before, run.floor_rank
    chosen = [first]
    cur_c, cur_m = first[0], first[1]
    n_par = cur_c.n_parameters
    used = {cur_c.effect}
    also = list(run.lin_later.values())
    shares_g = [run.gap_before, cur_c.gap_after]
    while len(chosen) < 3:
        if _excess(cur_c.gap_after, floor) <= 0.5 * floor:
            break
        cands = _addition_candidates(chosen, used, per_class, screened, also)
        if not cands:
            break
        chain = [(c[3], c[4]) for c in chosen]
        with ThreadPoolExecutor(max(1, workers)) as ex:
            tries = [r for r in ex.map(partial(_try_addition, run, chosen, chain, cur_m), cands) if r is not None]
        tries = [r for r in tries if r[0].vanishes(r[1]) is None]
        if not tries:
            break
        step = _accepted_addition(run, tries, chain, cur_c, n_par)
        if step is None:
            break
        s, p, m_new, g, yh, gfit, base_new, chp = step
        n_par += s.n
        used.add(s.effect)
        if chp is not None:  # the chosen effects as refitted jointly with this one
            chosen = [c[:4] + (p_c,) + c[5:] for c, p_c in zip(chosen, chp)]
        c_new = Candidate(effect=s.effect, where=dict(s.where) | s.qualifiers(p), parameters=s.describe(p),
                          gap_after=g, score=1.0 - key(g, n_par) / k_before if k_before > 0 else 0.0,
                          gap_fit=gfit, n_parameters=s.n, model_toml=_dumps(m_new))
        chosen.append((c_new, m_new, yh, s, p, base_new))
        cur_c, cur_m = c_new, m_new
        shares_g.append(g)
    total = shares_g[0] - shares_g[-1]
    shares = [float((shares_g[i] - shares_g[i + 1]) / total) if total > 0 else 0.0 for i in range(len(shares_g) - 1)]
    return chosen, shares


def _addition_candidates(chosen: list, used: set, per_class: dict, screened: list, also: list) -> list:
    """The effects that may join `chosen`, as ``(spec, start p or None)``: the four best other
    classes of `per_class` (none of a family with a chosen member), the two best classes screened
    at a chosen effect's connection, and the specs of `also` (from their own starts)."""
    def free(eff):
        return eff not in used and not any(eff in fam and used & fam for fam in NESTED_FAMILIES)

    cands = [(s_, p_) for eff, (s_, p_, g_, b_) in sorted(per_class.items(), key=lambda kv: kv[1][2])
             if free(eff)][:4]
    # effects where a chosen one acts (a joint has friction and a stiffness nonlinearity at
    # once): the best two classes screened at a chosen effect's connection
    pairs = [tuple(c[0].where["between"]) for c in chosen if "between" in c[0].where]
    have = {id(s_) for s_, _ in cands}
    near: dict[str, tuple] = {}
    for s_, p_, g_, b_ in sorted(screened, key=lambda r: r[2]):
        if (tuple(s_.where.get("between", ())) in pairs and free(s_.effect) and s_.effect not in near
                and id(s_) not in have):
            near[s_.effect] = (s_, p_)
    cands += list(near.values())[:2]
    cands += [(s_, None) for s_ in also if s_.effect not in used]
    return cands


def _joint_chain_fit(run: _Run, chain: list, s, x0, nfev):
    """The added effect `s`'s parameters, the chosen effects' (`chain`: ``(spec, p)``) and the
    linear ones fitted together on the screening prefix: ``(p, fitting gap, model, linear base, x,
    chain refitted)``."""
    lin, model, split = run.lin, run.model, run.split
    nl = len(lin)
    sizes = [s_c.n for s_c, _ in chain]
    offs = np.cumsum([nl] + sizes)

    def build_j(x, s=s):
        m_ = lin.apply(model, x[:nl])
        for (s_c, _), a_, b_ in zip(chain, offs[:-1], offs[1:]):
            m_ = s_c.apply(m_, x[a_:b_])
        return s.apply(m_, x[offs[-1]:])

    lo = np.concatenate([run.lo_l] + [s_c.lower for s_c, _ in chain] + [s.lower])
    hi = np.concatenate([run.hi_l] + [s_c.upper for s_c, _ in chain] + [s.upper])
    x, gj, _ = fit_time_domain(build_j, np.clip(x0, lo, hi), lo, hi,
                               run.sims, run.ys, split.fit, split.screen_prefix, fast=True, max_nfev=nfev)
    ch_new = [(s_c, x[a_:b_]) for (s_c, _), a_, b_ in zip(chain, offs[:-1], offs[1:])]
    return x[offs[-1]:], gj, build_j(x), lin.apply(model, x[:nl]), x, ch_new


def _try_addition(run: _Run, chosen: list, chain: list, cur_m, item):
    """One addition `item` ``(spec, start p or None)`` to the current model `cur_m`: its best start
    on the screening prefix, its own parameters fitted, then jointly with the chosen effects and the
    linear parameters (:func:`_joint_chain_fit`), kept when better and no chosen effect vanishes in
    it; evaluated on the held-out data. Returns ``(spec, p, model, held-out gap, outputs, gap_fit,
    linear base, joint x or None, chosen effects' refitted p or None)``, or None when it cannot be
    built."""
    sims, ys, split, lin, model = run.sims, run.ys, run.split, run.lin, run.model
    sp = split.screen_prefix
    nl = len(lin)
    s, p_s = item
    p0s = [p_s] + list(s.starts[:2]) if p_s is not None else list(s.starts[:3])
    best = None
    for p0 in p0s:
        try:
            m0 = s.apply(cur_m, p0)
        except (ValueError, TypeError):  # e.g. a second clearance where no spring is left
            return None
        g = _prefix_gap(run, m0)
        if np.isfinite(g) and (best is None or g < best[1]):
            best = (p0, g)
    if best is None:
        return None

    def build(p, s=s):
        return s.apply(cur_m, p)

    p, gfit, _ = fit_time_domain(build, best[0], s.lower, s.upper, sims, ys, split.fit, sp, fast=True,
                                 max_nfev=4 + 2 * s.n)
    m_new, base_new, x_j, chp = build(p), chosen[-1][5], None, None
    if nl:
        th0 = lin.theta_between(model, chosen[-1][5])
        try:
            x0 = np.concatenate([np.clip(th0, run.lo_l, run.hi_l)] + [np.asarray(p_c, float) for _, p_c in chain]
                                + [p])
            pj, gj, mj, bj, xj, chj = _joint_chain_fit(run, chain, s, x0, 4)
        except (ValueError, TypeError):
            gj = float("inf")
        if gj < gfit and not _chain_vanishes(chain, chj):
            p, gfit, m_new, base_new, x_j, chp = pj, gj, mj, bj, xj, [p_c for _, p_c in chj]
    g, yh = run.held_out(m_new, fast=True)
    return s, p, m_new, g, yh, gfit, base_new, x_j, chp


def _accepted_addition(run: _Run, tries: list, chain: list, cur_c, n_par: int):
    """The best of the `tries` (by penalised held-out gap) when it is significant: a promising
    joint fit is carried further first (:data:`REFINE_FACTOR`), and where the chosen effects were
    refitted with it, it must beat them refitted without it too. Returns ``(spec, p, model,
    held-out gap, outputs, gap_fit, linear base, chosen effects' p or None)`` or None (the
    selection stops)."""
    key, held_out = run.key, run.held_out
    s, p, m_new, g, yh, gfit, base_new, x_j, chp = min(tries, key=lambda r: key(r[3], n_par + r[0].n))
    k_cur = key(cur_c.gap_after, n_par)
    if x_j is not None and ADD_FACTOR * k_cur <= key(g, n_par + s.n) < REFINE_FACTOR * k_cur:
        # promising but not yet significant: the joint fit is carried further before deciding
        try:
            pr, gr, mr, br, _, chr_ = _joint_chain_fit(run, chain, s, x_j, 10)
            if gr < gfit and not _chain_vanishes(chain, chr_):
                gh, yhr = held_out(mr, fast=True)
                p, gfit, m_new, base_new, g, yh = pr, gr, mr, br, gh, yhr
                chp = [p_c for _, p_c in chr_]
        except (ValueError, TypeError):
            pass
    if chp is not None:
        # the chosen effects were refitted with this one: the addition must beat them refitted
        # too (without it), not only as they were (a refit alone can close a few per cent)
        m_wo = base_new
        for (s_c, _), p_c in zip(chain, chp):
            m_wo = s_c.apply(m_wo, p_c)
        k_cur = min(k_cur, key(held_out(m_wo, fast=True)[0], n_par))
    if not key(g, n_par + s.n) < ADD_FACTOR * k_cur:
        return None
    return s, p, m_new, g, yh, gfit, base_new, chp


def _chain_vanishes(before, after) -> bool:
    """Whether a joint refit made a chosen effect vanish (`before`, `after`: ``(spec, p)``
    lists) that did not before: the addition then replaces it rather than joins it."""
    return any(s_.vanishes(np.asarray(pa, float)) is not None and s_.vanishes(np.asarray(pb, float)) is None
               for (s_, pb), (_, pa) in zip(before, after))


def _polish(cand, chain, *, model, lin, lo_l, hi_l, sims, ys, split, fs, held_out, key, k_before, floor=0.0):
    """Refine the winning candidate's effects (`chain`: ``(spec, p)`` applied in order to the
    linear model) jointly with the linear parameters on up to POLISH_S s of the fitting data at the
    full integration accuracy (Ljung 1999, output error); the held-out gap is recomputed at
    full accuracy. The fit takes at least four iterations and up to 4 :data:`POLISH_ROUNDS`
    evaluations, while its fitting gap is above :data:`POLISH_FLOOR_FACTOR` times `floor` and every
    four iterations close at least :data:`POLISH_GAIN` of it. The polished model is kept only when its held-out gap is not
    worse and no effect's polished parameters make it vanish where they did not before
    (asymmetric friction polished into two equal forces is no verdict; the candidate stays as it
    was fitted)."""
    c, m_aug, _, s_last, p_last, base = cand
    nl = len(lin)
    th = lin.theta_between(model, base)
    sizes = [s_.n for s_, _ in chain]
    offs = np.cumsum([nl] + sizes)

    def build(x):
        m = lin.apply(model, x[:nl])
        for (s_, _), a_, b_ in zip(chain, offs[:-1], offs[1:]):
            m = s_.apply(m, x[a_:b_])
        return m

    ns = [min(n, int(POLISH_S * fs)) if n else 0 for n in split.fit_prefix]
    x0 = np.concatenate([th] + [np.asarray(p_, float) for _, p_ in chain])
    lo = np.concatenate([lo_l] + [s_.lower for s_, _ in chain])
    hi = np.concatenate([hi_l] + [s_.upper for s_, _ in chain])
    hist = []

    def go_on(intermediate_result):
        """A fit still descending (a hysteretic loop's shape, whose valley is long) is carried on
        while it is above the noise floor and every 4 iterations close POLISH_GAIN of its gap."""
        g_it = math.sqrt(2 * intermediate_result.cost)
        hist.append(g_it)
        if len(hist) >= 4 and (g_it <= POLISH_FLOOR_FACTOR * floor or g_it > (1 - POLISH_GAIN) * hist[-4]):
            raise StopIteration

    x, gfit, _ = fit_time_domain(build, x0, lo, hi, sims, ys, split.fit, ns, fast=False,
                                 max_nfev=4 * POLISH_ROUNDS, callback=go_on)
    m_new = build(x)
    g, yh = held_out(m_new)
    g0, yh0 = held_out(m_aug)  # the candidate itself at full accuracy
    n_par = sum(sizes)
    vanished_now = any(s_.vanishes(x[a_:b_]) is not None and s_.vanishes(np.asarray(p_, float)) is None
                       for (s_, p_), a_, b_ in zip(chain, offs[:-1], offs[1:]))
    if not np.isfinite(g) or (np.isfinite(g0) and g > g0) or vanished_now:
        if not np.isfinite(g0):
            return cand
        return (replace(c, gap_after=g0, score=1.0 - key(g0, n_par) / k_before if k_before > 0 else 0.0),
                m_aug, yh0, s_last, p_last, base)
    pn = x[offs[-2]:offs[-1]]
    keep = {k: v for k, v in c.where.items() if k == "frequency_hz"}
    c_new = Candidate(effect=c.effect, where=dict(s_last.where) | s_last.qualifiers(pn) | keep,
                      parameters=s_last.describe(pn), gap_after=g,
                      score=1.0 - key(g, n_par) / k_before if k_before > 0 else 0.0, gap_fit=gfit,
                      n_parameters=s_last.n, model_toml=_dumps(m_new), vanished=s_last.vanishes(pn) or "")
    return (c_new, m_new, yh, s_last, pn, lin.apply(model, x[:nl]))


def _dumps(model) -> str:
    from vibroscope.models.modelfile import dumps_model

    return dumps_model(model)
