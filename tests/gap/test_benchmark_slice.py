"""The withheld-effect benchmark (benchmarks/gap): its generator, its scorer, and the fast
CI slice (one case per class through :func:`vibroscope.gap.diagnose`)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from vibroscope.io import read_mcap
from vibroscope.models.elements import Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.modelfile import load_model, loads_model

REPO = Path(__file__).resolve().parents[2]
BENCH = REPO / "benchmarks" / "gap"


def _load(stem: str):
    """benchmarks/gap/<stem>.py as a module (the scorer loads file paths under the same names)."""
    name = f"_gapbench_{stem}"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, BENCH / f"{stem}.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


gen = _load("generate")
score = _load("score")


# ---------------------------------------------------------------------------------------------
# truth integrator vs the analytic linear response
# ---------------------------------------------------------------------------------------------
def _one_dof(delay=0.0):
    m, f, zeta = 1.3, 23.0, 0.03
    k = m * (2 * np.pi * f) ** 2
    c = 2 * zeta * np.sqrt(k * m)
    return LumpedModel(
        dofs=(Dof("m1", m),),
        elements=(Spring(("m1", "ground"), k), Damper(("m1", "ground"), c)),
        inputs=(Input(dof="m1", quantity="force", channel=gen.INPUT_CHANNEL, saturation=None, delay=delay),),
        outputs=(Output("m1", "acceleration", gen.output_channel("m1")),),
    )


def _two_dof():
    base = gen._chain_model([1.2, 0.6], [3.0e4, 5.0e4], [40.0, 15.0], "m2")
    assert all(base.modes().damping_ratios > 0.015)  # transients die within the 6 s run-in
    return base


def _steady_state(model, u: "gen.ContinuousInput", period_s: float):
    """The periodic steady-state outputs over one period, from ``LumpedModel.frf``: exact for
    a multisine band-limited below fs/2."""
    n = int(round(period_s * u.fs))
    x = u.coarse[:n]
    f = np.fft.rfftfreq(n, 1.0 / u.fs)
    H = model.frf(f)[:, :, 0]  # (n_f, n_out), includes the input delay
    return np.fft.irfft(H * np.fft.rfft(x)[:, None], n, axis=0).T


@pytest.mark.parametrize("case", ["1dof", "1dof_delay", "2dof"])
def test_truth_integrator_matches_analytic_linear_response(case):
    model = {"1dof": lambda: _one_dof(), "1dof_delay": lambda: _one_dof(7e-3), "2dof": _two_dof}[case]()
    rng = np.random.default_rng(1)
    period = 1.0
    u = gen.make_input(rng, 6.0, kind="multisine", f_hi=280.0, levels=False, period_s=period)
    run = gen.simulate_truth(model, u)
    ref = _steady_state(model, u, period)
    n = int(period * gen.FS)
    last = run.outputs[:, -2 * n :]
    err = gen.nrmse(np.hstack([ref, ref]), last)
    assert err < 1e-4, err


@pytest.mark.parametrize("kind", ["random", "sweep"])
def test_input_is_band_limited_and_exactly_sampled(kind):
    rng = np.random.default_rng(2)
    u = gen.make_input(rng, 20.0, kind=kind, f_hi=200.0)
    # no content at or above 300 Hz on the fine grid
    X = np.abs(np.fft.rfft(u.fine))
    f = np.fft.rfftfreq(u.fine.size, 1.0 / u.fs_fine)
    assert X[f >= gen.F_BAND_EDGE].max() < 1e-9 * X.max()
    # the logged samples are samples of the continuous force
    t = np.arange(u.coarse.size) / u.fs
    np.testing.assert_allclose(u(t), u.coarse, rtol=0, atol=1e-12 * np.abs(u.coarse).max())
    # three levels 1 : 2.5 : 6
    assert sorted({b["level"] for b in u.info["blocks"]}) == [1.0, 2.5, 6.0]
    if kind == "sweep":
        # three sweeps of a third each, one per level, each from 2 Hz up to f_hi: the
        # instantaneous frequency (zero crossings) of a block's first and last 10 % of its span
        for b in u.info["blocks"]:
            i0, i1 = int(round(b["t_start_s"] * u.fs)), int(round((b["t_start_s"] + b["duration_s"]) * u.fs))
            seg = u.fine[i0 * u.oversample:i1 * u.oversample]
            m = seg.size // 10
            late = seg[-2 * m:-m]  # short of the fade-out
            f_late = np.count_nonzero(np.diff(np.signbit(late))) / 2 / (m / u.fs_fine)
            peak = np.abs(seg[m:-m]).max()
            assert peak == pytest.approx(b["level"] * np.abs(u.fine).max() / 6.0, rel=0.05)
            # the log sweep's frequency 80-90 % of the way: 2 Hz * 100^0.8..0.9 = 79-126 Hz
            assert 2.0 * 100 ** 0.8 * 0.95 < f_late < 2.0 * 100 ** 0.9 * 1.05, f_late


def test_a_stepped_multisine_holds_each_level_for_whole_periods_of_the_drawn_length():
    from vibroscope.gap.levels import detect_period, period_floor

    rng = np.random.default_rng(5)
    u = gen.make_input(rng, 30.0, kind="multisine", f_hi=200.0, period_s=1.3, level_blocks=True)
    blocks = u.info["blocks"]
    assert [b["t_start_s"] for b in blocks] == pytest.approx([0.0, 9.1, 18.2])  # 7 whole periods each
    assert sorted(b["level"] for b in blocks) == [1.0, 2.5, 6.0]
    assert detect_period(u.coarse, u.fs) == 1300
    # the RMS per block (a period in from each end, not whole periods: 1 %) is 1 : 2.5 : 6
    lv = {b["level"]: np.sqrt(np.mean(u.coarse[int((b["t_start_s"] + 1.3) * 1000):
                                               int((b["t_start_s"] + b["duration_s"] - 1.3) * 1000)] ** 2))
          for b in blocks}
    assert lv[6.0] / lv[1.0] == pytest.approx(6.0, rel=0.01) and lv[2.5] / lv[1.0] == pytest.approx(2.5, rel=0.01)
    # the period floor of the force itself is the ringing of the brick wall only: the periods that
    # hold part of a level transition or the fade-out are left out although they pass the 10 % input
    # tolerance (they left 0.019 before); per block of 7 periods: the first two settle, the one
    # holding the next transition (or the fade) goes: 3 + 4 + 6 periods
    n = u.coarse.size
    y = u.coarse[None, :]
    pf = period_floor([y], [u.coarse], [np.ones(n, bool)], u.fs)
    assert pf is not None and pf.period_samples == (1300,) and pf.n_periods == 13
    assert pf.nrmse < 1e-6
    # with 3 % noise on the logged force and 2 % on the output (each of its block's level), the floor
    # is the output noise
    env = np.repeat([b["level"] for b in blocks], [int(round(b["duration_s"] * 1000)) for b in blocks])
    hits = []
    for k in range(5):
        r = np.random.default_rng(10 + k)
        un = u.coarse + 0.03 * env * r.standard_normal(n)
        yn = y + 0.02 * env * r.standard_normal(n)
        hits.append(period_floor([yn], [un], [np.ones(n, bool)], u.fs).nrmse)
    assert np.allclose(hits, 0.02, rtol=0.1), hits


def test_random_chain_model_ranges():
    for i in range(20):
        m = gen.random_chain_model(np.random.default_rng(i))
        modes = m.modes()
        assert 1 <= m.n_dofs <= 3 and len(modes) == m.n_dofs
        assert np.all((modes.natural_frequencies >= 8) & (modes.natural_frequencies <= 120))
        assert np.all((modes.damping_ratios >= 0.01) & (modes.damping_ratios <= 0.04))
        assert all(0.5 <= d.mass <= 5 for d in m.dofs)
        conns = gen.model_connections(m)
        # a chain through every DOF (n - 1 links between DOFs) and at least one ground link
        assert sum(gen.GROUND not in c for c in conns) == m.n_dofs - 1
        assert any(gen.GROUND in c for c in conns)
        assert 1 <= sum(o.quantity == "acceleration" for o in m.outputs) <= m.n_dofs


def test_random_chain_model_draws_the_dof_range_it_is_given():
    ns = set()
    for i in range(12):
        m = gen.random_chain_model(np.random.default_rng(100 + i), dofs=(4, 5))
        modes = m.modes()
        ns.add(m.n_dofs)
        assert len(modes) == m.n_dofs
        assert np.all((modes.natural_frequencies >= 8) & (modes.natural_frequencies <= 120))
    assert ns == {4, 5}


def test_a_smooth_saturation_truth_is_the_linear_model_driven_by_the_tanh_of_the_force():
    """``--forms other``: the truth's saturation is ``L tanh(u / L)``, not a clip at L."""
    from dataclasses import replace

    model = _one_dof()
    u = gen.make_input(np.random.default_rng(5), 3.0, kind="random", f_hi=100.0).scaled(50.0)
    lim = 0.6 * float(np.abs(u.fine).max())
    sat = replace(model, inputs=(replace(model.inputs[0], saturation=lim),))
    soft = gen.simulate_truth(gen.TruthModel(sat, soft_saturation=True), u, integrator="rk4")
    hard = gen.simulate_truth(sat, u, integrator="rk4")
    lin = gen.simulate_truth(model, gen.ContinuousInput(lim * np.tanh(u.fine / lim)), integrator="rk4")
    assert gen.nrmse(lin.outputs, soft.outputs) < 2e-3
    assert gen.nrmse(lin.outputs, hard.outputs) > 0.05
    assert not gen.TruthModel(sat, soft_saturation=True).expressible


def test_other_forms_and_input_noise_are_what_the_truth_says():
    """``--forms other --input-noise``: the logged force is the driving force plus white noise
    of the stated relative RMS; the friction's regularisation velocity and the hysteresis
    exponent are not the diagnoser's; the default case is unchanged by the new options' code."""
    case = gen.make_case("saturation", gen.case_rng(11, "saturation", 0), 12.0, integrator="rk4",
                         forms="other", input_noise=0.03)
    t = case.truth
    assert t["forms"] == "other" and t["details"]["form"].startswith("limit * tanh") and t["truth_model"] is None
    rel = t["input_noise"]["relative_rms"]
    assert 0.01 <= rel <= 0.03
    logged = case.signals(0).data[0]
    clean = case.u.coarse[: logged.size]
    assert np.std(logged - clean) / np.sqrt(np.mean(clean**2)) == pytest.approx(rel, rel=0.05)
    fr = gen.make_case("coulomb_friction", gen.case_rng(11, "coulomb_friction", 0), 12.0, integrator="rk4",
                       forms="other")
    assert 1e-4 <= fr.truth["parameters"]["v_eps_m_per_s"] <= 1e-2 and fr.truth["parameters"]["v_eps_m_per_s"] != gen.V_EPS
    assert "input_noise" not in fr.truth and np.array_equal(fr.signals(0).data[0], fr.u.coarse[: fr.outputs.shape[1]])
    hy = gen.make_case("hysteresis", gen.case_rng(11, "hysteresis", 0), 12.0, integrator="lsoda", forms="other")
    p = hy.truth["parameters"]
    assert p["nu"] == 2.0 and hy.truth["gap_nominal_noise_free"] >= gen.GAP_MIN
    # the loop's ultimate force (alpha / (beta (gamma + delta)))^(1/nu) is alpha times the yield
    # displacement, as for nu = 1
    zu = (p["alpha_N_per_m"] / (p["beta_per_m"] * (p["gamma"] + p["delta"]))) ** 0.5
    assert 0.0 < zu / p["alpha_N_per_m"] < 1.0
    default = gen.make_case("hysteresis", gen.case_rng(11, "hysteresis", 0), 12.0, integrator="lsoda")
    assert default.truth["parameters"]["nu"] == 1.0 and "forms" not in default.truth


def test_rk4_and_lsoda_truths_agree_on_a_linear_case():
    rng = np.random.default_rng(4)
    model = gen.random_chain_model(rng, 3)
    u = gen.make_input(rng, 5.0, kind="random", f_hi=250.0).scaled(10.0)
    a = gen.simulate_truth(model, u, integrator="lsoda")
    b = gen.simulate_truth(model, u, integrator="rk4")
    assert b.integrator["step_hz"] == 10000.0
    assert gen.nrmse(a.outputs, b.outputs) < 1e-4


@pytest.mark.parametrize("case", ["coulomb", "saturation+hysteresis"])
def test_point_output_sampling_reproduces_the_truth_integrators(case):
    """The truth integrators sample their outputs at the log's times; vibroscope's simulation
    with ``output_sampling="point"`` does the same and reproduces them where a nonlinearity's
    harmonics pass fs / 2 (a friction's stick-slip, a clipped force fed through to the driven
    mass's acceleration), while the default low-passed outputs differ by 1.5 % (friction) and
    13 % (heavy clipping) nrmse: what the gap diagnosis's output-sampling choice is for
    (seed 1729 case 000, seed 2357 case 004)."""
    from dataclasses import replace

    from vibroscope.models.elements import BoucWen, Friction
    from vibroscope.models.simulate import simulate

    base = _two_dof()
    if case == "coulomb":
        model = replace(base, elements=base.elements + (Friction(("m2", "ground"), 4.0),))
    else:
        model = replace(base, elements=base.elements + (BoucWen(("m2", "ground"), alpha=2e3, beta=2e3, gamma=0.8,
                                                                delta=0.05, nu=1.0),),
                        inputs=(replace(base.inputs[0], saturation=10.0),))
    u = gen.make_input(np.random.default_rng(3), 8.0, kind="random", f_hi=250.0).scaled(10.0)
    for integrator in ("lsoda", "rk4"):
        truth = gen.simulate_truth(model, u, integrator=integrator).outputs
        point = np.asarray(simulate(model, u.coarse[None], gen.FS, output_sampling="point").data[1:])
        filtered = np.asarray(simulate(model, u.coarse[None], gen.FS).data[1:])
        assert gen.nrmse(truth, point) < 1e-3
        assert gen.nrmse(truth, filtered) > 0.01


# ---------------------------------------------------------------------------------------------
# generated cases
# ---------------------------------------------------------------------------------------------
def test_generated_case_reads_back(tmp_path):
    case = gen.make_case("backlash", gen.case_rng(0, "backlash", 0), duration=20.0)
    gen.write_case(tmp_path, "case_000", case)
    cdir = tmp_path / "cases" / "case_000"
    assert sorted(p.name for p in cdir.iterdir()) == ["log.mcap", "nominal.toml"]
    model = load_model(cdir / "nominal.toml")
    chans = model.input_channels() + model.output_channels()
    assert chans[0] == gen.INPUT_CHANNEL
    truth = json.loads((tmp_path / "truth" / "case_000.json").read_text())
    assert chans[1:] == [o["channel"] for o in truth["outputs"]]
    sig = read_mcap(cdir / "log.mcap", channels=chans)
    assert sig.channels == tuple(chans)
    assert sig.fs == pytest.approx(1000.0)
    assert sig.n_samples == 20000
    np.testing.assert_allclose(sig.data, case.signals().data, rtol=1e-9, atol=1e-9 * np.abs(sig.data).max())
    assert truth["effect"] == "backlash"
    assert truth["gap_nominal_noise_free"] >= 0.05
    assert 0.01 <= truth["noise"]["relative_rms"] <= 0.03
    truth_model = loads_model(truth["truth_model"])
    assert "backlash" in [e.type for e in truth_model.elements]
    assert set(truth["where"]["between"]) <= set(model.dof_names) | {"ground"}
    # the log holds the truth plus noise: the nominal gap of the noisy log is close to the noise-free one
    assert truth["gap_nominal_noisy"] == pytest.approx(truth["gap_nominal_noise_free"], abs=0.04)


def test_a_band_edge_below_the_drawn_upper_edge_is_refused_by_name_and_the_lowest_allowed_one_works():
    with pytest.raises(ValueError, match=r"band_edge=150.0 must lie in \[170, 500\) Hz"):
        gen.make_case("none", gen.case_rng(0, "none", 0), duration=4.0, band_edge=150.0)
    with pytest.raises(SystemExit):
        gen.main(["--out", "unused", "--band-edge", "160"])
    case = gen.make_case("none", gen.case_rng(0, "none", 0), duration=4.0, band_edge=170.0)
    x = case.signals().data[0]
    spec = np.abs(np.fft.rfft(x - x.mean())) ** 2
    f = np.fft.rfftfreq(x.size, 1.0 / gen.FS)
    assert spec[f >= 175.0].sum() < 1e-6 * spec.sum()  # nothing at or beyond the band edge


@pytest.mark.parametrize("effect", [e for e in gen.CLASSES if e != "none"])
def test_every_effect_has_a_gap_and_a_consistent_truth_model(effect):
    integrator = gen.INTEGRATORS[gen.CLASSES.index(effect) % 2]
    case = gen.make_case(effect, gen.case_rng(5, effect, 0), duration=16.0, integrator=integrator)
    t = case.truth
    assert t["gap_nominal_noise_free"] >= 0.05
    assert t["integrator"]["name"] == integrator
    w = t["where"]
    if effect == "two_effects":
        assert len(t["effect"]) == 2 and len(set(t["effect"])) == 2 and set(t["effect"]) <= set(gen.PAIR_EFFECTS)
        assert len(w) == 2 and len(t["parameters"]) == 2
        g = t["gap_calibration_window"]
        assert min(t["gap_each_alone_calibration_window"]) >= gen.PAIR_SHARE * g
        return
    if effect in gen.NOT_EXPRESSIBLE:
        assert t["truth_model"] is None and t["true_model_toml"] is None
        if effect == "offset":
            assert 0.02 * 0.999 <= abs(t["details"]["offset_over_input_rms"]) <= gen.OFFSET_MAX * 1.001
            assert any(o.quantity == "displacement" for o in case.nominal.outputs)
        elif effect == "asymmetric_friction":
            p = t["parameters"]
            assert 1.5 <= max(p["Fp_N"], p["Fn_N"]) / min(p["Fp_N"], p["Fn_N"]) <= 4.0
            # its mean force while sliding is a constant force: only a displacement sensor sees it
            assert any(o.quantity == "displacement" for o in case.nominal.outputs)
        else:
            p = t["parameters"]
            assert 0.2 <= p["r"] <= 0.6 and 3 <= p["n_jenkins"] <= 5 and len(p["slip_forces_N"]) == p["n_jenkins"]
        assert list(w["between"]) if effect != "offset" else w == {"side": "input"}
        return
    tm = loads_model(t["truth_model"])
    if effect == "cubic_stiffness":
        assert t["variant"] == ("hardening" if t["parameters"]["k3_N_per_m3"] > 0 else "softening")
    if effect in gen.ELEMENT_EFFECTS:
        typ = {"coulomb_friction": "friction", "backlash": "backlash", "hysteresis": "bouc_wen",
               "cubic_stiffness": "cubic_spring"}[effect]
        el = [e for e in tm.elements if e.type == typ]
        assert len(el) == 1 and list(el[0].between) == w["between"]
    elif effect == "extra_mode":
        assert tm.n_dofs == case.nominal.n_dofs + 1
        assert w["dof"] in case.nominal.dof_names
        fn = case.nominal.modes().natural_frequencies
        assert np.all(np.abs(w["frequency_hz"] - fn) >= 0.1 * fn - 1e-9)
    elif effect == "time_delay":
        assert 0.6e-3 <= tm.inputs[0].delay <= 25e-3 and w == {"side": "input"}
    elif effect == "saturation":
        assert tm.inputs[0].saturation == pytest.approx(t["parameters"]["limit_N"])
    elif effect == "parameter_mismatch":
        assert 1 <= len(w["parameters"]) <= 2
        for name, r in t["details"]["ratio"].items():
            assert 0.003 - 1e-9 <= abs(r - 1) <= 0.50 + 1e-9
    # the nominal model file is the truth without the effect
    assert t["truth_model"] != gen.dumps_model(case.nominal)


def test_calibration_floor_only_searches_below_when_the_old_lower_bound_overshoots():
    """A strength range with a floor ``(floor, lo, hi)`` gives what ``(lo, hi)`` gave whenever
    the target lies above the gap at `lo` (the cases of earlier seeds stay as they were), and
    reaches a target below it, which ``(lo, hi)`` overshot (gap = 2 s: a target of 0.1 needs s = 0.05)."""
    def gap_of(s):
        return 2.0 * s, ["run"]

    def build(s):
        return s, None

    always = lambda runs, s: True  # noqa: E731
    for target in (0.4, 0.7, 0.95):
        assert (gen._calibrate(build, (0.01, 0.15, 0.5), always, target, gap_of)
                == gen._calibrate(build, (0.15, 0.5), always, target, gap_of))
    s_old, g_old = gen._calibrate(build, (0.15, 0.5), always, 0.1, gap_of)
    assert s_old == 0.15 and g_old == pytest.approx(0.3)  # overshoots 3x
    s_new, g_new = gen._calibrate(build, (0.01, 0.15, 0.5), always, 0.1, gap_of)
    assert abs(np.log(g_new / 0.1)) < 0.1 and s_new == pytest.approx(0.05, rel=0.1)
    # --without-weak-end: the old range only, for the seeds run before
    assert gen._calibrate(build, (0.01, 0.15, 0.5), always, 0.1, gap_of, weak_end=False) == (s_old, g_old)


def test_generate_is_deterministic_and_keeps_truth_apart(tmp_path):
    a = gen.make_case("none", gen.case_rng(3, "none", 0), duration=6.0)
    b = gen.make_case("none", gen.case_rng(3, "none", 0), duration=6.0)
    np.testing.assert_array_equal(a.outputs, b.outputs)
    assert a.truth["gap_nominal_noise_free"] == 0.0
    gen.generate(tmp_path, per_class=1, classes=["none", "time_delay"], seed=0, duration=16.0)
    assert sorted(p.name for p in (tmp_path / "truth").iterdir()) == ["case_000.json", "case_001.json"]
    under_cases = [p for p in (tmp_path / "cases").rglob("*") if p.is_file()]
    assert sorted(p.name for p in under_cases) == ["log.mcap", "log.mcap", "nominal.toml", "nominal.toml"]
    # the scorer: the oracle stub scores 100 %, "always none" only the none case
    s = score.score(tmp_path, diagnose=str(BENCH / "stubs.py") + ":oracle")
    assert s["overall"]["top1"] == 1.0 and s["overall"]["top2"] == 1.0 and s["overall"]["false_alarm"] == 0.0
    assert (tmp_path / "reports" / "case_001.json").is_file()
    s = score.score(tmp_path, diagnose=str(BENCH / "stubs.py") + ":always_none")
    assert s["overall"]["top1"] == 0.5 and s["classes"]["time_delay"]["top1"] == 0.0
    assert "| class |" in score.table(s, markdown=True)


def test_scorer_location_rules():
    t_el = {"effect": "backlash", "where": {"between": ["m2", "m1"]}}
    rep = {"verdict": "hysteresis", "shrink": 0.5,
           "candidates": [{"effect": "hysteresis", "where": {"between": ["m1", "m2"]}},
                          {"effect": "backlash", "where": {"between": ["m1", "m2"]}}]}
    m = score.score_case(rep, t_el)
    assert not m["top1"] and m["top2"] and m["location"]
    t_em = {"effect": "extra_mode", "where": {"dof": "m1", "frequency_hz": 50.0}}
    ok = {"verdict": "extra_mode", "candidates": [{"effect": "extra_mode", "where": {"dof": "m1", "frequency_hz": 54.0}}]}
    bad = {"verdict": "extra_mode", "candidates": [{"effect": "extra_mode", "where": {"dof": "m1", "frequency_hz": 56.0}}]}
    assert score.score_case(ok, t_em)["location"] and not score.score_case(bad, t_em)["location"]
    t_none = {"effect": "none", "where": {}}
    assert score.score_case({"verdict": "none", "candidates": [{"effect": "backlash"}]}, t_none)["top2"]
    m = score.score_case({"verdict": "backlash", "candidates": [{"effect": "backlash"}, {"effect": "none"}]}, t_none)
    assert not m["top1"] and m["top2"]
    # "unexplained" on a none case is a false alarm; on an effect class simply wrong
    assert not score.score_case({"verdict": "unexplained", "candidates": []}, t_none)["top1"]
    assert not score.score_case({"verdict": "unexplained", "candidates": []}, t_el)["top1"]
    # two effects: top-1 = first named effect in the truth set, both = all named
    t2 = {"effect": ["offset", "backlash"], "class": "two_effects", "where": [{"side": "input"}, {"between": ["m1", "ground"]}]}
    r2 = {"verdict": ["backlash", "offset"], "candidates": [{"effect": "backlash", "where": {"between": ["ground", "m1"]}},
                                                         {"effect": "offset", "where": {"side": "input"}}]}
    m = score.score_case(r2, t2)
    assert m["top1"] and m["both"] and m["top2"] and m["location"] and m["effect"] == "two_effects"
    m = score.score_case(dict(r2, verdict="backlash"), t2)
    assert m["top1"] and not m["both"]
    # a verdict whose winning candidate makes the effect vanish
    rv = {"verdict": "time_delay", "candidates": [{"effect": "time_delay", "parameters": {"delay_s": 1e-4}}]}
    assert score.score_case(rv, {"effect": "time_delay", "where": {"side": "input"}})["vanishing"]
    rv["candidates"][0]["parameters"]["delay_s"] = 2e-3
    assert not score.score_case(rv, {"effect": "time_delay", "where": {"side": "input"}})["vanishing"]


# ---------------------------------------------------------------------------------------------
# the CI slice: one case per class through the diagnoser
# ---------------------------------------------------------------------------------------------
#: wrong verdicts the 12-case slice may hold (about 85 % right, the benchmark's overall top-1)
MAX_SLICE_WRONG = 2


@pytest.mark.slow
def test_benchmark_slice(tmp_path):
    from vibroscope.gap import diagnose

    out = tmp_path / "bench"
    gen.generate(out, per_class=1, classes=[e for e in gen.EFFECTS if e in gen.CLASSES], seed=0, duration=30.0,
                 offset_max=gen.OFFSET_MAX_BEFORE_43)
    cases = out / "cases"
    assert not any(p.suffix == ".json" for p in cases.rglob("*"))
    assert not (cases / "truth").exists() and (out / "truth").is_dir()
    import importlib.util

    spec = importlib.util.spec_from_file_location("gap_predictability", BENCH / "predictability.py")
    pred = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pred)
    wrong, unpredictable, rows = [], [], []
    for cdir in sorted(cases.iterdir()):
        truth = json.loads((out / "truth" / f"{cdir.name}.json").read_text())
        model = load_model(cdir / "nominal.toml")
        sig = read_mcap(cdir / "log.mcap", channels=model.input_channels() + model.output_channels())
        rep = diagnose(model, sig).to_dict()
        m = score.score_case(rep, truth)
        rows.append(f"{cdir.name} {truth['effect']:<20} verdict {rep['verdict']!s:<28} shrink {rep['shrink']:.2f}")
        assert not m["vanishing"], rows[-1]  # never a verdict whose parameters make it vanish
        if truth["effect"] == "none":
            assert rep["verdict"] == "none", rows[-1]  # no false alarm
        if not m["top1"]:
            # a case whose TRUE model cannot reproduce its own log (chaotic response) does not
            # test the diagnoser; it is reported, not counted
            p = pred.truth_gap(out, cdir.name)
            if p.get("predictable") is False:
                unpredictable.append(f"{cdir.name} ({truth['effect']}: true model's gap {p['truth_gap']:.3f})")
                continue
            wrong.append(f"{cdir.name}: truth {truth['effect']}, verdict {rep['verdict']}")
    print("\n".join(rows))
    print("unpredictable cases:", unpredictable, "wrong:", wrong)
    assert len(unpredictable) <= 2, unpredictable
    # the slice is one case per class: held to the benchmark's overall level (85 % top-1 on the
    # 39-case run of the README), not to every class
    assert len(wrong) <= MAX_SLICE_WRONG, "; ".join(wrong)


@pytest.mark.slow  # one 30 s case generated (RK4 truth) and diagnosed with two forward selections, ~90-180 s
def test_a_clipped_input_behind_a_delay_is_found_from_the_delay_first():
    """Seed 8484's two-effect case 005: a 4.05 ms input delay and an actuator that clips 23 % of
    the input peaks at 22.4 N (3-DOF chain). The clipping makes the BLA change with the level, so
    the delay is not fitted alone; the linear refit, bent by the delay, leaves most of the gap,
    and every nonlinear candidate screened on it or on the nominal does nothing (the verdict was
    ``unexplained``). The phase slope measures the delay: from the delay fitted alone the
    forward selection finds the limit; both are named with their values."""
    from vibroscope.gap import diagnose

    case = gen.make_case("two_effects", gen.case_rng(8484, "two_effects", 5), 30.0, integrator="rk4",
                         offset_max=gen.OFFSET_MAX_BEFORE_43)
    t = case.truth
    assert sorted(t["effect"]) == ["saturation", "time_delay"]
    rep = diagnose(case.nominal, case.signals(0))
    assert set(rep.verdicts) == {"time_delay", "saturation"}, rep.summary()
    p_true = dict(zip(t["effect"], t["parameters"]))
    delay = next(c for c in rep.candidates if c.effect == "time_delay")
    assert delay.parameters["delay_s"] == pytest.approx(p_true["time_delay"]["delay_s"], rel=0.1)
    sat = next(c for c in rep.candidates if c.effect == "saturation")
    assert sat.parameters["limit_N"] == pytest.approx(p_true["saturation"]["limit_N"], rel=0.1)
    assert rep.gap_after < 1.5 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 60 s case generated (RK4 truth) and diagnosed, two forward selections, ~100-180 s
@pytest.mark.extended  # session 89: 172 s in the rehearsal of 48515c4; CI's time limit
def test_a_delay_alone_is_not_named_with_a_nonlinear_effect_that_adds_nothing_to_it():
    """Seed 7979's second time_delay case (RK4 truth, one log): a 3.52 ms input delay on a linear
    3-DOF chain. The level test of the BLA flags a change with the level (the delay is fitted
    only as an addition, ``lin_later``), so a linear explanation was not admissible alone; a softening cubic
    spring that changes nothing (held-out 0.5187 against the refit's 0.5218) was the best
    admissible candidate, the delay joined it (0.0301, floor 0.0249) and the verdict was
    ``cubic_stiffness + time_delay`` (the code before 493ee2a still gives it). The
    selection from the delay fitted alone adds nothing, and the pair is not significantly better
    than the delay alone (the test an addition to the delay must pass): the delay alone."""
    from vibroscope.gap import diagnose

    case = gen.make_case("time_delay", gen.case_rng(7979, "time_delay", 1), 60.0, integrator="rk4")
    t = case.truth
    assert t["parameters"]["delay_s"] == pytest.approx(3.5156e-3, rel=1e-3)
    rep = diagnose(case.nominal, case.signals(0))
    assert rep.verdict == "time_delay" and len(rep.verdicts) <= 1, rep.summary()
    delay = rep.candidates[0]
    assert delay.effect == "time_delay"
    assert delay.parameters["delay_s"] == pytest.approx(t["parameters"]["delay_s"], rel=0.05)
    assert rep.gap_after < 1.3 * rep.noise_floor, rep.summary()


#: a regenerated case's truth parameter against the value recorded when it was first read: the
#: generator's LSODA calibration of the strength agrees to about 2e-4 between machines
TRUTH_REL = 2e-3
#: the same for a chaotic true model, whose calibration follows the machine's rounding
#: (test_a_chaotic_clearance_model_is_not_searched_for_further_effects)
CHAOTIC_TRUTH_REL = 0.05


def _named_alone_at_its_link(effect: str, seed: int, integrator: str, param: str, value: float,
                             duration: float = 60.0, multi_share: float = 0.0,
                             offset_max: float = gen.OFFSET_MAX_BEFORE_43):
    """Regenerate the first `duration` s case of class `effect` of `seed` (its truth's `param`
    checked against `value`; three logs where ``generate.py --multi-log multi_share`` drew them),
    diagnose it, and check that `effect` alone is named at the truth's connection. Returns
    (truth, report, the effect's best candidate)."""
    from vibroscope.gap import diagnose

    multi = gen.multi_log_drawn(seed, effect, 0, multi_share)
    case = gen.make_case(effect, gen.case_rng(seed, effect, 0), duration, integrator=integrator,
                         multi_log=multi, offset_max=offset_max)
    t = case.truth
    # the same case as recorded: a strength calibrated by LSODA agrees to ~2e-4 across machines
    # (6.0656e-6 against 6.0648e-6 m), another case would differ by far more
    assert t["parameters"][param] == pytest.approx(value, rel=TRUTH_REL)
    rep = diagnose(case.nominal, case.signals_list() if multi else case.signals(0))
    assert rep.verdict == effect and len(rep.verdicts) <= 1, rep.summary()
    best = next(c for c in rep.candidates if c.effect == effect)
    assert score._same_pair(best.where["between"], t["where"]["between"]), best.where
    return t, rep, best


@pytest.mark.slow  # one 60 s case generated (LSODA truth) and diagnosed, ~30-60 s
def test_a_chaotic_clearance_model_is_not_searched_for_further_effects():
    """Fresh seed 5301's second backlash case (case 014 of the nine classes, 3 per class): a
    clearance of 0.113 mm replacing the grounded spring of a 2-DOF chain's light mass. The true
    model is chaotic: two correct integrations of it drift apart (LSODA against RK4: 0.113 and
    0.058 nrmse against the log at a noise of 0.018), so the named clearance, fitted to within
    1 % of the truth, leaves 4.2 times the floor, and forward selection spent 98 s of the case's
    138 s looking for a further effect. The chosen model's own held-out outputs at twice its
    sub-steps now differ by more than that gap: it is reported as not predictable and nothing
    is searched for beyond it."""
    from vibroscope.gap import diagnose

    case = gen.make_case("backlash", gen.case_rng(5301, "backlash", 1), 60.0, integrator="lsoda",
                         offset_max=gen.OFFSET_MAX)
    t = case.truth
    # the model is chaotic, so its LSODA calibration of the clearance is not reproducible to
    # TRUTH_REL across machines: 1.1305e-4 m where it was recorded, 1.1581e-4 m (+2.4 %) on an AMD
    # EPYC with scipy 1.17.1 and numpy 2.4.6 (session 89). The strengths drawn for other backlash
    # cases span 0.01-5 times the rms deflection, so 5 % still pins this case
    assert t["parameters"]["gap_m"] == pytest.approx(1.1304748e-4, rel=CHAOTIC_TRUTH_REL)
    rep = diagnose(case.nominal, case.signals(0))
    assert rep.verdicts == ("backlash",), rep.summary()
    best = rep.candidates[0]
    assert score._same_pair(best.where["between"], t["where"]["between"]), best.where
    assert best.parameters["gap_m"] == pytest.approx(t["parameters"]["gap_m"], rel=0.05)
    pr = rep.meta["predictability"]["models"]["backlash@" + "-".join(best.where["between"])]
    assert pr["unpredictable"] and pr["self_disagreement"] > 3 * rep.noise_floor, pr
    assert "not predictable" in rep.summary()
    assert rep.timings["forward_selection"] < 0.2 * rep.timings["total"], rep.timings


def test_a_predictable_model_agrees_with_itself_at_twice_the_substeps():
    """The predictability check's measure on models that are not chaotic: 0 for a linear model
    (the exact linear path), and far below a 1 % noise floor for a weak hardening spring on a
    well-damped 1-DOF oscillator under a random force (a unique, attracting steady state)."""
    from types import SimpleNamespace

    from vibroscope.gap._selection import self_disagreement
    from vibroscope.gap.fit import LogSimulator
    from vibroscope.models.elements import CubicSpring

    fs, n = 1000.0, 20000
    u = np.random.default_rng(3).standard_normal((1, n)) * 20.0
    lin = _one_dof()
    k = lin.elements[0].k
    duff = LumpedModel(dofs=lin.dofs, elements=(CubicSpring(("m1", "ground"), k3=k * 2.0e5, k=k), lin.elements[1]),
                       inputs=lin.inputs, outputs=lin.outputs)
    val = np.zeros(n, bool)
    val[n // 2:] = True
    run = SimpleNamespace(fs=fs, val_logs=[0], sims=[LogSimulator(u, fs)], split=SimpleNamespace(validation=[val]))
    assert self_disagreement(run, lin) == 0.0
    y = run.sims[0].run(lin)
    assert np.all(np.isfinite(y)) and np.std(y[0, val]) > 0
    d = self_disagreement(run, duff)
    assert 0.0 < d < 1e-3, d


@pytest.mark.slow  # one 60 s case generated (LSODA truth) and diagnosed, ~30-60 s
def test_a_hysteresis_whose_starts_all_fit_worse_than_none_is_still_refined_at_its_link():
    """Seed 2468's hysteresis case (class index 0, the third case of ``--classes coulomb_friction
    backlash hysteresis ...``): a Bouc-Wen element of 23 % of the loaded link's stiffness in a
    3-DOF chain. Every start of the hysteresis at its own link fits the screening prefix worse
    than no effect at all (0.218 against 0.136), while a start that changes nothing at another
    link does not; only the best location of each class was refined when the second probed more
    than 15 % worse, so the hysteresis was never fitted where it is, and an Iwan joint there (its
    softening cousin) was named. The three best locations of each class are now refined: the
    hysteresis is named at its link, below twice the noise floor."""
    _, rep, _ = _named_alone_at_its_link("hysteresis", 2468, "lsoda", "alpha_N_per_m", 10584.3)
    assert rep.gap_after < 2.0 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 60 s case generated (RK4 truth) and diagnosed, ~30-60 s
def test_a_strong_hardening_cubic_spring_is_reached_from_its_start_values():
    """Seed 3579's first cubic case (``--per-class 2``, every class but ``two_effects``: case
    007): a hardening cubic spring at a grounded link of a 2-DOF chain, nominal gap 1.03. Its
    valley is narrow (from the nominal linear parameters: 0.59 at 0.7x the true k3, 0.029 at it,
    0.40 at 1.4x); the start q = 0.03 lies in it, but the starts were made unique to 0.3 (0.1 %
    of q's range) and only 0.0086, 3 and 20 were kept, so a hardening Bouc-Wen element was named.
    Now the cubic spring is named with k3 within 15 %, at the noise floor."""
    t, rep, best = _named_alone_at_its_link("cubic_stiffness", 3579, "rk4", "k3_N_per_m3", 6.7907e10)
    assert best.parameters["k3_N_per_m3"] == pytest.approx(t["parameters"]["k3_N_per_m3"], rel=0.15)
    assert rep.gap_after < 1.5 * rep.noise_floor, rep.summary()


@pytest.mark.extended  # one 60 s case in three logs generated (RK4 truth) and diagnosed, ~150-220 s
def test_the_chosen_effect_refitted_beside_an_addition_is_adopted_without_it():
    """Fresh seed 7350's first cubic case (``generate.py --per-class 2 --seed 7350 --forms other
    --integrator rk4``, seven classes: case 001, three logs): a hardening cubic spring between the
    two masses of a 2-DOF chain. Its polish ended in a basin at 2.6x the ranking floor (held-out
    0.0586); refitted jointly beside an extra mode and evaluated without it, the spring left 0.0252,
    but no addition passed and the selection went on through a delay-first selection and a
    stand-in retry (325 s of the case's 373 s) to that same spring. The refit without the
    addition, significantly better itself, is now adopted in the first round: no retry runs."""
    from vibroscope.gap import diagnose

    effect = "cubic_stiffness"
    multi = gen.multi_log_drawn(7350, effect, 0, 0.25)
    case = gen.make_case(effect, gen.case_rng(7350, effect, 0), 60.0, integrator="rk4", multi_log=multi,
                         offset_max=1.0, forms="other")
    t = case.truth
    assert multi and t["parameters"]["k3_N_per_m3"] == pytest.approx(1.80877e8, rel=TRUTH_REL)
    rep = diagnose(case.nominal, case.signals_list())
    assert rep.verdicts == (effect,), rep.summary()
    best = rep.candidates[0]
    assert score._same_pair(best.where["between"], t["where"]["between"]), best.where
    assert best.parameters["k3_N_per_m3"] == pytest.approx(t["parameters"]["k3_N_per_m3"], rel=0.1)
    rounds = rep.meta["selection"]["rounds"]
    assert "refit_adopted" in rounds[0] and rounds[0]["refit_adopted"]["gap"] < 0.5 * rounds[0]["current_gap"], rounds[0]
    assert not any(r["start"].startswith(("time_delay", "stand-in")) for r in rounds), [r["start"] for r in rounds]
    assert rep.gap_after < 1.25 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 30 s case generated (RK4 truth) and diagnosed, ~10-20 s
def test_a_strong_cubic_springs_valley_a_hundredth_of_its_bracket_wide_is_found():
    """Fresh seed 6619's cubic case (``generate.py --per-class 1 --seed 6619 --duration 30
    --integrator rk4 --multi-log 0.5 --offset-max 0.5``, case 007): a hardening cubic spring on
    a 1-DOF oscillator, k3 d_rms^2 / k = 0.027, nominal gap 1.05. From the nominal linear
    parameters its valley is about 1 % of k3 wide (fitting gap 0.031 at the true k3, 0.11 at
    +-0.7 %, 0.25 at -2 %, 0.5 at +10 %), inside the bracket 0.011-0.03 between its starts. The
    bracketed search stopped at a tolerance of 1e-3 of the parameter's whole range (0.3 on a
    range of -0.5 to 300), wider than the bracket, so it took one or two steps and left 0.61;
    the spring then shared the gap with a hysteresis and an extra mode (named together, 124 s).
    The tolerance is now 1e-3 of the bracket: the spring alone at the noise floor, k3 within
    1 % (12 s)."""
    t, rep, best = _named_alone_at_its_link("cubic_stiffness", 6619, "rk4", "k3_N_per_m3", 5.54245e10,
                                            duration=30.0, multi_share=0.5, offset_max=0.5)
    assert best.parameters["k3_N_per_m3"] == pytest.approx(t["parameters"]["k3_N_per_m3"], rel=0.01)
    assert rep.gap_after < 1.2 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 40 s case in three logs generated (RK4 truth) and diagnosed, ~20-30 s
def test_an_offset_at_the_floor_leaves_the_level_dependent_classes_untried():
    """Fresh seed 5172's offset case (``generate.py --per-class 1 --seed 5172 --duration 40
    --multi-log 0.4 --offset-max 0.5``, case 011): an input offset of -3.95 N (0.36 of the input's
    RMS force) on a 3-DOF chain, three logs. The offset alone reached the noise floor (held-out
    0.0198 against 0.0194), yet every level-dependent class was screened and fitted at every
    connection after it (90 of the case's 96 s). An effect that does not change with the level,
    at the floor, now leaves them untried (``not_tried``), as a linear effect at the floor does:
    the offset alone, within 1 %, at the floor."""
    from vibroscope.gap import diagnose
    from vibroscope.gap.effects import EFFECT_TABLE

    multi = gen.multi_log_drawn(5172, "offset", 0, 0.4)
    assert multi
    case = gen.make_case("offset", gen.case_rng(5172, "offset", 0), 40.0, integrator="rk4", multi_log=multi,
                         offset_max=0.5)
    t = case.truth
    assert t["parameters"]["offset_N"] == pytest.approx(-3.95372, rel=TRUTH_REL)
    rep = diagnose(case.nominal, case.signals_list())
    assert list(rep.verdicts) == ["offset"], rep.summary()
    off = next(c for c in rep.candidates if c.effect == "offset")
    assert off.parameters["offset_N"] == pytest.approx(t["parameters"]["offset_N"], rel=0.01)
    assert rep.gap_after < 1.1 * rep.noise_floor, rep.summary()
    untried = rep.meta["not_tried"]
    assert {e for e, d in EFFECT_TABLE.items() if d.level_dependent} <= set(untried), untried
    assert all(why.startswith("offset leaves a held-out gap") for why in untried.values()), untried


@pytest.mark.slow  # one 60 s case generated (LSODA truth) and diagnosed, ~70-150 s
def test_a_mostly_stuck_friction_a_linear_refit_nearly_explains_is_still_tried():
    """Fresh seed 5602's first Coulomb case (``generate.py --per-class 2 --seed 5602``, case 004):
    a 39.1 N friction at m2-ground, twice the connection's RMS force, so the mass is stuck most of
    the time and slips at the peaks. A linear refit that pins the mass (or an extra mode of 12.9 kg
    at 20 Hz) left 1.14x the noise floor on held-out data and the BLA does not change with the
    level, so the level-dependent classes were left untried at 1.3x and ``extra_mode`` was named.
    They are now tried above 1.1x (:data:`~vibroscope.gap.diagnosis.LINEAR_STOP_FACTOR`): the
    friction, within 2 %, at its link, at the floor."""
    from vibroscope.gap import diagnose

    multi = gen.multi_log_drawn(5602, "coulomb_friction", 0, 0.25)
    assert not multi
    case = gen.make_case("coulomb_friction", gen.case_rng(5602, "coulomb_friction", 0), 60.0, integrator="lsoda",
                         multi_log=False, offset_max=gen.OFFSET_MAX)
    t = case.truth
    assert t["parameters"]["Fc_N"] == pytest.approx(39.1445, rel=TRUTH_REL)
    assert set(t["where"]["between"]) == {"m2", "ground"}
    rep = diagnose(case.nominal, case.signals(0))
    assert list(rep.verdicts) == ["coulomb_friction"], rep.summary()
    best = rep.candidates[0]
    assert set(best.where["between"]) == {"m2", "ground"}
    assert best.parameters["Fc_N"] == pytest.approx(t["parameters"]["Fc_N"], rel=0.02)
    assert rep.gap_after < 1.05 * rep.noise_floor, rep.summary()
    assert "coulomb_friction" not in rep.meta["not_tried"]


@pytest.mark.slow  # one 40 s case generated (RK4 truth) and diagnosed, ~60-90 s
@pytest.mark.xfail(strict=False, reason=(
    "machine-dependent (session 43): on that session's machine session 42's code (836ef12) and this "
    "code both name a softening cubic spring first and the clearance second, both at m1-ground, the "
    "clearance at 6.083e-6 m (true 6.066e-6) and held-out 0.0188 at the floor 0.0194: a single effect "
    "named with a spurious partner; it passed on the machine of session 42's CI. Session 44's backward "
    "elimination drops such a partner: it passed (XPASS) in session 44's CI rehearsal"))
def test_a_clearance_in_a_narrow_valley_between_its_starts_is_found_at_its_link():
    """Seed 9494's first backlash case (``--per-class 2 --duration 40 --integrator rk4``, case
    005): a clearance of 6.06e-6 m (0.065 of the rms deflection) at m1-ground of a 2-DOF chain.
    On the nominal linear parameters its valley is about a factor 2 wide (0.16 at 4.5e-6 m, 0.19
    at 7.1e-6 m, 0.50 at 1.1e-5 m); the starts 1.7e-6 and 8.3e-6 m lie outside it, and the
    least-squares refinement from 8.3e-6 m moved to 8.2e-6 m (0.269), so the clearance was named
    at m2-ground (held-out 0.092, floor 0.023). The bracketed search between the starts finds
    the valley: named at m1-ground, within 10 % of the true clearance."""
    t, rep, best = _named_alone_at_its_link("backlash", 9494, "rk4", "gap_m", 6.0648e-6, duration=40.0)
    assert best.parameters["gap_m"] == pytest.approx(t["parameters"]["gap_m"], rel=0.1)
    assert rep.gap_after < 2.0 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 30 s case generated (LSODA truth) and diagnosed, ~40 s
def test_a_clearance_at_its_springs_stiffness_is_refined_where_its_matched_variant_refined_best():
    """Fresh seed 7357's backlash case (``--forms other --duration 30 --integrator lsoda``, case
    003): a clearance of 5.78e-5 m (0.34 of the rms deflection) in place of the spring at
    m2-ground of a 3-DOF chain, contact at that spring's stiffness. The clearance's two contact
    laws (the base's stiffness and the one matched to the base) share the class's three
    refinements; the matched one took them all, and the clearance at the base's stiffness stayed
    at its best probed start on the refit (4.3e-6 m): named with the matched contact at 0.40 held
    out (20 times the floor, a shrink of 51 %). Each variant is now refined also where another
    refined best (``_candidates.shared_locations``): from the nominal, its valley (0.09 at the
    truth, 0.29 at 12 % below) is found."""
    from vibroscope.gap import diagnose

    case = gen.make_case("backlash", gen.case_rng(7357, "backlash", 0), 30.0, integrator="lsoda", forms="other")
    t = case.truth
    assert t["where"]["between"] == ["m2", "ground"]
    assert t["parameters"]["gap_m"] == pytest.approx(5.7759e-5, rel=0.03)  # LSODA of a clearance: not to 2e-3 across machines
    rep = diagnose(case.nominal, case.signals(0))
    assert rep.verdict == "backlash", rep.summary()
    best = rep.candidates[0]
    assert best.where == {"between": ["m2", "ground"]}, rep.summary()  # the base's own contact stiffness
    assert best.parameters["gap_m"] == pytest.approx(t["parameters"]["gap_m"], rel=0.03)
    assert rep.gap_after < 3.0 * rep.noise_floor and rep.shrink > 0.9, rep.summary()


@pytest.mark.slow  # one 30 s case of three logs generated (RK4 truth) and diagnosed, ~40 s
def test_a_log_whose_response_stops_repeating_is_left_out_and_the_spring_found_on_the_others():
    """Fresh seed 7359's cubic-spring case (``--forms other --duration 30 --integrator rk4``, case
    003): a hardening cubic spring of share 0.30 at m2-m3 of a 3-DOF chain, three logs of a
    periodic multisine at input RMS 1.3, 3.2 and 7.7 N. At the highest level the response no
    longer repeats with the input (period to period 0.44 nrmse against 0.028 at the others), and
    the truth simulated with 32 and 64 sub-steps differs there by 0.42: no model predicts that log.
    Fitted and validated on all three, a clearance at m2-m1 was named at 0.448 held out (16 times
    the floor), the cubic spring at m2-m3 near its true k3 leaving 0.48. That log is now left out
    (:func:`~vibroscope.gap.levels.aperiodic_logs`), and the spring is found at the floor."""
    from vibroscope.gap import diagnose

    assert gen.multi_log_drawn(7359, "cubic_stiffness", 0, 0.25)
    case = gen.make_case("cubic_stiffness", gen.case_rng(7359, "cubic_stiffness", 0), 30.0, integrator="rk4",
                         multi_log=True, forms="other")
    t = case.truth
    assert t["where"]["between"] == ["m2", "m3"]
    rep = diagnose(case.nominal, case.signals_list())
    assert rep.meta["aperiodic_logs"]["logs"] == [2], rep.summary()
    assert rep.verdict == "cubic_stiffness", rep.summary()
    best = rep.candidates[0]
    assert best.where["between"] == ["m2", "m3"], rep.summary()
    assert best.parameters["k3_N_per_m3"] == pytest.approx(t["parameters"]["k3_N_per_m3"], rel=0.05)
    assert rep.gap_after < 1.5 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 60 s case generated (RK4 truth) and diagnosed, three forward selections, ~90-150 s
def test_a_clearance_replaced_by_a_stiffening_spring_is_swapped_back_when_its_partner_closes_the_gap():
    """Seed 6262's tenth two-effect case (case 129, ``weak_end`` False): a clearance of
    1.66e-5 m at m2-ground and a Coulomb friction of 0.369 N at m1-m2 of a 2-DOF chain. On the
    linear refit, which has absorbed it, the clearance fits best at 2.3e-6 m (vanishing); on the
    nominal it fits at 1.63e-5 m, worse alone. A hardening cubic spring at m2-ground was the
    verdict, and the friction on top of it closed 0.075 -> 0.056 (floor 0.019), short of the
    addition test: ``cubic_stiffness`` alone. Now the non-vanishing fit is kept as a candidate of
    its own, and a selection that leaves more than ``PM_FURTHER`` times the floor is run again from
    the best other class at the first effect's connection: backlash + Coulomb friction, each
    within 5 % and at its link, at the noise floor."""
    from vibroscope.gap import diagnose

    case = gen.make_case("two_effects", gen.case_rng(6262, "two_effects", 9), 60.0, integrator="rk4",
                         weak_end=False, offset_max=gen.OFFSET_MAX_BEFORE_43)
    t = case.truth
    p_true = dict(zip(t["effect"], t["parameters"]))
    w_true = dict(zip(t["effect"], t["where"]))
    assert p_true["backlash"]["gap_m"] == pytest.approx(1.66374e-5, rel=TRUTH_REL)
    rep = diagnose(case.nominal, case.signals(0))
    assert set(rep.verdicts) == {"backlash", "coulomb_friction"}, rep.summary()
    for eff, par in (("backlash", "gap_m"), ("coulomb_friction", "Fc_N")):
        c = next(c for c in rep.candidates if c.effect == eff)
        assert c.parameters[par] == pytest.approx(p_true[eff][par], rel=0.05), (eff, c.parameters)
        assert score._same_pair(c.where["between"], w_true[eff]["between"]), (eff, c.where)
    # where the clearance is the fit kept on the other linear base, its label says so. On session
    # 54's code (the analytic FRF Jacobian moves the linear refit's path; which change did it was not
    # isolated) the clearance fitted on the refit no longer vanishes (1.6644e-5 m, true 1.6637e-5 m,
    # the only backlash candidate): the other base is not needed, and it carries no label
    assert next(c for c in rep.candidates if c.effect == "backlash").where.get("linear_base") in (None, "nominal")
    assert rep.gap_after < 1.5 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 60 s case generated (LSODA truth) and diagnosed, two forward selections, ~60-120 s
def test_a_refit_far_above_the_floor_gives_way_to_two_effects_that_close_it():
    """Seed 6262's ninth two-effect case (case 116, generated before session 39: ``weak_end``
    False): an input offset of -0.866 N and a Bouc-Wen hysteresis at m1-ground. The BLA does not
    change with the level, so a nonlinear effect alone must beat the linear refit by
    ``NL_MARGIN``; the hysteresis alone (held-out 0.079) did not, the refit (0.124, 5.6x the
    noise floor) was the verdict, and no effect was tried on top of it. Now a refit verdict above
    ``PM_FURTHER`` times the floor is tested against the selection from the best nonlinear
    candidate: hysteresis + offset, at the noise floor, the offset within 5 %."""
    from vibroscope.gap import diagnose

    case = gen.make_case("two_effects", gen.case_rng(6262, "two_effects", 8), 60.0, integrator="lsoda",
                         weak_end=False, offset_max=gen.OFFSET_MAX_BEFORE_43)
    t = case.truth
    p_true = dict(zip(t["effect"], t["parameters"]))
    assert p_true["offset"]["offset_N"] == pytest.approx(-0.86596, rel=TRUTH_REL)
    rep = diagnose(case.nominal, case.signals(0))
    assert set(rep.verdicts) == {"hysteresis", "offset"}, rep.summary()
    off = next(c for c in rep.candidates if c.effect == "offset")
    assert off.parameters["offset_N"] == pytest.approx(p_true["offset"]["offset_N"], rel=0.05)
    hyst = next(c for c in rep.candidates if c.effect == "hysteresis")
    assert score._same_pair(hyst.where["between"], t["where"][1]["between"]), hyst.where
    assert rep.gap_after < 1.5 * rep.noise_floor, rep.summary()


# ---------------------------------------------------------------------------------------------
# closed-loop and modal kinds
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow  # one 30 s closed-loop case generated (RK4 truth, three logs) and diagnosed, ~10-20 s
def test_a_closed_loop_actuator_delay_is_fitted_in_its_valley():
    """Fresh closed-loop seed 3307's first delay case (case 003 of ``--kind closed_loop
    --per-class 2 --duration 30``): a 5.8 ms actuator delay in a position loop, three logs. The
    refit bent the plant (a damping to 8 %) to mimic the delay, the delay fitted on it from the
    2 ms start stopped at 3.2 ms (shrink 68 %), and from the nominal the bracket above the 8 ms
    start (8-100 ms) was too wide for the search's eight evaluations. With starts an octave
    apart, searched between the best one's neighbours on both linear bases: 5.71 ms, shrink 87 %."""
    from vibroscope.gap import diagnose

    effect = "closed_loop_time_delay"
    case = gen.make_case(effect, gen.case_rng(3307, effect, 0), 30.0, integrator="rk4", multi_log=True)
    t = case.truth
    assert t["parameters"]["delay_s"] == pytest.approx(0.0058)
    rep = diagnose(case.nominal, [case.signals(i) for i in range(len(t["logs"]))])
    assert list(rep.verdicts) == ["time_delay"], rep.summary()
    assert rep.candidates[0].parameters["delay_s"] == pytest.approx(0.0058, rel=0.05), rep.summary()
    assert rep.shrink > 0.8, rep.summary()


def test_a_closed_loop_delay_whose_loop_diverges_around_it_is_read_from_the_logged_command():
    """Fresh closed-loop seed 7315's second delay case (case 009 of ``--kind closed_loop
    --per-class 2``): a 10 ms actuator delay in a cascade loop around a 2-DOF drive whose
    nominal loop, given that delay, diverges from 3 to 9 ms and leaves 2.06 nrmse at 16 ms. From
    the octave grid of starts the delay stopped at 3.1 ms (unexplained, 0.347 held out). The
    delay read from the logged command's FRF against the open plant's (less the nominal's own
    lag) starts the search in its valley."""
    from vibroscope.gap import diagnose
    from vibroscope.gap._evidence import loop_delay_start
    from vibroscope.gap.closed_loop import log_channels, measured_rows
    from vibroscope.models.simulate import simulate

    effect = "closed_loop_time_delay"
    case = gen.make_case(effect, gen.case_rng(7315, effect, 1), 60.0, integrator="rk4", multi_log=False)
    t = case.truth
    assert t["parameters"]["delay_s"] == pytest.approx(0.01)
    sig = case.signals(0)
    ins, outs = log_channels(case.nominal)
    data = np.asarray(sig.data)
    u, y = data[:len(ins)], data[len(ins):]
    y_nom = measured_rows(case.nominal, simulate(case.nominal, u[0], sig.fs))
    mask = np.ones(y.shape[1], bool)
    tau = loop_delay_start(case.nominal, [u], [y], [y_nom], [mask], sig.fs, 1024, "hann")
    assert tau == pytest.approx(0.01, abs=0.001)
    rep = diagnose(case.nominal, sig)
    assert list(rep.verdicts) == ["time_delay"], rep.summary()
    assert rep.candidates[0].parameters["delay_s"] == pytest.approx(0.01, rel=0.02), rep.summary()
    assert rep.gap_after < 1.1 * rep.noise_floor, rep.summary()


@pytest.mark.parametrize("index, limit, before", [(1, 42.016, 0.2), (3, 145.43, 0.14)])
def test_an_actuator_limit_beyond_the_screening_prefix_or_beside_a_plateau_is_found(index, limit, before):
    """Fresh closed-loop seed 7316's saturation cases 010 and 022 (``--kind closed_loop
    --per-class 5``), both ``unexplained`` before. Case 010: limits of 78-254 N fit the screening
    prefix alike (the limit does not act) and 32.5 N fits worse; the search between 78 and 254 N
    left 200 N. Case 022: the first 8 s of a slow reference never reach the 145 N limit, so every
    start fitted the screening prefix alike; probed on a prefix that reaches the largest force."""
    from vibroscope.gap import diagnose

    effect = "closed_loop_saturation"
    case = gen.make_case(effect, gen.case_rng(7316, effect, index), 60.0, integrator="rk4", multi_log=False)
    assert case.truth["parameters"]["limit_N"] == pytest.approx(limit, rel=1e-4)
    rep = diagnose(case.nominal, case.signals(0))
    assert list(rep.verdicts) == ["saturation"], rep.summary()
    assert rep.candidates[0].parameters["limit_N"] == pytest.approx(limit, rel=0.01), rep.summary()
    assert rep.gap_after < 1.1 * rep.noise_floor and rep.gap_before > before, rep.summary()


def test_a_plateau_of_starts_is_searched_beyond_its_edges():
    from vibroscope.gap._candidates import plateau_brackets

    xs = [1.0, 2.0, 3.0, 4.0, 5.0]
    flat = {1.0: 0.9, 2.0: 0.5, 3.0: 0.3, 4.0: 0.3, 5.0: 0.3}
    assert plateau_brackets(xs, 3.0, 0.3, flat) == [(2.0, 3.0)]  # the valley lies below the plateau
    assert plateau_brackets(xs, 2.0, 0.3, {**flat, 2.0: 0.3, 1.0: 0.3, 3.0: 0.3, 4.0: 0.35}) == [(3.0, 4.0)]
    both = {1.0: 0.9, 2.0: 0.3, 3.0: 0.3, 4.0: 0.8, 5.0: 0.9}
    assert plateau_brackets(xs, 2.0, 0.3, both) == [(1.0, 2.0), (3.0, 4.0)]
    assert plateau_brackets(xs, 3.0, 0.3, {1.0: 0.9, 2.0: 0.5, 3.0: 0.3, 4.0: 0.31, 5.0: 0.4}) is None  # a valley
    assert plateau_brackets(xs, 3.0, 0.3, {x: 0.3 for x in xs}) is None  # flat everywhere: nothing beyond


def test_a_closed_loop_truth_with_a_stiff_friction_at_a_light_load_is_integrated_within_rk4s_stability():
    """Fresh closed-loop seed 7316's case 025 as first drawn: 14.2 N of friction (v_eps 1 mm/s)
    between a 2.26 kg drive and a 0.55 kg load, integrated at the 10 kHz the probe friction at the
    drive set (h F / v_eps (1/m1 + 1/m2) = 3.2, beyond RK4's 2.78): its accelerations were numerical
    chatter (1.25 and 3.3 nrmse from the converged run), and vibroscope's correct simulation of
    the truth model could not fit them. The truth's own law now sets the sub-steps."""
    from vibroscope.models.elements import Friction

    m1, m2 = 2.263680442765756, 0.5477699308151411
    model = LumpedModel(
        dofs=(Dof("m1", m1), Dof("m2", m2)),
        elements=(Damper(("m1", "ground"), 15.82557243014655), Spring(("m2", "m1"), 10067.782326854856),
                  Damper(("m2", "m1"), 4.937728025447414), Friction(("m2", "m1"), force_=14.228336462099763, v_eps=1e-3)),
        inputs=(Input(dof="m1", quantity="force", channel=gen.CL_FORCE_CHANNEL),),
        outputs=(Output("m1", "displacement"), Output("m1", "acceleration"), Output("m2", "acceleration")),
    )
    ctl = gen.DriveController(kp=15.253250961281976, kv=11.409020639372017, gain=15.145146142789972)
    ref = gen.make_reference(np.random.default_rng(3), 10000)[0].coarse
    sub = gen.CL_SUB * gen._rk4_substeps(gen._tm(model), np.full(4, 0.01))
    assert sub >= 20
    converged = gen.simulate_closed_loop_truth(model, ctl, ref, substeps=200).outputs
    for k, agree in ((sub, True), (gen.CL_SUB, False)):
        out = gen.simulate_closed_loop_truth(model, ctl, ref, substeps=k).outputs
        err = np.sqrt(np.mean((out - converged) ** 2, axis=1) / np.mean(converged**2, axis=1))
        assert (err.max() < 1e-3) == agree, (k, err)


@pytest.mark.parametrize("two_dof", [False, True])
def test_closed_loop_truth_matches_vibroscope_without_effect(two_dof):
    """The generator's own closed loop (RK4 between controller ticks) and vibroscope's
    simulation of the written nominal file agree on a 5 s case (measured: 1-DOF 6e-15, 2-DOF
    3.6e-9 worst channel nrmse)."""
    from vibroscope.gap.closed_loop import measured_rows
    from vibroscope.models.simulate import simulate

    rng = np.random.default_rng(1 if two_dof else 0)
    model, ctl = gen.random_drive(rng, two_dof=two_dof)
    ref = gen.make_reference(rng, 5000)[0].coarse
    run = gen.simulate_closed_loop_truth(model, ctl, ref)
    nominal = loads_model(gen.dumps_model(gen.closed_loop_nominal(model, ctl)), "nominal.toml")
    assert nominal.controllers and nominal.controllers[0].output_channel == gen.CL_COMMAND_CHANNEL
    y = measured_rows(nominal, simulate(nominal, ref[None], gen.FS))
    assert y.shape == run.outputs.shape
    assert max(gen.nrmse(a, b) for a, b in zip(run.outputs, y)) < 1e-4


def test_modal_nominal_is_the_exact_pole_residue_model():
    from vibroscope.gap.physical import as_lumped

    rng = np.random.default_rng(3)
    truth = gen.random_modal_truth(rng)
    m = as_lumped(loads_model(gen.dumps_model(gen.exact_pole_residue(truth)), "nominal.toml"))
    f = np.linspace(1.0, 200.0, 400)
    H, Hm = truth.frf(f), m.frf(f)
    assert np.max(np.abs(Hm - H)) / np.max(np.abs(H)) < 1e-8
    assert set(m.points) == set(truth.dof_names)


#: a fresh-seed case CI does not run (its 90-minute limit on 2 cores); `python -m pytest -m extended`
#: runs them (session 62, 2-core machine: the 7 cases left in CI took 279 s, these 15 1509-2031 s)
_EXTENDED = pytest.mark.extended

# two-effect cases of fresh seeds (``--classes two_effects --duration 30 --multi-log 0.25``, the
# default integrators; on seed 3737 session 40's code named both effects in 2 of 10). Each row is
# one mechanism of the forward selection: (seed, case index, the effects, (effect, parameter,
# relative tolerance) checked against the truth); every effect at a connection at its link.
_FRESH_TWO_EFFECTS = [
    # an input delay fitted alone raises the damping a friction supplies: the friction's joint fit
    # starts from the nominal linear parameters, where the delay and the screened friction meet
    pytest.param(3737, 6, {"time_delay", "asymmetric_friction"},
                 [("time_delay", "delay_s", 0.05), ("asymmetric_friction", "Fc_pos_N", 0.1),
                  ("asymmetric_friction", "Fc_neg_N", 0.1)], id="3737-006-delay-then-friction-from-the-nominal"),
    # an asymmetric friction's unequal forces beside a softening spring are a constant force,
    # invisible in acceleration: the projection to Coulomb at the mean wins the nested test
    pytest.param(3737, 0, {"cubic_stiffness", "coulomb_friction"},
                 [("coulomb_friction", "Fc_N", 0.05), ("cubic_stiffness", "k3_N_per_m3", 0.3)],
                 id="3737-000-asymmetry-projected-to-coulomb"),
    # an asymmetric friction stuck at 1.96/0.07 N beside a saturation: refitted from the Coulomb
    # projection's solution, it wins the nested test
    pytest.param(3737, 2, {"asymmetric_friction", "saturation"},
                 [("asymmetric_friction", "Fc_pos_N", 0.05), ("asymmetric_friction", "Fc_neg_N", 0.05),
                  ("saturation", "limit_N", 0.05)], id="3737-002-asymmetry-refitted-from-coulomb", marks=_EXTENDED),
    # a clearance the refit absorbed (its spring softened to 1600 N/m): the nominal-base fit,
    # kept aside, joins the friction
    pytest.param(3737, 5, {"asymmetric_friction", "backlash"},
                 [("backlash", "gap_m", 0.05), ("asymmetric_friction", "Fc_pos_N", 0.1)],
                 id="3737-005-clearance-from-the-other-base", marks=_EXTENDED),
    # a hysteresis that screened best where the friction acts is tried at its best other link
    pytest.param(3737, 1, {"coulomb_friction", "hysteresis"}, [("hysteresis", "alpha_N_per_m", 0.2)],
                 id="3737-001-hysteresis-at-its-other-link", marks=_EXTENDED),
    # a Bouc-Wen element of alpha 1.9e7 N/m fitted beside a saturation for a Coulomb friction: its
    # projection to the Coulomb friction it tends to (the Dahl limit) wins the nested test
    pytest.param(4848, 5, {"saturation", "coulomb_friction"},
                 [("coulomb_friction", "Fc_N", 0.05), ("saturation", "limit_N", 0.1)],
                 id="4848-005-hysteresis-projected-to-coulomb"),
    # a hysteresis beside an asymmetric friction whose fits ended at phi = 1.45 (a bound), held-out
    # 4.2x the floor: the joint fit from its generic start reaches the truth (40 s, RK4, one log)
    pytest.param(5858, 1, {"asymmetric_friction", "hysteresis"},
                 [("hysteresis", "alpha_N_per_m", 0.1)],
                 id="5858-001-hysteresis-from-its-generic-start", marks=_EXTENDED),
    # the same beside a Coulomb friction, its joint fit ended at phi = 1.19 (not on the bound),
    # held-out 1.7x the floor: from the generic start too, both are named
    pytest.param(5858, 3, {"coulomb_friction", "hysteresis"},
                 [("coulomb_friction", "Fc_N", 0.1), ("hysteresis", "alpha_N_per_m", 0.1)],
                 id="5858-003-hysteresis-beside-coulomb-from-its-generic-start", marks=_EXTENDED),
    # a hysteresis at m3-ground beside a backlash at m2-m1 screened best at m1-ground (on a linear
    # base without the backlash), where beside the backlash it changes nothing: placed again on
    # the model with the backlash, m3-ground is its best connection (3 logs)
    pytest.param(1414, 4, {"backlash", "hysteresis"}, [("hysteresis", "alpha_N_per_m", 0.1)],
                 id="1414-004-hysteresis-placed-again-beside-the-backlash", marks=_EXTENDED),
    # a clearance of 3.5 um beside an input saturation (3 logs): fitted alone the clearance bent
    # the masses up 23 % and sat at 2.3 um, from where the pair's joint fit stopped at 0.144
    # (the clearance's valley is +-10 % wide); the pair fitted on the nominal base, the clearance
    # scanned first, reaches the truth
    pytest.param(5858, 0, {"backlash", "saturation"}, [("backlash", "gap_m", 0.1), ("saturation", "limit_N", 0.05)],
                 id="5858-000-saturation-beside-a-clearance-from-the-nominal-base"),
    # a weak hysteresis was chosen first for a clearance and a hardening spring at two
    # connections, the three at the noise floor: backward elimination drops it (40 s, RK4, 3 logs)
    pytest.param(6363, 4, {"backlash", "cubic_stiffness"},
                 [("backlash", "gap_m", 0.1), ("cubic_stiffness", "k3_N_per_m3", 0.1)],
                 id="6363-004-a-spurious-first-effect-eliminated", marks=_EXTENDED),
    # a Coulomb friction and a hysteresis at one link: the asymmetric friction fitted alone
    # (4.3/14.6 N) became symmetric jointly with the hysteresis, at the floor; that is a Coulomb
    # friction, not a vanished effect (40 s, RK4, 3 logs)
    pytest.param(6363, 7, {"coulomb_friction", "hysteresis"},
                 [("coulomb_friction", "Fc_N", 0.1), ("hysteresis", "alpha_N_per_m", 0.1)],
                 id="6363-007-asymmetric-friction-made-symmetric-jointly-is-coulomb", marks=_EXTENDED),
    # a weak hysteresis (alpha / k = 0.09, yielding at a quarter of the RMS deflection) beside an
    # asymmetric friction at another link: reached from its weak generic start (30 s, one log)
    pytest.param(7272, 0, {"hysteresis", "asymmetric_friction"},
                 [("hysteresis", "alpha_N_per_m", 0.1), ("asymmetric_friction", "Fc_pos_N", 0.1),
                  ("asymmetric_friction", "Fc_neg_N", 0.1)],
                 id="7272-000-a-weak-hysteresis-from-its-weak-start", marks=_EXTENDED),
    # a weak hysteresis beside an asymmetric friction fitted alone to 2.01/0.058 N (true 1.72/0.55
    # N): the hysteresis's own fit on that model changes nothing and ranked last; the two fitted
    # together on the nominal base rank it first and start its joint fit (30 s, lsoda)
    pytest.param(9393, 3, {"hysteresis", "asymmetric_friction"},
                 [("hysteresis", "alpha_N_per_m", 0.1), ("asymmetric_friction", "Fc_neg_N", 0.1)],
                 id="9393-003-a-hysteresis-ranked-by-the-pair-on-the-nominal-base", marks=_EXTENDED),
    # a Coulomb friction and a hysteresis at one link, fitted as an asymmetric friction of
    # 0.40/0.59 N: its Coulomb projection leaves the smaller held-out gap, and refitted as
    # asymmetric from there it stays symmetric, so the Coulomb friction is taken (30 s, lsoda)
    pytest.param(9393, 2, {"coulomb_friction", "hysteresis"},
                 [("coulomb_friction", "Fc_N", 0.05), ("hysteresis", "alpha_N_per_m", 0.1)],
                 id="9393-002-an-asymmetric-friction-that-stays-symmetric-from-coulomb"),
    # an input offset of 7.4 N and an input delay of 0.6 ms (3 logs): the offset was chosen first
    # and the delay, fitted alone to 0.5999 ms, was never offered as an addition
    pytest.param(4545, 4, {"offset", "time_delay"},
                 [("offset", "offset_N", 0.02), ("time_delay", "delay_s", 0.05)],
                 id="4545-004-a-delay-fitted-alone-joins-an-offset", marks=_EXTENDED),
    # a clearance of 1.7 um (3 % of the RMS deflection) in a 1.1e6 N/m link beside an input
    # saturation clipping 15 % of the peaks (30 s, RK4, one log): screened without the
    # saturation the clearance vanished at both connections and was never offered; a class that
    # vanished everywhere is offered at its connections when the first effect leaves more than
    # twice the floor
    pytest.param(5003, 1, {"backlash", "saturation"}, [("backlash", "gap_m", 0.1), ("saturation", "limit_N", 0.05)],
                 id="5003-001-a-clearance-masked-by-a-saturation"),
    # a strong hysteresis (alpha / k = 0.16) beside a 1 ms input delay (40 s, lsoda, one log): the
    # delay alone at 17x the floor, the hysteresis screened on a linear base without the delay
    # never joined it; screened again on the delay it does
    pytest.param(7411, 4, {"hysteresis", "time_delay"},
                 [("hysteresis", "alpha_N_per_m", 0.1), ("time_delay", "delay_s", 0.05)],
                 id="7411-004-a-hysteresis-screened-again-on-the-delay", marks=_EXTENDED),
    # a 0.63 ms input delay and a 23 N Coulomb friction (60 s, lsoda, one log): the BLA changes
    # with the level, so the delay was not fitted alone; the friction, screened on a base without
    # the delay, fitted at 6.3 N, and a Jenkins joint was named at 11.7x the floor with nothing
    # joining it. A verdict far above the floor is now tried against the selection from the delay
    # the phase slope measures (3 min)
    pytest.param(5201, 6, {"time_delay", "coulomb_friction"},
                 [("time_delay", "delay_s", 0.05), ("coulomb_friction", "Fc_N", 0.05)],
                 id="5201-006-a-verdict-far-above-the-floor-tried-from-the-delay"),
    # an 8.3 N Coulomb friction and an 8.8 um clearance (0.46 of the RMS deflection) in a 7e5 N/m
    # link to ground (60 s, RK4, one log): the friction holds the mass inside the clearance, so
    # each alone vanished (the clearance fitted to 2 nm, the friction to 1 N) and a hysteresis at
    # the other link was named at 2.6x the floor; the two are now fitted as a pair at each
    # connection (~100 s)
    pytest.param(5701, 7, {"coulomb_friction", "backlash"},
                 [("coulomb_friction", "Fc_N", 0.05), ("backlash", "gap_m", 0.05)],
                 id="5701-007-a-friction-held-clearance-fitted-as-a-pair", marks=_EXTENDED),
    # a 5.8 um clearance (0.13 of the RMS deflection) and a hysteresis (alpha / k = 0.15) in one
    # 6.7e5 N/m link to ground (30 s, lsoda, three logs): the clearance alone at 2.4x the floor;
    # the hysteresis, added to it, was fitted jointly into a basin of 50 % more linear damping
    # from every start. A hysteresis holds a clearance's DOF as a friction does: the pair is now
    # fitted on the nominal base too (~200 s; the hysteresis's alpha comes out at 0.7 of the
    # truth's, so only the clearance is checked). Sensitive to the machine: it passed in CI on 2ac7f64
    # (session 58 measured 0.0471 held-out), but on a 2-core AMD EPYC (session 62) the pair's joint
    # fit ended at 0.0529 (1.15x the data's floor; the clearance alone 0.1099) and was not taken by
    # the significance test: the backlash alone was named (an open miss)
    pytest.param(5706, 1, {"backlash", "hysteresis"}, [("backlash", "gap_m", 0.1)],
                 id="5706-001-a-hysteresis-held-clearance-fitted-as-a-pair", marks=_EXTENDED),
    # a hysteresis (alpha / k = 0.24) and a 0.65 N Coulomb friction (3.5 % of the RMS connection
    # force) at one link (60 s, RK4, three logs): the hysteresis alone, gamma + delta = 0.038 (a
    # slider of 1.5 N), at 1.39x the floor was not retried from the friction (the retry needed
    # gamma + delta > 0.05); it now is, for any positive sum (~110 s)
    pytest.param(5801, 3, {"hysteresis", "coulomb_friction"},
                 [("coulomb_friction", "Fc_N", 0.05), ("hysteresis", "alpha_N_per_m", 0.05)],
                 id="5801-003-a-near-slider-hysteresis-retried-from-the-friction", marks=_EXTENDED),
    # a weak Coulomb friction (0.44 N) beside an input saturation: added as an asymmetric
    # friction it is fitted jointly to 0.443/0.435 N, held-out at the floor, and vanishes into
    # the Coulomb member, which is evaluated in its place instead of the addition being
    # dropped (before: saturation alone, 2.3x the floor; 40 s, LSODA, one log, ~50 s)
    pytest.param(6904, 0, {"saturation", "coulomb_friction"},
                 [("coulomb_friction", "Fc_N", 0.05), ("saturation", "limit_N", 0.05)],
                 id="6904-000-an-asymmetric-addition-reduced-to-coulomb"),
]
#: cases generated with other settings than the default here (30 s, lsoda/RK4 by case number, a
#: quarter multi-log, offsets up to 0.2 of the input's RMS force)
_FRESH_SETTINGS = {5858: dict(duration=40.0, integrator="rk4", multi_share=0.5),
                   6363: dict(duration=40.0, integrator="rk4", multi_share=0.6, offset_max=0.5),
                   4545: dict(multi_share=0.4, offset_max=gen.OFFSET_MAX),
                   5003: dict(multi_share=0.4, offset_max=gen.OFFSET_MAX),
                   7411: dict(duration=40.0, multi_share=0.5, offset_max=gen.OFFSET_MAX),
                   7272: dict(offset_max=gen.OFFSET_MAX),
                   5201: dict(duration=60.0, offset_max=gen.OFFSET_MAX),
                   9393: dict(integrator="lsoda", offset_max=gen.OFFSET_MAX, weak_end=False),
                   5701: dict(duration=60.0, offset_max=gen.OFFSET_MAX),
                   5706: dict(duration=30.0, integrator="lsoda", multi_share=0.8, offset_max=0.5),
                   5801: dict(duration=60.0, offset_max=gen.OFFSET_MAX),
                   6904: dict(duration=40.0, integrator="lsoda", multi_share=0.5, offset_max=gen.OFFSET_MAX)}


@pytest.mark.slow  # one 30 s case generated and diagnosed (1-3 DOF, 1 or 3 logs), ~20-180 s each
@pytest.mark.parametrize("seed, index, effects, checks", _FRESH_TWO_EFFECTS)
def test_a_fresh_seeds_two_effects_are_named_at_their_links(seed, index, effects, checks):
    """Both true effects named, their parameters within the tolerance of the truth, each effect
    at a connection at its link, and the held-out gap within 1.5 times the noise floor."""
    from vibroscope.gap import diagnose

    opts = _FRESH_SETTINGS.get(seed, {})
    share = opts.get("multi_share", 0.25)
    multi = gen.multi_log_drawn(seed, "two_effects", index, share)
    case = gen.make_case("two_effects", gen.case_rng(seed, "two_effects", index), opts.get("duration", 30.0),
                         integrator=opts.get("integrator", gen.INTEGRATORS[index % 2]), multi_log=multi,
                         offset_max=opts.get("offset_max", gen.OFFSET_MAX_BEFORE_43),
                         weak_end=opts.get("weak_end", True))
    t = case.truth
    assert set(t["effect"]) == effects
    p_true = dict(zip(t["effect"], t["parameters"]))
    w_true = dict(zip(t["effect"], t["where"]))
    rep = diagnose(case.nominal, case.signals_list() if multi else case.signals(0))
    assert set(rep.verdicts) == effects, rep.summary()
    truth_name = {"Fc_pos_N": "Fp_N", "Fc_neg_N": "Fn_N"}  # the report's names -> the generator's
    for eff, par, tol in checks:
        c = next(c for c in rep.candidates if c.effect == eff)
        want = p_true[eff][truth_name.get(par, par)]
        assert c.parameters[par] == pytest.approx(want, rel=tol), (eff, par, c.parameters, p_true[eff])
    for eff in effects:
        c = next(c for c in rep.candidates if c.effect == eff)
        if "between" in c.where:
            assert score._same_pair(c.where["between"], w_true[eff]["between"]), (eff, c.where, w_true[eff])
    assert rep.gap_after < 1.5 * rep.noise_floor, rep.summary()


# fresh seed 7102 drawn with an unlogged force at the drive point (``--disturbance 0.2``), 60 s:
# (class, case number in the benchmark, the truth's parameter checked, tolerance). Before session
# 71: none -> unexplained (nominal 0.24 against a white floor of 0.012), parameter_mismatch ->
# joint_friction (a low level's noise split a mode into two peaks: a +1.8 % "shift" barred the
# refit), coulomb_friction -> unexplained (the friction fitted to 0.057 N, truth 0.056 N, lost
# to the refit on the parameter penalty)
_DISTURBED = [
    pytest.param("none", 0, None, None, id="7102-000-none"),
    # extended (session 89: 174 s in the rehearsal of 48515c4; CI's time limit)
    pytest.param("parameter_mismatch", 1, "k:m2-ground", 0.02, id="7102-001-parameter-mismatch",
                 marks=pytest.mark.extended),
    pytest.param("coulomb_friction", 4, "Fc_N", 0.1, id="7102-004-coulomb-friction"),
]


@pytest.mark.slow  # the full diagnosis of a 60 s case, 30-210 s each on the 2-core box
@pytest.mark.parametrize("cls, number, par, tol", _DISTURBED)
def test_an_unlogged_disturbance_leaves_the_true_verdict(cls, number, par, tol):
    """The truth driven by the logged force and an unlogged one (8-11 % of its RMS, in its band):
    what no model of the logged force can explain is not coherent with it, and the verdict is
    the truth's, its parameter within the tolerance; the gap left is that disturbance, far above
    the white floor."""
    from vibroscope.gap import diagnose

    multi = gen.multi_log_drawn(7102, cls, 0, 0.25)
    case = gen.make_case(cls, gen.case_rng(7102, cls, 0), 60.0, integrator=gen.INTEGRATORS[number % 2],
                         multi_log=multi, disturbance=0.2)
    t = case.truth
    assert t["disturbance"]["gap_it_adds_noise_free"] > 0.08
    rep = diagnose(case.nominal, case.signals_list() if multi else case.signals(0))
    assert rep.verdict == cls and list(rep.verdicts) == [cls], rep.summary()
    assert rep.meta["incoherent_gap"]["changed"], rep.summary()
    assert rep.gap_after > 3 * rep.noise_floor, rep.summary()
    if par is not None:
        c = rep.candidates[0]
        assert c.effect == cls
        assert c.parameters[par] == pytest.approx(t["parameters"][par], rel=tol), (c.parameters, t["parameters"])


# extra modes under an unlogged disturbance (``--classes none parameter_mismatch extra_mode ...
# --disturbance 0.3 --integrator rk4``): (seed, extra_mode index). The refit's coherent part passes
# the `none` bound only on its scatter allowance (few averages) while the extra mode's own is
# within NONE_FACTOR x the floor without it; before session 89 the extra mode also had to beat the
# refit with a held-out t of 4 (t 3.63 and 3.12) and both were named `parameter_mismatch`
_DISTURBED_EXTRA_MODES = [
    pytest.param(7353, 0, id="7353-002-a-16-hz-mode-at-m3"),
    pytest.param(7355, 3, id="7355-011-a-44-hz-mode-at-m1-three-logs"),
]


@pytest.mark.slow
@pytest.mark.extended  # one 60 s case generated (RK4 truth) and diagnosed, 130-210 s each
@pytest.mark.parametrize("seed, index", _DISTURBED_EXTRA_MODES)
def test_an_extra_mode_under_a_disturbance_is_not_left_to_the_refit_on_its_scatter(seed, index):
    from vibroscope.gap import diagnose

    multi = gen.multi_log_drawn(seed, "extra_mode", index, 0.25)
    case = gen.make_case("extra_mode", gen.case_rng(seed, "extra_mode", index), 60.0, integrator="rk4",
                         multi_log=multi, disturbance=0.3)
    t = case.truth
    rep = diagnose(case.nominal, case.signals_list() if multi else case.signals(0))
    ig = rep.meta["incoherent_gap"]
    assert ig["refit_within"] and not ig["refit_strictly_within"], ig  # the rule's condition
    assert rep.verdict == "extra_mode" and list(rep.verdicts) == ["extra_mode"], rep.summary()
    c = rep.candidates[0]
    assert c.where["dof"] == t["where"]["dof"], (c.where, t["where"])
    assert c.where["frequency_hz"] == pytest.approx(t["where"]["frequency_hz"], rel=0.05), (c.where, t["where"])


@pytest.mark.slow  # the full diagnosis of a 60 s three-log case, 50-140 s on the 2-core box
def test_a_disturbed_periodic_case_ranks_against_its_period_to_period_floor():
    """Fresh seed 7305 case 002 (``--classes two_effects --disturbance 0.2 --multi-log 1.0``): an
    input offset and a saturation, the truth driven by an unlogged force as well (it adds 0.11 to
    the gap, the white floor 0.024). The outputs' variation from period to period of the
    multisine measures that in the band (0.112; the disturbance and the noise give 0.114); ranked
    against it, both effects are named. Against the white floor: ``unexplained`` (session 71)."""
    from vibroscope.gap import diagnose

    case = gen.make_case("two_effects", gen.case_rng(7305, "two_effects", 2), 60.0, integrator="lsoda",
                         multi_log=True, disturbance=0.2)
    t = case.truth
    assert sorted(t["effect"]) == ["offset", "saturation"] and t["disturbance"]["gap_it_adds_noise_free"] > 0.1
    rep = diagnose(case.nominal, case.signals_list())
    pf = rep.meta["incoherent_gap"]["period_floor"]
    assert pf is not None and pf["nrmse"] == pytest.approx(0.112, rel=0.1) and pf["ratio_to_white_floor"] > 3
    assert "period to period" in rep.meta["noise_floor_ranking"]["method"]
    assert sorted(rep.verdicts) == ["offset", "saturation"], rep.summary()
    off = next(c for c in rep.candidates if c.effect == "offset")
    assert off.parameters["offset_N"] == pytest.approx(t["parameters"][0]["offset_N"], rel=0.1)


@pytest.mark.slow  # the full diagnosis of a 60 s case, 35-70 s on the 2-core box
def test_a_hysteresis_fitted_close_behind_a_joint_is_polished_and_wins():
    """Fresh seed 7307 case 006 (``--period 0.5 8 --level-blocks``: random force, the three levels in
    three contiguous blocks): a Bouc-Wen hysteresis between m1 and m2. Its joint fit (0.108 on the
    fitting data, 0.283 held out) ended close behind an Iwan joint's (0.102), and only the winner
    was polished: ``joint_friction`` at 0.0325. Polished beside it, the hysteresis reaches the
    floor (0.0273 against 0.023) and is named."""
    from vibroscope.gap import diagnose

    case = gen.make_case("hysteresis", gen.case_rng(7307, "hysteresis", 0), 60.0, integrator="lsoda",
                         period=(0.5, 8.0), level_blocks=True)
    t = case.truth
    assert t["input"]["kind"] == "random" and t["input"]["level_blocks"]
    rep = diagnose(case.nominal, case.signals(0))
    assert rep.verdict == "hysteresis" and list(rep.verdicts) == ["hysteresis"], rep.summary()
    c = rep.candidates[0]
    assert c.where["between"] == ["m1", "m2"] and c.gap_after < 1.5 * rep.noise_floor, rep.summary()
    joint = next(x for x in rep.candidates if x.effect == "joint_friction")
    assert joint.gap_after > c.gap_after


@pytest.mark.slow  # the diagnosis restricted to the extra mode, 30-50 s on the 2-core box
def test_an_extra_mode_tied_on_the_frf_at_two_dofs_is_placed_by_the_held_out_data():
    """Fresh seed 7308 case 011 (``--period 0.5 8 --level-blocks --forms other --input-noise 0.03
    --dofs 1 4``): a 0.01 kg mode at 47.16 Hz on m3, the one sensed DOF, sprung to m2. Its FRF fits
    at m2, m3 and m1 cost within 0.2 % of each other and only the cheapest (m2) was polished in time;
    polished at each, the held-out data place it at m3 (0.0365 against 0.0371 at m2)."""
    from vibroscope.gap import diagnose

    case = gen.make_case("extra_mode", gen.case_rng(7308, "extra_mode", 1), 60.0, integrator="rk4",
                         forms="other", input_noise=0.03, dofs=(1, 4), period=(0.5, 8.0), level_blocks=True)
    t = case.truth
    assert t["where"]["dof"] == "m3" and [o["dof"] for o in t["outputs"]] == ["m3"]
    rep = diagnose(case.nominal, case.signals(0), effects=["extra_mode"])
    assert rep.verdict == "extra_mode", rep.summary()
    c = rep.candidates[0]
    assert c.where["dof"] == "m3" and c.parameters["frequency_hz"] == pytest.approx(47.16, rel=0.005)
    assert {x.where["dof"] for x in rep.candidates if x.effect == "extra_mode"} >= {"m2", "m3"}


def test_an_extra_mode_at_the_residuals_strongest_peak_is_polished_though_a_spike_fits_the_frf_better():
    """Fresh seed 7363 case 002 (``--level-blocks --band-edge 200 --duration 30 --forms other
    --integrator rk4``): an absorber of 9 % of m1's mass at 11.17 Hz, damping ratio 0.0204. Its
    FRF fit from the residual's strongest peak (11.3 Hz) lands on it (11.11 Hz, 9.3 %, 0.0207), but a
    spike at 130.6 Hz pressed against the damping bound fits the FRF's noisy lines better (cost 878
    against 915) at the same DOF, and only that one was polished in time: ``parameter_mismatch``.
    Polished too, the absorber wins on the held-out data."""
    from vibroscope.gap import diagnose

    multi = gen.multi_log_drawn(7363, "extra_mode", 0, 0.25)
    case = gen.make_case("extra_mode", gen.case_rng(7363, "extra_mode", 0), 30.0, integrator="rk4",
                         multi_log=multi, forms="other", band_edge=200.0, level_blocks=True)
    t = case.truth
    assert t["where"]["dof"] == "m1" and t["where"]["frequency_hz"] == pytest.approx(11.17, rel=0.01)
    rep = diagnose(case.nominal, case.signals(0))
    assert rep.verdict == "extra_mode", rep.summary()
    c = rep.candidates[0]
    assert c.where["dof"] == "m1" and c.parameters["frequency_hz"] == pytest.approx(11.17, rel=0.02)


@pytest.mark.slow  # one 60 s modal case generated (LSODA truth) and diagnosed for the joint, ~20-40 s
def test_a_modal_joint_slipping_through_the_whole_record_is_started_at_the_stiffness_it_took():
    """Fresh modal seed 7322's first joint case (case 010 of ``--kind modal --per-class 2``): a
    joint of 44 % of the m1-ground connection's stiffness whose slip displacement is 1/50 of its
    RMS deflection, so it slips through the whole record: to its BLA, that stiffness lost. The
    joint's valley in its share is narrow (shares 0.3 and 0.6 leave 0.73 and 0.66 held out, 0.44
    leaves 0.07), and no fixed start reached it: ``unexplained``, the linear refit at 3.2 x the
    floor. The stiffness a physical change at each connection alone takes out to fit the FRF
    (:func:`~vibroscope.gap._evidence.stiffness_lost`) starts the joint there."""
    from vibroscope.gap import diagnose
    from vibroscope.models.modelfile import loads_model

    effect = "modal_joint_friction"
    case = gen.make_case(effect, gen.case_rng(7322, effect, 0), 60.0, integrator=gen.INTEGRATORS[0],
                         multi_log=gen.multi_log_drawn(7322, effect, 0, 0.25))
    assert case.truth["where"] == {"between": ["m1", "ground"]}
    assert case.truth["details"]["rms_deflection_over_largest_slip_displacement"] > 40
    nominal = loads_model(case.nominal_text, "nominal.toml")
    rep = diagnose(nominal, case.signals_list(), effects=["joint_friction"])
    assert list(rep.verdicts) == ["joint_friction"], rep.summary()
    assert rep.candidates[0].where["between"] == ["m1", "ground"], rep.summary()
    assert rep.gap_after < 1.1 * rep.noise_floor, rep.summary()


@pytest.mark.slow  # one 30 s modal case generated (RK4 truth) and diagnosed, ~30-45 s
def test_an_asymmetric_friction_significant_over_its_coulomb_member_keeps_the_verdict_after_the_polish():
    """Fresh modal seed 7326's asymmetric-friction case (case 009 of ``--kind modal --per-class
    1 --forms other --dofs 2 3 --multi-log 0.5 --duration 30``): 0.34 N forward, 1.10 N back at
    m2-ground. Its held-out gain over Coulomb friction there is significant (t 7.4 > NESTED_T), so
    it is ranked first; both reach the floor once polished and the complexity penalty put the
    Coulomb rival ahead: named ``coulomb_friction`` on bdbd349. The polished best keeps its place
    before a simpler member of its family while its gain over it stays significant."""
    from vibroscope.gap import diagnose
    from vibroscope.gap._run import NESTED_T
    from vibroscope.models.modelfile import loads_model

    effect = "modal_asymmetric_friction"
    case = gen.make_case(effect, gen.case_rng(7326, effect, 0), 30.0, integrator=gen.INTEGRATORS[1],
                         multi_log=gen.multi_log_drawn(7326, effect, 0, 0.5), forms="other", dofs=(2, 3))
    assert case.truth["where"] == {"between": ["m2", "ground"]}
    fp, fn = case.truth["parameters"]["Fp_N"], case.truth["parameters"]["Fn_N"]
    assert fn > 3 * fp
    rep = diagnose(loads_model(case.nominal_text, "nominal.toml"), case.signals_list(),
                   effects=["coulomb_friction", "asymmetric_friction"])
    assert list(rep.verdicts) == ["asymmetric_friction"], rep.summary()
    c = rep.candidates[0]
    assert c.where["between"] == ["m2", "ground"], rep.summary()
    assert c.parameters["Fc_neg_N"] == pytest.approx(fn, rel=0.1) and c.parameters["Fc_pos_N"] == pytest.approx(fp, rel=0.2)
    t = {k: v for k, v in rep.meta["nested_tests"]["t"].items() if k.endswith("after the polish")}
    assert t and max(t.values()) > NESTED_T, rep.meta["nested_tests"]


@pytest.mark.slow  # one 60 s case generated (RK4 truth) and diagnosed, ~10-20 s
def test_a_smooth_saturation_near_the_peak_is_screened_under_its_own_law():
    """Fresh seed 7367 case 008 (``--per-class 1 --integrator rk4 --forms other --input-kind sweep
    --multi-log 0.0 --band-edge 480``): an actuator ``3.56 tanh(u / 3.56)`` whose limit is the
    input's peak, under one log of three stepped sweeps. It takes 24 % off the top level's peaks
    and 6 % off the middle level's; a clip, the law the screening fitted (the smooth law was
    tried only on a clip already chosen), bites only the top level's peaks: at 3.40 N it left
    0.159 held out and changed the held-out outputs by less than the noise floor, so it vanished
    and the case was ``unexplained`` (the true model leaves 0.029). The smooth law is now screened
    as a variant of its own: saturation, limit within 3 %, at the floor."""
    from vibroscope.gap import diagnose

    multi = gen.multi_log_drawn(7367, "saturation", 0, 0.0)
    assert not multi
    case = gen.make_case("saturation", gen.case_rng(7367, "saturation", 0), 60.0, integrator="rk4",
                         multi_log=multi, forms="other", input_kind="sweep", band_edge=480.0)
    t = case.truth
    assert t["parameters"]["limit_N"] == pytest.approx(3.55917, rel=TRUTH_REL)
    rep = diagnose(case.nominal, case.signals(0))
    assert list(rep.verdicts) == ["saturation"], rep.summary()
    c = rep.candidates[0]
    assert c.effect == "saturation" and c.where.get("law") == "limit tanh(u / limit)", rep.summary()
    assert c.parameters["limit_N"] == pytest.approx(t["parameters"]["limit_N"], rel=0.03)
    assert rep.gap_after < 1.2 * rep.noise_floor, rep.summary()
