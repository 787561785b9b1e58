"""The closed-loop flexible joint: transmission, integrator, controller design, and what
it does on the built-in scenarios (docs/physics.md, "Joint dynamics and position controller")."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rippleb import simulate
from rippleb.simulator.scenario import load_scenario
from rippleb.simulator import Device, controller, joint, robot
from rippleb.simulator import device as device_module

SPEC = load_scenario("paper-quintic").spec
N = SPEC.gear_ratio
LIFT = robot.load_table("ur5", "shoulder_lift_joint", {"elbow_joint": 1.5}, (-2.3, -0.8))
#: The UR5's base joint turns about the vertical: no gravity, and an inertia that does
#: not depend on its own angle (``h = 0``), so a free joint conserves energy and momentum.
PAN = robot.load_table("ur5", "shoulder_pan_joint", {"elbow_joint": 1.5}, (-0.5, 0.5))


def _integrate(table, state0, inputs, device=None, temperature_c=25.0, **switches):
    """Integrate from ``state0``; cogging off (it is a torque from the stator: it would
    break the momentum balance and shift the equilibria these tests compare against)."""
    device = device or Device.from_seed(0)
    gains = controller.design_gains(SPEC, float(np.mean(table.inertia)))
    motor = {**controller.motor_params(device, temperature_c, SPEC), "cogging": 0.0}
    params = joint.pack_params(**motor, **controller.loop_params(SPEC, gains, table, **switches))
    out = np.empty((len(joint.STATE), inputs.shape[1]))
    joint.integrate(params, controller.table_rows(table), np.ascontiguousarray(inputs), state0, out)
    return out


def _rest(table, q0, device=None):
    """State at rest with the shaft holding gravity at ``q0``, and the motor angle there."""
    device = device or Device.from_seed(0)
    tau0 = float(np.interp(q0, table.angle, table.gravity))
    theta0 = device.encoder_zero + N * (q0 + float(joint.twist(tau0)))
    return np.array([q0, 0.0, theta0, 0.0, tau0]), theta0


@settings(max_examples=200, deadline=None)
@given(torque=st.floats(-300, 300), guess=st.floats(-300, 300))
def test_inverse_twist_recovers_the_torque(torque, guess):
    assert joint.torque_of_twist(float(joint.twist(torque)), guess) == pytest.approx(torque, abs=1e-8)


@settings(max_examples=100, deadline=None)
@given(v=st.floats(-300, 300), angle=st.floats(-50, 50), tau=st.floats(-60, 60),
       temperature=st.floats(0, 60), seed=st.integers(0, 50))
def test_compiled_friction_is_the_devices(v, angle, tau, temperature, seed):
    device = Device.from_seed(seed)
    params = joint.pack_params(**controller.motor_params(device, temperature, SPEC),
                               **controller.loop_params(SPEC, controller.design_gains(SPEC, 2.7), LIFT))
    scale = joint.motor_coulomb_scale(params, angle, tau)
    motor, _ = joint.friction(v, params, scale, tau, True)
    assert motor == pytest.approx(float(device.motor_friction(np.array([v]), np.array([tau]), np.array([angle]),
                                                              temperature, N)[0]), rel=1e-9, abs=1e-12)
    bearing, _ = joint.friction(v / N, params, 1.0, tau, False)
    assert bearing == pytest.approx(float(device.output_bearing_friction(np.array([v / N]), temperature)[0]),
                                    rel=1e-9, abs=1e-12)


def test_free_oscillation_against_the_clamped_motor_is_at_the_predicted_resonance():
    q0 = -1.5
    state0, _ = _rest(LIFT, q0)
    state0[0] += 1e-4                                  # a small initial deflection
    n = 20_000
    out = _integrate(LIFT, state0, np.zeros((4, n)), controller=False, friction=False, clamp_motor=True)
    x = out[0] - q0
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    measured = (len(up) - 1) / ((up[-1] - up[0]) / SPEC.fs)
    # the link on the drive's tangent stiffness at the gravity torque, stiffened by gravity
    tau0 = state0[4]
    k = joint.stiffness(tau0) + np.interp(q0, LIFT.angle, np.gradient(LIFT.gravity, LIFT.angle))
    predicted = np.sqrt(k / np.interp(q0, LIFT.angle, LIFT.inertia)) / (2 * np.pi)
    assert measured == pytest.approx(predicted, rel=0.05)
    assert measured == pytest.approx(predicted, rel=0.002)   # what the integrator actually achieves
    assert 15 < predicted < 25                                # the "near 17 Hz"


def test_free_joint_conserves_energy_and_momentum_and_rings_at_the_two_mass_resonance():
    device = Device.from_seed(0)
    state0, theta0 = _rest(PAN, 0.0, device)
    state0[2] += N * 3e-4                              # motor wound up: about 9 Nm in the drive
    n = 40_000
    q, qd, theta, w, tau, _ = _integrate(PAN, state0, np.zeros((4, n)), device, controller=False,
                                         friction=False)
    M, J = float(np.mean(PAN.inertia)), SPEC.rotor_inertia
    assert np.ptp(PAN.inertia) < 1e-9 * M and np.ptp(PAN.gravity) < 1e-9
    energy = 0.5 * M * qd**2 + 0.5 * J * w**2 + joint.spring_energy(tau)
    assert np.abs(energy / energy[0] - 1).max() < 0.01        # symplectic Euler: bounded
    assert abs(energy[-2000:].mean() / energy[:2000].mean() - 1) < 1e-3   # and no drift
    momentum = M * qd + J * N * w
    assert np.abs(momentum).max() < 1e-9
    # the two masses ring against each other at sqrt(K (1/M + 1/(J N^2)))
    x = tau - tau.mean()
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    measured = (len(up) - 1) / ((up[-1] - up[0]) / SPEC.fs)
    k = float(np.mean(joint.stiffness(tau)))
    assert measured == pytest.approx(np.sqrt(k * (1 / M + 1 / (J * N**2))) / (2 * np.pi), rel=0.05)


def test_closed_loop_step_response_has_the_designed_damping():
    q0 = -1.5
    state0, theta0 = _rest(LIFT, q0)
    n, start, step = 20_000, 2_000, 0.5
    inputs = np.zeros((4, n))
    inputs[1] = theta0
    inputs[1, start:] += step                          # the motor reference steps by 0.5 rad
    inputs[3] = state0[4] / N                          # gravity fed forward
    out = _integrate(LIFT, state0, inputs, friction=False)
    overshoot = (out[2, start:] - theta0).max() / step - 1
    zeta = -np.log(overshoot) / np.sqrt(np.pi**2 + np.log(overshoot) ** 2)
    # The design is the rigid joint in continuous time; the 1 ms zero-order hold, the
    # velocity filter (6 deg at w_c) and the compliance cost a few hundredths of zeta.
    assert zeta == pytest.approx(controller.DAMPING_RATIO, abs=0.05)
    # and the response settles on the reference
    # gravity at the new angle is not fed forward: K_p holds it with a small error
    sag = (np.interp(out[0, -1], LIFT.angle, LIFT.gravity) - state0[4]) / N / controller.design_gains(
        SPEC, float(np.mean(LIFT.inertia))).kp
    assert out[2, -1000:].mean() - theta0 == pytest.approx(step - sag, abs=2 * np.pi / SPEC.counts_per_rev)


def _joint_error(sim):
    q = (sim.wave_angle - sim.device.encoder_zero) / N - joint.twist(sim.log.torque_true)
    return q - sim.scenario.trajectory(sim.log.t)[0]


@pytest.mark.parametrize("seed", [0, 1])
def test_tracking_error_on_paper_quintic_is_bounded_as_the_design_predicts(seed):
    """A PD loop holds a disturbance torque d on the motor shaft with an error d / K_p. The
    disturbances the feedforward leaves out: motor friction and cogging, and the model
    error of eq. (7) seen through the gear; their largest sum bounds the error, up to the
    4.3 % overshoot of the design and the drive's twist error."""
    sim = simulate("paper-quintic", seed)
    dev, log, sc = sim.device, sim.log, sim.scenario
    q_d, qd_d, _ = sc.trajectory(log.t)
    gains = controller.design_gains(SPEC, float(np.mean(joint.load_table(sc, q_d, nominal_seed=seed).inertia)))
    running = np.abs(dev.motor_friction(N * qd_d, log.torque_true, sim.wave_angle, sc.temperature_c, N))
    f = dev.friction
    holding = (np.exp(-device_module.COULOMB_TEMP_COEFF * (sc.temperature_c - 25))
               * (f["static"] + f["load"] * np.abs(log.torque_true) / N) * (1 + f["ripple1"] + f["ripple2"]))
    disturbance = (np.maximum(running, holding) + device_module.COGGING
                   + np.abs(log.torque_true - log.torque_ref) / N)
    bound = (1.05 * disturbance.max() / gains.kp / N
             + np.abs(joint.twist(log.torque_true) - joint.twist(log.torque_ref)).max())
    error = _joint_error(sim)[sim.eval_mask]
    assert np.abs(error).max() < bound
    assert np.abs(error).max() > 0.2 * bound          # the bound is the error's own size


def test_torque_ref_misses_torque_true_by_the_documented_amount():
    # docs/physics.md, "Joint dynamics and position controller": seeds 0-2 on paper-quintic
    stats = []
    for seed in range(3):
        sim = simulate("paper-quintic", seed)
        diff = (sim.log.torque_ref - sim.log.torque_true)[sim.eval_mask]
        stats.append((np.sqrt(np.mean(diff**2)), np.abs(diff).max()))
    rms, peak = np.array(stats).T
    assert rms == pytest.approx(DOCUMENTED_RMS, abs=0.01)
    assert peak == pytest.approx(DOCUMENTED_MAX, abs=0.01)


# with the gear's transmission error (issue 31), its order-2 share 0.25 (issue 38; at 0.5:
# RMS 0.785, 1.008, 0.823, max 2.208, 2.848, 2.763)
DOCUMENTED_RMS = [0.692, 0.882, 0.670]
DOCUMENTED_MAX = [1.727, 2.448, 2.241]


def test_motor_rests_without_chatter_in_the_holds_of_stop_restart():
    """At a stop the motor friction's smoothed sign ``tanh(w / eps)`` holds the unbalanced
    torque ``T`` by a creep ``w = eps atanh(T / F)``: an integrator that took the friction
    explicitly would flip the friction's sign every step (its time constant ``J_m eps / F``
    is some 1e-5 s). The motor must creep smoothly, within that speed."""
    sc = load_scenario("stop-restart")
    device = Device.from_seed(0)
    t = np.arange(int(round(sc.duration * SPEC.fs))) / SPEC.fs
    trajectory = sc.trajectory(t)
    nominal = joint.load_table(sc, trajectory[0], nominal_seed=0)
    tau_ref = nominal.model_torque(trajectory[0], trajectory[2])
    gains = controller.design_gains(SPEC, float(np.mean(nominal.inertia)))
    q, qd, theta, w, tau, current = controller.run(SPEC, device, sc.temperature_c, joint.load_table(sc, trajectory[0]),
                                                   gains, t, trajectory, tau_ref, sc.external_torque(t))
    holding = np.abs(trajectory[1]) < 1e-12
    settled = holding & (np.convolve(~holding, np.ones(4000), "full")[:len(t)] == 0)   # 0.2 s into a hold
    f = device.friction
    scale = np.exp(-device_module.COULOMB_TEMP_COEFF * (sc.temperature_c - 25))
    ripple = 1 + f["ripple1"] * np.cos(theta + device.friction_phase[0]) \
        + f["ripple2"] * np.cos(2 * theta + device.friction_phase[1])
    static = scale * ripple * (f["static"] + f["load"] * np.abs(tau) / N)   # friction level at w << w_s
    unbalanced = SPEC.torque_constant * current - tau / N - device.cogging(theta)
    holds = np.split(np.flatnonzero(settled), np.flatnonzero(np.diff(np.flatnonzero(settled)) > 1) + 1)
    assert len(holds) == 4                       # the start and the holds of 0.3 s and longer
    for hold in holds:
        ratio = np.abs(unbalanced[hold]).max() / static[hold].min()
        assert ratio < 1                         # the stop holds: less than the static level
        creep = device_module.SIGN_SMOOTHING * np.arctanh(ratio)
        assert np.abs(w[hold]).max() <= 1.05 * creep
        sign = np.sign(w[hold])
        assert np.sum(sign[1:] != sign[:-1]) < 10           # not a flip per sample


def test_a_shakers_chirp_is_in_the_reference_but_not_fed_through_the_motor():
    """Fed forward through the motor, 8 Nm of chirp drove the two-mass resonance to 75 Nm
    on the shaft; acting on the link from outside it stays within the drive's rating."""
    sim = simulate("torque-chirp", 1)
    log, sc = sim.log, sim.scenario
    assert np.abs(log.torque_true).max() < SPEC.rated_torque
    q_d, _, qdd_d = sc.trajectory(log.t)
    eq7 = joint.load_table(sc, q_d, nominal_seed=1).model_torque(q_d, qdd_d)
    assert np.allclose(log.torque_ref - eq7, sc.external_torque(log.t, known_only=True))
    assert np.ptp(sc.external_torque(log.t, known_only=True)) > 10
