"""Asymmetric Coulomb friction: ``f = F+ t`` for ``v >= 0``, ``F- t`` for ``v < 0``,
``t = tanh(v / v_eps)``; limits ``+F+`` and ``-F-``, monotonic for any ratio; the compiled kernel
against the pure-Python reference integrator and an independent ODE solve; the symmetric
law unchanged bit for bit."""

import math

import numpy as np
import pytest
from scipy import integrate as sp_integrate

from vibroscope.errors import ModelFileError
from vibroscope.models._reference_integrator import _Integrator, reference_simulate_fine
from vibroscope.models.elements import Friction, make_element
from vibroscope.models.excitation import band_limited_random
from vibroscope.models.integrate import ELEMENT_CODES, _element, flatten_model, integrate
from vibroscope.models.lumped import LumpedModel
from vibroscope.models.modelfile import dumps_model, loads_model
from vibroscope.models.simulate import default_oversample, simulate, upsample

FS = 1000.0
V = np.r_[-np.logspace(-6, 1, 40)[::-1], 0.0, np.logspace(-6, 1, 40)]


def nrmse(a, ref):
    a, ref = np.atleast_2d(a), np.atleast_2d(ref)
    return float(np.max(np.sqrt(np.mean((a - ref) ** 2, axis=1)) / np.sqrt(np.mean(ref**2, axis=1))))


def test_force_limits_and_law():
    e = Friction(("m1", "ground"), force_=3.0, v_eps=1e-3, force_neg=1.0)
    assert e.force(0.0, 1.0) == pytest.approx(3.0, rel=1e-15)
    assert e.force(0.0, -1.0) == pytest.approx(-1.0, rel=1e-15)
    assert e.force(0.0, 0.0) == 0.0
    for v in V:  # f = F+ t (v >= 0), F- t (v < 0)
        t = math.tanh(v / 1e-3)
        assert e.force(0.0, v) == pytest.approx((3.0 if v >= 0 else 1.0) * t, rel=1e-14, abs=1e-300)
    # monotonic in v, independent of d
    f = np.array([e.force(0.0, v) for v in V])
    assert np.all(np.diff(f) >= 0) and f[0] == pytest.approx(-1.0) and f[-1] == pytest.approx(3.0)
    assert e.force(5.0, 0.01) == e.force(-5.0, 0.01)
    # monotonic for any ratio, also with one force 0
    one = Friction(("m1", "ground"), force_=0.0, force_neg=2.0)
    assert one.force(0.0, 1.0) == 0.0 and one.force(0.0, -1.0) == pytest.approx(-2.0)
    f1 = np.array([one.force(0.0, v) for v in V])
    assert np.all(np.diff(f1) >= 0)


def test_symmetric_law_is_unchanged_bit_for_bit():
    sym = Friction(("m1", "ground"), force_=3.0, v_eps=2e-3)
    same = Friction(("m1", "ground"), force_=3.0, v_eps=2e-3, force_neg=3.0)
    for v in V:
        old = 3.0 * math.tanh(v / 2e-3)  # the law before force_neg existed
        assert sym.force(0.0, v) == old and same.force(0.0, v) == old
    # the compiled law: remainder force and its velocity derivative as before
    prm = np.array([[3.0, 2e-3, 3.0] + [0.0] * 6])
    for v in V:
        t = math.tanh(v / 2e-3)
        res = _element(ELEMENT_CODES["friction"], prm, 0, 0.0, 0.5, 1e-3, v, 0.0, 0.0)
        assert res[0] == 3.0 * t - 0.0 * 1e-3 - 0.5 * v
        assert res[2] == 3.0 / 2e-3 * (1.0 - t * t) - 0.5
    # the symmetric row repeats force_ in place of force_neg
    m = LumpedModel.chain([1.0], [1e4], [2.0], nonlinear=[sym])
    assert flatten_model(m, 1e-4).params[0, :3].tolist() == [3.0, 2e-3, 3.0]
    u = band_limited_random(FS, 500, fmin=1, fmax=100, rms=20.0, seed=2)
    a = simulate(m, u, FS).data
    b = simulate(m.replace(elements=m.elements[:-1] + (same,)), u, FS).data
    np.testing.assert_array_equal(a, b)


def test_compiled_jacobian_matches_the_law():
    """df/dv = F (1 - t^2)/v_eps with F the sliding force of the side of v, checked by central
    differences of f (away from the kink at v = 0)."""
    ve = 1e-3
    e = Friction(("m1", "ground"), force_=3.0, v_eps=ve, force_neg=1.0)
    prm = np.array([[3.0, ve, 1.0] + [0.0] * 6])
    for v in np.linspace(-5e-3, 5e-3, 40):
        res = _element(ELEMENT_CODES["friction"], prm, 0, 0.0, 0.0, 0.0, v, 0.0, 0.0)
        assert res[0] == pytest.approx(e.force(0.0, v), rel=1e-15, abs=1e-15)
        h = 1e-9
        fd = (e.force(0.0, v + h) - e.force(0.0, v - h)) / (2 * h)
        assert res[2] == pytest.approx(fd, rel=1e-5, abs=1e-6)


def sdof(force_neg, quantity="displacement"):
    """1 kg on 1e4 N/m, 2 N s/m (15.9 Hz), friction to ground 3 N / force_neg N."""
    fr = Friction(("m1", "ground"), force_=3.0, v_eps=1e-2, force_neg=force_neg)
    return LumpedModel.chain([1.0], [1e4], [2.0], output_quantity=quantity, nonlinear=[fr])


def test_kernel_matches_reference_and_ode_solve():
    model = sdof(1.0)
    n = 1000
    t = np.arange(n) / FS
    u = 20.0 * np.sin(2 * np.pi * 8.0 * t) * np.sin(np.pi * t / t[-1]) ** 2  # smooth driven case
    s = simulate(model, u, FS)
    assert s.meta["simulator"] == "trapezoidal" and s.meta["newton_failures"] == 0
    R = default_oversample(model, FS)
    # the pure-Python integrator (element law through Friction.force, numerical Jacobian)
    ref = reference_simulate_fine(model, upsample(u[None], R), FS, R)
    assert nrmse(s.data[1:], ref) < 1e-3
    U = upsample(u[None], R)[:, :4000]
    res = integrate(model, U, 1.0 / (FS * R), store_states=True)
    Q, G = _Integrator(model, 1.0 / (FS * R)).run(U)
    assert nrmse(res.q, Q) <= 1e-9 and nrmse(res.g, G) <= 1e-9
    # an independent solve of m x'' + c x' + k x + f(x') = u(t), the input as reconstructed
    tf = np.arange(n * R) / (FS * R)
    Uf = upsample(u[None], R)[0]
    e = model.elements[-1]

    def rhs(tt, y):
        uu = np.interp(tt, tf, Uf)
        return [y[1], uu - 1e4 * y[0] - 2.0 * y[1] - e.force(y[0], y[1])]

    sol = sp_integrate.solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, method="LSODA", rtol=1e-10, atol=1e-13,
                                 max_step=1.0 / (FS * R))  # fmt: skip
    assert sol.success
    assert nrmse(s.data[1, 20:-20], sol.y[0, 20:-20]) < 1e-3
    # the asymmetry matters: the symmetric model's response differs (and drifts less)
    sym = simulate(sdof(None), u, FS).data[1]
    assert nrmse(sym, s.data[1]) > 1e-2


def test_validation():
    for bad in (-1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="force_neg="):
            Friction(("m1", "ground"), force_=1.0, force_neg=bad)
    assert Friction(("m1", "ground"), force_=1.0, force_neg=2).force_neg == 2.0
    assert Friction(("m1", "ground"), force_=1.0).force_neg is None
    e = make_element("friction", ("m1", "ground"), force=1.0, force_neg=0.5)
    assert e.params() == {"force": 1.0, "v_eps": 1e-3, "force_neg": 0.5}
    assert Friction(("m1", "ground"), force_=1.0).params() == {"force": 1.0, "v_eps": 1e-3}
    assert make_element("friction", ("m1", "ground"), **e.params()) == e


def test_model_file_round_trip():
    model = sdof(1.0, quantity="acceleration")
    text = dumps_model(model)
    assert "force_neg = 1.0" in text
    assert loads_model(text) == model
    sym = sdof(None)
    text_sym = dumps_model(sym)
    assert "force_neg" not in text_sym and loads_model(text_sym) == sym
    for bad, msg in (("-1.0", "must be >= 0"), ('"x"', "must be a finite number")):
        with pytest.raises(ModelFileError, match=msg) as exc:
            loads_model(text.replace("force_neg = 1.0", f"force_neg = {bad}"))
        assert "'force_neg'" in str(exc.value)
