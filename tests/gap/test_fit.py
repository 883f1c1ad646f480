"""The time-domain fit of the gap diagnosis: the parallel Jacobian changes nothing."""

import numpy as np
import pytest
from scipy import signal

from vibroscope.gap.fit import LogSimulator, fit_time_domain
from vibroscope.models.elements import CubicSpring, Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

FS = 1000.0


def _model(k3: float) -> LumpedModel:
    return LumpedModel(
        dofs=(Dof("m1", 1.0), Dof("m2", 0.5)),
        elements=(Spring(("m1", "ground"), k=4e4), Damper(("m1", "ground"), c=8.0),
                  CubicSpring(("m2", "m1"), k=3e4, k3=k3), Damper(("m2", "m1"), c=4.0)),
        inputs=(Input(dof="m1", channel="f"),),
        outputs=(Output("m1", "acceleration", "a1"), Output("m2", "acceleration", "a2")),
    )


def test_two_parameters_in_two_threads_match_one_thread():
    rng = np.random.default_rng(4)
    u = rng.standard_normal((1, 2000)) * 30
    sim = LogSimulator(u, FS)
    y = sim.run(_model(2e9), fast=True)
    mask = np.ones(u.shape[1], bool)

    def build(p):
        m = _model(float(p[0]) * 1e9)
        els = list(m.elements)
        els[1] = Damper(("m1", "ground"), c=8.0 * float(p[1]))
        return LumpedModel(dofs=m.dofs, elements=tuple(els), inputs=m.inputs, outputs=m.outputs)

    x0, lo, hi = np.array([0.5, 1.5]), np.array([0.0, 0.1]), np.array([10.0, 10.0])
    r1 = fit_time_domain(build, x0, lo, hi, [sim], [y], [mask], [2000], max_nfev=6, jac_workers=1)
    r2 = fit_time_domain(build, x0, lo, hi, [sim], [y], [mask], [2000], max_nfev=6, jac_workers=2)
    np.testing.assert_array_equal(r1[0], r2[0])
    assert r1[1] == r2[1] and r1[2] == r2[2]  # same nrmse, same number of simulations
    g0 = float(np.sqrt(np.mean((sim.run(build(x0), fast=True) - y) ** 2, axis=1).sum()
                       / np.sum(np.mean(y**2, axis=1)) / 2) * np.sqrt(2))
    assert r1[1] < 0.5 * g0  # and it moved towards the truth (2, 1)


def _fd_jacobian(fun, x, h=1e-6):
    """Central differences of `fun` (the oracle of the analytic Jacobian)."""
    f0 = fun(x)
    J = np.empty((f0.size, x.size))
    for i in range(x.size):
        step = h * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += step
        xm[i] -= step
        J[:, i] = (fun(xp) - fun(xm)) / (2 * step)
    return J


def test_the_frf_fit_jacobian_agrees_with_central_differences():
    """The analytic Jacobian of the FRF fit (through the model's matrices) against central
    differences of the residual, for the linear log-factors with an input delay, with an extra
    mode (its mass follows the DOF's), and for a modal-coordinates model's physical stiffness and
    damping changes (which move the mode shapes' coupling)."""
    from vibroscope.gap.effects import LinearParams, candidate_specs
    from vibroscope.gap.fit import frf_residual, frf_residual_jacobian
    from vibroscope.gap.physical import as_lumped
    from vibroscope.models.modelfile import dumps_model, loads_model

    rng = np.random.default_rng(7)
    base = LumpedModel.chain([2.0, 1.5, 1.0], [1e5, 8e4, 5e4], [20.0, 10.0, 5.0], input_dof=0)
    base = base.replace(outputs=(Output("m1", "acceleration", "a1"), Output("m2", "velocity", "v2"),
                                 Output("m3", "displacement", "x3")))
    f = np.linspace(2.0, 150.0, 120)
    H = base.frf(f, quantity=None)[:, :, 0] * (1 + 0.05 * rng.standard_normal((f.size, 3)))
    w = rng.uniform(0.5, 1.0, (f.size, 3))
    lin = LinearParams(base)
    specs = [s for s in candidate_specs(base, {"fs": FS, "f_extra": [40.0]}, ["time_delay", "extra_mode"])
             if s.effect == "time_delay" or s.where.get("dof") == "m2"]
    cases = []
    for s in specs:
        def build(x, s=s):
            return s.apply(lin.apply(base, x[:len(lin)]), x[len(lin):])
        x = np.concatenate([0.3 * rng.standard_normal(len(lin)), np.asarray(s.starts[0], float)])
        if s.effect == "time_delay":
            x[-1] = 0.003
        cases.append((s.effect, build, x))
    # a modal-coordinates model with the physical changes (dk:, dc:)
    from tests.gap.test_modal_models import chain, exact_modal  # noqa: E402 - the same truth

    mm = as_lumped(loads_model(dumps_model(exact_modal(chain())), "chain_modal.toml"))
    lp = LinearParams(mm, physical=True)
    Hm = mm.frf(f, quantity=None)[:, :, 0] * (1 + 0.05 * rng.standard_normal((f.size, len(mm.outputs))))
    wm = np.ones((f.size, len(mm.outputs)))
    cases.append(("modal", lambda x: lp.apply(mm, x), 0.2 * rng.standard_normal(len(lp))))
    seen = set()
    for name, build, x in cases:
        HH, ww = (Hm, wm) if name == "modal" else (H, w)
        Ja = frf_residual_jacobian(build, x, f, HH, ww)
        Jn = _fd_jacobian(lambda z: frf_residual(build(z), f, HH, ww), x)
        err = np.max(np.abs(Ja - Jn), axis=0) / np.maximum(np.max(np.abs(Jn), axis=0), 1e-12)
        assert np.all(err < 1e-4), (name, err)
        assert np.all(np.max(np.abs(Jn), axis=0) > 0), name  # every column moves the FRF
        seen.add(name)
    assert seen == {"time_delay", "extra_mode", "modal"}


def test_a_lead_in_of_whole_periods_starts_the_simulation_in_periodic_steady_state():
    """A log of a periodic input in steady state from its first sample, of a mode whose time
    constant (1 / (zeta omega_n) = 3.2 s) outlasts the 1 s period: simulated from rest, the
    model's transient is in the log's first periods; with a lead-in of whole periods (the
    input's periodic continuation) the simulation matches the steady state the log holds."""
    from vibroscope.gap.diagnosis import _skip_samples

    m = LumpedModel(dofs=(Dof("m1", 1.0),),
                    elements=(Spring(("m1", "ground"), k=(2 * np.pi * 5.0) ** 2), Damper(("m1", "ground"), c=0.625)),
                    inputs=(Input(dof="m1", channel="f"),), outputs=(Output("m1", "acceleration", "a1"),))
    T = 1000  # one period at 1 kHz
    rng = np.random.default_rng(7)
    period = np.fft.irfft(np.r_[0, np.exp(2j * np.pi * rng.random(40)), np.zeros(T // 2 - 40)], T)[None] * 30
    u = np.tile(period, 12)
    # the truth: 30 periods (over nine time constants) simulated before the log
    y_ss = LogSimulator(u, FS, period=T, lead_periods=30).run(m)
    y_rest = LogSimulator(u, FS).run(m)
    skip, why, lead = _skip_samples(m, FS, u, y_ss, None)
    assert skip == T and lead == 9  # three time constants (9.6 s) less the 1 s period skipped
    assert "start 9 period(s)" in why
    y_lead = LogSimulator(u, FS, period=T, lead_periods=lead).run(m)

    def err(y):
        return float(np.sqrt(np.mean((y - y_ss)[:, skip:] ** 2) / np.mean(y_ss[:, skip:] ** 2)))

    assert err(y_rest) > 0.2  # from rest: the transient past the skipped period
    assert err(y_lead) < 0.1 * err(y_rest)  # three time constants: e^-3 of it left where the log begins
    assert y_lead.shape == u.shape


def test_a_delay_started_periods_of_the_top_line_away_is_found_through_the_frf_profile():
    """The FRF cost of a delay has a valley every period of the highest fitted line. The FRF
    of a 4-DOF chain (modes 30-226 Hz, lines 3.6-446 Hz) with an input delay of 0.678 ms (1.36
    samples at 2 kHz), fitted jointly with the sixteen linear parameters from starts of 7.5 and
    8 ms (the phase slope's wrong start of the blind suite's seed 16 case 003 and the grid's),
    stays in a wrong valley with the linear parameters at their bounds; the profile of the
    cost over the delay with the linear parameters at the nominal (``EffectSpec.profile``)
    gives a start in the right one, and the fit returns the truth."""
    import dataclasses

    from vibroscope.gap.effects import LinearParams, _time_delay
    from vibroscope.gap.fit import fit_linear_frf
    from vibroscope.models.elements import Damper, Spring
    from vibroscope.models.lumped import Dof, Input, LumpedModel, Output

    def link(a, b, k, c):
        return Spring((a, b), k=k), Damper((a, b), c=c)

    m = LumpedModel(
        dofs=(Dof("m3", 1.3319), Dof("m2", 7.4223), Dof("m1", 29.6239), Dof("m4", 5.6189)),
        elements=(*link("m3", "ground", 292171.1, 2.703), *link("m2", "m3", 316220.4, 4.886),
                  *link("m1", "m2", 1047069.1, 72.91), *link("m4", "m1", 620433.9, 29.46),
                  *link("m1", "ground", 1508064.0, 148.3), *link("m1", "m3", 2004593.4, 113.0)),
        inputs=(Input(dof="m2", channel="f"),),
        outputs=(Output("m2", "acceleration", "a2"), Output("m1", "acceleration", "a1"),
                 Output("m4", "acceleration", "a4")))
    f = np.arange(3.6, 446.0, 0.1157)
    tau = 0.000678
    H = dataclasses.replace(m, inputs=(dataclasses.replace(m.inputs[0], delay=tau),)).frf(f, quantity=None)[:, :, 0]
    w = np.ones(H.shape)
    lin = LinearParams(m)
    assert len(lin) == 16
    spec = _time_delay(m, {"fs": 2000.0, "delay0": 0.0075})[0]
    starts = [np.array([0.0075]), np.array([0.008])]
    _, th0, p0, cost0 = fit_linear_frf(m, lin, f, H, w, spec=dataclasses.replace(spec, profile=None), p_starts=starts,
                                       max_nfev=60)
    assert abs(p0[0] - tau) > 1e-3 and cost0 > 100.0  # without the profile: another valley
    _, th, p, cost = fit_linear_frf(m, lin, f, H, w, spec=spec, p_starts=starts, max_nfev=60)
    assert p[0] == pytest.approx(tau, rel=1e-4)
    assert cost < 1e-12 and np.abs(th).max() < 1e-6
