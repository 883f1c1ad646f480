"""Input offset: a constant force bias added to the logged input before saturation,
``clip(u(t - delay) + offset)``, on both simulation paths; analytic truth: the static
deflection ``F0 / k`` of a single DOF."""

import numpy as np
import pytest

from vibroscope.errors import ModelFileError
from vibroscope.models.elements import CubicSpring, Friction
from vibroscope.models.excitation import band_limited_random
from vibroscope.models.lumped import Input, LumpedModel, Output, demo_model
from vibroscope.models.modelfile import TransferFunctionModel, dumps_model, loads_model
from vibroscope.models.simulate import simulate, simulate_periodic

FS = 1000.0
CH = "/actuator/force.wrench.force.x"
# 1 kg on 1e4 N/m with 20 N s/m: w_n = 100 rad/s, zeta = 0.1, time constant 1/(zeta w_n) = 0.1 s
M, K, C = 1.0, 1.0e4, 20.0
TAU = M * 2.0 / C


def sdof(*nonlinear, **inp):
    m = LumpedModel.chain([M], [K], [C], output_quantity="displacement", nonlinear=nonlinear)
    return m.replace(inputs=(Input(dof="m1", channel=CH, **inp),))


MODELS = {
    "linear": sdof,
    "cubic_k3_0": lambda **inp: sdof(CubicSpring(("m1", "ground"), k3=0.0), **inp),
    "friction_0": lambda **inp: sdof(Friction(("m1", "ground"), force_=0.0), **inp),
}
SIMULATOR = {"linear": "foh-exact", "cubic_k3_0": "trapezoidal", "friction_0": "trapezoidal"}


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("F0", [2.5, -4.0])
def test_offset_alone_settles_to_the_static_deflection(name, F0):
    model = MODELS[name](offset=F0)
    n = int(round(20 * TAU * FS)) + 200  # 20 time constants and more
    s = simulate(model, np.zeros(n), FS)
    assert s.meta["simulator"] == SIMULATOR[name]
    np.testing.assert_array_equal(s.data[0], np.full(n, F0))  # the applied force is logged
    x = s.data[1]
    assert x[-1] == pytest.approx(F0 / K, rel=1e-6)
    assert abs(x[0]) <= 1e-6 * abs(F0 / K)  # from rest
    # the onset at t = 0 is a step: the peak overshoot of an underdamped SDOF step response
    zeta = C / (2 * np.sqrt(K * M))
    peak = F0 / K * (1 + np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2)))
    assert np.max(np.abs(x)) == pytest.approx(abs(peak), rel=1e-2)


def test_offset_is_superposed_on_the_linear_response():
    """Affine: response(u, offset) = response(u) + response(0, offset), and the FRF is unchanged."""
    base = demo_model()
    off = base.replace(inputs=(Input(dof="m3", channel=CH, offset=3.0),))
    assert off.is_linear
    u = band_limited_random(FS, 3000, fmin=1, fmax=100, rms=10.0, seed=1)
    a = simulate(off, u, FS).data
    b = simulate(base, u, FS).data
    c = simulate(off, np.zeros_like(u), FS).data
    np.testing.assert_allclose(a, b + c, rtol=0, atol=1e-12 * np.abs(a).max())
    f = np.linspace(1, 100, 50)
    np.testing.assert_array_equal(off.frf(f), base.frf(f))


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("u0, expected", [(3.0, 5.0), (-3.0, 1.0), (-12.0, -5.0)])
def test_saturation_clips_after_the_offset(name, u0, expected):
    """u + offset, then clipped: 3 + 4 -> 5 (not min(3, 5) + 4 = 7), -3 + 4 -> 1, -12 + 4 -> -5."""
    model = MODELS[name](offset=4.0, saturation=5.0)
    n = int(round(20 * TAU * FS)) + 200
    s = simulate(model, np.full(n, u0), FS)
    np.testing.assert_array_equal(s.data[0], np.full(n, expected))
    # 20 time constants in, away from the reconstruction's ringing at the record's end
    assert s.data[1, -200] == pytest.approx(expected / K, rel=1e-6)


def test_offset_with_delay_and_periodic():
    # integer delay of 2 samples: u(t - delay) is 0 before the start, the offset acts from t = 0
    model = sdof(offset=1.5, delay=2 / FS)
    u = np.arange(1.0, 11.0)
    s = simulate(model, u, FS)
    np.testing.assert_array_equal(s.data[0], np.r_[0.0, 0.0, u[:-2]] + 1.5)
    # periodic steady state: sine response plus the static deflection
    n = 500
    t = np.arange(n) / FS
    up = np.sin(2 * np.pi * 10.0 * t)
    periods = int(np.ceil(20 * TAU * FS / n)) + 1
    for make in (MODELS["linear"], MODELS["cubic_k3_0"]):
        y = simulate_periodic(make(offset=2.0), up, FS, n_periods=periods).data[1]
        y0 = simulate_periodic(make(), up, FS, n_periods=periods).data[1]
        np.testing.assert_allclose(y - y0, 2.0 / K, rtol=1e-6)


def test_offset_validation():
    assert Input(dof="m1").offset == 0.0
    assert Input(dof="m1", offset=-2).offset == -2.0
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError, match="offset="):
            Input(dof="m1", offset=bad)


def test_offset_model_file_round_trip():
    model = sdof(offset=-2.5, saturation=30.0, delay=0.004)
    text = dumps_model(model)
    assert "offset = -2.5" in text
    assert loads_model(text) == model
    # omitted when 0: existing files are unchanged
    plain = dumps_model(sdof())
    assert "offset" not in plain and loads_model(plain) == sdof()
    tf = TransferFunctionModel((1.0,), (1.0, 2.0, 100.0), Input(dof="u", channel="/cmd.x", offset=0.5),
                               Output("y", "displacement", "/y.x"))  # fmt: skip
    assert loads_model(dumps_model(tf)) == tf
    bad = text.replace("offset = -2.5", 'offset = "a lot"')
    with pytest.raises(ModelFileError, match="'offset'"):
        loads_model(bad)


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("u0", [3.0, -12.0, 40.0])
def test_a_smooth_saturation_is_its_limit_times_tanh(name, u0):
    """``saturation_law = "tanh"``: the applied force is ``L tanh((u + offset) / L)`` (analytic:
    u0 + 4 at L = 5), the static deflection that force over k; the law round-trips through the
    model file, a default (clip) file does not mention it, and an unknown law is refused."""
    model = MODELS[name](offset=4.0, saturation=5.0, saturation_law="tanh")
    n = int(round(20 * TAU * FS)) + 200
    s = simulate(model, np.full(n, u0), FS)
    expected = 5.0 * np.tanh((u0 + 4.0) / 5.0)
    np.testing.assert_allclose(s.data[0], expected, rtol=1e-12)
    assert s.data[1, -200] == pytest.approx(expected / K, rel=1e-6)
    text = dumps_model(model)
    assert 'saturation_law = "tanh"' in text and loads_model(text) == model
    assert "saturation_law" not in dumps_model(MODELS[name](saturation=5.0))
    with pytest.raises(ModelFileError, match="saturation_law"):
        loads_model(text.replace('"tanh"', '"cubic"'))
    with pytest.raises(ValueError, match="saturation_law"):
        Input(dof="m1", saturation=5.0, saturation_law="soft")
