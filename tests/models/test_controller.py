"""Closed loops: discrete controllers around lumped models (vibroscope.models.controller,
vibroscope.models.closed_loop), checked against analytic / python-control truths, the
founding paper's instruments (hydraulic P / PD2 loop, PI + PDT1 block schema) and the EMPS
data set (Janot, Gautier & Brunot 2019)."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vibroscope.instruments.block_schema import paper_block_schema
from vibroscope.instruments.hydraulic import HYDRAULIC_NOMINAL as HN
from vibroscope.instruments.hydraulic import hydraulic_closed_loop, hydraulic_comparison, hydraulic_motor
from vibroscope.instruments.hydraulic import hydraulic_natural_frequency_rad_s
from vibroscope.instruments.lti import step_response
from vibroscope.models.closed_loop import loop_inputs, zoh_matrices
from vibroscope.models.controller import LAWS, Controller
from vibroscope.models.elements import Damper, Spring, make_element
from vibroscope.models.lumped import Dof, Input, LumpedModel, Output
from vibroscope.models.modelfile import dumps_model, loads_model
from vibroscope.models.simulate import simulate


# ------------------------------------------------------------------------------ models
def hydraulic_lumped(controller: Controller) -> LumpedModel:
    """Merritt's valve-controlled cylinder ``x/u = K/(s (s^2/wh^2 + 2 zeta s/wh + 1))`` as
    a lumped model: the valve is a velocity source (a 1 kg DOF on a damper ``ca`` to ground,
    driven by ``ca K u``: ``xdot_valve = K u`` up to 1e-7), the oil column a spring
    ``k = m wh^2`` to the piston (mass m, damper ``2 zeta wh m`` to ground)."""
    wh = hydraulic_natural_frequency_rad_s(HN["beta_e"], HN["A"], HN["V_t"], HN["m_t"])
    m, z = HN["m_t"], HN["zeta_h"]
    k = m * wh**2
    ca = 1e7 * 2 * z * k / wh
    return LumpedModel(
        dofs=(Dof("valve", 1.0), Dof("piston", m)),
        elements=(Damper(("valve", "ground"), c=ca), Spring(("valve", "piston"), k=k), Damper(("piston", "ground"), c=2 * z * wh * m)),
        inputs=(Input(dof="valve", channel="/valve/flow.x"),),
        outputs=(Output("piston", "displacement", "/piston/position.x"),), name="hydraulic motor",
        controllers=(controller,),
    )


def hydraulic_controller(law: str, rate: float, measures=("position", "velocity", "acceleration")) -> tuple[Controller, tuple]:
    wh = hydraulic_natural_frequency_rad_s(HN["beta_e"], HN["A"], HN["V_t"], HN["m_t"])
    ca = 1e7 * 2 * HN["zeta_h"] * HN["m_t"] * wh
    cmp = hydraulic_comparison()
    if law == "P":
        gains, gk = {"kp": cmp.gains_p["k_p"]}, (cmp.gains_p["k_p"], 0.0, 0.0)
    else:
        g = cmp.gains_pd2
        gains, gk = {"kp": float(g["k_p"]), "kd": 0.0, "ka": float(g["k_a"])}, (float(g["k_p"]), 0.0, float(g["k_a"]))
    c = Controller(name="position", law=law, gains=gains, rate_hz=rate, dof="piston", drives=0,
                   reference="/piston/reference.x",
                   measures=measures, gain=ca * HN["K_q"] / HN["A"], output_channel="/valve/command.x")
    return c, gk


# ------------------------------------------------------------------------------ the laws
def test_laws_registry_and_validation():
    assert set(LAWS) == {"P", "PD", "PID", "PD2", "PI_PDT1", "cascade"}
    with pytest.raises(ValueError, match="needs gain 'kv'"):
        Controller(name="c", law="cascade", gains={"kp": 1.0}, rate_hz=1000.0, dof="m1")
    with pytest.raises(ValueError, match="not a gain"):
        Controller(name="c", law="P", gains={"kp": 1.0, "ki": 2.0}, rate_hz=1000.0, dof="m1")
    with pytest.raises(ValueError, match="rate_hz"):
        Controller(name="c", law="P", gains={"kp": 1.0}, rate_hz=0.0, dof="m1")
    with pytest.raises(ValueError, match="law="):
        Controller(name="c", law="LQR", gains={"kp": 1.0}, rate_hz=1000.0, dof="m1")
    m = LumpedModel.chain([1.0], [1e4], [2.0], output_quantity="displacement")
    with pytest.raises(ValueError, match="drives"):
        m.replace(controllers=(Controller(name="c", law="P", gains={"kp": 1.0}, rate_hz=1000.0, dof="m1", drives=3),))
    with pytest.raises(ValueError, match="unknown DOF"):
        m.replace(controllers=(Controller(name="c", law="P", gains={"kp": 1.0}, rate_hz=1000.0, dof="m9"),))


def test_p_loop_on_a_mass_spring_matches_the_exact_discrete_loop():
    """P control of m x'' + c x' + k x = F: the kernel's loop equals the discrete loop
    built from the ZOH-sampled plant (Åström & Wittenmark sec. 2.3), to rounding."""
    kp, T = 3e3, 1e-3
    m = LumpedModel.chain([1.0], [1e4], [20.0], output_quantity="displacement")
    c = Controller(name="c", law="P", gains={"kp": kp}, rate_hz=1 / T, dof="m1", drives=0, reference="/r.x")
    mc = m.replace(controllers=(c,))
    assert [r[0] for r in loop_inputs(mc)] == ["/r.x"]
    n = 3000
    r = np.ones(n) * 1e-3
    s = simulate(mc, r, 1 / T)
    assert list(s.channels) == ["/r.x", "/imu/m1.displacement.x", "/controller/c.command"]
    A, B, C, _ = m.state_matrices()
    Phi, Gam = zoh_matrices(A, B, T)
    q = np.zeros(2)
    y, u = np.zeros(n), np.zeros(n)
    for k in range(n):
        y[k] = (C @ q)[0]
        u[k] = kp * (r[k] - y[k])
        q = Phi @ q + Gam[:, 0] * u[k]
    np.testing.assert_allclose(s.data[1], y, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.data[2], u, rtol=0, atol=1e-9)
    # static error of the P loop: k / (k + kp)
    assert s.data[1, -1] == pytest.approx(1e-3 * kp / (1e4 + kp), rel=1e-6)


@pytest.mark.parametrize("delay_ticks", [3.0, 2.5])
def test_a_delayed_actuator_applies_the_command_delay_s_late(delay_ticks):
    """A driven input with ``delay``: the force applied over tick k is the command of tick
    k - delay (linearly interpolated between ticks for a fractional delay, zero before the
    start); the kernel equals that discrete loop built from the ZOH-sampled plant."""
    kp, T = 3e3, 1e-3
    m = LumpedModel.chain([1.0], [1e4], [20.0], output_quantity="displacement")
    m = m.replace(inputs=(Input(dof="m1", delay=delay_ticks * T),))
    c = Controller(name="c", law="P", gains={"kp": kp}, rate_hz=1 / T, dof="m1", drives=0, reference="/r.x")
    mc = m.replace(controllers=(c,))
    n = 2000
    r = np.r_[np.zeros(5), np.ones(n - 5)] * 1e-3
    s = simulate(mc, r, 1 / T)
    A, B, C, _ = m.state_matrices()
    Phi, Gam = zoh_matrices(A, B, T)
    q = np.zeros(2)
    y, u = np.zeros(n), np.zeros(n)
    d0, a = int(delay_ticks), delay_ticks - int(delay_ticks)
    for k in range(n):
        y[k] = (C @ q)[0]
        u[k] = kp * (r[k] - y[k])
        ua = (1 - a) * (u[k - d0] if k >= d0 else 0.0) + a * (u[k - d0 - 1] if k >= d0 + 1 else 0.0)
        q = Phi @ q + Gam[:, 0] * ua
    np.testing.assert_allclose(s.data[1], y, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.data[2], u, rtol=0, atol=1e-9)
    # the delay changes the loop: the undelayed loop's response differs
    s0 = simulate(m.replace(inputs=(Input(dof="m1"),), controllers=(c,)), r, 1 / T)
    assert np.max(np.abs(s0.data[1] - s.data[1])) > 1e-2 * np.max(np.abs(s.data[1]))


def test_trapezoidal_path_agrees_with_exact_zoh_path():
    c = Controller(name="c", law="PID", gains={"kp": 3e4, "ki": 1e5, "kd": 100.0}, rate_hz=1000.0, dof="m1", drives=0,
                   reference="/r.x")
    m = LumpedModel.chain([1.0], [1e4], [20.0], output_quantity="displacement").replace(controllers=(c,))
    r = np.r_[np.zeros(10), np.ones(4990)] * 1e-3
    a = simulate(m, r, 1000.0)
    b = simulate(m, r, 1000.0, method="nonlinear", oversample=40)
    assert a.meta["simulator"] == "closed-loop-zoh-exact" and b.meta["simulator"] == "closed-loop-trapezoidal"
    np.testing.assert_allclose(b.data[1], a.data[1], atol=1e-6 * 1e-3)
    assert a.data[1, -1] == pytest.approx(1e-3, rel=1e-6)  # integral action: no static error


# ------------------------------------------------------------------------------ the paper's loops
@pytest.mark.parametrize("law", ["P", "PD2"])
def test_hydraulic_position_loop_matches_instruments(law):
    """The paper's hydraulic motor under P / PD2 position control, rebuilt as a lumped model
    in a 100 kHz controller, follows instruments.hydraulic's python-control step response."""
    rate = 1e5
    c, gk = hydraulic_controller(law, rate)
    t = np.arange(int(0.25 * rate)) / rate
    s = simulate(hydraulic_lumped(c), np.ones_like(t), rate)
    ref = step_response(hydraulic_closed_loop(*gk), t).response
    err = np.max(np.abs(s.data[1] - ref))
    assert err < 3e-4, err  # the ZOH's half-period lag: ~ max|x'| T/2
    # the valve command: u = kp (r - x) - ka x'' from the instruments' transfer functions
    sv = control.tf([1.0, 0.0], [1.0])
    cl = hydraulic_closed_loop(*gk)
    cmd = step_response(control.minreal(gk[0] * (1 - cl) - gk[2] * sv * sv * cl, verbose=False), t).response
    assert np.max(np.abs(s.data[2, 1:] - cmd[1:])) < 3e-3 * np.max(np.abs(cmd))


@pytest.mark.parametrize("law", ["P", "PD2"])
def test_hydraulic_loop_equals_discretised_instrument_plant(law):
    """At 2 kHz, the closed loop equals the instruments' plant sampled with a ZOH in the
    same discrete law (state space from python-control), to the velocity-source model's 1e-6."""
    rate = 2000.0
    c, (kp, kd, ka) = hydraulic_controller(law, rate)
    T = 1 / rate
    n = 500
    s = simulate(hydraulic_lumped(c), np.ones(n), rate)
    P = control.ss(hydraulic_motor())
    A, B, C = np.asarray(P.A), np.asarray(P.B), np.asarray(P.C)
    Phi, Gam = zoh_matrices(A, B, T)
    K = kp * C + kd * C @ A + ka * C @ A @ A  # x, x' = C A q, x'' = C A^2 q (relative degree 3)
    q = np.zeros(A.shape[0])
    y = np.zeros(n)
    for k in range(n):
        y[k] = (C @ q)[0]
        u = kp * 1.0 - (K @ q)[0]
        q = Phi @ q + Gam[:, 0] * u
    assert np.max(np.abs(s.data[1] - y)) < 2e-6


def test_pd2_from_backward_differences_converges_to_sampled_states():
    rate = 1e5
    c1, _ = hydraulic_controller("PD2", rate)
    c2, gk = hydraulic_controller("PD2", rate, measures=("position",))
    t = np.arange(int(0.1 * rate)) / rate
    a = simulate(hydraulic_lumped(c1), np.ones_like(t), rate).data[1]
    b = simulate(hydraulic_lumped(c2), np.ones_like(t), rate).data[1]
    assert np.max(np.abs(a - b)) < 5e-3


def test_pi_pdt1_block_schema_matches_instruments():
    """The paper's eq. (4) schema, PI 0.9 (9.9 s + 1)/(3 s), correction 1/(0.7 s + 1), plant
    1/(s^2/25 + 0.28 s + 1) under unity feedback, as a PI_PDT1 controller (kp = 2.97,
    ki = 0.3 1/s, t1 = 0.7 s) around a 1 kg / 25 N/m / 7 N s/m mass (gain 25 N): step
    responses at y and at the correction output c match python-control's."""
    rate = 2e4
    c = Controller(name="schema", law="PI_PDT1", gains={"kp": 0.9 * 9.9 / 3, "ki": 0.9 / 3, "t1": 0.7}, rate_hz=rate,
                   dof="m1", drives=0,
                   reference="/r.x", gain=25.0, output_channel="/schema/c.x")
    m = LumpedModel.chain([1.0], [25.0], [7.0], output_quantity="displacement").replace(controllers=(c,))
    t = np.arange(int(20 * rate)) / rate
    s = simulate(m, np.ones_like(t), rate)
    steps = paper_block_schema().step(t)
    for row, point in ((1, "y"), (2, "c")):
        ref = steps[point].response
        err = np.max(np.abs(s.data[row] - ref)) / np.max(np.abs(ref))
        assert err < 2e-4, (point, err)


# ------------------------------------------------------------------------------ model file
def test_modelfile_round_trip_with_controller():
    c = Controller(name="emps", law="cascade", gains={"kp": 160.18, "kv": 243.45}, rate_hz=1000.0, dof="q",
                   drives="/emps/force.x",
                   reference="/emps/qg.x", velocity_filter=(0.5, 0.5), gain=35.15, saturation=10.0,
                   output_channel="/emps/vir.x", output_unit="V", feedforward="/emps/pulses.x")
    c2 = Controller(name="aux", law="PD2", gains={"kp": 1.0, "ka": 0.1}, rate_hz=1000.0, dof="q", drives=1,
                    measures=("acceleration",))
    m = LumpedModel(dofs=(Dof("q", 95.11),),
                    elements=(Damper(("q", "ground"), c=203.5), make_element("friction", ("q", "ground"), force=20.39)),
                    inputs=(Input(dof="q", channel="/emps/force.x", offset=3.16), Input(dof="q", channel="/aux.x")),
                    outputs=(Output("q", "displacement", "/emps/qm.x"),), name="emps", controllers=(c, c2))
    text = dumps_model(m)
    assert "[[controller]]" in text
    assert loads_model(text) == m
    assert loads_model(dumps_model(LumpedModel.chain([1.0], [1.0]))).controllers == ()


def test_modelfile_controller_errors_name_the_key():
    from vibroscope.errors import ModelFileError

    base = LumpedModel.chain([1.0], [1e4], output_quantity="displacement").replace(
        controllers=(Controller(name="c", law="P", gains={"kp": 1.0}, rate_hz=1000.0, dof="m1"),))
    text = dumps_model(base)
    for bad, key in ((text.replace('law = "P"', 'law = "X"'), "law"), (text.replace('dof = "m1"\ndrives', 'dof = "m7"\ndrives'), "dof"),
                     (text.replace("drives = 0", "drives = 4"), "drives"), (text.replace("gains = {kp = 1.0}", "gains = {kp = 1.0, kv = 2.0}"), "gains")):
        with pytest.raises(ModelFileError, match=f"key '{key}'"):
            loads_model(bad)


# ------------------------------------------------------------------------------ EMPS
def emps_model(gtau, *, friction: bool, pulses: bool = False) -> LumpedModel:
    """EMPS (Janot et al. 2019): M q'' + Fv q' [+ Fc sign(q') + offset] = gtau vir in the
    cascade loop (eq. 6) with the two-tap velocity filter, IDIM-LS values."""
    c = Controller(name="emps", law="cascade", gains={"kp": 160.18, "kv": 243.45}, rate_hz=1000.0, dof="q", drives=0,
                   reference="/emps/qg.x",
                   velocity_filter=(0.5, 0.5), gain=gtau, saturation=10.0, output_channel="/emps/vir.x",
                   output_unit="V", feedforward="/emps/pulses.x" if pulses else None)
    els = (Damper(("q", "ground"), c=203.5034),)
    if friction:
        els += (make_element("friction", ("q", "ground"), force=20.3935),)
    inp = Input(dof="q", channel="/emps/force.x", offset=3.1648 if friction else 0.0)
    return LumpedModel(dofs=(Dof("q", 95.1089),), elements=els, inputs=(inp,),
                       outputs=(Output("q", "displacement", "/emps/qm.x"),), name="EMPS", controllers=(c,))


def _relerr(y, yh):
    return 100 * np.linalg.norm(y - yh) / np.linalg.norm(y)


@pytest.mark.parametrize("fname, friction, max_q, max_vir", [
    ("DATA_EMPS.mat", False, 0.02, 45.0), ("DATA_EMPS.mat", True, 0.005, 5.5),
    ("DATA_EMPS_PULSES.mat", False, 0.02, 45.0), ("DATA_EMPS_PULSES.mat", True, 0.005, 6.0),
])
def test_emps_reproduction(shared_data, fname, friction, max_q, max_vir):
    """The logged qg through the loop reproduces qm and vir (eq. 11 relative errors; the
    description's Simulink model gives 0.0138 % / 5.85 % and 0.0080 % / 8.94 %)."""
    path = shared_data / "emps" / fname
    if not path.exists():
        pytest.skip(f"{path} not found")
    from scipy.io import loadmat

    d = loadmat(path)
    qg, qm, vir = (d[k].ravel().astype(float) for k in ("qg", "qm", "vir"))
    pulses = "pulses_N" in d
    m = emps_model(float(d["gtau"][0, 0]), friction=friction, pulses=pulses)
    rows = [qg] + ([d["pulses_N"].ravel().astype(float)] if pulses else [])
    s = simulate(m, np.vstack(rows), 1000.0)
    eq, ev = _relerr(qm, s.data[list(s.channels).index("/emps/qm.x")]), _relerr(vir, s.data[list(s.channels).index("/emps/vir.x")])
    assert eq < max_q and ev < max_vir, (eq, ev)


def test_closed_loop_1dof_friction_converges_and_tracks():
    """60 s of a 1-DOF drive with friction in its cascade loop at 1 kHz: every Newton step
    converges and the position follows the slow reference (its speed, >= 100x real time, is
    measured by ``benchmarks/run.py``'s closed_loop case, not here)."""
    m = emps_model(35.15, friction=True)
    t = np.arange(60000) / 1000.0
    r = 0.1 * (1 - np.cos(2 * np.pi * 0.2 * t))
    s = simulate(m, r, 1000.0)
    assert s.meta["newton_failures"] == 0
    q = s.data[list(s.channels).index("/emps/qm.x")]
    assert np.max(np.abs(q - r)) < 0.05 * np.max(np.abs(r))


def test_controllers_at_two_rates_each_update_on_their_own_ticks():
    """Two loops on a 2-DOF chain: a PID at 1 kHz on m1 and a PD at 250 Hz on m2. The kernel
    equals the discrete loop built from the plant ZOH-sampled at the fast period (Åström &
    Wittenmark sec. 2.3) in which the slow controller measures, differentiates and updates
    every 4th tick and holds its command in between."""
    T, every = 1e-3, 4
    m = LumpedModel.chain([1.0, 0.5], [1e4, 5e3], [20.0, 10.0], output_quantity="displacement")
    m = m.replace(inputs=(Input(dof="m1", channel="/f1.x"), Input(dof="m2", channel="/f2.x")))
    fast = Controller(name="fast", law="PID", gains={"kp": 3e4, "ki": 1e5, "kd": 50.0}, rate_hz=1 / T,
                      dof="m1", drives=0, reference="/r1.x")
    slow = Controller(name="slow", law="PD", gains={"kp": 2e3, "kd": 20.0}, rate_hz=1 / (every * T), dof="m2",
                      drives=1, reference="/r2.x")
    mc = m.replace(controllers=(fast, slow))
    n = 3000
    r1 = np.r_[np.zeros(7), np.ones(n - 7)] * 1e-3
    r2 = np.r_[np.zeros(13), -np.ones(n - 13)] * 5e-4
    s = simulate(mc, np.vstack([r1, r2]), 1 / T)
    A, B, C, _ = m.state_matrices()
    Phi, Gam = zoh_matrices(A, B, T)
    q = np.zeros(4)
    u = np.zeros((2, n))
    integ = e_prev = 0.0
    pf_prev = np.zeros(2)
    for k in range(n):
        y = C @ q
        # fast PID: trapezoidal integral, derivative of the measured position over T
        e = r1[k] - y[0]
        integ += 0.5 * 1e5 * T * (e + e_prev)
        e_prev = e
        vel = (y[0] - pf_prev[0]) / T
        pf_prev[0] = y[0]
        u[0, k] = 3e4 * e + integ - 50.0 * vel
        if k % every == 0:  # slow PD: its own period every * T
            vel2 = (y[1] - pf_prev[1]) / (every * T)
            pf_prev[1] = y[1]
            u[1, k] = 2e3 * (r2[k] - y[1]) - 20.0 * vel2
        else:
            u[1, k] = u[1, k - 1]
        q = Phi @ q + Gam @ u[:, k]
    cmd = s.data[-2:]
    np.testing.assert_allclose(cmd, u, rtol=0, atol=1e-9 * np.max(np.abs(u)))
    # the slow command changes only on its own ticks
    changes = np.flatnonzero(np.diff(cmd[1]) != 0) + 1
    assert changes.size > 10 and np.all(changes % every == 0)
    # run at one rate, the slow loop would be another loop
    one_rate = simulate(m.replace(controllers=(fast, Controller(name="slow", law="PD",
                                                                gains={"kp": 2e3, "kd": 20.0}, rate_hz=1 / T,
                                                                dof="m2", drives=1, reference="/r2.x"))),
                        np.vstack([r1, r2]), 1 / T)
    assert np.max(np.abs(one_rate.data[-1] - cmd[1])) > 1e-3 * np.max(np.abs(cmd[1]))


def test_a_controller_rate_that_does_not_divide_the_fastest_is_refused():
    m = LumpedModel.chain([1.0, 0.5], [1e4, 5e3], [20.0, 10.0], output_quantity="displacement")
    m = m.replace(inputs=(Input(dof="m1", channel="/f1.x"), Input(dof="m2", channel="/f2.x")))
    a = Controller(name="a", law="P", gains={"kp": 1e3}, rate_hz=1000.0, dof="m1", drives=0, reference="/r1.x")
    b = Controller(name="b", law="P", gains={"kp": 1e3}, rate_hz=300.0, dof="m2", drives=1, reference="/r2.x")
    with pytest.raises(ValueError, match="'b'.*rate_hz=300"):
        simulate(m.replace(controllers=(a, b)), np.zeros((2, 100)), 1000.0)


def test_a_driven_input_with_a_smooth_saturation_is_refused():
    """A loop's driven input clips in the compiled kernel: ``saturation_law = "tanh"`` there is a
    clear error naming the input and the controller, not a silent clip."""
    from dataclasses import replace

    m = LumpedModel.chain([1.0], [1e4], [20.0], output_quantity="displacement")
    c = Controller(name="c", law="P", gains={"kp": 3e3}, rate_hz=1000.0, dof="m1", drives=0, reference="/r.x")
    mc = m.replace(controllers=(c,), inputs=(replace(m.inputs[0], saturation=5.0, saturation_law="tanh"),))
    with pytest.raises(ValueError, match="saturation_law='tanh'.*controller 'c'|controller 'c'.*saturation_law"):
        simulate(mc, np.ones(100) * 1e-3, 1000.0)
    clipped = mc.replace(inputs=(replace(m.inputs[0], saturation=5.0),))
    assert np.abs(simulate(clipped, np.ones(100), 1000.0).data[2]).max() > 5.0  # the command itself is not limited
