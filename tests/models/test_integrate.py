"""The compiled trapezoidal kernel (vibroscope.models.integrate) against today's pure-Python
integrator (vibroscope.models._reference_integrator) on every element type, and the input
physics of simulate(): delay is a pure time shift, saturation clips the reconstructed
(fine-grid) force, a precomputed fine_input changes nothing."""

import threading
import warnings

import numpy as np
import pytest

from vibroscope.models._reference_integrator import _Integrator, reference_simulate_fine
from vibroscope.models.elements import Backlash, BoucWen, CubicSpring, Friction, MRDamper
from vibroscope.models.excitation import band_limited_random
from vibroscope.models.integrate import flatten_model, integrate
from vibroscope.models.linear_sim import dlsim_modal, foh_equivalent, triangle_hold_compensation
from vibroscope.models.lumped import Input, LumpedModel, demo_model
from vibroscope.models.resample import decimate_fir, decimate_sharp
from vibroscope.models.simulate import default_oversample, reconstruct_input, simulate, upsample

FS = 1000.0
CH = "/actuator/force.wrench.force.x"


def nrmse(a, ref):
    a, ref = np.atleast_2d(a), np.atleast_2d(ref)
    return float(np.max(np.sqrt(np.mean((a - ref) ** 2, axis=1)) / np.sqrt(np.mean(ref**2, axis=1))))


def chain(*nonlinear, quantity="acceleration", **inp):
    """2-DOF chain, modes ~ 22 and 45 Hz, force on m2."""
    m = LumpedModel.chain([1.0, 0.5], [4e4, 2e4], [8.0, 3.0], input_dof=1, output_quantity=quantity,
                          nonlinear=nonlinear)  # fmt: skip
    if inp:
        m = m.replace(inputs=(Input(dof="m2", channel=CH, **inp),))
    return m


def record(seconds, rms=20.0, seed=0, fmax=150.0):
    return band_limited_random(FS, int(seconds * FS), fmin=1, fmax=fmax, rms=rms, seed=seed)


CASES = {
    "cubic_spring": (chain(CubicSpring(("m2", "m1"), k3=5e9)), 30.0),
    "backlash": (chain(Backlash(("m1", "ground"), k=1e5, gap=5e-4)), 30.0),
    "friction": (chain(Friction(("m2", "ground"), force_=3.0, v_eps=1e-3)), 20.0),
    "bouc_wen": (chain(BoucWen(("m1", "ground"), alpha=2e4, beta=1e3)), 40.0),
    "mr_damper": (chain(MRDamper(("m1", "ground"), current=0.5)), 60.0),
    "friction+cubic": (chain(Friction(("m2", "ground"), force_=3.0), CubicSpring(("m2", "m1"), k3=5e9)), 30.0),
}


@pytest.mark.parametrize("name", list(CASES))
def test_kernel_matches_reference_integrator(name):
    """Whole simulate() (kernel) vs today's integrator on the same applied fine-grid input."""
    model, rms = CASES[name]
    seconds = 1.0 if name in ("mr_damper", "friction+cubic") else 2.0
    u = record(seconds, rms=rms, seed=3)
    R = default_oversample(model, FS)
    s = simulate(model, u, FS)
    assert s.meta["simulator"] == "trapezoidal" and s.meta["newton_failures"] == 0
    ref = reference_simulate_fine(model, upsample(u[None], R), FS, R)
    assert nrmse(s.data[1:], ref) <= 1e-3
    # states and nonlinear forces on the fine grid, step by step (same scheme: ~ rounding)
    U = upsample(u[None], R)[:, : 4000]
    res = integrate(model, U, 1.0 / (FS * R), store_states=True)
    Q, G = _Integrator(model, 1.0 / (FS * R)).run(U)
    assert nrmse(res.q, Q) <= 1e-9
    assert nrmse(res.g, G) <= 1e-9
    # the nonlinearity matters: the linear model's response differs
    lin = model.replace(elements=tuple(e for e in model.elements if e.is_linear))
    assert nrmse(simulate(lin, u, FS).data[1:], ref) > 1e-2


def test_several_elements_of_one_type_and_dof_to_dof_ends():
    model = LumpedModel.chain([1.0, 0.8, 0.6], [5e4, 4e4, 3e4], [5.0, 4.0, 3.0], input_dof=2,
                              nonlinear=(CubicSpring(("m2", "m1"), k3=4e9), CubicSpring(("m3", "m2"), k3=2e9),
                                         BoucWen(("m1", "ground"), alpha=1e4)))  # fmt: skip
    fm = flatten_model(model, 1e-4)
    assert fm.ends.tolist() == [[1, 0], [2, 1], [0, -1]] and fm.codes.tolist() == [0, 0, 3]
    assert fm.state_offsets.tolist() == [0, 0, 0, 1]
    u = record(1.0, rms=30.0, seed=4)
    R = default_oversample(model, FS)
    ref = reference_simulate_fine(model, upsample(u[None], R), FS, R)
    assert nrmse(simulate(model, u, FS).data[1:], ref) <= 1e-3


def test_saturation_clips_the_reconstructed_input_nonlinear():
    model = chain(CubicSpring(("m2", "m1"), k3=5e9), saturation=15.0)
    u = record(2.0, rms=20.0, seed=5)
    R = default_oversample(model, FS)
    s = simulate(model, u, FS)
    U = np.clip(upsample(u[None], R), -15.0, 15.0)  # reconstructed, then clipped, by hand
    ref = reference_simulate_fine(model, U, FS, R)
    assert nrmse(s.data[1:], ref) <= 1e-3
    np.testing.assert_array_equal(s.data[0], np.clip(u, -15.0, 15.0))  # logged samples as applied
    # clipping the logged samples instead is a different (wrong) input
    wrong = reference_simulate_fine(model, upsample(np.clip(u, -15, 15)[None], R), FS, R)
    assert nrmse(wrong, ref) > 1e-3


@pytest.mark.parametrize("step", [1, 8])
def test_modal_recursion_matches_scipys_foh_dlsim(step):
    """dlsim_modal (the modal recursion, its block sums as one real matrix product) against
    scipy.signal.dlsim on scipy's own first-order-hold discretisation: two inputs, a 2-DOF
    chain, from rest; every fine sample (step 1) or every 8th (step 8)."""
    from scipy import signal

    rng = np.random.default_rng(3)
    k = np.array([[5e4, -2e4], [-2e4, 3e4]])
    c = np.array([[8.0, -3.0], [-3.0, 5.0]])
    mi = np.diag([1.0, 2.0])  # inverse mass, 1/kg
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-mi @ k, -mi @ c]])
    B = np.vstack([np.zeros((2, 2)), mi])
    C, D = A[2:], B[2:]  # accelerations
    dt, n = 1.0 / 8000.0, 400
    u = rng.standard_normal((2, n * 8))
    disc = foh_equivalent(A, B, C, D, dt)
    sd = signal.cont2discrete((A, B, C, D), dt, method="foh")
    _, y_ref, _ = signal.dlsim((*sd[:4], dt), u.T, x0=-disc[4] @ u[:, 0])
    y_ref = y_ref.T[:, ::step][:, : u.shape[1] // step]
    y = dlsim_modal(*disc, u, D, u[:, ::step], step)
    assert y.shape == y_ref.shape
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-10 * np.abs(y_ref).max())
    # one coarse sample: the initial state's output alone
    y1 = dlsim_modal(*disc, u[:, :step], D, u[:, :1], step)
    np.testing.assert_allclose(y1[:, 0], y_ref[:, 0], rtol=0, atol=1e-10 * np.abs(y_ref).max())


def test_saturation_clips_the_reconstructed_input_linear():
    base = demo_model()
    sat = base.replace(inputs=(Input(dof="m3", channel=CH, saturation=5.0),))
    u = record(3.0, rms=10.0, seed=2, fmax=100.0)
    s = simulate(sat, u, FS, output_sampling="point")
    assert s.meta["simulator"] == "foh-exact"
    # by hand: reconstruct, clip on the fine grid, FOH path, outputs at the sample instants
    R = 8
    U = np.clip(upsample(u[None], R), -5.0, 5.0)
    A, B, C, D = base.state_matrices()
    Ad = foh_equivalent(A, B, C, D, 1.0 / (FS * R))
    y = dlsim_modal(*Ad, triangle_hold_compensation(U), D, U[:, ::R], R)
    np.testing.assert_allclose(s.data[1:], y, rtol=0, atol=1e-12 * np.abs(y).max())
    # filtered / sharp: the fine-grid outputs (feedthrough of the clipped fine force included)
    # brought back as the nonlinear path brings its own
    y_fine = dlsim_modal(*Ad, triangle_hold_compensation(U), D, U, 1)
    for mode, dec in (("filtered", decimate_fir), ("sharp", decimate_sharp)):
        sm = simulate(sat, u, FS, output_sampling=mode)
        assert sm.meta["output_sampling"] == mode
        np.testing.assert_allclose(sm.data[1:], dec(y_fine, R), rtol=0, atol=1e-12 * np.abs(y).max())
        # the kernel on the same saturated linear model agrees (independent discretisation)
        # on every output, the driven DOF's acceleration (D x the clipped force) included
        nl = simulate(sat, u, FS, method="nonlinear", oversample=R, output_sampling=mode, scheme="exponential")
        for k in (1, 2, 3):  # 2e-4 each (the exact linear free response in both)
            assert nrmse(nl.data[k, 50:-50], sm.data[k, 50:-50]) < 1e-3
    # at the instants the clipped force's harmonics above fs/2 alias on the driven DOF only
    nl = simulate(sat, u, FS, method="nonlinear", oversample=R, output_sampling="sharp", scheme="exponential")
    assert nrmse(nl.data[1:3, 50:-50], s.data[1:3, 50:-50]) < 1e-3
    assert nrmse(nl.data[3, 50:-50], s.data[3, 50:-50]) > 5e-3  # 1.2e-2
    # and clipping the logged samples is not the same thing
    assert nrmse(simulate(base, np.clip(u, -5, 5), FS).data[1:], s.data[1:]) > 1e-3


def _tapered(seconds, seed):
    u = record(seconds, rms=10.0, seed=seed, fmax=100.0)
    n = u.size
    w = np.ones(n)
    ramp = np.sin(np.linspace(0, np.pi / 2, 200)) ** 2
    w[:200] = ramp
    w[n // 4 - 200 : n // 4] = ramp[::-1]
    w[n // 4 :] = 0.0  # then silent: the response decays before the end
    return u * w


@pytest.mark.parametrize("method", ["linear", "nonlinear"])
def test_delay_is_a_pure_shift(method):
    base = demo_model()
    u = _tapered(8.0, seed=6)
    s0 = simulate(base, u, FS, method=method)
    # integer number of samples: exact shift of inputs and outputs
    s1 = simulate(base.replace(inputs=(Input(dof="m3", channel=CH, delay=7 / FS),)), u, FS, method=method)
    np.testing.assert_array_equal(s1.data[0, 7:], s0.data[0, :-7])
    assert np.all(s1.data[0, :7] == 0.0)
    # (away from the record's ends, where the reconstruction and decimation filters see the
    # record's edges: the delayed record carries the reconstruction's precursor of u[0:40])
    inner = slice(60, -60)
    np.testing.assert_allclose(s1.data[1:, 7:][:, inner], s0.data[1:, :-7][:, inner], rtol=0,
                               atol=1e-10 * np.abs(s0.data[1:]).max())  # fmt: skip
    # fractional: the band-limited shift of the undelayed response by tau
    tau = 7.4 / FS
    s2 = simulate(base.replace(inputs=(Input(dof="m3", channel=CH, delay=tau),)), u, FS, method=method)
    f = np.fft.rfftfreq(u.size, 1 / FS)
    shifted = np.fft.irfft(np.fft.rfft(s0.data[1:], axis=1) * np.exp(-2j * np.pi * f * tau), u.size, axis=1)
    assert nrmse(s2.data[1:, inner], shifted[:, inner]) < 1e-4
    ushift = np.fft.irfft(np.fft.rfft(u) * np.exp(-2j * np.pi * f * tau), u.size)
    assert nrmse(s2.data[0, inner], ushift[inner]) < 1e-4


def test_delay_with_nonlinear_element_matches_reference():
    model = chain(CubicSpring(("m2", "m1"), k3=5e9), delay=0.005)
    u = record(2.0, rms=30.0, seed=7)
    R = default_oversample(model, FS)
    U = upsample(u[None], R)
    m = int(round(0.005 * FS * R))
    Ud = np.zeros_like(U)
    Ud[:, m:] = U[:, :-m]
    ref = reference_simulate_fine(model, Ud, FS, R)
    assert nrmse(simulate(model, u, FS).data[1:], ref) <= 1e-3


@pytest.mark.parametrize(
    "model",
    [demo_model().replace(inputs=(Input(dof="m3", channel=CH, delay=0.0123, saturation=8.0),)),
     chain(Friction(("m2", "ground"), force_=3.0), CubicSpring(("m2", "m1"), k3=5e9), delay=0.0031, saturation=25.0)],
    ids=["linear", "nonlinear"],
)  # fmt: skip
def test_fine_input_gives_identical_results(model):
    u = record(1.5, rms=20.0, seed=8)
    method = "linear" if all(e.is_linear for e in model.elements) else "nonlinear"
    R = 8 if method == "linear" else default_oversample(model, FS)
    U = reconstruct_input(u, FS, R)
    U0 = U.copy()
    a = simulate(model, u, FS)
    b = simulate(model, u, FS, fine_input=U)
    np.testing.assert_array_equal(a.data, b.data)
    np.testing.assert_array_equal(U, U0)  # not modified
    assert a.meta == b.meta
    with pytest.raises(ValueError, match="oversample"):
        simulate(model, u, FS, fine_input=U, oversample=R + 1)
    with pytest.raises(ValueError, match="fine_input"):
        simulate(model, u, FS, fine_input=U[:, :-1])


def test_newton_failures_are_counted_and_warned_once():
    model, _ = CASES["cubic_spring"]
    U = upsample(record(0.5, rms=30.0)[None], 20)
    with pytest.warns(RuntimeWarning, match="did not converge") as rec:
        res = integrate(model, U, 1.0 / (FS * 20), max_iter=1)
    assert res.newton_failures > 0 and len(rec) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = integrate(model, U, 1.0 / (FS * 20))
    assert ok.newton_failures == 0 and ok.newton_iterations >= U.shape[1] - 1


def test_linear_model_without_nonlinear_elements_in_the_kernel():
    model = demo_model()
    u = record(2.0, rms=10.0, seed=9, fmax=100.0)
    a = simulate(model, u, FS, method="nonlinear")
    b = simulate(model, u, FS, method="linear")
    assert a.meta["newton_failures"] == 0
    assert nrmse(a.data[1:, 50:-50], b.data[1:, 50:-50]) < 2e-3


def test_two_threads_give_the_sequential_results():
    models = [CASES["cubic_spring"][0], CASES["friction+cubic"][0]]
    u = record(2.0, rms=25.0, seed=10)
    seq = [simulate(m, u, FS).data for m in models]
    out = [None, None]

    def run(i):
        out[i] = simulate(models[i], u, FS).data

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for a, b in zip(seq, out):
        np.testing.assert_array_equal(a, b)


def test_reconstruct_input_and_default_oversample():
    u = record(0.2)
    U = reconstruct_input(u, FS, 5)
    assert U.shape == (1, u.size * 5)
    np.testing.assert_allclose(U[0, ::5], u, atol=1e-4 * np.abs(u).max())
    np.testing.assert_array_equal(reconstruct_input(u, FS, 5, upsampling="linear")[0, ::5], u)
    with pytest.raises(ValueError):
        reconstruct_input(u, FS, 0)
    with pytest.raises(ValueError):
        reconstruct_input(u, -1.0, 2)
    assert default_oversample(demo_model(), 1000.0) == 20
    assert default_oversample(demo_model(), 100.0) == 25  # 40 x 60.4 Hz / 100 Hz
