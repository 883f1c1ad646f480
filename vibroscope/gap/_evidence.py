"""Stage 3 of the gap diagnosis: the evidence gathered before any candidate is fitted.

:func:`gather_evidence` sets on the :class:`~vibroscope.gap._run.Run` the scales of the
candidates' start values (the relative motion of every connection, :func:`relative` of the
states of :func:`states_model`; the input's distribution; an extra mode's start frequencies; the
residual regressed on each element law's force, :func:`regression_starts`), the BLA's level
dependence (:mod:`vibroscope.gap._level_evidence`) and the signature tests of the refit's
residual (:func:`~vibroscope.gap.signatures.run_signatures`).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy import signal as sps

from vibroscope.gap._level_evidence import bla_levels, level_groups, level_test, modal_level_test
from vibroscope.gap._run import Run, frf_data, pow2
from vibroscope.gap.closed_loop import actuator_force, basis_model, basis_rows, is_closed_loop, measured_rows
from vibroscope.gap.effects import (DK_SCALE, FRICTION_V_EPS, LinearParams, connection_stiffness, connections, pair_name,
                                    sliding_connections)
from vibroscope.gap.fit import frf_residual
from vibroscope.gap.levels import level_blas
from vibroscope.gap.measure import masked_csd
from vibroscope.gap.signatures import run_signatures
from vibroscope.models.elements import GROUND, Spring
from vibroscope.models.lumped import LumpedModel, Output


def states_model(model: LumpedModel) -> LumpedModel:
    """`model` with its outputs replaced by every DOF's displacement, then every DOF's velocity."""
    outs = tuple(Output(d.name, "displacement", f"/state/{d.name}.x") for d in model.dofs) + tuple(
        Output(d.name, "velocity", f"/state/{d.name}.v") for d in model.dofs)
    return replace(model, outputs=outs)


def relative(model: LumpedModel, X: np.ndarray, V: np.ndarray, pairs=None) -> dict:
    """Each connection's (or each of `pairs`') relative displacement and velocity from the
    states `X`, `V`: ``{pair name: (d, v)}``."""
    out = {}
    for pair in (connections(model) if pairs is None else pairs):
        lv = model.element_vector(Spring(pair, k=0.0))
        out[pair_name(pair)] = (lv @ X, lv @ V)
    return out


#: the delays searched by :func:`loop_delay_start` (s): 0 to the time-delay candidate's bound, in
#: steps of a tenth of a millisecond
LOOP_DELAY_GRID = np.arange(0.0, 0.1, 1e-4)
#: lines whose coherence (command -> plant output) is below this carry no weight there
LOOP_DELAY_COH = 0.5


def _command_delay(model: LumpedModel, us, ys, masks, fs: float, nperseg: int, window) -> float | None:
    """The delay (s) that best aligns the H1 from the actuator force (the logged command times
    its gain) to the plant outputs with `model`'s open-plant FRF: the argmax over
    :data:`LOOP_DELAY_GRID` of the coherence-weighted real part of the unit ratios
    ``H1 / G`` turned by ``exp(j w tau)``; None where no line is coherent."""
    n_out = len(model.outputs)
    uf = [actuator_force(model, u, y, fs)[None] for u, y in zip(us, ys)]
    fd = frf_data(uf, [np.asarray(y)[:n_out] for y in ys], masks, fs, nperseg, window)
    if fd is None:
        return None
    f, H, coh = fd[0], fd[1], fd[2]
    j = model.driven_input(model.controllers[0])
    G = np.zeros_like(H)
    pos = f > 0
    try:
        G[pos] = model.frf(f[pos], quantity=None)[:, :, j]
    except np.linalg.LinAlgError:
        return None
    ok = np.all(np.abs(G) > 0, axis=1) & pos
    c = np.clip(coh, 0.0, 0.999)
    wgt = np.where(ok[:, None] & (c >= LOOP_DELAY_COH), c / (1 - c), 0.0)
    if not np.any(wgt > 0):
        return None
    used = np.any(wgt > 0, axis=1)  # the coherent lines only
    R = H[used] / G[used]
    Z = wgt[used] * R / np.maximum(np.abs(R), 1e-300)
    score = np.real(np.exp(2j * np.pi * np.multiply.outer(LOOP_DELAY_GRID, f[used])) @ Z).sum(axis=1)
    return float(LOOP_DELAY_GRID[int(np.argmax(score))])


def loop_delay_start(model: LumpedModel, us, ys, y_nom, masks, fs: float, nperseg: int, window) -> float | None:
    """A closed loop's actuator delay read from its logged command: the delay that aligns the
    measured command -> plant-output FRF with the open plant's (:func:`_command_delay`), less the
    same read from the nominal's simulated command and outputs (the loop's own lag: the
    zero-order hold, the controller's tick), in s, at least 0.

    Parameters
    ----------
    model : LumpedModel
        A closed-loop model whose first controller with an ``output_channel`` has its command
        logged.
    us, ys : sequence of ndarray
        Each log's input and output rows (:func:`~vibroscope.gap.closed_loop.log_channels`).
    y_nom : sequence of ndarray
        The nominal model's simulated output rows, as `ys`.
    masks : sequence of ndarray of bool
        The samples of each log to use (the fitting samples).
    fs : float
        Sampling frequency, Hz.
    nperseg : int
        Welch segment length, samples.
    window : str
        Welch window.

    Returns
    -------
    float or None
        None without a logged command or a coherent line.

    Notes
    -----
    A time-domain search of the delay from a few starts misses it where the loop is unstable
    for most delays around the true one: fresh closed-loop seed 7315 case 009, a 10 ms actuator
    delay whose loop (nominal + delay) diverges from 3 to 9 ms and leaves 2.06 at 16 ms; from
    this start it is found. The phase of a delay, ``exp(-j w tau)``, is the classic estimate
    (Ljung 1999, sec. 6.3: a delay read from the phase of the FRF).
    """
    if not is_closed_loop(model) or not any(c.output_channel for c in model.controllers):
        return None
    t_meas = _command_delay(model, us, ys, masks, fs, nperseg, window)
    t_nom = _command_delay(model, us, y_nom, masks, fs, nperseg, window)
    if t_meas is None or t_nom is None:
        return None
    return max(t_meas - t_nom, 0.0)


#: a peak-extended screening prefix ends this long after the peak, s
PEAK_MARGIN_S = 0.5


def peak_prefix(u_force, fit, fit_prefix, screen_prefix, fs: float) -> list | None:
    """The screening prefix of each log extended to its largest input force among its fitting
    samples, where that force is beyond every force the screening prefixes hold (plus
    :data:`PEAK_MARGIN_S`; at most the log's fitting prefix): where an effect that acts only at
    the input's peaks is probed (:attr:`~vibroscope.gap.effects.EffectSpec.peak_prefix`).

    Parameters
    ----------
    u_force : sequence of ndarray, shape (n_samples,) each
        The force at the plant's first actuated input per log, N
        (:func:`~vibroscope.gap.closed_loop.actuator_force`).
    fit : sequence of ndarray of bool
        The fitting samples of each log.
    fit_prefix, screen_prefix : sequence of int
        Each log's fitting and screening prefix, samples.
    fs : float
        Sampling frequency, Hz.

    Returns
    -------
    list of int or None
        None where no log is extended (the screening prefixes hold the largest force).

    Notes
    -----
    Fresh closed-loop seed 7316 case 022: an actuator limit of 145 N that the first 8 s of a
    slow reference never reach (the nominal fits the screening prefix at the noise floor), while
    the later blocks clip at up to 680 N; every start of the limit fitted the prefix alike.
    """
    def peak(u, m, n):
        a = np.abs(np.asarray(u[:n], float)) * m[:n]
        return (float(a.max()), int(np.argmax(a))) if a.size else (0.0, 0)

    in_prefix = max((peak(u, m, n)[0] for u, m, n in zip(u_force, fit, screen_prefix) if n), default=0.0)
    out, changed = [], False
    for u, m, n_fit, n_scr in zip(u_force, fit, fit_prefix, screen_prefix):
        top, k = peak(u, m, n_fit) if n_fit else (0.0, 0)
        if n_fit and top > in_prefix and k >= n_scr:
            out.append(int(min(n_fit, k + int(PEAK_MARGIN_S * fs))))
            changed = True
        else:
            out.append(n_scr)
    return out if changed else None


def pair_force_model(model: LumpedModel, pair) -> LumpedModel:
    """`model` with its inputs replaced by a force pair at the ends of `pair`: ``-f`` on the
    first end, ``+f`` on the second (an element's force); ground ends are left out."""
    return basis_model(model, [d for d in pair if d != GROUND])


def regression_starts(refit, rel, ys, y_ref, fit_log, n, fs, effects):
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

    for pair in sliding_connections(refit):
        key = pair_name(pair)
        if key not in rel:
            continue
        d, v = rel[key]
        d, v = d[:n], v[:n]
        m = pair_force_model(refit, pair)
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


def residual_peaks(resid: np.ndarray, mask: np.ndarray, fs: float, nperseg: int, window: str,
                   sel: np.ndarray, noise_psd: np.ndarray, n_peaks: int = 2) -> list[float]:
    """Frequencies (Hz) where a residual's power stands highest above the noise floor.

    Parameters
    ----------
    resid : ndarray, shape (n_outputs, n_samples)
        Measured minus modelled outputs, SI units of each channel.
    mask : ndarray of bool, shape (n_samples,)
        Samples to use (Welch segments wholly inside, :func:`vibroscope.gap.measure.masked_csd`).
    fs : float
        Sampling frequency in Hz.
    nperseg : int
        Welch segment length in samples.
    window : str
        Welch window (``"hann"`` or ``"boxcar"``).
    sel : ndarray of bool, shape (nperseg // 2 + 1,)
        The lines to search (the excited band).
    noise_psd : ndarray, shape (n_outputs,)
        Each channel's white noise level (unit²/Hz, :class:`vibroscope.gap.measure.NoiseFloor`).
    n_peaks : int, optional
        Most peaks returned; default 2.

    Returns
    -------
    list of float
        Up to `n_peaks` peak frequencies (Hz) of the residual PSD over the noise level, summed
        over the channels, by prominence (at least 5 % of the highest and 3 times the floor);
        empty when the residual has no usable segment.

    Notes
    -----
    The power spectrum of the gap itself: a mode the model lacks leaves its residual power
    at and around its frequency (Ewins, *Modal Testing*, 2000, §4.3 on residual FRF
    comparison), where a dB comparison of FRFs weighs a line of small response alike.
    """
    f, G, n_avg = masked_csd(np.asarray(resid, float), mask, fs, nperseg, window)
    if n_avg == 0:
        return []
    P = np.real(np.einsum("fii->fi", G))[sel] / np.maximum(np.asarray(noise_psd, float), 1e-300)[None, :]
    s = np.sum(P, axis=1)
    if not np.all(np.isfinite(s)) or s.size < 3:
        return []
    f = f[sel]
    pk, props = sps.find_peaks(s, prominence=max(0.05 * float(s.max()), 3.0 * P.shape[1]))
    order = np.argsort(props["prominences"])[::-1][:n_peaks]
    return [float(f[pk[i]]) for i in order]


def gather_evidence(run: Run) -> None:
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
        st = sims[fit_log].run(states_model(base), n_sc)
        nd = base.n_dofs
        # where a friction can act (:func:`~vibroscope.gap.effects.sliding_connections`): its scales
        rels.append(relative(base, st[:nd], st[nd:2 * nd], pairs=sliding_connections(base)))
    rel = rels[0]
    # the input-side scales are forces (closed loop: the actuator's, gain x command)
    u_force = [actuator_force(model, u, y, fs) for u, y in zip(us, ys)]
    u_fit = u_force[fit_log][:n_sc]
    run.peak_prefix = peak_prefix(u_force, split.fit, ns_fit, split.screen_prefix, fs)
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

    def model_frf(m_, y_m, lines=sel):
        """The model's FRF to the first input on `lines` (a mask of ``f``): the open plant's, or
        (closed loop) the H1 of its simulation `y_m` under the logged references on the fitting
        samples."""
        if closed:
            return frf_data(us, y_m, split.fit, fs, nps, window)[1][lines]
        return m_.frf(f[lines], quantity=None)[:, :, 0]

    H_refit = model_frf(refit, y_ref)
    # start frequencies of an extra mode: first where the refit's residual holds the most power
    # above the noise floor (the gap's own spectrum: a small absorber's lines stand far above
    # it, seeds 5403 cases 002 and 015: 300 to 680 times the floor, the next peak 20 times),
    # then where measured / model deviates most significantly (deviation in dB times the
    # coherence weight), against the refitted and the nominal model; the dB measure alone is led
    # by lines of small response (a displacement at 200 Hz) where its noise is largest
    # (both on every line of the band, not the fits' thinned ones: a narrow mode falls between those)
    resid = ys[fit_log][:, :n_sc] - y_ref[fit_log][:, :n_sc]  # the refit's residual (also the signatures')
    dense = sel if run.sel_dense is None else run.sel_dense
    starts: list[float] = residual_peaks(resid, mfit0, fs, nps, window, dense, nf.psd_level)
    for ref_m, y_m in ((refit, y_ref), (model, y_nom)):
        Hr = model_frf(ref_m, y_m, dense)
        rt = H[dense] / np.where(np.abs(Hr) > 0, Hr, 1)
        dev = np.mean(np.abs(20 * np.log10(np.maximum(np.abs(rt), 1e-300))) * w[dense], axis=1)
        pk, props = sps.find_peaks(dev, prominence=0.05 * max(float(dev.max()), 1e-12))
        order = np.argsort(props["prominences"])[::-1] if pk.size else []
        for i in order[:3]:
            fc = float(f[dense][pk[i]])
            if all(abs(fc - o) > 0.03 * o for o in starts):
                starts.append(fc)
    scales["f_extra"] = starts
    if not closed:  # where an extra mode can be seen (in a loop the plant's input is not the reference)
        scales["f_band"] = tuple(float(x) for x in nf.excited_band)
    if model.point_names() and not closed:  # a joint's share from the stiffness each connection lost
        scales["k_lost"] = stiffness_lost(model, f_s, H_s, w[sel])
    # levels (within and across logs) and level-wise H1: the BLA's level dependence
    groups = level_groups(us, all_masks, fs)
    blas = bla_levels(us, ys, groups, fs, nps, f_s)
    # against the refitted model's own level dependence on the same groups (noise-free)
    level = level_test(f_s, blas, bla_levels(us, y_ref, groups, fs, nps, f_s))
    level["evidence"] = "lines" if level["flagged"] else None
    # the resonances per level (the report's level evidence), against the refitted model's own
    level_ev, level_ev_ref = None, None
    if len(groups) >= 2:
        n_min = min(int(np.sum(g[1])) for g in groups)
        np_ev = pow2(min(nps, max(n_min // 4, 256)))  # four averages per level, Hann
        band = tuple(nf.excited_band)

        def blas_at(n):
            try:
                return level_blas(us, ys, all_masks, fs, n, f_band=band, input_unit=in_unit)
            except (ValueError, np.linalg.LinAlgError):  # evidence only: the diagnosis goes on without it
                return None

        level_ev = blas_at(np_ev)
        if window == "boxcar" and n_min >= 2 * nps and nps != np_ev:
            # a periodic input's one period (rectangular window, no leakage) when it finds more
            # resonances: a Hann window's leakage at a lightly damped mode under-resolved by the
            # shorter segment drops the coherence at its peak below the mode finder's 0.5 (a 7.3 Hz
            # mode of 0.07 Hz half-power bandwidth under 0.1 Hz lines went unseen); where both find
            # the same, the Hann estimate's more averages are kept
            alt = blas_at(nps)
            if alt is not None and (level_ev is None or len(alt.modes) > len(level_ev.modes)):
                level_ev, np_ev = alt, nps
        if level_ev is not None:
            try:
                level_ev_ref = level_blas(us, y_ref, all_masks, fs, np_ev, f_band=band, window=level_ev.window,
                                          input_unit=in_unit)
            except (ValueError, np.linalg.LinAlgError):  # the report keeps the measured evidence
                pass
    f_model = None  # the refit's own resonances, where its evidence resolves none (open loop)
    if not closed:
        try:
            f_model = np.asarray(refit.modes().natural_frequencies, float)
        except (AttributeError, ValueError, np.linalg.LinAlgError):
            f_model = None
    modal_level = modal_level_test(level_ev, level_ev_ref, f_model)
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
    at_elements = {pair_name(p) for p in connections(model)}  # the signatures read the model's connections
    rel_fit = {k: (d[mfit0], v[mfit0]) for k, (d, v) in rel.items() if k in at_elements}
    sigs_tests = run_signatures(
        frequencies=f_s, H_levels=H_lv if len(H_lv) >= 2 else [], level_rms=lv_rms, H_meas=H_s, H_refit=H_refit, coh=coh_s,
        noise_coh=noise_coh, resid=resid[:, mfit0], u=u_fit[mfit0], states={"relative": rel_fit}, fs=fs,
        out_channels=run.out_ch, level_stat=level, input_unit=in_unit, u_unit="N" if closed else in_unit)
    tau = next((s.value for s in sigs_tests if s.name == "phase_slope"), 0.0)
    scales["delay0"] = float(min(max(tau, 1e-4), 0.05))
    if closed:
        scales["delay0_loop"] = loop_delay_start(model, us, ys, run.y_nom, split.fit, fs, nps, window)
    n_reg = min(n_sc, int(20 * fs))
    scales["regress"] = regression_starts(refit, rel, ys, y_ref, fit_log, n_reg, fs, run.effect_set)
    if np.any(run.theta):  # the nominal's residual too: a strong nonlinearity bends the refit
        scales["regress_nominal"] = regression_starts(model, rels[1], ys, y_nom, fit_log, n_reg, fs,
                                                       run.effect_set & {"coulomb_friction", "cubic_stiffness"})
    run.timings["signatures"] = time.perf_counter() - t
    run.f_s, run.H_s, run.scales, run.groups, run.blas, run.level = f_s, H_s, scales, groups, blas, level
    run.level_ev, run.level_ev_ref, run.sigs_tests = level_ev, level_ev_ref, sigs_tests


#: the shares of a connection's static stiffness :func:`stiffness_lost` scans
K_LOST_GRID = np.linspace(0.0, 0.95, 39)


def stiffness_lost(model: LumpedModel, f, H, w) -> dict[str, float]:
    """Per connection of a modal-coordinates model, the stiffness (N/m) that a physical stiffness
    change there, alone, takes out to fit the measured FRF best.

    A joint that slips through the whole record (its slip force far below its elastic force at
    the RMS deflection) is, to its BLA, that connection's stiffness lost in part: the share
    starts the joint's fit (``joint_friction`` in :mod:`vibroscope.gap.effects`), whose valley
    in the share is narrow (fresh modal seed 7322 case 010: a joint of 44 % of the connection's
    stiffness slipping at 1/50 of its RMS deflection; shares 0.3 and 0.6 left held-out gaps of
    0.73 and 0.66, 0.44 left 0.07, the nominal 0.92). The FRF cost is scanned over the shares
    (:data:`K_LOST_GRID`) and polished by a bounded Brent search between the best share's
    neighbours: a least-squares fit from no change stops in the FRF's local minima as the
    resonances move (it stopped at 0.06 there).

    Parameters
    ----------
    model : LumpedModel
        The nominal, with measured points (a modal-coordinates model).
    f : ndarray, shape (n_f,)
        Frequencies (Hz).
    H : ndarray of complex, shape (n_f, n_outputs)
        Measured FRF to the first input.
    w : ndarray, shape (n_f, n_outputs)
        The FRF fit's weights.

    Returns
    -------
    dict of str to float
        ``pair_name`` -> the stiffness taken out (N/m; 0 to 0.95 of the nominal's static
        stiffness across the connection) that fits the FRF best
        (:func:`~vibroscope.gap.fit.frf_residual`, a ``dk:`` change of
        :class:`~vibroscope.gap.effects.LinearParams`, each mode's own parameters held).
    """
    from scipy.optimize import minimize_scalar

    out: dict[str, float] = {}
    for pair in connections(model):
        name = f"dk:{pair_name(pair)}"
        lin = LinearParams(model, [name], physical=True)
        k_ref = connection_stiffness(model, pair)
        if len(lin) != 1 or not k_ref > 0:
            continue

        def cost(r, lin=lin):  # the dk: change is DK_SCALE * k_ref * theta
            try:
                res = frf_residual(lin.apply(model, [-r / DK_SCALE]), f, H, w)
            except (ValueError, np.linalg.LinAlgError, FloatingPointError):
                return np.inf
            c = float(res @ res)
            return c if np.isfinite(c) else np.inf

        costs = np.array([cost(r) for r in K_LOST_GRID])
        if not np.isfinite(costs).any():
            continue
        j = int(np.argmin(costs))
        lo, hi = K_LOST_GRID[max(j - 1, 0)], K_LOST_GRID[min(j + 1, len(K_LOST_GRID) - 1)]
        r = float(K_LOST_GRID[j])
        if hi > lo:
            opt = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 * (hi - lo)})
            if opt.fun < costs[j]:
                r = float(opt.x)
        out[pair_name(pair)] = r * k_ref
    return out
