"""The gap diagnosis on model-generated logs with a known hidden effect (ground truth), and its
building blocks against analytic results."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from vibroscope.gap import diagnose
from vibroscope.gap.diagnosis import as_lumped
from vibroscope.gap.measure import input_levels, make_split, noise_floor, nrmse
from vibroscope.models.elements import Backlash, CubicSpring, Damper, Friction, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.modelfile import TransferFunctionModel, loads_model
from vibroscope.models.simulate import simulate
from vibroscope.signals import Signals

FS = 1000.0
IN = "/actuator/force_cmd.wrench.force.x"


def nominal() -> LumpedModel:
    """2-DOF chain: modes 23.8 and 52.2 Hz, 1.4 and 2.4 % damping."""
    return LumpedModel(
        dofs=(Dof("m1", 1.0), Dof("m2", 0.5)),
        elements=(Spring(("m1", "ground"), k=4e4), Damper(("m1", "ground"), c=8.0),
                  Spring(("m2", "m1"), k=3e4), Damper(("m2", "m1"), c=4.0)),
        inputs=(Input(dof="m1", channel=IN),),
        outputs=(Output("m1", "acceleration", "/imu/m1.linear_acceleration.x"),
                 Output("m2", "acceleration", "/imu/m2.linear_acceleration.x")),
        name="two-mass chain",
    )


def excitation(n: int, seed: int = 1) -> np.ndarray:
    """Band-limited random force (2-200 Hz) at three levels (1 : 2.5 : 6) in 2 s blocks."""
    rng = np.random.default_rng(seed)
    b, a = signal.butter(4, [2 / (FS / 2), 200 / (FS / 2)], "band")
    u = signal.lfilter(b, a, rng.standard_normal(n))
    lev = np.array([1, 2.5, 6])[(np.arange(n) // 2000) % 3]
    return u / np.std(u) * lev * 5


def log_of(truth: LumpedModel, u: np.ndarray, noise: float = 0.02, seed: int = 2) -> Signals:
    s = simulate(truth, u, FS)
    y = np.asarray(s.data[1:])
    rng = np.random.default_rng(seed)
    y = y + noise * np.std(y, axis=1, keepdims=True) * rng.standard_normal(y.shape)
    return Signals(data=np.vstack([u, y]), fs=FS, channels=truth.input_channels() + truth.output_channels(),
                   units=["N", "m/s^2", "m/s^2"])


@pytest.fixture(scope="module")
def u20():
    return excitation(20000)


def test_nrmse_normalises_each_channel_by_its_own_energy():
    y = np.array([[1.0, -1.0, 1.0, -1.0], [2.0, 2.0, -2.0, -2.0]])
    yh = y * 0.9
    assert nrmse(y, yh) == pytest.approx(0.1)
    # channel 1 missed entirely (its nrmse 1), channel 2 exact: sqrt((1 + 0) / 2), whatever the
    # channels' units (channel 1 in m beside channel 2 in m/s^2 counts the same)
    yh2 = y.copy()
    yh2[0] = 0
    assert nrmse(y, yh2) == pytest.approx(np.sqrt(0.5))
    assert nrmse(y * np.array([[1e-6], [1.0]]), yh2 * np.array([[1e-6], [1.0]])) == pytest.approx(np.sqrt(0.5))
    # several logs pool their samples per channel
    assert nrmse([y, y], [yh2, y]) == pytest.approx(np.sqrt(0.5 * 0.5))


def test_levels_and_split_keep_every_level_on_both_sides(u20):
    labels, rms = input_levels(u20[None], FS)
    assert len(rms) == 3
    assert rms[2] / rms[0] == pytest.approx(6, rel=0.15)
    sp = make_split([u20[None]], FS)
    for k in range(3):
        assert np.any(labels[sp.fit[0]] == k) and np.any(labels[sp.validation[0]] == k)
    assert not np.any(sp.fit[0] & sp.validation[0])


def test_split_interleaves_when_levels_are_contiguous():
    rng = np.random.default_rng(3)
    b, a = signal.butter(4, [2 / (FS / 2), 200 / (FS / 2)], "band")
    u = signal.lfilter(b, a, rng.standard_normal(30000)) * np.repeat([1.0, 3.0, 8.0], 10000)
    sp = make_split([u[None]], FS)
    assert "interleaved" in sp.description
    labels, _ = input_levels(u[None], FS)
    for k in range(3):
        assert np.any(labels[sp.fit[0]] == k) and np.any(labels[sp.validation[0]] == k)


def test_split_of_a_sine_sweep_holds_out_every_band_not_its_end(u20):
    """A linear sine sweep 2-150 Hz over 60 s: the last third held out would be 101-150 Hz, a band
    the fit never saw (a test of extrapolation in frequency). The split interleaves 2 s blocks
    instead, so that the held-out and the fitting input energy both spread over the whole band,
    and the screening prefix is the whole sweep (a prefix covering 80 % of its energy left out
    the GVT sweep's second mode, 13.2 Hz of 2-15 Hz, which no candidate was then fitted on). A
    stationary random input keeps its time split and its 8 s prefix."""
    from vibroscope.models.excitation import sine_sweep

    u = np.asarray(sine_sweep(FS, duration=60.0, f0=2.0, f1=150.0, amplitude=1.0), float).ravel()
    n = u.size
    sp = make_split([u[None]], FS)
    assert sp.description.startswith("interleaved") and "sweep" in sp.description, sp.description

    def shares(mask):  # the input energy of the masked samples in six bands of 2-150 Hz
        f, p = signal.welch(np.where(mask, u, 0.0), FS, nperseg=2048)
        e = np.array([p[(f >= lo) & (f < lo + 24.7)].sum() for lo in np.linspace(2, 125.3, 6)])
        return e / e.sum()

    assert shares(sp.fit[0]).min() > 0.1 and shares(sp.validation[0]).min() > 0.1
    late = np.zeros(n, bool)
    late[int(2 / 3 * n):] = True
    assert shares(late)[:3].max() < 0.01  # what the time split would have held out
    assert sp.screen_prefix[0] == n
    stationary = make_split([u20[None]], FS)
    assert stationary.description.startswith("time split")
    assert stationary.screen_prefix[0] == 8 * FS  # as before: its first 8 s cover its spectrum


def test_sweeps_at_several_levels_fit_and_hold_out_every_band():
    """The sine sweep of a ground vibration test at three levels (2-15 Hz, 120 s, 400 Hz): were
    the same blocks held out at every level, a third of the sweep's bands would never be fitted
    (in examples/gap/gvt_joint.py the torsion mode's ring-down after its resonance passage), and
    the held-out gap there would measure an extrapolation. Each block is fitted at two levels
    and held out at the third, the same whichever order the logs are given in."""
    from vibroscope.models.excitation import sine_sweep

    fs, nb = 400.0, 9
    us = [np.asarray(sine_sweep(fs, duration=120.0, f0=2.0, f1=15.0, amplitude=a), float).reshape(1, -1)
          for a in (0.14, 0.7, 1.4)]
    n = us[0].shape[1]
    bl = -(-n // nb)

    def held(split):  # per log, which of the nine blocks are held out
        return np.array([[v[i * bl:(i + 1) * bl].mean() > 0.5 for i in range(nb)] for v in split.validation])

    sp = make_split(us, fs)
    h = held(sp)
    assert "sweep" in sp.description, sp.description
    assert h.sum(axis=0).tolist() == [1] * nb  # each block held out at exactly one level
    for v, f in zip(sp.validation, sp.fit):
        assert not np.any(v & f)
        assert 0.3 < v.mean() < 0.37
    assert h[0].tolist() == [i % 3 == 1 for i in range(nb)]  # the lowest level: the middle of each three
    assert sp.screen_prefix == [n] * 3  # the candidates are screened on the whole of each sweep
    h2 = held(make_split([us[2], us[0], us[1]], fs))
    assert h2.tolist() == h[[2, 0, 1]].tolist()


def test_a_sweep_restarted_at_each_level_of_one_log_is_held_out_at_every_phase():
    """One log of three 20 s level blocks, each a log sweep 2-455 Hz (fresh seed 7366's case
    015, a hysteresis whose 12.9 Hz mode each sweep passes 6.8 s into its block). Each block's
    spectrum is the whole sweep's, so the record is no sweep and is cut in 2 s blocks; held out
    at the same phase at every level (4-6 s, 10-12 s, 16-18 s into each), the mode's passage
    was never validated and the nominal's held-out gap read 0.066 against 0.167 over the whole
    record. The levels now hold out the third, the first and the second block of each three:
    every 2 s of the sweep is held out at exactly one level, and every level is on both sides."""
    fs, dur = 1000.0, 20.0
    t = np.arange(int(dur * fs)) / fs
    one = signal.chirp(t, 2.0, dur, 455.0, method="logarithmic")
    u = np.concatenate([a * one for a in (1.0, 2.5, 6.0)])[None]
    sp = make_split([u], fs)
    assert sp.description.startswith("interleaved") and "sweep" not in sp.description, sp.description
    v = sp.validation[0]
    assert not np.any(v & sp.fit[0])
    b = 2000
    held = np.array([[v[lv * 20000 + i * b: lv * 20000 + (i + 1) * b].mean() > 0.5 for i in range(10)]
                     for lv in range(3)])
    assert held.sum(axis=0).tolist() == [1] * 10  # each 2 s phase of the sweep held out at one level
    assert held[0].tolist() == [i % 3 == 2 for i in range(10)]  # the lowest level: the third of each three
    assert held[1].tolist() == [i % 3 == 0 for i in range(10)]
    # the mode's passage (6.8 s into each block) is held out at the second level
    assert v[20000 + 6800] and not v[6800] and not v[40000 + 6800]


def test_a_periodic_chirp_is_screened_on_whole_periods_not_the_whole_record():
    """A log chirp 4-400 Hz repeated every 5 s (the harder blind seed 19's case 016: three logs of
    80 s at three levels) is no sweep: its spectrum is the same in every period. The screening
    prefix is the shortest whole number of 2 s blocks holding a period (6 s), where it was the
    whole fitting part (the 4 s prefix missed part of the band, and 2 s blocks without overlap
    weighed the instants at their edges by nearly nothing), and every screening fit integrated
    all of it. The same chirp swept once over the record stays a sweep, screened whole."""
    fs, period = 1000.0, 5.0
    t = np.arange(int(period * fs)) / fs
    one = signal.chirp(t, 4.0, period, 400.0, method="logarithmic")
    reps = int(80 / period)
    us = [a * np.tile(one, reps)[None] for a in (1.0, 3.2, 6.3)]
    n = us[0].shape[1]
    sp = make_split(us, fs)
    assert "different input levels" in sp.description, sp.description
    assert sp.screen_prefix == [6000] * 3  # three 2 s blocks: the first that hold a whole period
    assert sp.fit_prefix == [int(round(n * 2 / 3))] * 3  # the fits themselves still take all of it
    single = make_split([us[0]], fs)
    assert single.description.startswith("time split") and single.screen_prefix == [8000]
    swept = signal.chirp(np.arange(n) / fs, 4.0, n / fs, 400.0, method="logarithmic")[None]
    once = make_split([swept], fs)
    assert "sweep" in once.description and once.screen_prefix == [n]


def test_noise_floor_recovers_the_added_noise(u20):
    for noise in (0.01, 0.03):
        sig = log_of(nominal(), u20, noise=noise)
        y = np.asarray(sig.data[1:])
        nf = noise_floor([y], [np.asarray(sig.data[:1])], [np.ones(y.shape[1], bool)], FS, 2048)
        # noise added relative to each noisy channel's RMS: nrmse = noise / sqrt(1 + noise^2)
        assert nf.nrmse == pytest.approx(noise, rel=0.12)


@pytest.mark.parametrize("nperseg", [256, 1024, 4096])
def test_noise_floor_of_a_white_force_is_the_noise_not_the_resonances_coherence_bias(nperseg):
    """A force that excites the whole band leaves no line beyond it: the floor comes from the
    non-coherent output PSD in the band, whose leakage bias at the lightly damped modes is
    not noise (its sum gave 0.15-0.66 here, 8-33x the noise); the median level is the noise."""
    u = 5 * np.random.default_rng(1).standard_normal(20000)
    clean = np.asarray(simulate(nominal(), u, FS).data[1:])
    for noise in (0.01, 0.03):
        y = clean + noise * np.std(clean, axis=1, keepdims=True) * np.random.default_rng(2).standard_normal(clean.shape)
        nf = noise_floor([y], [u[None]], [np.ones(u.size, bool)], FS, nperseg)
        assert "non-coherent" in nf.method
        assert nf.nrmse == pytest.approx(nrmse(y, clean), rel=0.12)


def test_noise_floor_is_normalised_on_the_samples_a_gap_is_measured_on():
    """Noise of one standard deviation over the whole record, a signal at level 1 on the first
    half and 4 on the second: the floor in nrmse is sigma / RMS of the samples it is normalised
    on, so the second half's floor is a quarter of the first half's (the held-out part of a
    record whose level changes in blocks must be compared with its own floor)."""
    rng = np.random.default_rng(5)
    n = 40000
    spec = np.fft.rfft(rng.standard_normal(n))
    fr = np.fft.rfftfreq(n, 1 / FS)
    spec[(fr < 2) | (fr > 150)] = 0  # an ideal band: nothing of the signal beyond it
    u = np.fft.irfft(spec, n)
    u *= np.where(np.arange(n) < n // 2, 1.0, 4.0) / np.std(u)
    sigma = 0.05
    y = (u + sigma * rng.standard_normal(n))[None]
    allm = np.ones(n, bool)
    first, second = allm.copy(), allm.copy()
    first[n // 2:] = False
    second[:n // 2] = False
    f1 = noise_floor([y], [u[None]], [allm], FS, 2048, norm_masks=[first]).nrmse
    f2 = noise_floor([y], [u[None]], [allm], FS, 2048, norm_masks=[second]).nrmse
    f0 = noise_floor([y], [u[None]], [allm], FS, 2048).nrmse
    assert f1 == pytest.approx(sigma / np.sqrt(np.mean(y[0, first] ** 2)), rel=0.12)
    assert f2 == pytest.approx(sigma / np.sqrt(np.mean(y[0, second] ** 2)), rel=0.12)
    assert f1 / f2 == pytest.approx(4.0, rel=0.02)  # the same noise estimate, only normalised apart
    assert f0 == pytest.approx(sigma / np.sqrt(np.mean(y[0] ** 2)), rel=0.12)


def test_noise_floor_of_several_logs_does_not_count_distortion_that_grows_faster_than_the_signal():
    """Two logs at levels 1 and 4 with the same sensor noise: the floor is the noise's. Out-of-band
    distortion growing with the cube of the level (a hardening spring's harmonics) added to both
    would make the loud log's out-of-band level 64 times the quiet log's distortion: capped at the
    quiet log's level scaled with the signal energy, the floor stays within 25 % of the noise's
    instead of several times it. Relative noise (3 % of each log) is not capped."""
    rng = np.random.default_rng(8)
    n = 30000
    fr = np.fft.rfftfreq(n, 1 / FS)

    def band(lo, hi):
        spec = np.fft.rfft(rng.standard_normal(n))
        spec[(fr < lo) | (fr > hi)] = 0
        x = np.fft.irfft(spec, n)
        return x / np.std(x)

    us, clean, dist = [], [], []
    for level in (1.0, 4.0):
        u = band(2, 150) * level
        us.append(u[None])
        clean.append(u[None].copy())
        dist.append(0.05 * level ** 3 * band(250, 450)[None])  # 5 % of the quiet log's signal
    masks = [np.ones(n, bool)] * 2
    sigma = 0.02
    noisy = [y + sigma * rng.standard_normal(y.shape) for y in clean]
    pooled = sigma / np.sqrt(np.mean(np.concatenate([y[0] for y in noisy]) ** 2))
    assert noise_floor(noisy, us, masks, FS, 1024).nrmse == pytest.approx(pooled, rel=0.1)
    distorted = [y + d for y, d in zip(noisy, dist)]
    raw = np.sqrt((0.05 ** 2 + 3.2 ** 2) / (1 + 16))  # the distortion's share of the signal energy
    nf = noise_floor(distorted, us, masks, FS, 1024)
    assert nf.nrmse < 0.1 * raw and "capped" in nf.method
    # the quiet log's own distortion (5 %, over 200 of the 500 Hz taken as white) stays counted,
    # the loud log's is capped at it scaled with the signal energy
    assert nf.nrmse == pytest.approx(np.sqrt(0.05 ** 2 * 500 / 200 + sigma ** 2), rel=0.25)
    relative = [y + 0.03 * np.std(y) * rng.standard_normal(y.shape) for y in clean]
    nr = noise_floor(relative, us, masks, FS, 1024)
    assert nr.nrmse == pytest.approx(0.03, rel=0.1) and "capped" not in nr.method


def test_noise_floor_of_a_residual_sees_through_harmonics_beyond_the_band(u20):
    """Distortion beyond the excited band (a nonlinearity's harmonics) raises the data's
    out-of-band floor far above the noise; the residual of a model that reproduces the
    distortion, normalised by the measured outputs (``reference``), leaves the noise alone."""
    sig = log_of(nominal(), u20, noise=0.0)
    y0 = np.asarray(sig.data[1:])
    u = np.asarray(sig.data[:1])
    rng = np.random.default_rng(11)
    b, a = signal.butter(4, [260 / (FS / 2), 480 / (FS / 2)], "band")
    dist = signal.lfilter(b, a, rng.standard_normal(y0.shape), axis=1)
    dist *= 0.1 * np.std(y0, axis=1, keepdims=True) / np.std(dist, axis=1, keepdims=True)
    noise = 0.01 * np.std(y0, axis=1, keepdims=True) * rng.standard_normal(y0.shape)
    y = y0 + dist + noise
    m = np.ones(y.shape[1], bool)
    data = noise_floor([y], [u], [m], FS, 2048)
    assert data.nrmse > 4 * 0.01  # the harmonics count as noise
    resid = noise_floor([y - (y0 + dist)], [u], [m], FS, 2048, reference=[y])
    assert resid.nrmse == pytest.approx(0.01, rel=0.12)


def test_transfer_function_of_second_order_becomes_one_mass():
    tf = TransferFunctionModel((1.0,), (2.0, 10.0, 1e5), Input(dof="u", channel="/u.x"),
                               Output("y", "displacement", "/y.x"))
    m = as_lumped(tf)
    assert m.M[0, 0] == 2.0 and m.C[0, 0] == 10.0 and m.K[0, 0] == 1e5
    f = np.array([5.0, 35.0, 80.0])
    np.testing.assert_allclose(m.frf(f, quantity=None)[:, 0, 0], tf.frf(f)[:, 0, 0], rtol=1e-12)
    with pytest.raises(ValueError, match="second-order"):
        as_lumped(TransferFunctionModel((1.0,), (1.0, 2.0, 3.0, 4.0), Input(dof="u", channel="/u.x"),
                                        Output("y", "displacement", "/y.x")))


def test_none_when_the_model_is_right(u20):
    r = diagnose(nominal(), log_of(nominal(), u20))
    assert r.verdict == "none"
    assert r.gap_before == pytest.approx(r.noise_floor, rel=0.2)
    assert r.candidates[0].effect == "none"


@pytest.mark.slow  # each case: the full diagnosis, ~47 s CPU (70-178 s wall on a loaded 2-core box)
@pytest.mark.parametrize(
    "name, change, effect, where",
    [
        ("stiffer m1 spring", lambda m: replace(m, elements=(Spring(("m1", "ground"), k=5e4),) + m.elements[1:]),
         "parameter_mismatch", {"parameters": ["k:m1-ground"]}),
        ("input delay 5 ms", lambda m: replace(m, inputs=(replace(m.inputs[0], delay=0.005),)), "time_delay",
         {"side": "input"}),
        # a delay of 25 samples: the refit bends the linear parameters into nonsense (it closes almost
        # nothing), so the delay must be fitted from the nominal too
        ("input delay 25 ms", lambda m: replace(m, inputs=(replace(m.inputs[0], delay=0.025),)), "time_delay",
         {"side": "input"}),
        ("friction at m1", lambda m: replace(m, elements=m.elements + (Friction(("m1", "ground"), force_=1.7),)),
         "coulomb_friction", {"between": ["m1", "ground"]}),
        ("cubic spring m2-m1", lambda m: replace(m, elements=m.elements + (CubicSpring(("m2", "m1"), k3=4.5e8),)),
         "cubic_stiffness", {"between": ["m2", "m1"]}),
    ],
)
def test_hidden_effect_is_named_located_and_closed(u20, name, change, effect, where):
    truth = change(nominal())
    r = diagnose(nominal(), log_of(truth, u20))
    assert r.verdict == effect, r.summary()
    best = r.candidates[0]
    if "between" in where:
        assert set(best.where["between"]) == set(where["between"])
    else:
        assert best.where == where
    # the augmented model closes the gap down to the noise floor, on held-out data
    assert r.gap_after < 1.3 * r.noise_floor
    assert r.shrink > 0.8
    # every effect was fitted, or is reported as not tried with the reason (one that could not win)
    tried = {c.effect for c in r.candidates}
    assert tried | set(r.meta["not_tried"]) >= {"time_delay", "saturation", "coulomb_friction", "backlash",
                                                "hysteresis", "cubic_stiffness", "extra_mode",
                                                "parameter_mismatch", "none"}
    assert not tried & set(r.meta["not_tried"])
    if effect == "parameter_mismatch":  # the refit is at the noise floor: no level-dependent effect is fitted
        assert {"backlash", "hysteresis", "cubic_stiffness"} <= set(r.meta["not_tried"])
    if effect in ("coulomb_friction", "cubic_stiffness"):  # the BLA changes with the level
        assert {"time_delay", "extra_mode"} <= set(r.meta["not_tried"])
    d = json.loads(json.dumps(r.to_dict()))
    for key in ("metric", "validation", "noise_floor", "gap_before", "gap_refit", "gap_after", "bands",
                "channels", "candidates", "verdict"):
        assert key in d
    # the exported model runs and, over the whole log, misses it by about the augmented gap
    # (the noise floor), far less than the nominal model does
    aug = loads_model(r.augmented_model_toml)
    log = log_of(truth, u20)
    s = simulate(aug, u20, FS)
    assert np.asarray(s.data[1:]).shape == (2, u20.size)
    err = nrmse(np.asarray(log.data[1:]), np.asarray(s.data[1:]))
    print(f"{name}: exported model nrmse {err:.4f}, gap_after {r.gap_after:.4f}, gap_before {r.gap_before:.4f}")
    assert err < 1.5 * r.noise_floor and err < 0.5 * r.gap_before


def test_gravity_and_a_bias_on_the_accelerometers_are_removed_before_the_diagnosis(u20):
    """An IMU's linear_acceleration holds gravity along its axis and a bias: the diagnosis removes
    each acceleration output's mean per log (a model's acceleration has none over a record from
    rest), says so in the report, and names the hidden friction as it does without them (left
    in, the offsets are a gap no model closes: the augmented model stayed at 0.197 held-out
    against a floor of 0.021)."""
    truth = replace(nominal(), elements=nominal().elements + (Friction(("m1", "ground"), force_=1.7),))
    log = log_of(truth, u20)
    data = np.array(log.data)
    data[1] += 9.81
    data[2] -= 0.35
    log = replace(log, data=data)
    r = diagnose(nominal(), log, effects=["coulomb_friction", "cubic_stiffness", "parameter_mismatch"])
    assert r.verdict == "coulomb_friction", r.summary()
    assert set(r.candidates[0].where["between"]) == {"m1", "ground"}
    assert r.candidates[0].parameters["Fc_N"] == pytest.approx(1.7, rel=0.1)
    assert r.gap_after < 1.3 * r.noise_floor, r.summary()
    means = r.meta["acceleration_means_removed"]["means"]
    assert means[nominal().output_channels()[0]][0] == pytest.approx(9.81, abs=0.05)
    assert means[nominal().output_channels()[1]][0] == pytest.approx(-0.35, abs=0.05)


def test_only_a_grounded_models_acceleration_means_are_removed():
    """A free body (a rigid-body mode) accelerates on average under a constant force: its
    acceleration outputs keep their means; a grounded model's lose them, displacements never."""
    from vibroscope.gap.diagnosis import _remove_acceleration_means

    free = LumpedModel(dofs=(Dof("m1", 1.0), Dof("m2", 0.5)),
                       elements=(Spring(("m2", "m1"), k=3e4), Damper(("m2", "m1"), c=4.0)),
                       inputs=(Input(dof="m1", channel=IN),),
                       outputs=(Output("m1", "acceleration", "/a1.x"), Output("m2", "displacement", "/d2.x")))
    grounded = replace(free, elements=free.elements + (Spring(("m1", "ground"), k=1e4),))
    y = np.vstack([np.full(50, 2.0), np.full(50, 0.5)]) + np.sin(np.arange(50))[None]
    out, means = _remove_acceleration_means(free, ["/a1.x", "/d2.x"], [y])
    assert means == {} and np.array_equal(out[0], y)
    out, means = _remove_acceleration_means(grounded, ["/a1.x", "/d2.x"], [y])
    assert means["/a1.x"] == [pytest.approx(np.mean(y[0]))] and list(means) == ["/a1.x"]
    assert np.mean(out[0][0]) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(out[0][1], y[1])


def test_a_stiffness_two_percent_off_is_a_parameter_mismatch_not_a_vanished_one(u20):
    """A spring 2 % stiffer moves the lightly damped first mode by 1 %, a held-out gap several
    times the noise floor that the linear refit closes: whether a parameter change vanishes is
    decided on the outputs it changes, not on its size (the 3 % rule before flagged it as
    vanished and the verdict was ``unexplained``)."""
    truth = replace(nominal(), elements=(Spring(("m1", "ground"), k=4e4 * 1.02),) + nominal().elements[1:])
    r = diagnose(nominal(), log_of(truth, u20), effects=["parameter_mismatch", "time_delay"])
    assert r.gap_before > 3 * r.noise_floor, r.summary()
    assert r.verdict == "parameter_mismatch", r.summary()
    pm = next(c for c in r.candidates if c.effect == "parameter_mismatch")
    assert not pm.vanished
    assert "k:m1-ground" in pm.where["parameters"]
    assert pm.parameters["k:m1-ground"] == pytest.approx(4e4 * 1.02, rel=0.005)
    assert r.gap_after < 1.3 * r.noise_floor


def test_a_refit_far_above_the_floor_is_unexplained_not_a_mismatch(u20):
    """A 0.1 kg absorber at 38 Hz on m2, where only the linear refit is tried: the refit closes
    most of the gap but leaves many times the noise floor, which a refit of every linear
    parameter does not where the truth is the nominal's structure (the test above: 1.3x). The
    verdict is ``unexplained`` (the BLA does not change with the level: nothing else made it
    so), the refit first among the candidates, the selection's trace says why
    (PM_UNEXPLAINED)."""
    from vibroscope.gap.diagnosis import PM_UNEXPLAINED

    n0, ma = nominal(), 0.1
    k = ma * (2 * np.pi * 38.0) ** 2
    truth = replace(n0, dofs=n0.dofs + (Dof("a", ma),),
                    elements=n0.elements + (Spring(("a", "m2"), k=k), Damper(("a", "m2"), c=0.04 * np.sqrt(k * ma))))
    r = diagnose(n0, log_of(truth, u20), effects=["parameter_mismatch"])
    pm = r.candidates[0]
    assert pm.effect == "parameter_mismatch" and not pm.vanished, r.summary()
    assert pm.score > 0.5 and pm.gap_after > PM_UNEXPLAINED * r.noise_floor, r.summary()
    assert r.verdict == "unexplained" and list(r.verdicts) == ["unexplained"], r.summary()
    assert r.gap_after == pytest.approx(pm.gap_after)
    assert any("not a mismatch" in e.get("stopped", "") for e in r.meta["selection"]["rounds"])


def test_bands_locate_an_added_mode_region(u20):
    """A stiffer first spring moves mode 1: the gap energy sits around 24-27 Hz."""
    truth = replace(nominal(), elements=(Spring(("m1", "ground"), k=5e4),) + nominal().elements[1:])
    r = diagnose(nominal(), log_of(truth, u20), effects=["parameter_mismatch"])
    b = r.bands[0]
    assert b.fmin < 25.5 and b.fmax > 24.0
    assert b.share > 0.4


def test_a_log_too_gappy_to_diagnose_is_named(u20):
    """Gaps every 1.5 s leave no stretch of the 8 s the diagnosis needs: the error names the log (its
    ``source``), the channels and what is needed, and gives advice the CLI can follow."""
    sig = log_of(nominal(), u20)
    x = np.array(sig.data)
    for s in range(1000, sig.n_samples, 1500):
        x[1:, s : s + 20] = np.nan
    gappy = Signals(data=x, fs=sig.fs, channels=sig.channels, units=sig.units, t0=sig.t0, meta={"source": "run7.mcap"})
    with pytest.raises(ValueError, match=r"^run7\.mcap: missing samples .* needs .*: give a log with fewer gaps"):
        diagnose(nominal(), [gappy])


@pytest.mark.slow  # the full diagnosis of a 1-DOF case and the forward selection, ~40-90 s wall
def test_friction_and_a_clearance_at_one_spring_are_both_named():
    """Coulomb friction and a clearance in the same spring (1-DOF, 13 Hz): fitted alone, the
    friction bends the spring to mimic the clearance; the added clearance is fitted jointly with
    the linear parameters, so both are named and the gap closes to the noise floor."""
    base = LumpedModel(dofs=(Dof("m1", 1.12),),
                       elements=(Spring(("m1", "ground"), k=7460.0), Damper(("m1", "ground"), c=3.8)),
                       inputs=(Input(dof="m1", channel=IN),),
                       outputs=(Output("m1", "acceleration", "/imu/m1.linear_acceleration.x"),),
                       name="one mass")
    truth = replace(base, elements=(Backlash(("m1", "ground"), k=7460.0, gap=1.5e-4), base.elements[1],
                                    Friction(("m1", "ground"), force_=1.0)))
    u = excitation(40000, seed=5) * 0.3
    s = simulate(truth, u, FS)
    y = np.asarray(s.data[1:])
    y = y + 0.02 * np.std(y) * np.random.default_rng(6).standard_normal(y.shape)
    log = Signals(data=np.vstack([u, y]), fs=FS, channels=base.input_channels() + base.output_channels(), units=["N", "m/s^2"])
    r = diagnose(base, log, effects=["coulomb_friction", "backlash", "cubic_stiffness"])
    assert set(r.verdicts) == {"coulomb_friction", "backlash"}, r.summary()
    clear = next(c for c in r.candidates if c.effect == "backlash")
    assert clear.parameters["gap_m"] == pytest.approx(1.5e-4, rel=0.25)
    assert r.gap_after < 1.5 * r.noise_floor
    # the selection's trace says which addition was kept, and why: below the threshold
    kept = [e for e in r.meta["selection"]["rounds"] if e.get("kept") and "tries" in e]
    assert [e["kept"] for e in kept][:1] == [f"{r.verdicts[1]}@m1-ground"], r.meta["selection"]
    assert kept[0]["best_penalised"] < kept[0]["threshold"] == pytest.approx(0.5 * kept[0]["current_penalised"])
    assert kept[0]["tries"][0]["effect"] == kept[0]["kept"]
    # and why it ended: the two effects leave the noise floor, so a third is not tried
    stops = [e for e in r.meta["selection"]["rounds"] if "stopped" in e]
    assert any(e["stopped"].startswith("within the noise floor") and " + " in e["current"] for e in stops), stops


@pytest.mark.slow  # the full diagnosis, ~40-90 s wall
def test_asymmetric_friction_is_told_from_coulomb_friction(u20):
    """Sliding forces 2.4 N and 1.5 N at m1, seen by a displacement sensor beside the two
    accelerometers (half their difference, 0.45 N, shifts m1 by 11 um: what tells the asymmetry,
    which accelerometers alone see only in the pulses at velocity reversals; without the
    displacement sensor both laws leave the same held-out gap, at the noise floor, and the
    simpler one is named). The asymmetric law is named, with the ratio of the forces, and fits
    the data at least as well as the Coulomb law it contains."""
    out = nominal().outputs + (Output("m1", "displacement", "/laser/m1.displacement.x"),)
    base = replace(nominal(), outputs=out)
    truth = replace(base, elements=base.elements + (Friction(("m1", "ground"), force_=2.4, force_neg=1.5),))
    s = simulate(truth, u20, FS)
    y = np.asarray(s.data[1:])
    y = y + 0.02 * np.std(y, axis=1, keepdims=True) * np.random.default_rng(2).standard_normal(y.shape)
    log = Signals(data=np.vstack([u20, y]), fs=FS, channels=base.input_channels() + base.output_channels(),
                  units=["N", "m/s^2", "m/s^2", "m"])
    r = diagnose(base, log)
    assert r.verdict == "asymmetric_friction", r.summary()
    best = r.candidates[0]
    assert set(best.where["between"]) == {"m1", "ground"}
    assert best.parameters["Fc_pos_N"] / best.parameters["Fc_neg_N"] == pytest.approx(1.6, rel=0.15)
    coulomb = next(c for c in r.candidates if c.effect == "coulomb_friction")
    assert best.gap_fit <= coulomb.gap_fit


@pytest.mark.slow  # the full diagnosis of three 1-DOF logs and the forward selection, ~60-200 s wall
def test_a_delay_beside_a_clearance_is_named_as_the_second_effect():
    """Three logs at levels 1 : 2.5 : 6 of a mass on a spring with a clearance (a fifteenth of
    the lowest level's RMS deflection) behind a 1.6 ms input delay: the clearance makes the BLA
    change with the level, so a delay cannot be the verdict alone (and is not fitted alone);
    beside the clearance it is still a second effect: the forward selection tries it, and both
    are named, the delay with its value."""
    out = (Output("m1", "acceleration", "/imu/m1.linear_acceleration.x"),
           Output("m1", "displacement", "/laser/m1.displacement.x"))
    base = LumpedModel(dofs=(Dof("m1", 1.93),),
                       elements=(Spring(("m1", "ground"), k=13042.0), Damper(("m1", "ground"), c=9.72)),
                       inputs=(Input(dof="m1", channel=IN),), outputs=out, name="one mass")
    truth = replace(base, elements=(Backlash(("m1", "ground"), k=13042.0, gap=5.6e-5), base.elements[1]),
                    inputs=(Input(dof="m1", channel=IN, delay=0.0016),))
    rng = np.random.default_rng(9)
    b, a = signal.butter(4, [2 / (FS / 2), 170 / (FS / 2)], "band")
    logs = []
    for i, level in enumerate((1.0, 2.5, 6.0)):
        u = signal.lfilter(b, a, rng.standard_normal(20000))
        u = u / np.std(u) * 2.36 * level
        y = np.asarray(simulate(truth, u, FS).data[1:])
        y = y + 0.01 * np.std(y, axis=1, keepdims=True) * rng.standard_normal(y.shape)
        logs.append(Signals(data=np.vstack([u, y]), fs=FS, channels=base.input_channels() + base.output_channels(),
                            units=["N", "m/s^2", "m"]))
    r = diagnose(base, logs, effects=["backlash", "time_delay", "coulomb_friction", "cubic_stiffness"])
    assert r.meta["level_dependence"]["flagged"] and "time_delay" in r.meta["not_tried"], r.summary()
    assert set(r.verdicts) == {"backlash", "time_delay"}, r.summary()
    delay = next(c for c in r.candidates if c.effect == "time_delay")
    assert delay.parameters["delay_s"] == pytest.approx(0.0016, rel=0.1)
    assert r.gap_after < 0.25 * r.gap_before


@pytest.mark.slow  # the full diagnosis of a 3-DOF case and the forward selection, ~60-200 s wall
def test_friction_and_a_stiffening_spring_at_one_connection_are_both_named():
    """Coulomb friction (8.2 N) and a hardening cubic spring (k3 3.4e9 N/m^3) in the same
    connection of a 3-DOF chain (from the benchmark's seed 6161, case 012): the friction wins
    alone, and the cubic spring screened alone fits best elsewhere; the forward selection also
    tries the classes screened at the friction's connection, so both are named there, with
    k3 within 10 %, and the gap closes to the noise floor."""
    springs = {("m1", "m3"): (90139.0, 28.17), ("m2", "m1"): (559438.0, 46.04), ("m3", "ground"): (663771.0, 88.90)}
    els = tuple(e for pair, (k, c) in springs.items() for e in (Spring(pair, k=k), Damper(pair, c=c)))
    base = LumpedModel(dofs=(Dof("m1", 4.467), Dof("m2", 4.858), Dof("m3", 3.937)), elements=els,
                       inputs=(Input(dof="m2", channel=IN),),
                       outputs=tuple(Output(m, "acceleration", f"/imu/{m}.linear_acceleration.x") for m in ("m1", "m2", "m3")),
                       name="three masses")
    truth = replace(base, elements=els + (CubicSpring(("m1", "m3"), k=0.0, k3=3.436e9),
                                          Friction(("m1", "m3"), force_=8.215)))
    rng = np.random.default_rng(12)
    n = 30000
    b, a = signal.butter(4, [2 / (FS / 2), 270 / (FS / 2)], "band")
    u = signal.lfilter(b, a, rng.standard_normal(n))
    lev = np.array([6.0, 2.5, 1.0])[(np.arange(n) // 3500) % 3]
    u = u / np.std(u) * lev * 60.0 / np.sqrt(np.mean(lev**2))
    y = np.asarray(simulate(truth, u, FS).data[1:])
    y = y + 0.023 * np.std(y, axis=1, keepdims=True) * rng.standard_normal(y.shape)
    log = Signals(data=np.vstack([u, y]), fs=FS, channels=base.input_channels() + base.output_channels(),
                  units=["N", "m/s^2", "m/s^2", "m/s^2"])
    r = diagnose(base, log)
    assert set(r.verdicts) == {"coulomb_friction", "cubic_stiffness"}, r.summary()
    cubic = next(c for c in r.candidates if c.effect == "cubic_stiffness")
    assert cubic.where["between"] == ["m1", "m3"], r.summary()
    assert cubic.parameters["k3_N_per_m3"] == pytest.approx(3.436e9, rel=0.1)
    assert r.gap_after < 1.5 * r.noise_floor, r.summary()


@pytest.mark.parametrize("sampling", ["point", "filtered"])
def test_output_sampling_is_chosen_from_the_data(u20, sampling):
    """A friction at the driven mass makes its acceleration jump when the mass sticks and slips:
    harmonics far above fs / 2. Logged by a sensor without an anti-aliasing filter (the outputs
    taken at the sample instants) they alias into the band; through one (low-passed and
    decimated) they do not; the two records differ by more than 0.5 % nrmse. The diagnosis
    chooses the sampling the data were made with, and names the friction either way."""
    truth = replace(nominal(), elements=nominal().elements + (Friction(("m1", "ground"), force_=1.7),))
    s = simulate(truth, u20, FS, output_sampling=sampling)
    other = simulate(truth, u20, FS, output_sampling={"point": "filtered", "filtered": "point"}[sampling])
    assert nrmse(np.asarray(s.data[1:]), np.asarray(other.data[1:])) > 0.005  # the two samplings differ
    y = np.asarray(s.data[1:])
    y = y + 0.02 * np.std(y, axis=1, keepdims=True) * np.random.default_rng(2).standard_normal(y.shape)
    log = Signals(data=np.vstack([u20, y]), fs=FS, channels=truth.input_channels() + truth.output_channels(),
                  units=["N", "m/s^2", "m/s^2"])
    r = diagnose(nominal(), log, effects=["coulomb_friction"])
    ch = r.meta["output_sampling"]
    assert ch["chosen"] == sampling, ch
    assert ch["by"] == "coulomb_friction @ m1-ground"
    assert r.verdict == "coulomb_friction"
    assert r.gap_after < 1.2 * r.noise_floor, r.summary()
    # given, it is used as given
    r2 = diagnose(nominal(), log, effects=["coulomb_friction"], output_sampling="filtered")
    assert r2.meta["output_sampling"] == {"chosen": "filtered", "by": "given"}
    with pytest.raises(ValueError, match="output_sampling"):
        diagnose(nominal(), log, output_sampling="nearest")


def _unmodelled_noise_log(kind: str, seed: int = 1) -> Signals:
    """The nominal chain itself (no effect), 30 s, and noise the white floor cannot see: an
    unlogged band-limited force at m2 of 20 % of the logged force's RMS ("disturbance"), or 3 %
    sensor noise low-passed at 200 Hz by a 4th-order Butterworth ("lowpass", a sensor's
    anti-aliasing filter: the band beyond the excited one, where the floor is measured, holds
    less noise than the band)."""
    n, nom = 30000, nominal()
    u = excitation(n, seed)
    rng = np.random.default_rng(seed + 10)
    if kind == "disturbance":
        b, a = signal.butter(4, [2 / (FS / 2), 200 / (FS / 2)], "band")
        d = signal.lfilter(b, a, rng.standard_normal(n))
        d *= 0.2 * np.std(u) / np.std(d)
        truth = replace(nom, inputs=nom.inputs + (Input(dof="m2", channel="/unlogged"),))
        y = np.asarray(simulate(truth, np.vstack([u, d]), FS).data[2:])
        y = y + 0.01 * np.std(y, axis=1, keepdims=True) * rng.standard_normal(y.shape)
    else:
        y = np.asarray(simulate(nom, u, FS).data[1:])
        b, a = signal.butter(4, 0.2 * FS / (FS / 2))
        e = signal.lfilter(b, a, rng.standard_normal(y.shape), axis=1)
        y = y + 0.03 * np.std(y, axis=1, keepdims=True) * e / np.std(e, axis=1, keepdims=True)
    return Signals(data=np.vstack([u, y]), fs=FS, channels=nom.input_channels() + nom.output_channels(),
                   units=["N", "m/s^2", "m/s^2"])


@pytest.mark.slow  # the full diagnosis, ~60-130 s wall on the 2-core box
@pytest.mark.parametrize("kind", ["disturbance", "lowpass"])
def test_noise_the_white_floor_cannot_see_is_not_a_model_gap(kind):
    """The nominal is the truth; the gap is an unlogged disturbance (nominal gap 0.24 against a
    white floor of 0.0097) or coloured sensor noise (0.027 against 0.0031). No candidate explains
    it on held-out data, and the nominal's residual holds no part coherent with the input: the
    verdict is ``none`` (before: ``unexplained``), and the report says why."""
    r = diagnose(nominal(), _unmodelled_noise_log(kind))
    assert r.gap_before > 3 * r.noise_floor, r.summary()  # the white floor is beaten
    inc = r.meta["incoherent_gap"]
    assert r.verdict == "none", (r.summary(), inc)
    assert inc["changed"].startswith("unexplained -> none")
    assert inc["nominal"]["coherent"] < 1.3 * r.noise_floor
    assert inc["nominal"]["incoherent"] > 0.9 * inc["nominal"]["total"]


@pytest.mark.slow  # the full diagnosis of a 2-DOF case and the free law's polish, ~30-90 s wall
def test_a_coulomb_friction_of_another_regularisation_velocity_is_named_alone_with_it(u20):
    """A Coulomb friction of 2.4 N at m1 whose law is ``tanh(v / 6 mm/s)``, where the screening
    fixes 1 mm/s: the friction alone is named (no partner stands in for the law's difference),
    with the regularisation velocity and the force recovered by its free law (``EffectSpec.law``),
    the held-out gap at the noise floor."""
    truth = replace(nominal(), elements=nominal().elements + (Friction(("m1", "ground"), force_=2.4, v_eps=6e-3),))
    r = diagnose(nominal(), log_of(truth, u20), effects=["coulomb_friction", "hysteresis", "cubic_stiffness"])
    assert r.verdict == "coulomb_friction" and len(r.verdicts) <= 1, r.summary()
    best = r.candidates[0]
    assert set(best.where["between"]) == {"m1", "ground"}
    assert best.parameters["v_eps_m_per_s"] == pytest.approx(6e-3, rel=0.2), best.parameters
    assert best.parameters["Fc_N"] == pytest.approx(2.4, rel=0.1), best.parameters
    assert r.gap_after < 1.3 * r.noise_floor, r.summary()



def test_an_extra_modes_frf_fit_sees_every_line_near_its_start():
    """``_candidates.frf_lines``: the fits' thinned lines (every 13th of 0.1 Hz, as the harder
    blind suite's 0.1-735 Hz cases) plus, near each extra-mode start, every line of the band
    within 25 % of it (at most 200 per start, evenly taken): a mode of damping ratio 0.02 at
    3.87 Hz has lines within its half-power band, which the thinned lines alone lack; the same
    mask for any order of the specs (their fits' costs compare); nothing added without starts."""
    from types import SimpleNamespace

    from vibroscope.gap._candidates import EXTRA_MODE_LINES, frf_lines

    f = np.arange(0, 7351) * 0.1
    dense = f > 0
    sel = np.zeros_like(dense)
    sel[np.nonzero(dense)[0][::13]] = True
    run = SimpleNamespace(fd=(f,), sel=sel, sel_dense=dense)

    def spec(effect, f0=None):
        return SimpleNamespace(effect=effect, where={"dof": "m1"} | ({"frequency_hz": f0} if f0 else {}))

    fn, zeta = 3.87, 0.02

    def resolved(mask):
        return bool(np.any(mask & (np.abs(f - fn) <= zeta * fn)))

    assert not resolved(sel)  # the thinned lines miss the absorber: the test can fail
    specs = [spec("extra_mode", 3.8), spec("time_delay"), spec("extra_mode", 700.0)]
    lines = frf_lines(run, specs)
    assert resolved(lines)
    assert np.all(lines[sel]) and not np.any(lines & ~dense)
    near = dense & (np.abs(f - 3.8) <= 0.25 * 3.8)
    assert np.all(lines[near])  # 19 lines: all of them
    assert int(np.sum(lines & ~sel)) <= 2 * EXTRA_MODE_LINES
    np.testing.assert_array_equal(frf_lines(run, specs[::-1]), lines)
    np.testing.assert_array_equal(frf_lines(run, [spec("time_delay")]), sel)


def test_a_refit_within_what_right_models_leave_ranks_before_the_extra_modes_that_nest_it():
    """An extra mode nests the linear refit (its mass going to zero). Where the refit's held-out
    gap is within STAND_IN_FACTOR (1.05) times the ranking floor, an extra mode ranked before it
    on the penalty alone is moved behind it (fresh benchmarks/gap seed 7341 case 001: the refit at
    1.025x the floor, a 171 Hz extra mode at 1.015x, named over a parameter mismatch); further
    from the floor the penalised order stands."""
    from types import SimpleNamespace

    from vibroscope.gap._ranking import nested_order
    from vibroscope.gap.report import Candidate

    rng = np.random.default_rng(3)
    y = rng.standard_normal((1, 4000))
    split = SimpleNamespace(validation=[np.ones(4000, bool)])

    def cand(effect, gap, noise):
        c = Candidate(effect=effect, where={"dof": "m2"} if effect == "extra_mode" else {"parameters": []},
                      parameters={}, gap_after=gap, score=0.0, gap_fit=gap, n_parameters=3 * (effect == "extra_mode"),
                      model_toml="", vanished="")
        spec = SimpleNamespace(lifts_from=None) if effect == "extra_mode" else None
        return (c, None, {0: y + noise * rng.standard_normal(y.shape)}, spec, None, None)

    for pm_gap, first in ((0.0205, "parameter_mismatch"), (0.0232, "extra_mode")):
        cands = [cand("extra_mode", 0.0203, 0.0203), cand("parameter_mismatch", pm_gap, pm_gap)]
        out = nested_order(cands, [y], split, [0], 1000.0, floor=0.02)
        assert cands[0][0].effect == first, (pm_gap, out)
    # within the floor's factor the nested test is recorded, not applied
    cands = [cand("extra_mode", 0.0203, 0.0203), cand("parameter_mismatch", 0.0205, 0.0205)]
    out = nested_order(cands, [y], split, [0], 1000.0, floor=0.02)
    assert list(out) == ["extra_mode@m2 over parameter_mismatch@model (not applied: parameter_mismatch within "
                         "1.05x the ranking floor or the period-to-period floor)"]
    # a refit within the outputs' period-to-period variation stands too, unless that variation
    # grows with the level (the response's own, not a floor)
    for grows, first in ((False, "parameter_mismatch"), (True, "extra_mode")):
        period = SimpleNamespace(nrmse=0.024, grows_with_level=grows)
        cands = [cand("extra_mode", 0.0203, 0.0203), cand("parameter_mismatch", 0.0232, 0.0232)]
        nested_order(cands, [y], split, [0], 1000.0, floor=0.02, period=period)
        assert cands[0][0].effect == first, grows


def test_no_held_clearance_pair_is_tried_where_the_nominal_leaves_little_beyond_the_floor(u20, monkeypatch):
    """With nothing chosen (an unexplained gap: here the nominal is the truth, and the `none`
    threshold is lowered so that the search runs), a friction-held clearance pair is tried only
    where the nominal leaves more than PM_FURTHER times the noise floor, as after a chosen effect
    (the trial took 75 of 318 s of a `none` case of the harder blind variant, seed 17 case 000,
    and found nothing); the report says why it was not tried."""
    import vibroscope.gap._candidates as cand
    import vibroscope.gap._selection as sel

    def no_trial(*args, **kwargs):
        raise AssertionError("held_clearance_trial called")

    monkeypatch.setattr(cand, "NONE_FACTOR", 0.5)
    monkeypatch.setattr(sel, "held_clearance_trial", no_trial)
    r = diagnose(nominal(), log_of(nominal(), u20[:10000]), effects=["coulomb_friction", "backlash"])
    assert r.gap_before <= 2.0 * r.noise_floor
    stops = [e for e in r.meta["selection"]["rounds"] if e["start"].startswith("held clearance")]
    assert len(stops) == 1 and stops[0]["stopped"].startswith("not tried: the nominal model leaves"), stops
