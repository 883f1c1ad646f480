"""Pole-residue (modal) models: a lumped model's exact poles and residues as the oracle for
the FRF, the real realisation and the simulation; the ``kind = "modal"`` model file."""

import warnings

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.errors import ModelFileError
from vibroscope.models import PoleResidueModel
from vibroscope.models.elements import Damper, Spring
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.modelfile import dump_model, dumps_model, load_model, loads_model
from vibroscope.models.simulate import simulate

P = {"displacement": 0, "velocity": 1, "acceleration": 2}


def lumped_3dof(quantities=("acceleration", "velocity", "displacement")) -> LumpedModel:
    """3 DOFs, non-proportional damping (complex residues), two force inputs, one output per
    DOF with the given quantities."""
    names = ["m1", "m2", "m3"]
    elements = (
        Spring(("m1", "ground"), k=1.0e5), Damper(("m1", "ground"), c=30.0),
        Spring(("m2", "m1"), k=8.0e4), Damper(("m2", "m1"), c=2.0),
        Spring(("m3", "m2"), k=5.0e4), Damper(("m3", "ground"), c=9.0),
    )  # fmt: skip
    inputs = (Input(dof="m3", channel="/act/f3.wrench.force.x"), Input(dof="m1", channel="/act/f1.wrench.force.x"))
    outputs = tuple(Output(n, q, f"/imu/{n}.{q}.x") for n, q in zip(names, quantities))
    return LumpedModel(dofs=tuple(Dof(n, m) for n, m in zip(names, [2.0, 1.5, 1.0])), elements=elements,
                       inputs=inputs, outputs=outputs, name="3dof")


def pole_residue_of(lumped: LumpedModel) -> PoleResidueModel:
    """Exact poles and residues from the state-space eigen-decomposition.

    With ``A = Psi Lambda Psi^-1`` (right eigenvectors ``psi_r``, left ones the rows
    ``chi_r^T`` of ``Psi^-1``), ``C (sI - A)^-1 B + D = sum_r (C psi_r)(chi_r^T B) / (s - lambda_r)
    + D``: the residue of ``lambda_r`` is ``R_r = (C psi_r)(chi_r^T B)``, the feedthrough ``D``
    of the acceleration rows is the lower residual times ``(jw)^0``.
    """
    A, B, C, D = lumped.state_matrices()
    lam, Psi = np.linalg.eig(A)
    Chi = np.linalg.inv(Psi)
    up = np.flatnonzero(lam.imag > 0)
    up = up[np.argsort(np.abs(lam[up]))]
    assert 2 * len(up) == len(lam)  # all modes underdamped
    R = np.array([np.outer(C @ Psi[:, r], Chi[r] @ B) for r in up])
    wn = np.abs(lam[up])
    lower = np.zeros(D.shape, complex)
    for o, out in enumerate(lumped.outputs):
        if out.quantity == "acceleration":
            lower[o] = D[o]
        else:
            assert not np.any(D[o])
    return PoleResidueModel.from_poles_residues(
        wn / (2 * np.pi), -lam[up].real / wn, R, inputs=lumped.inputs, outputs=lumped.outputs,
        lower=lower, name="3dof as poles and residues",
    )  # fmt: skip


F = np.linspace(0.0, 150.0, 1501)[1:]


def test_reproduces_the_lumped_frf_exactly():
    lumped = lumped_3dof()
    m = pole_residue_of(lumped)
    assert m.n_modes == 3
    np.testing.assert_allclose(m.natural_frequencies, lumped.modes().natural_frequencies, rtol=1e-12)
    H = m.frf(F)
    Href = lumped.frf(F, quantity=None)
    assert H.shape == Href.shape == (F.size, 3, 2)
    err = np.max(np.abs(H - Href) / np.abs(Href))
    assert err < 1e-8
    # no term is dropped: the realisation has the same transfer function
    assert m.dropped_residual_terms() == []
    np.testing.assert_array_equal(m.frf(F, realised=True), H)


def test_single_mode_receptance_closed_form():
    """1 kg on k: residue ``-j / (2 m w_d)``; static receptance ``1/k``, peak near
    ``1 / (2 zeta k)``; as mobility and accelerance the same mode has residues ``lambda R``
    and ``lambda^2 R`` (``s^2 / (s - lambda) = s + lambda + lambda^2 / (s - lambda)``) plus the
    constant ``R + conj(R) = 0`` resp. ``2 Re(lambda R) = 1 / m``, the accelerance's lower
    residual."""
    k, zeta = 1e4, 0.02
    w = np.sqrt(k)
    lam = -zeta * w + 1j * w * np.sqrt(1 - zeta**2)
    R = -0.5j / lam.imag
    f0 = w / (2 * np.pi)
    io = dict(inputs=["/f.x"])
    d = PoleResidueModel.from_poles_residues([f0], [zeta], [[[R]]], outputs=[Output("y", "displacement", "/d")], **io)
    assert d.frf([0.0])[0, 0, 0] == pytest.approx(1 / k, rel=1e-12)
    assert abs(d.frf([f0])[0, 0, 0]) == pytest.approx(1 / (2 * zeta * k), rel=1e-12)
    np.testing.assert_allclose(d.eigenvalues, [lam], rtol=1e-15)
    s = 2j * np.pi * F
    exact = 1 / (s**2 + 2 * zeta * w * s + w**2)
    v = PoleResidueModel.from_poles_residues([f0], [zeta], [[[lam * R]]], outputs=[Output("y", "velocity", "/v")], **io)
    np.testing.assert_allclose(v.frf(F)[:, 0, 0], s * exact, rtol=1e-12)
    a = PoleResidueModel.from_poles_residues(
        [f0], [zeta], [[[lam**2 * R]]], outputs=[Output("y", "acceleration", "/a")],
        lower=[[2 * (lam * R).real]], **io,
    )  # fmt: skip
    np.testing.assert_allclose(a.frf(F)[:, 0, 0], s**2 * exact, rtol=1e-10)  # 1 - 1 cancels below resonance


def test_realisation_is_the_pole_residue_sum_and_drops_what_it_must():
    """C (sI - A)^-1 B + D equals frf(realised=True) for random rank-2 residues and every
    residual; the dropped terms are named in a RuntimeWarning."""
    rng = np.random.default_rng(1)
    outs = [Output("y", q, f"/{q}") for q in ("acceleration", "velocity", "displacement")]
    R = rng.standard_normal((3, 3, 2)) + 1j * rng.standard_normal((3, 3, 2))
    LR = rng.standard_normal((3, 2)) + 1j * rng.standard_normal((3, 2))
    UR = rng.standard_normal((3, 2))
    m = PoleResidueModel.from_poles_residues(
        [5.0, 12.0, 12.0], [0.01, 0.05, 0.0], R, inputs=["/f1", "/f2"], outputs=outs, lower=LR, upper=UR
    )
    with pytest.warns(RuntimeWarning) as rec:
        A, B, C, D = m.state_matrices()
    msg = str(rec[0].message)
    for part in ("(jw)^2 of '/acceleration' (improper)", "(jw)^1 of '/velocity' (improper)",
                 "(jw)^-2 of '/displacement' (double integrator)", "imaginary part of the lower residual x (jw)^0"):  # fmt: skip
        assert part in msg
    # 3 modes x rank 2 x 2 real states, plus one integrator per input for LR / (jw) of the velocity row
    assert A.shape == (14, 14) and B.shape == (14, 2) and C.shape == (3, 14)
    s = 2j * np.pi * F[::50]
    Hss = np.array([C @ np.linalg.solve(si * np.eye(14) - A, B) + D for si in s])
    Hr = m.frf(F[::50], realised=True)
    assert np.max(np.abs(Hss - Hr)) < 1e-12 * np.max(np.abs(Hr))
    np.testing.assert_array_equal(D[0], LR[0].real)
    np.testing.assert_array_equal(D[2], UR[2])
    # what is realised differs from the full model exactly by the dropped terms
    full = m.frf(F[::50])
    np.testing.assert_allclose(full[:, 2] - Hr[:, 2], LR[2][None] / s[:, None] ** 2, rtol=0, atol=1e-13 * np.abs(full[:, 2]).max())


def _rel_rms(a, b):
    return np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2))


def test_simulation_equals_the_lumped_models():
    lumped = lumped_3dof()
    m = pole_residue_of(lumped)
    rng = np.random.default_rng(7)
    fs = 500.0
    u = rng.standard_normal((2, 20_000)) * [[10.0], [3.0]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing dropped, nothing warned
        a = simulate(m, u, fs)
    b = simulate(lumped, u, fs)
    assert a.channels == b.channels and a.units == b.units
    assert a.meta["simulator"] == "foh-exact"
    for o in range(3):
        assert _rel_rms(a.data[2 + o], b.data[2 + o]) < 1e-6
    np.testing.assert_array_equal(a.data[:2], u)


@pytest.mark.parametrize("f_hz", [7.0, 18.0, 33.3, 61.0, 90.0])
def test_sine_steady_state_matches_frf(f_hz):
    """A sine through the simulated model: amplitude and phase of the steady state equal
    ``H(f)`` of the pole-residue model (accelerance with a lower residual in D)."""
    m = pole_residue_of(lumped_3dof(("acceleration",) * 3))
    fs, n = 1000.0, 20_000
    t = np.arange(n) / fs
    u = np.vstack([np.sin(2 * np.pi * f_hz * t), np.zeros(n)])
    y = simulate(m, u, fs).data[2:, -5000:]
    tt = t[-5000:]
    basis = np.column_stack([np.sin(2 * np.pi * f_hz * tt), np.cos(2 * np.pi * f_hz * tt)])
    coef, *_ = np.linalg.lstsq(basis, y.T, rcond=None)
    H = coef[0] + 1j * coef[1]  # y = Im(H e^{jwt}) = Re(H) sin + Im(H) cos
    np.testing.assert_allclose(H, m.frf([f_hz])[0, :, 0], rtol=1e-4)


def test_velocity_lower_residual_is_an_integrator_in_simulation():
    """``LR / (jw)`` on a velocity output: the simulation adds ``LR x integral of u``."""
    base = PoleResidueModel.from_poles_residues(
        [20.0], [0.03], [[[0.5 - 2.0j]]], inputs=["/f"], outputs=[Output("y", "velocity", "/v")]
    )
    withlr = PoleResidueModel.from_poles_residues(
        [20.0], [0.03], [[[0.5 - 2.0j]]], inputs=["/f"], outputs=[Output("y", "velocity", "/v")], lower=[[0.25]]
    )
    fs = 200.0
    u = np.ones(400)  # a step: the integrator ramps at LR per second
    d = simulate(withlr, u, fs, upsampling="linear").data[1] - simulate(base, u, fs, upsampling="linear").data[1]
    np.testing.assert_allclose(d, 0.25 * np.arange(400) / fs, rtol=1e-9, atol=1e-12)


def test_validation():
    io = dict(inputs=["/f"], outputs=["/a"])
    with pytest.raises(ValueError, match="natural_frequencies"):
        PoleResidueModel.from_poles_residues([-1.0], [0.01], [[[1j]]], **io)
    with pytest.raises(ValueError, match="damping_ratios"):
        PoleResidueModel.from_poles_residues([1.0], [1.0], [[[1j]]], **io)
    with pytest.raises(ValueError, match="residues must have shape"):
        PoleResidueModel.from_poles_residues([1.0], [0.1], [[[1j, 2j]]], **io)
    with pytest.raises(ValueError, match="lower_residual"):
        PoleResidueModel.from_poles_residues([1.0], [0.1], [[[1j]]], lower=[1.0, 2.0], **io)
    with pytest.raises(ValueError, match="repeat"):
        PoleResidueModel.from_poles_residues([1.0], [0.1], [[[1j]]], inputs=["/a"], outputs=["/a"])
    m = PoleResidueModel.from_poles_residues([1.0], [0.1], [[[1j]]], **io)
    assert not m.residues.flags.writeable and m.is_linear and m.elements == ()
    with pytest.raises(ValueError, match="nonlinear"):
        simulate(m, np.zeros(10), 100.0, method="nonlinear")


# ---------------------------------------------------------------------------------------------
# model files
# ---------------------------------------------------------------------------------------------
GOOD = """\
kind = "modal"
name = "frame, identified by LSCF"
[[input]]
channel = "/actuator/force.wrench.force.x"
quantity = "force"
[[output]]
channel = "/imu/m1.linear_acceleration.x"
quantity = "acceleration"
[[output]]
channel = "/imu/m2.linear_acceleration.x"
quantity = "acceleration"
[[mode]]
frequency_hz = 18.39
damping_ratio = 0.0102
residues = [[[1.2e-3, -4.5e-2]], [[2.0e-3, -9.0e-2]]]
[[mode]]
frequency_hz = 41.9
damping_ratio = 0.02
residues = [[[-3.0e-3, 1.0e-1]],
            [[1, 0]]]
[residual]
lower = [[[1.0e-4, 0.0]], [[-2.0e-4, 0.0]]]
"""


def write(tmp_path, text, name="model.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_load_good_file(tmp_path):
    m = load_model(write(tmp_path, GOOD))
    assert isinstance(m, PoleResidueModel)
    assert m.name == "frame, identified by LSCF"
    np.testing.assert_array_equal(m.natural_frequencies, [18.39, 41.9])
    np.testing.assert_array_equal(m.damping_ratios, [0.0102, 0.02])
    assert m.residues.shape == (2, 2, 1)
    assert m.residues[0, 1, 0] == 2.0e-3 - 9.0e-2j and m.residues[1, 1, 0] == 1.0
    np.testing.assert_array_equal(m.lower_residual, [[1e-4], [-2e-4]])
    np.testing.assert_array_equal(m.upper_residual, np.zeros((2, 1)))
    assert m.input_channels() == ["/actuator/force.wrench.force.x"]
    assert m.output_channels() == ["/imu/m1.linear_acceleration.x", "/imu/m2.linear_acceleration.x"]


@pytest.mark.parametrize("build", ["lumped", "random"])
def test_roundtrip_is_exact(tmp_path, build):
    if build == "lumped":
        m = pole_residue_of(lumped_3dof())
    else:
        rng = np.random.default_rng(3)
        m = PoleResidueModel.from_poles_residues(
            rng.uniform(1, 100, 4), rng.uniform(0, 0.2, 4),
            rng.standard_normal((4, 2, 3)) * 1e-3 + 1j * rng.standard_normal((4, 2, 3)),
            inputs=[Input(dof="shaker", channel=f"/in{k}") for k in range(3)],
            outputs=[Output("y", "velocity", "/v"), Output("tip", "displacement", "/d")],
            lower=rng.standard_normal((2, 3)) * 1e-7j, upper=rng.standard_normal((2, 3)), name='q"uoted',
        )  # fmt: skip
    p = tmp_path / "m.toml"
    dump_model(m, p)
    back = load_model(p)
    assert back == m
    for key in ("natural_frequencies", "damping_ratios", "residues", "lower_residual", "upper_residual"):
        np.testing.assert_array_equal(getattr(back, key), getattr(m, key))
    assert dumps_model(back) == p.read_text()


def _err(text):
    with pytest.raises(ModelFileError) as exc:
        loads_model(text, "model.toml")
    return str(exc.value)


def _line(text, needle):
    return text.splitlines().index(needle) + 1


@pytest.mark.parametrize(
    "old, new, key, needle",
    [
        ("frequency_hz = 41.9", "frequency_hz = -41.9", "'frequency_hz'", "frequency_hz = -41.9"),
        ("frequency_hz = 41.9", "frequency_hz = 0", "'frequency_hz'", "frequency_hz = 0"),
        ("damping_ratio = 0.02", "damping_ratio = 1.0", "'damping_ratio'", "damping_ratio = 1.0"),
        ("damping_ratio = 0.02", "damping_ratio = -0.1", "'damping_ratio'", "damping_ratio = -0.1"),
        ("residues = [[[1.2e-3, -4.5e-2]], [[2.0e-3, -9.0e-2]]]", "residues = [[[1.2e-3, -4.5e-2]]]",
         "'residues'", "residues = [[[1.2e-3, -4.5e-2]]]"),
        ("residues = [[[1.2e-3, -4.5e-2]], [[2.0e-3, -9.0e-2]]]", "residues = [[[1.2e-3]], [[2.0e-3]]]",
         "'residues'", "residues = [[[1.2e-3]], [[2.0e-3]]]"),
        ("residues = [[[1.2e-3, -4.5e-2]], [[2.0e-3, -9.0e-2]]]", 'residues = [[[1.2e-3, "x"]], [[2.0e-3, 0.0]]]',
         "'residues'", 'residues = [[[1.2e-3, "x"]], [[2.0e-3, 0.0]]]'),
        ("lower = [[[1.0e-4, 0.0]], [[-2.0e-4, 0.0]]]", "lower = [[1.0e-4, 0.0]]", "'lower'", "lower = [[1.0e-4, 0.0]]"),
        ("lower = [[[1.0e-4, 0.0]], [[-2.0e-4, 0.0]]]", "middle = 1.0", "'middle'", "middle = 1.0"),
        ("damping_ratio = 0.02", "damping_ratio = 0.02\nshape = 1.0", "'shape'", "shape = 1.0"),
        ('quantity = "acceleration"\n[[mode]]', 'quantity = "jerk"\n[[mode]]', "'quantity'", 'quantity = "jerk"'),
    ],
)
def test_bad_values_name_key_and_line(old, new, key, needle):
    text = GOOD.replace(old, new, 1)
    assert text != GOOD
    msg = _err(text)
    assert msg.startswith(f"model.toml:{_line(text, needle)}:"), msg
    assert key in msg


def test_residue_shape_error_says_what_is_expected():
    text = GOOD.replace("residues = [[[1.2e-3, -4.5e-2]], [[2.0e-3, -9.0e-2]]]", "residues = [[[1.2e-3, -4.5e-2]]]")
    msg = _err(text)
    assert "[[mode]] #1" in msg and "(n_outputs=2, n_inputs=1, 2)" in msg and "shape (1, 1, 2)" in msg
    assert "[residual]" in _err(GOOD.replace("lower = [[[1.0e-4, 0.0]], [[-2.0e-4, 0.0]]]", "lower = 3"))


@pytest.mark.parametrize("drop, key, header", [
    ("frequency_hz = 41.9\n", "'frequency_hz'", "[[mode]]"),
    ("damping_ratio = 0.0102\n", "'damping_ratio'", "[[mode]]"),
    ("residues = [[[1.2e-3, -4.5e-2]], [[2.0e-3, -9.0e-2]]]\n", "'residues'", "[[mode]]"),
    ('channel = "/imu/m2.linear_acceleration.x"\n', "'channel'", "[[output]]"),
])  # fmt: skip
def test_missing_key_names_key_and_block_line(drop, key, header):
    text = GOOD.replace(drop, "", 1)
    msg = _err(text)
    assert "missing required key" in msg and key in msg
    # the line of the block's header where the key is missing
    line = int(msg.split(":")[1])
    assert text.splitlines()[line - 1] == header


def test_structure_errors():
    no_modes = GOOD[: GOOD.index("[[mode]]")]
    assert "at least one [[mode]]" in _err(no_modes)
    no_inputs = GOOD.replace('[[input]]\nchannel = "/actuator/force.wrench.force.x"\nquantity = "force"\n', "")
    assert "at least one [[input]]" in _err(no_inputs)
    msg = _err(GOOD.replace('kind = "modal"', 'kind = "poles"'))
    assert "'modal'" in msg and "'lumped'" in msg and "'transfer_function'" in msg and msg.startswith("model.toml:1:")
    assert "'modal'" in _err(GOOD.replace('kind = "modal"\n', ""))
    assert "[residual]" in _err(GOOD.replace("[residual]", "[[residual]]"))


# ---------------------------------------------------------------------------------------------
# vibroscope simulate MODEL.toml
# ---------------------------------------------------------------------------------------------
def test_cli_simulates_a_modal_model_file(tmp_path, capsys):
    from scipy import signal

    from vibroscope.io import read_mcap

    p = write(tmp_path, GOOD)
    out = tmp_path / "sim.mcap"
    rc = main(["simulate", str(p), "--excitation", "random:f_lo=1,f_hi=150,rms=10", "--out", str(out),
               "--fs", "500", "--duration", "100", "--seed", "2"])  # fmt: skip
    assert rc == 0 and "wrote" in capsys.readouterr().out
    model = load_model(p)
    ch = model.input_channels() + model.output_channels()
    log = read_mcap(out, channels=ch)
    assert log.n_samples == 50_000 and log.units == ("N", "m/s^2", "m/s^2")
    ref = simulate(model, log.data[0], log.fs)
    np.testing.assert_allclose(log.data[1:], ref.data[1:], rtol=0, atol=1e-9 * np.abs(ref.data[1:]).max())
    f, Pxx = signal.welch(log.data[0], log.fs, nperseg=4096)
    _, Pxy = signal.csd(log.data[0], log.data[1:], log.fs, nperseg=4096)
    _, coh = signal.coherence(log.data[0], log.data[1:], log.fs, nperseg=4096)
    H = model.frf(f)[:, :, 0].T
    ok = (coh > 0.999) & (f > 2) & (f < 145)
    assert ok.sum() > 500
    assert np.max(np.abs(Pxy[ok] / Pxx[None].repeat(2, 0)[ok] / H[ok] - 1)) < 0.01
