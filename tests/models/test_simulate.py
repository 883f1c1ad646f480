"""Time simulation against truth: closed-form SDOF responses, the analytic FRF (H1 from
scipy.signal.csd/welch), eigenfrequencies in the PSD, and the integrator's convergence order."""

import numpy as np
import pytest
from scipy import integrate, signal

from vibroscope.models.elements import BoucWen, CubicSpring, Damper, Spring
from vibroscope.models.excitation import band_limited_random, multisine
from vibroscope.models.integrate import integrate as integrate_model
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output, demo_model
from vibroscope.models._reference_integrator import _Integrator
from vibroscope.models.simulate import decimate_fir, decimate_sharp, simulate, simulate_periodic, upsample


def sdof(m=1.0, k=4e4, c=8.0, quantity="displacement", **kw):
    return LumpedModel.chain([m], [k], [c], output_quantity=quantity, **kw)


@pytest.mark.parametrize("oversample", [1, 8])
def test_step_response_closed_form(oversample):
    # constant force F from t = 0: x = F/k (1 - e^{-zeta wn t} (cos wd t + zeta/sqrt(1-zeta^2) sin wd t))
    m, k, c, F, fs = 1.0, 4e4, 8.0, 3.0, 1000.0
    model = sdof(m, k, c)
    s = simulate(model, np.full(3000, F), fs, oversample=oversample, upsampling="linear")
    t = s.time
    wn = np.sqrt(k / m)
    z = c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - z * z)
    x = F / k * (1 - np.exp(-z * wn * t) * (np.cos(wd * t) + z / np.sqrt(1 - z * z) * np.sin(wd * t)))
    np.testing.assert_allclose(s.data[1], x, atol=1e-12 * F / k * 1e3)
    assert s.channels == ("/actuator/force.wrench.force.x", "/imu/m1.displacement.x")
    assert s.units == ("N", "m")


def test_ramp_is_exact_with_foh_and_no_delay():
    # u = a t (linear between samples: FOH is exact); x = a/k (t - 2 zeta/wn) + transient
    m, k, c, a, fs = 1.0, 4e4, 8.0, 50.0, 200.0
    model = sdof(m, k, c)
    n = 400
    t = np.arange(n) / fs
    s = simulate(model, a * t, fs, oversample=1)
    ref = integrate.solve_ivp(
        lambda tt, q: [q[1], (a * tt - c * q[1] - k * q[0]) / m], (0, t[-1]), [0, 0], t_eval=t,
        method="DOP853", rtol=1e-12, atol=1e-16,
    ).y[0]
    np.testing.assert_allclose(s.data[1], ref, atol=1e-9 * np.max(np.abs(ref)))


def test_sine_steady_state_matches_frf_amplitude_and_phase():
    model = demo_model()
    fs, f0 = 1000.0, 123.0
    n = 20000
    t = np.arange(n) / fs
    u = np.sin(2 * np.pi * f0 * t)
    s = simulate(model, u, fs)
    H = model.frf([f0])[0, :, 0]
    expected = np.imag(H[:, None] * np.exp(2j * np.pi * f0 * t)[None])
    tail = slice(n // 2, n - 200)
    np.testing.assert_allclose(s.data[1:, tail], expected[:, tail], atol=2e-3 * np.abs(H).max())


def test_h1_from_simulation_matches_analytic_frf():
    model = demo_model()
    fs, nps = 500.0, 4096
    u = band_limited_random(fs, 200_000, fmin=1, fmax=200, rms=10, seed=0)
    s = simulate(model, u, fs)
    f, Pxx = signal.welch(u, fs, nperseg=nps)
    _, Pxy = signal.csd(u, s.data[1:], fs, nperseg=nps)
    _, coh = signal.coherence(u, s.data[1:], fs, nperseg=nps)
    H1 = Pxy / Pxx
    H = model.frf(f)[:, :, 0].T
    ok = (coh > 0.999) & (f > 2) & (f < 200)
    assert ok.sum() > 0.6 * ok.size * 198 / 250
    err = np.abs(H1[ok] / H[ok] - 1)
    assert err.max() < 0.01, err.max()
    # PSD peaks of the response of a lightly damped model at its eigenfrequencies, within one bin
    light = LumpedModel.chain([2.0, 1.5, 1.0], [1e5, 8e4, 5e4], 2.0, input_dof=2)
    model = light
    _, Pyy = signal.welch(simulate(light, u, fs).data[1:], fs, nperseg=nps)
    df = f[1] - f[0]
    for fn in model.modes().natural_frequencies:
        band = (f > fn - 3) & (f < fn + 3)
        peaks = f[band][np.argmax(Pyy[:, band], axis=1)]
        assert np.any(np.abs(peaks - fn) <= df), (fn, peaks)


def test_periodic_linear_equals_frf_on_multisine_lines():
    model = demo_model()
    fs, n = 500.0, 4096
    u, k = multisine(fs, n, fmin=2, fmax=150, rms=5, seed=1)
    s = simulate_periodic(model, u, fs, n_periods=8)
    Y = np.fft.rfft(s.data[1:], axis=1)[:, k]
    U = np.fft.rfft(u)[k]
    H = model.frf(k * fs / n)[:, :, 0].T
    np.testing.assert_allclose(Y / U, H, rtol=2e-4)


def test_input_delay_and_saturation():
    base = demo_model()
    fs = 1000.0
    u = band_limited_random(fs, 5000, fmin=1, fmax=100, rms=10, seed=2)
    u[0] = 0.0  # so that the delayed input (zero before its start) is an exact shift
    delayed = base.replace(inputs=(Input(dof="m3", channel="/actuator/force.wrench.force.x", delay=0.01),))
    # linear reconstruction: a 10-sample delay is then an exact shift
    s0 = simulate(base, u, fs, upsampling="linear")
    s1 = simulate(delayed, u, fs, upsampling="linear")
    np.testing.assert_allclose(s1.data[:, 10:], s0.data[:, :-10], atol=1e-9 * np.abs(s0.data).max())
    sat = base.replace(inputs=(Input(dof="m3", channel="/actuator/force.wrench.force.x", saturation=5.0),))
    s2 = simulate(sat, u, fs)
    assert np.abs(s2.data[0]).max() == pytest.approx(5.0)
    # the actuator clips the continuous (reconstructed) force, not the samples: close to, but not
    # the same as, clipping the logged samples (exact fine-grid check in test_integrate.py)
    y_sat, y_samples = s2.data[1:], simulate(base, np.clip(u, -5, 5), fs).data[1:]
    rel = np.sqrt(np.sum((y_sat - y_samples) ** 2) / np.sum(y_samples**2))
    assert 1e-4 < rel < 0.1
    assert np.std(y_sat) < np.std(simulate(base, u, fs).data[1:])


def test_noise_is_relative_to_rms_and_seeded():
    model = demo_model()
    u = band_limited_random(1000.0, 20000, fmin=1, fmax=100, rms=10, seed=2)
    clean = simulate(model, u, 1000.0)
    noisy = simulate(model, u, 1000.0, noise=0.1, seed=4)
    d = noisy.data[1:] - clean.data[1:]
    rms = np.sqrt(np.mean(clean.data[1:] ** 2, axis=1))
    np.testing.assert_allclose(np.std(d, axis=1), 0.1 * rms, rtol=0.05)
    np.testing.assert_array_equal(noisy.data, simulate(model, u, 1000.0, noise=0.1, seed=4).data)
    np.testing.assert_array_equal(noisy.data[0], clean.data[0])


def test_nonlinear_path_on_linear_model_agrees_with_exact():
    # a cubic spring with k3 = 0 forces the nonlinear integrator on a linear system
    lin = LumpedModel(
        dofs=(Dof("m1", 1.0),),
        elements=(Spring(("m1", "ground"), k=4e4), Damper(("m1", "ground"), c=8.0)),
        inputs=(Input(dof="m1"),),
        outputs=(Output("m1", "acceleration"), Output("m1", "displacement")),
    )
    m = lin.replace(elements=lin.elements + (CubicSpring(("m1", "ground"), k3=0.0),))
    fs = 1000.0
    u = band_limited_random(fs, 4000, fmin=1, fmax=150, rms=10, seed=5)
    exact = simulate(lin, u, fs, method="linear").data[1:]
    nl = simulate(m, u, fs, method="nonlinear", oversample=20).data[1:]
    # taken at the instants (no anti-aliasing filter): a band-limited response is the same, up to
    # the filter's edge effects (the whole record)
    nl_point = simulate(m, u, fs, method="nonlinear", oversample=20, output_sampling="point")
    assert nl_point.meta["output_sampling"] == "point"
    inner = slice(50, -50)
    for i in range(2):
        err = np.sqrt(np.mean((nl[i, inner] - exact[i, inner]) ** 2)) / np.sqrt(np.mean(exact[i] ** 2))
        assert err < 2e-3, err
        err = np.sqrt(np.mean((nl_point.data[1 + i] - exact[i]) ** 2)) / np.sqrt(np.mean(exact[i] ** 2))
        assert err < 2e-3, err


def _duffing_reference(model, t_grid, uf):
    m = model.dofs[0].mass
    k, c = model.K[0, 0], model.C[0, 0]
    el = model.nonlinear_elements[0]

    def rhs(t, q):
        return [q[1], (uf(t) - k * q[0] - c * q[1] - el.force(q[0], q[1], None)) / m]

    return integrate.solve_ivp(rhs, (0, t_grid[-1]), [0, 0], t_eval=t_grid, method="DOP853", rtol=1e-12, atol=1e-15).y


def _zero_cubic(ends=("m1", "ground")):
    """A nonlinear element that adds no force: with it, the reference integrator takes its
    general (several-element) path on what is physically the same model."""
    return CubicSpring(ends, k3=0.0)


def _fine_states(integrator, model, U, dt):
    """States q (2n, N) of `model` under the fine-grid input `U`: the compiled kernel
    (vibroscope.models.integrate.integrate) or the pure-Python reference."""
    if integrator == "compiled":
        return integrate_model(model, U, dt, store_states=True).q
    ref = _Integrator(model, dt)
    Q, _ = ref.run(U)
    assert ref.newton_failures == 0
    return Q


def _two_tone(t):
    return 30 * np.sin(2 * np.pi * 25 * t) + 20 * np.sin(2 * np.pi * 47 * t)


def _errors_against_dop853(integrator, model, T=0.4):
    """The DOP853 solution of `model` under :func:`_two_tone` on 41 points of ``[0, T]`` and the
    max error of the trapezoidal solution there at 100, 200 and 400 steps per interval."""
    t_ref = np.linspace(0, T, 41)
    ref = _duffing_reference(model, t_ref, _two_tone)[0]
    errs = []
    for nsub in (100, 200, 400):
        n = 40 * nsub + 1
        t = np.linspace(0, T, n)
        Q = _fine_states(integrator, model, _two_tone(t)[None], T / (n - 1))
        errs.append(np.max(np.abs(Q[0, ::nsub] - ref)))
    return ref, np.array(errs)


@pytest.mark.parametrize("integrator", ["compiled", "reference"])
def test_trapezoidal_converges_with_second_order(integrator):
    """Error vs step size of the nonlinear integrator on a hardening Duffing oscillator with a
    smooth input: halving the step divides the error by 4 (order 2, Newmark 1959)."""
    ref, errs = _errors_against_dop853(integrator, _sdof_with(CubicSpring(("m1", "ground"), k3=4e9)))
    assert np.max(np.abs(ref)) > 2e-3  # cubic force 4e9 x^3 ~ 30 N: strongly nonlinear
    np.testing.assert_allclose(errs[:-1] / errs[1:], 4.0, rtol=0.1)


@pytest.mark.parametrize("integrator", ["compiled", "reference"])
def test_a_quintic_spring_term_converges_to_the_ode_solution(integrator):
    """The cubic spring's quintic term ``k5 d^5`` (force and tangent stiffness in the kernel):
    the trapezoidal solution converges with order 2 to a DOP853 solution of the same ODE, and
    differs from the model without it by far more than its own error."""
    ref, errs = _errors_against_dop853(integrator, _sdof_with(CubicSpring(("m1", "ground"), k3=1e9, k5=1e15)))
    assert 1e15 * np.max(np.abs(ref)) ** 5 > 5.0  # the quintic force, N: a strong term
    np.testing.assert_allclose(errs[:-1] / errs[1:], 4.0, rtol=0.1)
    without = _duffing_reference(_sdof_with(CubicSpring(("m1", "ground"), k3=1e9)), np.linspace(0, 0.4, 41),
                                 _two_tone)[0]
    assert np.max(np.abs(without - ref)) > 100 * errs[-1]


def test_bouc_wen_converges_and_the_integrators_agree():
    """The non-smooth Bouc-Wen element (|v|, |z|): the error against a 4x finer step still falls
    about 4x per halving, and the compiled kernel and both paths of the reference integrator
    (one element; several elements) give the same answer."""
    model = LumpedModel(
        dofs=(Dof("m", 2.0),),
        elements=(Spring(("m", "ground"), k=5e4), Damper(("m", "ground"), c=10.0), BoucWen(("m", "ground"))),
        inputs=(Input(dof="m"),),
        outputs=(Output("m", "displacement"),),
    )
    T = 0.5
    uf = lambda t: 60 * np.sin(2 * np.pi * 20 * t) + 40 * np.sin(2 * np.pi * 33 * t)  # noqa: E731
    sols = {}
    for nsub in (25, 50, 100, 400):
        n = 40 * nsub + 1
        t = np.linspace(0, T, n)
        sols[nsub] = _fine_states("compiled", model, uf(t)[None], T / (n - 1))[0, ::nsub]
    ref = sols[400]
    e = [np.max(np.abs(sols[s] - ref)) for s in (25, 50, 100)]
    assert e[0] / e[1] > 3.0 and e[1] / e[2] > 3.0, e
    n = 40 * 25 + 1
    t = np.linspace(0, T, n)
    U, dt = uf(t)[None], T / (n - 1)
    one = _fine_states("reference", model, U, dt)
    several = _fine_states("reference", model.replace(elements=model.elements + (_zero_cubic(("m", "ground")),)), U, dt)
    tol = 1e-12 * np.abs(ref).max() + 1e-14
    np.testing.assert_allclose(one[0, ::25], sols[25], atol=tol)
    np.testing.assert_allclose(several[0, ::25], sols[25], atol=tol)


def test_upsample_and_decimate_roundtrip():
    fs, n = 100.0, 1000
    t = np.arange(n) / fs
    x = np.sin(2 * np.pi * 3 * t) + 0.5 * np.cos(2 * np.pi * 11 * t)
    for method in ("fft", "poly"):
        up = upsample(x, 5, method=method, periodic=True)
        assert up.shape == (5000,)
        tf = np.arange(5000) / 500.0
        xf = np.sin(2 * np.pi * 3 * tf) + 0.5 * np.cos(2 * np.pi * 11 * tf)
        tol = 1e-12 if method == "fft" else 1e-4
        np.testing.assert_allclose(up, xf, atol=tol)
        np.testing.assert_allclose(up[::5], x, atol=tol)
    y = decimate_fir(xf, 20 // 4, periodic=True)
    np.testing.assert_allclose(y, x, atol=1e-3)
    y2 = decimate_fir(xf, 5)
    assert y2.shape == (1000,)
    np.testing.assert_allclose(y2[20:-20], x[20:-20], atol=1e-3)


@pytest.mark.parametrize("periodic", [False, True])
def test_decimate_sharp_is_flat_in_band_and_removes_what_would_alias(periodic):
    """A tone at 0.44 fs comes through at the sample instants within 1e-4 (decimate_fir loses
    a third of it); a tone at 0.6 fs, which would alias to 0.4 fs, is gone (below 1e-4)."""
    fs, R, n = 500.0, 10, 4000
    i = np.arange(n * R)
    for f_rel, keep in ((0.44, True), (0.6, False)):
        cycles = round(f_rel * n)  # whole cycles per record: exact for the periodic filter
        x = np.sin(2 * np.pi * cycles * i / (n * R))
        y = decimate_sharp(x, R, periodic=periodic)
        assert y.shape == (n,)
        mid = slice(None) if periodic else slice(100, -100)
        if keep:
            np.testing.assert_allclose(y[mid], x[::R][mid], atol=1e-4)
            assert np.abs(decimate_fir(x, R, periodic=periodic)[mid]).max() < 0.7
        else:
            assert np.abs(y[mid]).max() < 1e-4
    # a ramp survives the ends (point reflection), a constant exactly
    np.testing.assert_allclose(decimate_sharp(np.linspace(0.0, 1.0, 2000), 4), np.linspace(0.0, 1.0, 2000)[::4], atol=1e-9)
    with pytest.raises(ValueError, match="factor"):
        decimate_sharp(x, 0)
    with pytest.raises(ValueError, match="divisible"):
        decimate_sharp(np.zeros(101), 4, periodic=True)


def test_bad_arguments():
    m = demo_model()
    with pytest.raises(ValueError, match="shape"):
        simulate(m, np.zeros((2, 100)), 100.0)
    with pytest.raises(ValueError, match="fs"):
        simulate(m, np.zeros(100), 0.0)
    with pytest.raises(ValueError, match="method"):
        simulate(m, np.zeros(100), 100.0, method="magic")
    with pytest.raises(ValueError, match="output_sampling"):
        simulate(m, np.zeros(100), 100.0, output_sampling="nearest")


def _sdof_with(element, k=4e4, c=8.0):
    return LumpedModel(
        dofs=(Dof("m1", 1.0),),
        elements=(Spring(("m1", "ground"), k=k), Damper(("m1", "ground"), c=c), element),
        inputs=(Input(dof="m1"),),
        outputs=(Output("m1", "displacement"),),
    )


def test_backlash_with_large_gap_is_linear_and_friction_dissipates():
    from vibroscope.models.elements import Backlash, Friction

    fs = 1000.0
    u = band_limited_random(fs, 2000, fmin=1, fmax=100, rms=5, seed=8)
    lin = simulate(LumpedModel.chain([1.0], [4e4], [8.0], output_quantity="displacement"), u, fs, upsampling="poly").data[1]
    gap = 10 * np.abs(lin).max()
    bl = simulate(_sdof_with(Backlash(("m1", "ground"), k=1e6, gap=gap)), u, fs).data[1]
    assert np.sqrt(np.mean((bl - lin) ** 2)) < 2e-3 * np.sqrt(np.mean(lin**2))
    tight = simulate(_sdof_with(Backlash(("m1", "ground"), k=1e6, gap=0.1 * np.abs(lin).max())), u, fs).data[1]
    assert np.sqrt(np.mean(tight**2)) < 0.5 * np.sqrt(np.mean(lin**2))  # stiffened
    fr = simulate(_sdof_with(Friction(("m1", "ground"), force_=2.0, v_eps=1e-3)), u, fs).data[1]
    assert np.sqrt(np.mean(fr**2)) < np.sqrt(np.mean(lin**2))


def test_mr_damper_general_kernel_runs_and_damps():
    from vibroscope.models.elements import MRDamper

    fs = 1000.0
    u = band_limited_random(fs, 500, fmin=1, fmax=100, rms=50, seed=9)
    lin = simulate(LumpedModel.chain([1.0], [4e4], [8.0], output_quantity="displacement"), u, fs).data[1]
    y0 = simulate(_sdof_with(MRDamper(("m1", "ground"), current=0.0)), u, fs).data[1]
    y1 = simulate(_sdof_with(MRDamper(("m1", "ground"), current=2.0)), u, fs).data[1]
    assert np.all(np.isfinite(y1))
    r = lambda x: np.sqrt(np.mean(x**2))  # noqa: E731
    assert r(y1) < r(y0) < r(lin)  # more current, more damping


def test_mr_damper_element_matches_mr_damper_module():
    """The element's eq.-5 force and state derivatives equal vibroscope.instruments.mr_damper's."""
    mr = pytest.importorskip("vibroscope.instruments.mr_damper")
    from vibroscope.models.elements import MRDamper

    coeffs = mr.MRDamperParams.spencer1997().at_current(1.0)
    el = MRDamper.from_coefficients(("m1", "ground"), coeffs)
    rng = np.random.default_rng(0)
    for x, v, y, z in rng.normal(scale=[0.01, 0.1, 0.01, 0.005], size=(20, 4)):
        ydot, zdot = mr.mr_damper_rhs((y, z), x, v, coeffs)
        np.testing.assert_allclose(el.state_derivative(x, v, (z, y)), [zdot, ydot], rtol=1e-12)
        f_ref = mr.mr_damper_force(x, v, y, z, coeffs) + coeffs.k1 * coeffs.x0  # element drops the preload
        assert el.force(x, v, (z, y)) == pytest.approx(f_ref, rel=1e-12)


def test_integrators_agree_on_multi_dof():
    """Two DOFs and one nonlinear element: the compiled kernel, the reference integrator (its
    single-element path, numpy state update for n > 1) and the reference's general path (the
    same model with a force-free second element) agree."""
    model = LumpedModel.chain([1.0, 0.5], [4e4, 2e4], [8.0, 3.0], nonlinear=(CubicSpring(("m2", "m1"), k3=5e9),))
    n = 4001
    t = np.linspace(0, 0.4, n)
    U = (30 * np.sin(2 * np.pi * 25 * t) + 20 * np.sin(2 * np.pi * 61 * t))[None]
    res = integrate_model(model, U, t[1], store_states=True)
    ref = _Integrator(model, t[1])
    Qs, Gs = ref.run(U)
    gen = _Integrator(model.replace(elements=model.elements + (_zero_cubic(("m2", "m1")),)), t[1])
    Qg, Gg = gen.run(U)
    assert ref.newton_failures == gen.newton_failures == res.newton_failures == 0
    for a, b, c in zip(Qs, Qg, res.q):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9 * np.abs(a).max())
        np.testing.assert_allclose(c, a, rtol=0, atol=1e-9 * np.abs(a).max())
    np.testing.assert_allclose(Gg[:1], Gs, rtol=0, atol=1e-9 * np.abs(Gs).max())
    np.testing.assert_array_equal(Gg[1], 0.0)
    np.testing.assert_allclose(res.g, Gs, rtol=0, atol=1e-9 * np.abs(Gs).max())


def test_models_simulate_is_always_the_module():
    """``vibroscope.models.simulate`` means one thing: the module, before and after anything imports
    from it (the function is ``vibroscope.models.simulate.simulate``, also ``vibroscope.simulate``)."""
    import subprocess
    import sys

    code = (
        "import types, vibroscope, vibroscope.models as m\n"
        "first = m.simulate\n"
        "from vibroscope.models.simulate import simulate, upsample\n"
        "import vibroscope.models.simulate as by_import\n"
        "assert isinstance(first, types.ModuleType), first\n"
        "assert first is m.simulate is by_import, (first, m.simulate)\n"
        "assert m.simulate.simulate is simulate is vibroscope.simulate\n"
        "from vibroscope.models import simulate as again\n"
        "assert again is first\n"
        "assert m.simulate_periodic is m.simulate.simulate_periodic  # other lazy names unchanged\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_reference_integrator_reports_newton_failures():
    """The pure-Python reference counts and warns about steps whose Newton iteration did not
    converge, as the compiled kernel does: near-Coulomb friction (v_eps = 1 nm/s) with a step
    far too large for it; and none with a smooth element."""
    from vibroscope.models.elements import Friction

    model = _sdof_with(Friction(("m1", "ground"), force_=20.0, v_eps=1e-9))
    U = (50 * np.sin(2 * np.pi * 30 * np.arange(400) * 1e-3))[None]
    kernel = integrate_model(model, U, 1e-2, warn=False)
    assert kernel.newton_failures > 100
    ref = _Integrator(model, 1e-2)
    with pytest.warns(RuntimeWarning, match="did not converge at [0-9]+ of 399 integration steps"):
        ref.run(U)
    assert ref.newton_failures > 100
    smooth = _Integrator(_sdof_with(CubicSpring(("m1", "ground"), k3=4e9)), 1e-3)
    smooth.run(U)
    assert smooth.newton_failures == 0
