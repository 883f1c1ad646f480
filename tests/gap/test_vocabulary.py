"""The gap vocabulary is one table, every candidate it makes builds a model that simulates, and the
rules that keep a vanishing effect or a linear explanation of a level-dependent BLA from being a
verdict, against analytic cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibroscope.gap._evidence import regression_starts, relative, states_model
from vibroscope.gap._level_evidence import level_test
from vibroscope.gap.diagnosis import LEVEL_FRACTION
from vibroscope.gap.effects import EFFECT_TABLE, VERDICT_WORDS, candidate_specs, connections
from vibroscope.gap.fit import LogSimulator
from vibroscope.gap.report import EFFECTS, Candidate
from vibroscope.models.elements import Friction, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.modelfile import dumps_model, loads_model

FS = 1000.0


def chain() -> LumpedModel:
    from vibroscope.models.elements import Damper

    return LumpedModel(
        dofs=(Dof("m1", 1.0), Dof("m2", 0.5)),
        elements=(Spring(("m1", "ground"), k=4e4), Damper(("m1", "ground"), c=8.0),
                  Spring(("m2", "m1"), k=3e4), Damper(("m2", "m1"), c=4.0)),
        inputs=(Input(dof="m1", channel="/u.x"),),
        outputs=(Output("m1", "acceleration", "/y1.x"), Output("m2", "acceleration", "/y2.x")),
        name="chain",
    )


def scales(model):
    u = np.random.default_rng(0).standard_normal(4000) * 10
    return {"fs": FS, "u_rms": 10.0, "u_max": float(np.abs(u).max()),
            "u_quantiles": [float(np.quantile(np.abs(u), q)) for q in (0.99, 0.9)],
            "u_abs_sorted": np.sort(np.abs(u)),
            "d_rms": {"m1-ground": 1e-4, "m2-m1": 5e-5}, "v_rms": {"m1-ground": 0.02, "m2-m1": 0.01},
            "f_extra": [80.0], "delay0": 0.002}


def test_the_report_vocabulary_is_the_table():
    assert EFFECTS == tuple(EFFECT_TABLE)
    assert EFFECTS[:2] == ("none", "parameter_mismatch")
    assert not set(VERDICT_WORDS) & set(EFFECTS)
    for d in EFFECT_TABLE.values():
        assert d.kind in ("reference", "linear", "nonlinear")
        assert (d.factory is None) == (d.kind == "reference")
        assert d.trend in ("hardening", "softening", "either", "none")
    # linear explanations do not make the BLA depend on the level; element nonlinearities do
    assert not any(EFFECT_TABLE[e].level_dependent for e in ("extra_mode", "time_delay", "offset"))
    assert all(EFFECT_TABLE[e].level_dependent for e in ("coulomb_friction", "backlash", "cubic_stiffness",
                                                         "saturation", "joint_friction"))


def test_every_candidate_builds_a_model_that_simulates_and_round_trips():
    model = chain()
    specs = candidate_specs(model, scales(model))
    made = {s.effect for s in specs}
    assert made == {n for n, d in EFFECT_TABLE.items() if d.factory is not None}
    sim = LogSimulator(np.random.default_rng(1).standard_normal((1, 500)) * 10, FS)
    for s in specs:
        assert len(s.lower) == len(s.upper) == s.n and s.starts, s.label
        for p0 in s.starts:
            assert np.all(np.asarray(p0) >= s.lower) and np.all(np.asarray(p0) <= s.upper), s.label
        m = s.apply(model, s.starts[0])
        y = sim.run(m)
        assert y.shape == (2, 500) and np.all(np.isfinite(y)), s.label
        # the reported parameters are the table's keys
        keys = {k for k, _ in EFFECT_TABLE[s.effect].parameters}
        assert set(s.describe(s.starts[0])) <= keys, (s.effect, set(s.describe(s.starts[0])), keys)
        # the augmented model is a model file
        assert loads_model(dumps_model(m)).n_dofs == m.n_dofs
    # element effects sit at every connection; a friction also between each DOF and ground
    # where the model has no element (a mass sliding on a guide: here m2)
    for eff in ("backlash", "cubic_stiffness", "joint_friction"):
        where = sorted({tuple(s.where["between"]) for s in specs if s.effect == eff})
        assert where == sorted(tuple(c) for c in connections(model))
    assert ("m2", "ground") not in connections(model)
    for eff in ("coulomb_friction", "asymmetric_friction"):
        where = sorted({tuple(s.where["between"]) for s in specs if s.effect == eff})
        assert where == sorted([tuple(c) for c in connections(model)] + [("m2", "ground")])


def test_vanishing_parameters_are_named():
    model = chain()
    by = {}
    for s in candidate_specs(model, scales(model)):
        by.setdefault(s.effect, s)
    assert "half a sample" in by["time_delay"].vanishes([0.4 / FS])
    assert by["time_delay"].vanishes([2.0 / FS]) is None
    assert "far below the rms deflection" in by["backlash"].vanishes([math.log(1e-8)])
    assert by["backlash"].vanishes([math.log(1e-4)]) is None
    assert "clips" in by["saturation"].vanishes([math.log(1e3)])
    assert by["saturation"].vanishes([math.log(5.0)]) is None
    assert "symmetric" in by["asymmetric_friction"].vanishes([0.0, 0.02])
    assert by["asymmetric_friction"].vanishes([0.0, math.log(3.0)]) is None
    # equal sliding forces reduce to Coulomb friction at their mean; unequal ones do not
    name, p = by["asymmetric_friction"].reduces_to([0.0, math.log(1.06)])
    assert name == "coulomb_friction" and math.exp(p[0]) == pytest.approx(1.03)
    assert by["asymmetric_friction"].reduces_to([0.0, math.log(3.0)]) is None
    # the lifted Coulomb friction is symmetric (it vanishes into Coulomb); the starts that break
    # the symmetry do not, and lie either way of the Coulomb level
    af = by["asymmetric_friction"]
    q = np.array([math.log(2.0)])
    assert af.vanishes(af.lifts_from[1](q)) is not None
    splits = af.lift_splits(q)
    assert len(splits) == 2 and all(af.vanishes(p_) is None for p_ in splits)
    assert {np.sign(p_[0] - p_[1]) for p_ in splits} == {-1.0, 1.0}
    assert all(math.exp(p_[0]) * math.exp(p_[1]) == pytest.approx(4.0) for p_ in splits)
    assert by["cubic_stiffness"].qualifiers([-0.1]) == {"character": "softening"}
    assert by["cubic_stiffness"].qualifiers([0.1]) == {"character": "hardening"}


def test_a_delay_below_half_a_sample_that_lags_the_bands_top_is_an_effect():
    """A log sampled slowly for its band (the harder blind variant's seed 24 case 008: 500 Hz, a
    force to 250 Hz, a delay of 0.32 samples that lags the top line by 1.0 rad and leaves 0.24
    held out, 0.031 with it) holds a delay below half a sample that is no linear refit by another
    name; one that lags the band's top by less than DELAY_VANISH_PHASE still vanishes."""
    from vibroscope.gap.effects import DELAY_VANISH_PHASE

    model = chain()
    f_top = 250.0
    sc = scales(model) | {"f_band": (0.5, f_top)}
    d = next(s for s in candidate_specs(model, sc) if s.effect == "time_delay")
    assert d.vanishes([0.32 / FS]) is None  # 2 pi 250 Hz 0.32 ms = 0.50 rad
    small = 0.9 * DELAY_VANISH_PHASE / (2 * math.pi * f_top)
    assert small < 0.5 / FS and "half a sample" in d.vanishes([small])
    # without a known band (a closed loop) the half-sample rule alone
    d0 = next(s for s in candidate_specs(model, scales(model)) if s.effect == "time_delay")
    assert "half a sample" in d0.vanishes([0.32 / FS])


def test_an_extra_mode_resonating_outside_the_excited_band_vanishes():
    """Within the band, a mode far above it moves with its DOF (a mass) and one far below it
    stands still (a spring): a parameter change, not an extra mode (fresh modal seed 5603 case
    001: a 1.6 % heavier mass taken by a mode at 226.9 Hz, the band ending at 170.8 Hz). A mode
    whose half-power band reaches into the excited band is seen, and kept."""
    model = chain()
    sc = dict(scales(model), f_band=(2.0, 170.8))
    em = next(s for s in candidate_specs(model, sc, ["extra_mode"]))

    def p(f, zeta=0.02, mass_share=0.03):
        return [math.log(mass_share), math.log(f), math.log(zeta)]

    assert "acts as a mass" in em.vanishes(p(226.9, 0.002))
    assert "acts as a spring" in em.vanishes(p(1.5))
    for f in (2.5, 80.0, 170.0, 172.0):  # 172 Hz at 2 %: its half-power band reaches 168.6 Hz
        assert em.vanishes(p(f)) is None, f
    # a tiny mass is no reason by itself (a 0.1 % absorber beside its host mode splits it): the
    # ranking's output test decides
    assert em.vanishes(p(80.0, mass_share=1e-3)) is None
    # no band given (a closed loop, or a caller's own scales): no band rule
    em_free = next(s for s in candidate_specs(model, scales(model), ["extra_mode"]))
    assert em_free.vanishes(p(226.9)) is None


def test_an_extra_mode_whose_damping_is_pressed_against_a_bound_vanishes():
    """A fitted damping ratio at a bound of the fit's range (0.002-0.2) is the fit asking for
    a spike sharper or a bump broader than a mode (seed 13 case 016 of the blind suite's harder
    variant: a parameter mismatch named an extra mode at 110 Hz damped 0.00215). Those named
    rightly in the blind suites were fitted at 0.0059-0.047, and are kept."""
    model = chain()
    em = next(s for s in candidate_specs(model, dict(scales(model), f_band=(2.0, 170.8)), ["extra_mode"]))
    lo, hi = (math.exp(em.lower[2]), math.exp(em.upper[2]))
    assert (lo, hi) == pytest.approx((0.002, 0.2))

    def p(zeta, f=110.0):
        return [math.log(0.003), math.log(f), math.log(zeta)]

    assert "lower bound" in em.vanishes(p(0.00215))
    assert "upper bound" in em.vanishes(p(0.195))
    for zeta in (0.0059, 0.0065, 0.047, 0.1):
        assert em.vanishes(p(zeta)) is None, zeta


def test_joint_friction_softens_a_connection_and_keeps_its_small_amplitude_stiffness():
    """The Jenkins joint replaces a share r of the spring: stiffness k at small amplitude (the
    slider sticks), (1 - r) k once it slips."""
    model = chain()
    s = next(s for s in candidate_specs(model, scales(model)) if s.effect == "joint_friction"
             and s.where["between"] == ["m1", "ground"])
    r, fslip = 0.4, 2.0
    p = np.array([math.log(r / (1 - r)), math.log(fslip / 10.0)])
    m = s.apply(model, p)
    spring = next(e for e in m.elements if isinstance(e, Spring) and e.between == ("m1", "ground"))
    bw = m.elements[-1]
    assert spring.k == pytest.approx((1 - r) * 4e4)
    assert bw.alpha == pytest.approx(r * 4e4) and bw.alpha / bw.beta == pytest.approx(fslip)
    assert s.describe(p) == pytest.approx({"joint_share": r, "slip_force_N": fslip})
    assert s.where["form"] == "jenkins"


def test_iwan_joint_spreads_the_slip_forces_and_keeps_the_stiffness():
    """The Iwan form: the share r of the spring split over N Jenkins elements of stiffness
    r k / N whose slip forces are spread uniformly up to Fs; at small amplitude (every slider
    sticking) the connection keeps k, after the last one slips (1 - r) k remains."""
    from vibroscope.gap.effects import IWAN_NU, IWAN_SLIDERS

    model = chain()
    s = next(s for s in candidate_specs(model, scales(model)) if s.effect == "joint_friction"
             and s.where["between"] == ["m1", "ground"] and s.where["form"] == "iwan")
    r, fslip = 0.4, 2.0
    p = np.array([math.log(r / (1 - r)), math.log(fslip / 10.0)])
    m = s.apply(model, p)
    spring = next(e for e in m.elements if isinstance(e, Spring) and e.between == ("m1", "ground"))
    bws = [e for e in m.elements if e.type == "bouc_wen"]
    assert len(bws) == IWAN_SLIDERS and spring.k == pytest.approx((1 - r) * 4e4)
    assert sum(e.alpha for e in bws) == pytest.approx(r * 4e4)
    # each slider's force saturates at (alpha / beta)^(1 / nu): z' = alpha v (1 - |z / F_i|^nu)
    assert sorted((e.alpha / e.beta) ** (1 / e.nu) for e in bws) == pytest.approx(
        [fslip * i / IWAN_SLIDERS for i in range(1, IWAN_SLIDERS + 1)])
    assert all(e.gamma == 0.5 and e.delta == 0.5 and e.nu == IWAN_NU for e in bws)
    assert s.describe(p) == pytest.approx({"joint_share": r, "slip_force_N": fslip})


def test_level_test_flags_a_changing_bla_and_not_a_constant_one():
    rng = np.random.default_rng(3)
    f = np.linspace(5, 100, 400)
    H = 1.0 / (1 - (f / 40) ** 2 + 0.04j * f / 40)[:, None]
    coh = np.full((f.size, 1), 0.95)
    n_avg = 30
    sd = np.abs(H) * np.sqrt((1 - 0.95) / (n_avg * 0.95) / 2)

    def noisy():
        return H + sd * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape))

    same = level_test(f, [(1.0, noisy(), coh, n_avg), (6.0, noisy(), coh, n_avg)])
    assert not same["flagged"] and same["stat"] < LEVEL_FRACTION and same["trend"] == "none"
    H_hi = 1.0 / (1 - (f / 43) ** 2 + 0.04j * f / 43)[:, None]  # the resonance 7.5 % higher at 6x the level
    moved = level_test(f, [(1.0, noisy(), coh, n_avg), (6.0, H_hi, coh, n_avg)])
    assert moved["flagged"] and moved["trend"] == "hardening" and moved["shift"] == pytest.approx(0.075, abs=0.01)
    # one level only: nothing to compare
    assert not level_test(f, [(1.0, H, coh, n_avg)])["flagged"]


def test_residual_regression_recovers_a_friction_force():
    """The start value of a friction candidate: the residual of the linear model regressed on
    the response to tanh(v / v_eps) at the connection recovers the true Coulomb force."""
    model = chain()
    truth = model.replace(elements=model.elements + (Friction(("m1", "ground"), force_=3.0, v_eps=1e-3),))
    rng = np.random.default_rng(4)
    from scipy import signal

    b, a = signal.butter(4, [5 / 500, 150 / 500], "band")
    u = signal.lfilter(b, a, rng.standard_normal((1, 8000)), axis=1)
    u *= 40.0 / np.std(u)
    sim = LogSimulator(u, FS)
    y = sim.run(truth)
    y_lin = sim.run(model)
    st = sim.run(states_model(model))
    rel = relative(model, st[:2], st[2:])
    est = regression_starts(model, rel, [y], [y_lin], 0, u.shape[1], FS, {"coulomb_friction"})
    assert est[("coulomb_friction", "m1-ground")] == pytest.approx(3.0, rel=0.35)


def test_candidate_json_holds_its_model_file_and_the_vanishing_reason():
    c = Candidate(effect="time_delay", where={"side": "input"}, parameters={"delay_s": 1e-7}, gap_after=0.1,
                  score=0.5, model_toml="x = 1\n", vanished="delay below half a sample")
    d = c.to_dict()
    assert d["model_toml"] == "x = 1\n" and d["vanished"] == "delay below half a sample"
    assert Candidate(effect="none", where={}, parameters={}, gap_after=0.1, score=0.0).to_dict()["vanished"] is None


@pytest.mark.parametrize("trend", ["hardening", "softening", None])
def test_cubic_spring_starts_span_its_decades_and_both_signs(trend):
    """The cubic spring's starts (k3 = q k / d_rms^2) span q = 0.03 ... 20 and the softening
    -0.03, -0.15. They were made unique to 0.1 % of the range [-0.5, 300], i.e. 0.3: beside a
    regressed estimate of 0.0086, 0.03, 0.3, -0.03 and -0.15 were dropped, and a strong
    hardening spring whose valley is q 0.028 +- 0.005 (seed 3579's case 7) was never reached."""
    model = chain()
    sc = scales(model) | ({"level_trend": trend} if trend else {})
    specs = [s for s in candidate_specs(model, sc) if s.effect == "cubic_stiffness"]
    assert specs
    for s in specs:
        q = sorted(float(p[0]) for p in s.starts)
        assert {0.03, 0.3, 3.0, 20.0, -0.03, -0.15} <= {round(v, 6) for v in q}, q
        assert len(q) == len(set(q))


def test_a_hysteresis_yielding_far_below_the_rms_deflection_responds_as_its_coulomb_projection():
    """``tends_to``: a Bouc-Wen element that yields at 0.5 % of the rms deflection across it
    responds as the Coulomb friction it projects to (slip force ``alpha / (beta (gamma +
    delta))``), so a hysteresis chosen first can stand in for a friction at its link (the
    selection is then also started from that friction: fresh seeds 5302 case 004 and 5403 case
    025); one that yields at 30 % of it (the benchmark's true hysteresis yields at 20-100 %)
    responds otherwise."""
    from vibroscope.gap.measure import nrmse

    model = chain()
    rng = np.random.default_rng(3)
    u = 10 * rng.standard_normal((1, 6000))
    sim = LogSimulator(u, FS)
    y_lin = sim.run(model)
    x = LumpedModel(dofs=model.dofs, elements=model.elements, inputs=model.inputs,
                    outputs=(Output("m1", "displacement", "/x1.x"),))
    d_rms = float(np.sqrt(np.mean(LogSimulator(u, FS).run(x) ** 2)))
    sc = scales(model)
    sc["d_rms"] = dict(sc["d_rms"], **{"m1-ground": d_rms})
    s = next(s for s in candidate_specs(model, sc) if s.effect == "hysteresis"
             and s.where["between"] == ["m1", "ground"])
    coulomb = next(c for c in candidate_specs(model, sc) if c.effect == "coulomb_friction"
                   and c.where["between"] == ["m1", "ground"])
    f_slip = 4.0  # N, the Bouc-Wen's force while it slides, alpha x_yield
    err = {}
    for share in (0.005, 0.3):
        p = np.array([math.log(f_slip / (4e4 * share * d_rms)), math.log(1.0 / share), 0.0])
        bw = s.apply(model, p).elements[-1]
        assert bw.alpha / (bw.beta * (bw.gamma + bw.delta)) == pytest.approx(f_slip)  # slip force
        assert 1.0 / (bw.beta * (bw.gamma + bw.delta)) == pytest.approx(share * d_rms)  # yield
        p_c = s.tends_to[1](p)
        fc = coulomb.apply(model, p_c)
        assert fc.elements[-1].force_ == pytest.approx(f_slip)
        y_bw, y_c = sim.run(s.apply(model, p)), sim.run(fc)
        # how much of the hysteresis's own effect the Coulomb friction leaves
        err[share] = nrmse(y_bw, y_c) / nrmse(y_bw, y_lin)
    assert err[0.005] < 0.1 < err[0.3]  # 0.068 and 0.47 measured


def test_a_hysteresis_relieved_base_keeps_the_small_amplitude_stiffness():
    """``EffectSpec.relieved``: the base with the connection's spring reduced by the Bouc-Wen
    element's alpha, so that spring + element keep the nominal's small-amplitude stiffness (the
    Bouc-Wen benchmark's nominal is k_L + alpha); none where alpha would take 90 % of the spring
    or more, and none for an effect without a small-motion stiffness."""
    model = chain()
    specs = candidate_specs(model, scales(model))
    s = next(s for s in specs if s.effect == "hysteresis" and s.where["between"] == ["m1", "ground"])
    p = np.array([math.log(0.3), 0.0, -0.9])
    alpha = s.apply(model, p).elements[-1].alpha
    b = s.relieved(model, p)
    spring = next(e for e in b.elements if isinstance(e, Spring) and set(e.between) == {"m1", "ground"})
    other = next(e for e in b.elements if isinstance(e, Spring) and set(e.between) == {"m2", "m1"})
    assert spring.k == pytest.approx(4e4 - alpha) and 0 < alpha < 4e4
    assert other.k == 3e4 and model.elements[0].k == 4e4  # the rest, and the nominal, untouched
    aug = s.apply(b, p)
    # small amplitude (z = 0): the Bouc-Wen force grows as alpha x, so the tangent stiffness is the nominal's
    assert sum(e.k for e in aug.elements if isinstance(e, Spring) and set(e.between) == {"m1", "ground"}) \
        + aug.elements[-1].alpha == pytest.approx(4e4)
    assert s.relieved(model, np.array([0.0, 0.0, 0.0])) is None  # alpha = k_loc: nothing left of the spring
    assert all(c.relieved(model, c.starts[0]) is None for c in specs if c.effect != "hysteresis")
    assert any(st[2] < -0.5 and st[1] > 0.5 for st in s.starts)  # a start for a loop that stiffens as it yields


def test_a_hysteresis_slides_at_a_bounded_force_for_any_positive_gamma_plus_delta():
    """``tends_to`` projects a Bouc-Wen element to a Coulomb friction of force ``alpha / (beta
    (gamma + delta))`` wherever ``gamma + delta`` is positive, however small (fresh seed 5801
    case 003: a hysteresis fitted with gamma + delta = 0.038, a 1.5 N slider standing in for a
    0.65 N friction beside it, was not retried from the friction while the limit needed 0.05),
    and never where the sum is zero or negative (the real Bouc-Wen benchmark's: it never slides)."""
    model = chain()
    s = next(s for s in candidate_specs(model, scales(model)) if s.effect == "hysteresis")
    for phi in (-1.2, -0.7854, -0.76, 0.0, 0.6):  # gamma + delta = cos(phi) + sin(phi): -0.57 ... 1.39
        p = np.array([math.log(0.2), math.log(2.0), phi])
        bw = s.apply(model, p).elements[-1]
        limit = s.tends_to[1](p)
        if bw.gamma + bw.delta > 0:
            assert limit is not None, phi
            assert math.exp(limit[0]) == pytest.approx(bw.alpha / (bw.beta * (bw.gamma + bw.delta)))
        else:
            assert limit is None, phi
    p_small = np.array([0.0, 0.0, -0.766])  # gamma + delta = 0.027: a limit the old 0.05 refused
    assert s.tends_to[1](p_small) is not None


def test_a_clearance_is_paired_with_each_holder_not_already_named_beside_it():
    """The held-clearance step pairs a clearance with a Coulomb friction and with a hysteresis
    (each holds the clearance's DOF), except a holder whose family is already named with a
    clearance."""
    from vibroscope.gap._run import CLEARANCE_HOLDERS
    from vibroscope.gap._selection import held_holders

    assert CLEARANCE_HOLDERS == ("coulomb_friction", "hysteresis")
    assert held_holders({"cubic_stiffness"}) == CLEARANCE_HOLDERS
    assert held_holders({"backlash"}) == CLEARANCE_HOLDERS
    assert held_holders({"backlash", "coulomb_friction"}) == ("hysteresis",)
    assert held_holders({"backlash", "asymmetric_friction"}) == ("hysteresis",)
    assert held_holders({"backlash", "hysteresis"}) == ("coulomb_friction",)
    assert held_holders({"backlash", "joint_friction"}) == ("coulomb_friction",)
    assert held_holders({"backlash", "coulomb_friction", "hysteresis"}) == ()


def test_the_retry_from_a_stand_ins_simpler_effect_takes_one_that_lifts_from_it():
    """A hysteresis chosen first stands in for a Coulomb friction at its link; the retry from the
    friction takes the best ranked candidate there of that class or of one lifting from it (an
    asymmetric friction: fresh seed 5501 case 002, a 0.10 / 0.41 N friction under a hysteresis),
    never one at another link, of another class, or vanishing."""
    from types import SimpleNamespace

    from vibroscope.gap._selection import best_nonlinear

    model = chain()
    specs = {(s.effect, tuple(s.where.get("between", ()))): s for s in candidate_specs(model, scales(model))}

    def cand(effect, between, vanished=False):
        c0 = SimpleNamespace(effect=effect, where={"between": list(between)}, vanished=vanished)
        return (c0, model, None, specs[(effect, between)], None)

    here = ("m1", "ground")
    other = next(k[1] for k in specs if k[0] == "asymmetric_friction" and k[1] != here)
    ranked = [cand("hysteresis", here), cand("asymmetric_friction", other), cand("cubic_stiffness", here),
              cand("asymmetric_friction", here, vanished=True), cand("asymmetric_friction", here),
              cand("coulomb_friction", here)]
    got = best_nonlinear(ranked, at=list(here), other_than="hysteresis", only="coulomb_friction")
    assert got is ranked[4]
    assert best_nonlinear(ranked[5:], at=list(here), other_than="hysteresis", only="coulomb_friction") is ranked[5]
    assert best_nonlinear(ranked[:4], at=list(here), other_than="hysteresis", only="coulomb_friction") is None


def test_a_held_clearance_is_fitted_at_the_chosen_connections_and_the_best_screened_others():
    """The pair step fits a clearance with its holder at each connection where a chosen effect
    acts and at the HELD_CLEARANCE_CONNECTIONS others whose clearance or holder screened best
    alone, not at every connection (six in a three-point modal model)."""
    from types import SimpleNamespace

    from vibroscope.gap._run import HELD_CLEARANCE_CONNECTIONS
    from vibroscope.gap._selection import held_clearances
    from vibroscope.models.elements import Damper

    conns = [("m1", "ground"), ("m2", "m1"), ("m3", "m2"), ("m3", "ground")]
    model = LumpedModel(dofs=(Dof("m1", 1.0), Dof("m2", 0.5), Dof("m3", 0.4)),
                        elements=tuple(e for c in conns for e in (Spring(c, k=4e4), Damper(c, c=5.0))),
                        inputs=(Input(dof="m1", channel="/u.x"),),
                        outputs=(Output("m1", "acceleration", "/y1.x"),), name="three")
    sc = scales(model) | {"d_rms": {"-".join(c): 1e-4 for c in conns}, "v_rms": {"-".join(c): 0.02 for c in conns}}
    specs = [s for s in candidate_specs(model, sc) if s.effect == "backlash"]
    # two laws of contact stiffness at each connection: the spring's own and the one matched to it
    assert len(specs) == 8
    assert [s.qualifiers(s.starts[0]) for s in specs[:2]] == [{}, {"contact": "matched"}]
    specs = specs[::2]
    gaps = {("m1", "ground"): 0.3, ("m2", "m1"): 0.1, ("m3", "m2"): 0.2, ("m3", "ground"): 0.4}
    screened = [(s, s.starts[0], gaps[tuple(s.where["between"])], model) for s in specs]
    run = SimpleNamespace(specs=specs, screened=screened, model=model, refit=model, sims=[], ys=[], split=None)
    trace: dict = {}
    # holders=() fits nothing (no pair is complete); the trace names the connections it would fit
    assert held_clearances(run, 1, holders=(), at=(("ground", "m3"),), trace=trace) == []
    assert HELD_CLEARANCE_CONNECTIONS == 2
    assert trace["connections"] == ["ground-m3", "m1-m2", "m2-m3"]
    held_clearances(run, 1, holders=(), trace=trace)
    assert trace["connections"] == ["m1-m2", "m2-m3"]


def test_a_coulomb_frictions_law_with_its_shape_free_recovers_another_regularisation_velocity():
    """A Coulomb friction of another law than the screening's (``v_eps`` 4 mm/s against the fixed
    1 mm/s): fitted with the law fixed it leaves a gap beyond the noise-free truth's; its law
    variant (``EffectSpec.law``, lifted from the fixed-law fit) recovers the regularisation
    velocity and the force, and closes that gap. The backward elimination offers the variant in
    place of a partner (:func:`vibroscope.gap._selection.without`)."""
    from scipy import signal

    from vibroscope.gap._selection import without
    from vibroscope.gap.fit import fit_time_domain

    model = chain()
    truth = model.replace(elements=model.elements + (Friction(("m1", "ground"), force_=3.0, v_eps=4e-3),))
    b, a = signal.butter(4, [5 / 500, 150 / 500], "band")
    u = signal.lfilter(b, a, np.random.default_rng(5).standard_normal((1, 6000)), axis=1)
    u *= 40.0 / np.std(u)
    sim = LogSimulator(u, FS)
    y = sim.run(truth)
    v_rms = float(np.std(np.diff(sim.run(model.replace(outputs=(Output("m1", "displacement", "/d1.x"),)))[0]) * FS))
    spec = next(s for s in candidate_specs(model, scales(model) | {"v_rms": {"m1-ground": v_rms, "m2-m1": v_rms}})
                if s.effect == "coulomb_friction" and s.where["between"] == ["m1", "ground"])
    mask, n = [np.ones(u.shape[1], bool)], [u.shape[1]]
    p1, g1, _ = fit_time_domain(lambda p: spec.apply(model, p), np.array([math.log(2.0)]), spec.lower, spec.upper,
                                [sim], [y], mask, n, fast=False, max_nfev=20)
    law, lift = spec.law
    assert law.effect == "coulomb_friction" and law.shape_free and law.n == spec.n + 1
    p2, g2, _ = fit_time_domain(lambda p: law.apply(model, p), lift(p1), law.lower, law.upper,
                                [sim], [y], mask, n, fast=False, max_nfev=20)
    got = law.describe(p2)
    assert got["v_eps_m_per_s"] == pytest.approx(4e-3, rel=0.15) and got["Fc_N"] == pytest.approx(3.0, rel=0.1)
    assert g2 < 0.3 * g1 and law.vanishes(p2) is None
    # a viscous law (v_eps far beyond the sliding velocities) is no friction
    assert law.vanishes(np.array([p2[0], math.log(v_rms)])) is not None
    # the elimination offers the law beside the plain drop
    other = next(s for s in candidate_specs(model, scales(model)) if s.effect == "time_delay")
    offered = without([(spec, p1), (other, np.array([1e-3]))], 1)
    assert [len(r) for r, _ in offered] == [1, 1] and offered[1][0][0][0] is law
    assert offered[1][0][0][1][1] == pytest.approx(math.log(1e-3))


def test_a_smooth_saturation_is_fitted_by_the_saturations_other_law():
    """A saturation of the smooth law ``L tanh(u / L)`` (L = 60 N on a force of 40 N rms): the
    screening's clip leaves a gap; the saturation's other law (``EffectSpec.law``, the same limit
    parameter) recovers the limit and closes it. Not offered in a closed loop, whose driven input
    clips."""
    from dataclasses import replace

    from scipy import signal

    from vibroscope.gap.fit import fit_time_domain

    model = chain()
    truth = model.replace(inputs=tuple(replace(i, saturation=60.0, saturation_law="tanh") for i in model.inputs))
    b, a = signal.butter(4, [5 / 500, 150 / 500], "band")
    u = signal.lfilter(b, a, np.random.default_rng(6).standard_normal((1, 6000)), axis=1)
    u *= 40.0 / np.std(u)
    sim = LogSimulator(u, FS)
    y = sim.run(truth)
    au = np.sort(np.abs(u[0]))
    sc = scales(model) | {"u_rms": 40.0, "u_max": float(au[-1]), "u_abs_sorted": au,
                          "u_quantiles": [float(np.quantile(au, q)) for q in (0.99, 0.9)]}
    spec = next(s for s in candidate_specs(model, sc) if s.effect == "saturation")
    mask, n = [np.ones(u.shape[1], bool)], [u.shape[1]]
    p1, g1, _ = fit_time_domain(lambda p: spec.apply(model, p), spec.starts[0], spec.lower, spec.upper,
                                [sim], [y], mask, n, fast=False, max_nfev=20)
    law, lift = spec.law
    assert law.effect == "saturation" and law.shape_free and law.n == spec.n
    p2, g2, _ = fit_time_domain(lambda p: law.apply(model, p), lift(p1), law.lower, law.upper,
                                [sim], [y], mask, n, fast=False, max_nfev=20)
    assert law.describe(p2)["limit_N"] == pytest.approx(60.0, rel=0.05)
    assert g2 < 0.1 * g1 and law.vanishes(p2) is None and law.qualifiers(p2) == {"law": "limit tanh(u / limit)"}
    # a limit far above the force takes nothing off it: no effect
    assert law.vanishes(np.array([math.log(3 * au[-1])])) is not None


def _law_bench(seed: int):
    """A band-limited random force (5-150 Hz, 40 N RMS, 6 s) on :func:`chain`: the model, its
    simulator, the RMS deflection at m1-ground and the scales holding it."""
    from scipy import signal

    model = chain()
    b, a = signal.butter(4, [5 / 500, 150 / 500], "band")
    u = signal.lfilter(b, a, np.random.default_rng(seed).standard_normal((1, 6000)), axis=1)
    u *= 40.0 / np.std(u)
    sim = LogSimulator(u, FS)
    d_rms = float(np.std(sim.run(model.replace(outputs=(Output("m1", "displacement", "/d1.x"),)))[0]))
    return model, sim, d_rms, scales(model) | {"d_rms": {"m1-ground": d_rms, "m2-m1": d_rms}}


def _screening_fit(model, sim, y, sc, effect: str, n_starts: int):
    """The `effect` at m1-ground fitted from its first `n_starts` starts on the whole record:
    ``(spec, p, gap, mask, n)``."""
    from vibroscope.gap.fit import fit_time_domain

    spec = next(s for s in candidate_specs(model, sc) if s.effect == effect and s.where["between"] == ["m1", "ground"])
    mask, n = [np.ones(y.shape[1], bool)], [y.shape[1]]
    fits = [fit_time_domain(lambda p: spec.apply(model, p), s0, spec.lower, spec.upper, [sim], [y], mask, n,
                            fast=False, max_nfev=30) for s0 in spec.starts[:n_starts]]
    p1, g1, _ = min(fits, key=lambda f: f[1])
    return spec, p1, g1, mask, n


def test_a_bouc_wen_loop_of_another_exponent_is_fitted_by_the_hysteresis_law():
    """A Bouc-Wen hysteresis of exponent nu = 2 (the screening fixes 1): its law variant
    (``EffectSpec.law``, lifted from the nu = 1 fit at nu = 1) recovers the exponent and closes
    the gap the fixed exponent leaves."""
    from vibroscope.gap.fit import fit_time_domain
    from vibroscope.models.elements import BoucWen

    model, sim, d_rms, sc = _law_bench(7)
    truth = model.replace(elements=model.elements + (
        BoucWen(("m1", "ground"), alpha=1.2e4, beta=750.0, gamma=0.6, delta=0.4, nu=2.0),))
    y = sim.run(truth)
    spec, p1, g1, mask, n = _screening_fit(model, sim, y, sc, "hysteresis", 2)
    law, lift = spec.law
    assert law.shape_free and law.n == spec.n + 1 and law.describe(lift(p1))["nu"] == pytest.approx(1.0)
    assert law.describe(lift(p1))["beta_per_m"] == pytest.approx(spec.describe(p1)["beta_per_m"])
    p2, g2, _ = fit_time_domain(lambda p: law.apply(model, p), lift(p1), law.lower, law.upper, [sim], [y], mask, n,
                                fast=False, max_nfev=40)
    got = law.describe(p2)
    assert got["nu"] == pytest.approx(2.0, rel=0.15) and g2 < 0.3 * g1


def test_a_quintic_spring_is_fitted_by_the_cubic_springs_law():
    """A spring ``k3 d^3 + k5 d^5`` whose quintic part dominates at the peaks: the cubic spring's
    law variant (``EffectSpec.law``, lifted from the cubic fit at ``k5 = 0``, where it builds the
    same model) recovers both terms and closes the gap the cubic term alone leaves; its
    character is read from the tangent stiffness at the RMS deflection."""
    from vibroscope.gap.fit import fit_time_domain
    from vibroscope.models.elements import CubicSpring

    model, sim0, d_rms, sc = _law_bench(11)
    k3, k5 = 0.02 * 3e4 / d_rms**2, 0.05 * 3e4 / d_rms**4
    truth = model.replace(elements=model.elements + (CubicSpring(("m1", "ground"), k3=k3, k5=k5),))
    y = sim0.run(truth)
    spec, p1, g1, mask, n = _screening_fit(model, sim0, y, sc, "cubic_stiffness", 4)
    law, lift = spec.law
    q = lift(p1)
    assert law.shape_free and law.n == 2 and law.describe(q)["k5_N_per_m5"] == 0.0
    assert law.describe(q)["k3_N_per_m3"] == pytest.approx(spec.describe(p1)["k3_N_per_m3"])
    np.testing.assert_allclose(sim0.run(law.apply(model, q)), sim0.run(spec.apply(model, p1)), rtol=0, atol=1e-12)
    p2, g2, _ = fit_time_domain(lambda p: law.apply(model, p), q, law.lower, law.upper, [sim0], [y], mask, n,
                                fast=False, max_nfev=40)
    got = law.describe(p2)
    assert got["k5_N_per_m5"] == pytest.approx(k5, rel=0.15) and got["k3_N_per_m3"] == pytest.approx(k3, rel=0.3)
    assert g2 < 0.3 * g1
    assert law.qualifiers(p2) == {"character": "hardening", "law": "quintic fitted"}
    assert law.qualifiers(np.array([0.1, -0.1]))["character"] == "softening"  # 3 q3 + 5 q5 < 0


def test_a_matched_clearance_keeps_its_springs_equivalent_gain_under_gaussian_motion():
    """``effects.matched_contact``: a dead zone of half-width g whose contact stiffness is the
    matched multiple of a spring's k has that spring's equivalent linear gain under a Gaussian
    deflection, ``E[d f(d)] / E[d^2] = k`` (Bussgang's theorem), checked against samples; the
    multiple is 1 at no clearance and capped where the clearance is rarely closed."""
    from vibroscope.gap.effects import MATCHED_CONTACT_MAX, matched_contact

    rng = np.random.default_rng(79)
    sigma, k = 2e-3, 5e4
    d = rng.normal(0.0, sigma, 2_000_000)
    for g_rel in (0.05, 0.3, 1.0):
        g = g_rel * sigma
        kc = k * matched_contact(g, sigma)
        f = np.where(np.abs(d) > g, kc * (d - g * np.sign(d)), 0.0)
        assert np.mean(d * f) / np.mean(d * d) == pytest.approx(k, rel=5e-3), g_rel
    assert matched_contact(0.0, sigma) == 1.0
    assert matched_contact(5 * sigma, sigma) == MATCHED_CONTACT_MAX


def test_a_simpler_stand_in_retry_better_beyond_the_noise_replaces_the_chosen_effect():
    """The stand-in retry's single effect replaces the chosen one without halving its penalised
    excess when it has fewer parameters, scores higher and its held-out gain is significant
    (batch-means t above NESTED_T); not when it has as many parameters, nor when its gain is
    within the noise (seed 17 case 004 of the harder blind variant: a cubic + quintic spring,
    polished, 0.0262 against a five-parameter hysteresis's 0.0317)."""
    from types import SimpleNamespace

    from vibroscope.gap._selection import simpler_and_better

    fs, n = 1000.0, 20000
    rng = np.random.default_rng(4)
    t = np.arange(n) / fs
    y = np.sin(2 * np.pi * 7 * t)[None]
    noise = 0.02 * rng.standard_normal((1, n))
    meas = y + noise
    run = SimpleNamespace(ys=[meas], val_logs=[0], split=SimpleNamespace(validation=[np.ones(n, bool)]), fs=fs)

    def cand(effect, n_par, score, gap, out):
        c = Candidate(effect=effect, where={"between": ["m1", "m2"]}, parameters={}, gap_after=gap, score=score,
                      gap_fit=gap, n_parameters=n_par, model_toml="")
        return (c, None, {0: out}, None, None, None)

    distortion = 0.03 * np.sin(2 * np.pi * 21 * t)[None]
    hysteresis = cand("hysteresis", 5, 0.90, 0.032, y + distortion)
    cubic = cand("cubic_stiffness", 1, 0.93, 0.026, y + 0.3 * distortion)
    trace = {}
    assert simpler_and_better(run, [cubic], [hysteresis], trace)
    assert trace["simpler_gain_t"] > 4.0
    # as many parameters: the ranking's significance (beyond) is asked
    assert not simpler_and_better(run, [cand("cubic_stiffness", 5, 0.93, 0.026, y + 0.3 * distortion)], [hysteresis])
    # no gain beyond the noise: the same distortion, outputs that differ only by chance
    trifle = cand("cubic_stiffness", 1, 0.91, 0.0319, y + distortion + 0.002 * rng.standard_normal((1, n)))
    trace = {}
    assert not simpler_and_better(run, [trifle], [hysteresis], trace) and trace["simpler_gain_t"] < 4.0
    # a combination on either side: not this test
    assert not simpler_and_better(run, [cubic, cubic], [hysteresis])
    # what the elimination left at another connection, or the chosen effect's own class: not this test
    elsewhere = cand("cubic_stiffness", 1, 0.93, 0.026, y + 0.3 * distortion)
    elsewhere[0].where["between"] = ["m2", "ground"]
    assert not simpler_and_better(run, [elsewhere], [hysteresis])
    assert not simpler_and_better(run, [cand("hysteresis", 1, 0.93, 0.026, y + 0.3 * distortion)], [hysteresis])


def test_clearance_starts_leave_no_decade_unprobed():
    """A sine sweep's deflection is large only while it passes the lowest mode: the median of the
    relative motion is a sixteenth of its RMS, the 80 % quantile the RMS (fresh seed 7366's case
    005). The starts from them left a decade between 1.2e-4 and 1.2e-3 m, where the clearance's
    valley lay (3.8e-4 m), and both neighbours fitted worse than the refit: named `unexplained`.
    Every two neighbouring starts are now within CLEARANCE_START_RATIO, the data's first."""
    from vibroscope.gap.effects import CLEARANCE_START_RATIO

    model = chain()
    sc = scales(model) | {"d_rms": {"m1-ground": 1.16e-3, "m2-m1": 5e-5},
                          "d_quantiles": {"m1-ground": [7.2e-5, 1.15e-3, 2.5e-3]}}
    specs = [s for s in candidate_specs(model, sc, ["backlash"]) if s.where["between"] == ["m1", "ground"]]
    assert len(specs) == 2  # the clearance at the base's stiffness and with the matched contact
    for s in specs:
        gaps = np.exp(np.array([p[0] for p in s.starts]))
        # the data's own starts come first: 0.02 and 0.1 of the RMS deflection, then the quantiles
        np.testing.assert_allclose(gaps[:5], [2.32e-5, 1.16e-4, 7.2e-5, 1.15e-3, 2.5e-3], rtol=1e-9)
        steps = np.diff(np.sort(gaps))
        ratios = np.sort(gaps)[1:] / np.sort(gaps)[:-1]
        assert steps.min() > 0 and ratios.max() <= CLEARANCE_START_RATIO * (1 + 1e-9)
        # between 1.16e-4 and 1.15e-3 m (a factor 9.9): starts at 2.49e-4 and 5.35e-4 m
        inside = gaps[(gaps > 1.2e-4) & (gaps < 1.1e-3)]
        np.testing.assert_allclose(np.sort(inside), [2.487e-4, 5.353e-4], rtol=2e-3)
