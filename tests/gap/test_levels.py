"""Level dependence of the BLA, the period of a periodic input and the FRF segment length
(vibroscope.gap.levels), against a 1-DOF (Duffing) model's known truth."""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest
from scipy import signal

from vibroscope.gap.levels import detect_period, frf_segment_length, level_blas, steady_state_start
from vibroscope.models.elements import CubicSpring, Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.simulate import simulate

FS = 200.0
FN, ZETA = 10.0, 0.02  # the linear part: 10 Hz, 2 %, half-power bandwidth 0.4 Hz
K = (2 * np.pi * FN) ** 2
C = 2 * ZETA * np.sqrt(K)
LEVELS = (10.0, 25.0, 60.0)  # input RMS, N (1 : 2.5 : 6)


def duffing(k3: float) -> LumpedModel:
    el = [Spring(("m", "ground"), k=K), Damper(("m", "ground"), c=C)]
    if k3:
        el.append(CubicSpring(("m", "ground"), k3=k3))
    return LumpedModel(dofs=(Dof("m", 1.0),), elements=tuple(el), inputs=(Input(dof="m", channel="/u.x"),),
                       outputs=(Output("m", "acceleration", "/a.x"),), name="duffing")


def logs(k3: float, duration_s: float, seed: int = 0):
    """Three logs, one level each: band-limited random force (2-40 Hz), 2 % output noise."""
    rng = np.random.default_rng(seed)
    b, a = signal.butter(4, [2 / (FS / 2), 40 / (FS / 2)], "band")
    n = int(duration_s * FS)
    us, ys = [], []
    for lev in LEVELS:
        u = signal.lfilter(b, a, rng.standard_normal(n))
        u = u / np.std(u) * lev
        y = np.asarray(simulate(duffing(k3), u, FS).data[1:])
        y = y + 0.02 * np.std(y) * rng.standard_normal(y.shape)
        us.append(u[None])
        ys.append(y)
    return us, ys


@lru_cache(maxsize=4)
def evidence(k3, duration_s):
    us, ys = logs(k3, duration_s)
    nperseg, _ = frf_segment_length(us[0], FS, mode_bandwidths_hz=[2 * ZETA * FN])
    return level_blas(us, ys, [None] * 3, FS, nperseg)


def test_linear_system_is_level_independent_and_recovers_the_mode():
    ev = evidence(0.0, 120.0)
    assert len(ev.levels) == 3 and len(ev.modes) == 1
    assert not ev.level_dependent and ev.trend == "none"
    for lv in ev.levels:
        assert lv.natural_frequencies[0] == pytest.approx(FN, rel=0.01)
        assert lv.damping_ratios[0] == pytest.approx(ZETA, rel=0.08)
        assert 0 < lv.natural_frequency_std[0] < 0.02 and 0 < lv.damping_std[0] < 0.002
    np.testing.assert_allclose([lv.rms for lv in ev.levels], LEVELS, rtol=1e-6)


def test_hardening_cubic_spring():
    ev = evidence(1e5, 60.0)
    m = ev.modes[0]
    assert ev.level_dependent and ev.trend == "hardening" and m.trend == "hardening"
    assert m.frequency_change > 0.02 and m.frequency_z > 3


def test_level_figure_is_written(tmp_path):
    pytest.importorskip("matplotlib")
    ev = evidence(1e5, 60.0)
    path = ev.plot(out_path=tmp_path / "levels.png")
    assert path.exists() and path.stat().st_size > 10_000


def test_softening_cubic_spring():
    ev = evidence(-2e4, 90.0)
    m = ev.modes[0]
    assert ev.level_dependent and ev.trend == "softening"
    assert np.nanmin(m.frequency_changes) < -0.005


def multisine(period: int, fs: float, f_lo: float, f_hi: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(period, 1 / fs)
    X = np.where((f >= f_lo) & (f <= f_hi), np.exp(2j * np.pi * rng.random(f.size)), 0)
    x = np.fft.irfft(X, period)
    return x / np.std(x)


def test_detect_period_of_a_repeated_multisine_and_not_of_noise():
    one = multisine(8192, 400.0, 0.5, 100.0)
    assert detect_period(np.tile(one, 5), 400.0) == 8192
    # level steps between periods: still the period
    assert detect_period(np.tile(one, 5) * np.repeat([1.0, 1.0, 3.0, 3.0, 8.0], 8192), 400.0) == 8192
    # a little noise
    rng = np.random.default_rng(4)
    assert detect_period(np.tile(one, 5) + 0.01 * rng.standard_normal(5 * 8192), 400.0) == 8192
    assert detect_period(rng.standard_normal(5 * 8192), 400.0) is None
    b, a = signal.butter(4, 0.2)
    assert detect_period(signal.lfilter(b, a, rng.standard_normal(5 * 8192)), 400.0) is None


def test_steady_state_start_tells_a_log_cut_from_steady_state_from_one_recorded_from_rest():
    """A mildly hardening Duffing model (10 Hz, 2 %: time constant 0.8 s) under a 10 s multisine
    of 10 N RMS, simulated from rest for 6 periods: the first period holds the transient (its
    difference from the second is 0.18 of the output RMS over its first quarter), the last three
    do not (differences below 1e-4)."""
    per = int(10 * FS)
    u = np.tile(multisine(per, FS, 2.0, 40.0), 6) * 10.0
    y = np.asarray(simulate(duffing(1e6), u[None], FS).data[1:])
    rng = np.random.default_rng(6)
    noisy = y + 0.02 * np.std(y) * rng.standard_normal(y.shape)
    assert steady_state_start(u, noisy, FS) is None  # from rest: the data have the transient too
    # the last three periods: steady from the first sample, noise or not
    assert steady_state_start(u[3 * per:], y[:, 3 * per:], FS) == per
    assert steady_state_start(u[3 * per:], noisy[:, 3 * per:], FS) == per
    assert steady_state_start(u[3 * per:], noisy[:, 3 * per:], FS, period=per) == per
    # steady states at two levels, a step between the first two periods: not one steady state
    y2 = np.asarray(simulate(duffing(1e6), 2 * u[None], FS).data[1:])
    u_step = np.concatenate([u[3 * per: 4 * per], 2 * u[3 * per: 5 * per]])
    y_step = np.concatenate([y[:, 3 * per: 4 * per], y2[:, 3 * per: 5 * per]], axis=1)
    assert detect_period(u_step, FS) == per
    assert steady_state_start(u_step, y_step, FS) is None
    # a random input has no period
    r = rng.standard_normal(u.size)
    assert steady_state_start(r, noisy, FS) is None
    # three 30 s log sweeps 2-60 Hz at levels 1, 2.5, 6 from rest (a stepped-level test): periodic
    # to detect_period, which allows the level change, but not one steady state (before the input
    # test: its first sweep left out as a transient, seed 7002 case 010 with --input-kind sweep)
    t = np.arange(3 * per) / FS
    sweep = np.sin(2 * np.pi * 2.0 * 30.0 / np.log(30.0) * np.expm1(t * np.log(30.0) / 30.0))
    u_sw = np.concatenate([lv * 10.0 * sweep for lv in (1.0, 2.5, 6.0)])
    vel = replace(duffing(1e6), outputs=(Output("m", "velocity", "/v.x"),))  # rolls off on both sides of 10 Hz
    y_sw = np.asarray(simulate(vel, u_sw[None], FS).data[1:])
    assert detect_period(u_sw, FS) == 3 * per
    assert steady_state_start(u_sw, y_sw, FS) is None
    with pytest.raises(ValueError, match="lengths differ"):
        steady_state_start(u, y[:, :-1], FS)


def test_segment_length_resolves_a_narrow_mode_or_takes_the_period():
    rng = np.random.default_rng(5)
    fs = 400.0
    u = rng.standard_normal(int(600 * fs))
    nperseg, reason = frf_segment_length(u, fs, mode_bandwidths_hz=[0.07, 1.0])
    assert fs / nperseg <= 0.07 / 4 and "bandwidth" in reason
    assert (u.size - nperseg) // (nperseg // 2) + 1 >= 8
    # too short a record for that: capped at 8 averages, and the reason says so
    nperseg, reason = frf_segment_length(u[: int(60 * fs)], fs, mode_bandwidths_hz=[0.07])
    assert (int(60 * fs) - nperseg) // (nperseg // 2) + 1 >= 8 and "capped" in reason
    # periodic: one period
    per = np.tile(multisine(8192, fs, 0.5, 100.0), 6)
    nperseg, reason = frf_segment_length(per, fs, mode_bandwidths_hz=[0.07])
    assert nperseg == 8192 and "period" in reason
    # neither: the power-of-two default about 4 s
    assert frf_segment_length(u, fs)[0] == 1024  # diagnose's default: 2**floor(log2(min(4 fs, n/8)))


def test_mode_shift_evidence_less_the_models_own():
    from vibroscope.gap._level_evidence import modal_level_test

    assert modal_level_test(evidence(0.0, 120.0), None) is None  # a linear system: no shift
    soft = modal_level_test(evidence(-2e4, 90.0), None)
    assert soft["trend"] == "softening" and soft["shift"] < -0.005 and soft["z"] < -3
    assert soft["frequency_hz"] == pytest.approx(FN, rel=0.02)
    # a model whose own simulation shifts the same way explains the shift: no evidence left
    assert modal_level_test(evidence(-2e4, 90.0), evidence(-2e4, 90.0)) is None
    assert modal_level_test(evidence(1e5, 60.0), None)["trend"] == "hardening"


def test_a_resonance_the_model_does_not_have_is_not_tested():
    """A peak of the measured indicator with no resonance of the model within 15 % (on a
    benchmark case: a noise peak at 166 Hz above a 2-DOF chain's 26 and 94 Hz modes, z = 3.15)
    raised a false level alarm; a resonance the model has nearby is still tested."""
    from dataclasses import replace

    from vibroscope.gap._level_evidence import modal_level_test

    soft = evidence(-2e4, 90.0)
    lin = evidence(0.0, 90.0)

    def moved(ev, factor):
        return replace(ev, modes=tuple(replace(m, natural_frequency=m.natural_frequency * factor) for m in ev.modes))

    assert modal_level_test(soft, moved(lin, 2.0)) is None  # the model's resonance is at 2 FN
    assert modal_level_test(soft, moved(lin, 1.1))["trend"] == "softening"  # within 15 %: tested
    assert modal_level_test(soft, lin)["trend"] == "softening"
    # the model's evidence resolves no resonance (benchmarks/gap seed 7353 case 005): its own
    # natural frequencies stand in for the match
    none = replace(lin, modes=())
    assert modal_level_test(soft, none, [2.0 * FN]) is None
    assert modal_level_test(soft, none, [1.1 * FN])["trend"] == "softening"
    assert modal_level_test(soft, none)["trend"] == "softening"


def test_logs_at_different_levels_are_each_split_and_a_softening_spring_is_found():
    """Three logs at 1 : 2.5 : 6, the softening only visible at the top one: with the last log
    held out (fitted on the two low levels) the spring could not be identified."""
    from vibroscope.gap import diagnose
    from vibroscope.gap.measure import make_split
    from vibroscope.signals import Signals

    us, ys = logs(-2e4, 30.0, seed=4)
    sp = make_split(us, FS)
    assert "each split in time" in sp.description
    assert all(f.any() and v.any() and not np.any(f & v) for f, v in zip(sp.fit, sp.validation))
    same = make_split([u / np.std(u) for u in us], FS)  # one level: the last log is held out
    assert not same.fit[-1].any() and not any(v.any() for v in same.validation[:-1])
    last = make_split(us, FS, holdout="last")  # the user's choice: the last log, whatever the levels
    assert not last.fit[-1].any() and last.validation[-1].any() and not last.validation[0].any()
    sigs = [Signals(data=np.vstack([u, y]), fs=FS, channels=["/u.x", "/a.x"], units=["N", "m/s^2"]) for u, y in zip(us, ys)]
    r = diagnose(duffing(0.0), sigs, effects=["cubic_stiffness", "time_delay", "coulomb_friction"], progress=False)
    assert r.verdict == "cubic_stiffness"
    assert r.candidates[0].where["character"] == "softening"
    assert r.candidates[0].parameters["k3_N_per_m3"] == pytest.approx(-2e4, rel=0.3)


def test_the_models_own_shift_is_an_estimate_with_its_uncertainty():
    """The model's own change is subtracted with its standard deviation: a linear measurement
    against a model whose noise-free evidence moves its mode with a precise fit is flagged (the
    difference is significant), against the same move fitted 20 times less precisely it is not
    (fresh modal seed 5403 case 001: the refit's mode at 25.6 +- 0.77 Hz and 26.3 +- 1.18 Hz
    gave a linear stiffness mismatch z = -3.3, a level dependence, and `unexplained`)."""
    from dataclasses import replace

    from vibroscope.gap._level_evidence import modal_level_test

    lin, soft = evidence(0.0, 90.0), evidence(-2e4, 90.0)

    def vaguer(ev, factor):
        return replace(ev, levels=tuple(replace(lv, natural_frequency_std=lv.natural_frequency_std * factor)
                                        for lv in ev.levels))

    precise = modal_level_test(lin, soft)
    assert precise is not None and precise["trend"] == "hardening" and precise["z"] > 3
    assert modal_level_test(lin, vaguer(soft, 20.0)) is None


def _h1_lines(rng, n_avg, n_lines, snr, gain=1.0):
    """H1 and coherence of `n_lines` independent lines of y = gain x + noise, `n_avg` averages."""
    shape = (n_lines, n_avg)
    x = rng.standard_normal(shape) + 1j * rng.standard_normal(shape)
    y = gain * x + (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(snr)
    gxx, gyy = np.mean(np.abs(x) ** 2, 1), np.mean(np.abs(y) ** 2, 1)
    gxy = np.mean(np.conj(x) * y, 1)
    return (gxy / gxx)[:, None], (np.abs(gxy) ** 2 / (gxx * gyy))[:, None]


def test_a_linear_bla_with_few_averages_is_not_level_dependent():
    """The line-wise level test at 4 averages (the lowest level of a 10 s log) and 15: a linear
    system's H1 changes beyond z = 3 on 1 % of its lines (the estimated coherence in the variance),
    which the asymptotic bound counted as level dependence (fresh modal seed 5502 case 002, an
    extra mode barred); the F bound keeps the rate near exp(-9) = 1.2e-4; a 20 % change of the
    BLA is still found at those averages."""
    from vibroscope.gap._level_evidence import level_test, level_z2_bound

    assert level_z2_bound(10**6) == pytest.approx(9.0, rel=1e-4)  # chi^2_2 / 2 > 9: exp(-9)
    assert level_z2_bound(1) == np.inf
    rng = np.random.default_rng(5)
    n = 20_000
    f = np.linspace(1.0, 200.0, n)
    H0, c0 = _h1_lines(rng, 4, n, 20.0)
    H1, c1 = _h1_lines(rng, 15, n, 20.0)
    r = level_test(f, [(1.0, H0, c0, 4), (6.0, H1, c1, 15)])
    assert r["lines"] > 0.9 * n
    assert r["lines_beyond_3_sigma"] <= 20 and not r["flagged"]  # 2.5 expected; 1 % = 200 before
    H0, c0 = _h1_lines(rng, 4, n, 1000.0)
    H1, c1 = _h1_lines(rng, 15, n, 1000.0, gain=1.2)
    assert level_test(f, [(1.0, H0, c0, 4), (6.0, H1, c1, 15)])["flagged"]


def test_a_narrow_mode_under_a_band_limited_periodic_multisine_is_found():
    """A ground vibration test's record: 400 Hz, a multisine over 2-15 Hz in periods of 8192
    samples (three periods per level), a 7.3 Hz mode of 0.5 % damping (0.07 Hz half-power
    bandwidth), 1 % noise. Over whole periods the lines beyond the band carry no input; their H1
    (a ratio of residues, at a coherence of 0.2-0.3) topped the mode indicator by 250 dB and no
    resonance was found. Left out, the mode is found at every level, at its frequency and
    damping (ground truth: the 1-DOF model)."""
    fs, fn, zeta = 400.0, 7.32, 0.005
    k = (2 * np.pi * fn) ** 2
    m = LumpedModel(dofs=(Dof("m", 1.0),), elements=(Spring(("m", "ground"), k=k), Damper(("m", "ground"), c=2 * zeta * np.sqrt(k))),
                    inputs=(Input(dof="m", channel="/u.x"),), outputs=(Output("m", "acceleration", "/a.x"),), name="torsion")
    one = multisine(8192, fs, 2.0, 15.0, seed=3)
    rng = np.random.default_rng(8)
    us, ys = [], []
    for lev in (0.1, 0.5):
        u = np.tile(one, 4) * lev
        y = np.asarray(simulate(m, u, fs).data[1:])
        us.append(u[None])
        ys.append(y + 0.01 * np.std(y) * rng.standard_normal(y.shape))
    masks = [np.arange(u.shape[1]) >= 8192 for u in us]  # the first period: the transient
    ev = level_blas(us, ys, masks, fs, 8192, f_band=(1.9, 15.2))
    assert ev.window == "boxcar" and len(ev.modes) == 1, ev.description
    for lv in ev.levels:
        assert lv.natural_frequencies[0] == pytest.approx(fn, rel=2e-3)
        assert lv.damping_ratios[0] == pytest.approx(zeta, rel=0.15)
    assert not ev.level_dependent


def _periodic_logs(k3: float, n_periods: int, noise: float, disturbance: float, levels=(10.0, 40.0), seed: int = 7):
    """One log per level of a repeated multisine (2 s period at FS) through the Duffing model from
    rest, with white output noise and an unlogged low-passed random force (share of the logged
    force's RMS) in the truth; returns (us, ys, the part of ys that is not the periodic response)."""
    rng = np.random.default_rng(seed)
    T = int(2.0 * FS)
    one = multisine(T, FS, 1.0, 40.0)
    b, a = signal.butter(4, 40 / (FS / 2))
    us, ys, extra = [], [], []
    for lev in levels:
        u = np.tile(one, n_periods) * lev / np.std(one)
        d = signal.lfilter(b, a, rng.standard_normal(u.size))
        d *= disturbance * np.std(u) / np.std(d)
        m = duffing(k3)
        clean = simulate(m, u, FS).data[1]  # [0] is the input
        truth = simulate(m, u + d, FS).data[1]
        y = truth + noise * np.std(truth) * rng.standard_normal(u.size)
        us.append(u[None, :])
        ys.append(y[None, :])
        extra.append((y - clean)[None, :])
    return us, ys, extra


@pytest.mark.parametrize("k3, disturbance", [(0.0, 0.0), (0.0, 0.15), (1e5, 0.1)])
def test_period_floor_is_what_no_model_of_the_logged_input_can_explain(k3, disturbance):
    """The outputs' variation from period to period is the white noise plus the response to an
    unlogged force, whatever the model (linear or a hardening spring): the nrmse the truth
    itself leaves against the noisy, disturbed outputs, on the periods it uses."""
    from vibroscope.gap.levels import PERIOD_SETTLE, period_floor

    us, ys, extra = _periodic_logs(k3, 10, 0.02, disturbance)
    pf = period_floor(ys, us, [np.ones(y.shape[1], bool) for y in ys], FS)
    assert pf is not None and pf.n_periods == 2 * (10 - PERIOD_SETTLE) and pf.period_samples == (400, 400)
    T = pf.period_samples[0]
    keep = np.arange(ys[0].shape[1]) >= PERIOD_SETTLE * T
    # the truth's own residual (noise + the disturbance's response) on those samples; with a
    # hardening spring the disturbance's response is not additive, so only within 15 %
    left = np.sqrt(np.sum([np.sum(e[0, keep] ** 2) for e in extra]) / np.sum([np.sum(y[0, keep] ** 2) for y in ys]))
    assert pf.nrmse == pytest.approx(left, rel=0.15 if k3 else 0.06), (pf.nrmse, left)
    if disturbance:
        assert pf.nrmse > 3 * 0.02
    # noise relative to each log's level, a disturbance too: the relative variation does not grow
    assert not pf.grows_with_level and len(pf.run_nrmse) == 2


def test_period_floor_waits_for_a_slow_transient_to_decay():
    """A 10.5 Hz mode damped 0.3 % (time constant 5 s) driven from rest by a 1 s periodic
    multisine (lines every 1 Hz, so its free decay does not repeat with the period): the start-up
    transient outlasts the two periods dropped by default. It is the model's own response, not
    noise; the floor waits for it to decay and reads the 2 % noise, where dropping only the first
    two periods reads several times that."""
    import vibroscope.gap.levels as lv

    rng = np.random.default_rng(2)
    T, n_periods = int(FS), 60
    u = np.tile(multisine(T, FS, 1.0, 40.0), n_periods) * 10.0
    k = (2 * np.pi * 10.5) ** 2
    m = LumpedModel(dofs=(Dof("m", 1.0),), elements=(Spring(("m", "ground"), k=k),
                                                     Damper(("m", "ground"), c=2 * 0.003 * np.sqrt(k))),
                    inputs=(Input(dof="m", channel="/u.x"),), outputs=(Output("m", "acceleration", "/a.x"),))
    clean = simulate(m, u, FS).data[1]
    y = (clean + 0.02 * np.std(clean[-10 * T:]) * rng.standard_normal(u.size))[None, :]
    ones = [np.ones(u.size, bool)]
    pf = lv.period_floor([y], [u[None, :]], ones, FS)
    assert pf.nrmse == pytest.approx(0.02, rel=0.15), pf
    assert pf.n_periods < n_periods - lv.PERIOD_SETTLE
    two_only = lv._settling_periods
    try:
        lv._settling_periods = lambda Y: lv.PERIOD_SETTLE
        assert lv.period_floor([y], [u[None, :]], ones, FS).nrmse > 3 * 0.02
    finally:
        lv._settling_periods = two_only


def test_a_variation_that_grows_with_the_level_is_the_responses_own_not_a_floor():
    """Outputs that stop repeating at the higher level only (as a chaotic or subharmonic response
    does) are flagged; a fixed-size noise, whose relative part falls with level, is not."""
    from vibroscope.gap.levels import period_floor

    us, ys, _ = _periodic_logs(0.0, 10, 0.0, 0.0, levels=(10.0, 40.0))
    rng = np.random.default_rng(11)
    ones = [np.ones(y.shape[1], bool) for y in ys]
    fixed = 0.02 * np.std(ys[0])  # the low level's 2 %, the high level's 0.5 %
    noisy = [y + fixed * rng.standard_normal(y.shape) for y in ys]
    pf = period_floor(noisy, us, ones, FS)
    assert pf.run_nrmse[1] == pytest.approx(pf.run_nrmse[0] / 4, rel=0.2) and not pf.grows_with_level
    # the high level's outputs 10 % non-repeating besides that noise
    grown = [noisy[0], noisy[1] + 0.1 * np.std(ys[1]) * rng.standard_normal(ys[1].shape)]
    pf = period_floor(grown, us, ones, FS)
    assert pf.run_levels[1] == pytest.approx(4 * pf.run_levels[0])
    assert pf.run_nrmse[1] > 4 * pf.run_nrmse[0] and pf.grows_with_level
    # a ranking floor is not taken from it
    from types import SimpleNamespace

    from vibroscope.gap._ranking import ranking_floor

    f, why = ranking_floor(0.005, SimpleNamespace(method="given"), [], None, None, None, [], FS, 400, period=pf)
    assert f == 0.005 and "period" not in why


def test_a_log_that_stops_repeating_at_a_higher_level_is_left_out_and_no_other():
    """Three levels of a repeated multisine with 2 % noise: every log repeats. The highest
    level's outputs 10 % non-repeating besides it (a chaotic or subharmonic response) is that log
    alone; the lowest level's (an unlogged disturbance there) is none (it is not the level that
    makes it); a random input has no period, so none."""
    from vibroscope.gap.levels import APERIODIC_GROWTH, aperiodic_logs

    us, ys, _ = _periodic_logs(0.0, 6, 0.02, 0.0, levels=(10.0, 20.0, 40.0))
    rng = np.random.default_rng(5)
    masks = [np.arange(y.shape[1]) >= 400 for y in ys]  # the first period: the start from rest
    assert aperiodic_logs(ys, us, masks, FS) is None
    top = [ys[0], ys[1], ys[2] + 0.1 * np.std(ys[2]) * rng.standard_normal(ys[2].shape)]
    a = aperiodic_logs(top, us, masks, FS)
    assert a is not None and a.logs == (2,) and a.period_samples == (400, 400, 400)
    # 2 % noise on each sample of two periods: their difference is 2 % of the signal; 10 % more
    # gives sqrt(0.02^2 + 0.1^2) on the top level
    assert a.variation[0] == pytest.approx(0.02, rel=0.15) and a.variation[1] == pytest.approx(0.02, rel=0.15)
    assert a.variation[2] == pytest.approx(np.hypot(0.02, 0.1), rel=0.15)
    assert a.variation[2] > APERIODIC_GROWTH * max(a.variation[:2])
    assert a.levels[2] == pytest.approx(4 * a.levels[0], rel=1e-6)
    assert "log 3" in a.describe()
    low = [ys[0] + 0.1 * np.std(ys[0]) * rng.standard_normal(ys[0].shape), ys[1], ys[2]]
    assert aperiodic_logs(low, us, masks, FS) is None
    # logs at one level: the level does not make it
    one = [us[0], us[1] * 0.75, us[2] * 0.45]  # RMS 10, 15, 18
    assert aperiodic_logs(top, one, masks, FS) is None
    noise_in = [rng.standard_normal(u.shape) for u in us]
    assert aperiodic_logs(top, noise_in, masks, FS) is None


def test_period_floor_needs_alike_periods():
    """A random input has no period; a level step every period leaves no run of alike periods; a
    masked period splits a run."""
    from vibroscope.gap.levels import period_floor

    us, ys, _ = _periodic_logs(0.0, 10, 0.02, 0.0, levels=(10.0,))
    ones = [np.ones(ys[0].shape[1], bool)]
    rng = np.random.default_rng(3)
    assert period_floor(ys, [rng.standard_normal(us[0].shape)], ones, FS) is None
    stepped = us[0] * np.repeat(np.resize([1.0, 3.0], 10), 400)[None, :]
    assert period_floor(ys, [stepped], ones, FS) is None
    m = ones[0].copy()
    m[6 * 400 + 5] = False  # periods 2-5 and 7-9: runs of 4 and 3
    pf = period_floor(ys, us, [m], FS)
    assert pf is not None and pf.n_periods == 7


def test_level_trend_peaks_on_lines_excited_at_both_levels():
    """The low level excites 5-60 Hz only (the real Bouc-Wen benchmark's sine sweep beside a
    multisine to 150 Hz): its H1 beyond 60 Hz is noise, larger than the mode (coherence 0
    there). The trend's peaks are read on the lines well excited at both levels: a mode at
    40 Hz that softens 4 % is `softening` by about 4 %, not by the junk line's 50 %."""
    from vibroscope.gap._level_evidence import level_test

    f = np.linspace(5.0, 150.0, 581)

    def h(fn, zeta=0.05):
        w, wn = 2 * np.pi * f, 2 * np.pi * fn
        return (1.0 / (wn ** 2 - w ** 2 + 2j * zeta * wn * w))[:, None]

    H_lo, H_hi = h(40.0), h(38.4)
    c_lo = np.where(f <= 60.0, 0.99, 0.0)[:, None]
    c_hi = np.full((f.size, 1), 0.99)
    H_lo = np.where(f[:, None] > 60.0, 50.0 * np.abs(H_lo).max(), H_lo)  # junk where unexcited
    r = level_test(f, [(28.3, H_lo, c_lo, 8), (50.0, H_hi, c_hi, 8)])
    assert r["flagged"] and r["trend"] == "softening", r
    assert -0.06 < r["shift"] < -0.02, r
