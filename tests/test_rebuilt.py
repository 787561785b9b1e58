"""The torque rebuilt from the strain (rippleb/scoring/rebuilt.py), on a joint whose every part is known.

A synthetic joint: the motor turns through a rest-to-rest move; the true torque is a slow load
plus the gear's inertial torque, locked to the wave-generator angle and growing with the speed
squared; the strain reads the true torque plus the gauges' ripple, affine in the load, on
orders 2 and 4; the model reference is the load alone (what eq. (7) knows). Tolerances are
four times what was measured on this joint.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rippleb.scoring.rebuilt import MIN_REVOLUTIONS, rebuilt_torque, rms_error_rebuilt_nm

FS = 2000.0


def joint(seconds=20.0, revolutions=40.0, gear=0.0008, seed=0):
    """``(t, theta, load, gear torque, ripple)`` of a rest-to-rest quintic move."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    s = np.clip((t - 1.0) / (seconds - 2.0), 0.0, 1.0)
    theta = 2 * np.pi * revolutions * (10 * s**3 - 15 * s**4 + 6 * s**5)
    speed, accel = np.gradient(theta, 1 / FS), np.gradient(np.gradient(theta, 1 / FS), 1 / FS)
    load = 10.0 + 6.0 * np.sin(2 * np.pi * t / seconds) + 3.0 * s
    phase = rng.uniform(0, 2 * np.pi)
    # J d^2/dt^2 [a cos(2 theta + p)]: the inertial torque of an angle-locked error
    torque_gear = gear * (-4 * np.cos(2 * theta + phase) * speed**2 - 2 * np.sin(2 * theta + phase) * accel)
    ripple = (0.3 + 0.04 * load) * np.cos(2 * theta + 1.0) + (0.5 + 0.03 * load) * np.cos(4 * theta + 0.3)
    return t, theta, load, torque_gear, ripple


def test_the_rebuilt_torque_keeps_the_gears_torque_and_loses_the_ripple():
    _t, theta, load, gear, ripple = joint()
    true = load + gear
    strain = 0.01 * (true + ripple) + 0.2          # a bridge of 0.01 V/Nm with an offset
    rebuilt = rebuilt_torque(strain, theta, load, FS)
    rms = lambda x: float(np.sqrt(np.mean(x * x)))  # noqa: E731
    assert rms(gear) > 0.5 and rms(ripple) > 0.5
    assert rms(rebuilt - true) < 0.01 * rms(gear), rms(rebuilt - true)   # measured: 0.25 %
    # the model reference rewards erasing the gear's torque; the rebuilt torque does not
    erased, kept, rippled = true - gear, true, true + ripple
    assert rms(erased - load) < rms(kept - load)
    assert rms_error_rebuilt_nm(kept, rebuilt) < rms_error_rebuilt_nm(erased, rebuilt)
    assert rms_error_rebuilt_nm(kept, rebuilt) < rms_error_rebuilt_nm(rippled, rebuilt)


def test_a_log_that_hardly_turns_has_no_score():
    _t, theta, load, gear, ripple = joint(revolutions=MIN_REVOLUTIONS / 2)
    assert rebuilt_torque(load + ripple, theta, load, FS) is None
    assert np.isnan(rms_error_rebuilt_nm(load, None))
    still = np.zeros(4000)
    assert rebuilt_torque(np.ones(4000), still, np.linspace(0, 1, 4000), FS) is None


@settings(max_examples=12, deadline=None, derandomize=True)
@given(gain=st.floats(-50.0, 50.0).filter(lambda g: abs(g) > 1e-2), offset=st.floats(-5.0, 5.0),
       turns=st.integers(-3, 3))
def test_the_bridges_gain_offset_and_the_encoders_zero_do_not_change_it(gain, offset, turns):
    """The strain is calibrated on the reference over the log, and the map reads whole orders of
    the angle: a bridge of any sign and offset, or an encoder zero a whole number of turns
    away, rebuild the same torque: to 1e-3 Nm (measured 3e-4 Nm: the fit's small ridge weighs
    the columns as the bridge's scale leaves them)."""
    _t, theta, load, gear, ripple = joint(seconds=10.0, revolutions=20.0)
    strain = load + gear + ripple
    base = rebuilt_torque(strain, theta, load, FS)
    other = rebuilt_torque(gain * strain + offset, theta + 2 * np.pi * turns, load, FS)
    np.testing.assert_allclose(other, base, rtol=0, atol=1e-3)


@pytest.mark.parametrize("gear", [0.0, 0.0008])
def test_without_a_gear_torque_it_is_the_strain_without_its_ripple(gear):
    _t, theta, load, torque_gear, ripple = joint(gear=gear, seed=3)
    rebuilt = rebuilt_torque(load + torque_gear + ripple, theta, load, FS)
    np.testing.assert_allclose(rebuilt, load + torque_gear, rtol=0, atol=0.02)   # measured: 0.005 Nm


@pytest.mark.slow
def test_on_a_low_ratio_joint_the_rebuilt_torque_is_nearer_the_truth_than_the_model():
    """A 50:1 joint's `paper-quintic` turns 10 motor revolutions, the slow part of it about 2:
    the fit must cover enough of them (``MIN_REVOLUTIONS``) or its ripple columns take up the
    model's own error (13.7 Nm from the truth with 2, against the model's 5.6; 2.5 with 4)."""
    from rippleb.engine.sweep import swept_scenario
    from rippleb.scoring.metrics import Truth
    from rippleb.simulator import simulate
    from rippleb.simulator.transducer import lab_log

    sim = simulate(swept_scenario("paper-quintic", {"joint.gear_ratio": 50.0, "joint.counts_per_rev": 4096}), 5)
    truth = Truth.from_recording(lab_log(sim, "model"))
    rebuilt = rebuilt_torque(truth.strain, truth.encoder_angle, truth.torque_ref, truth.fs)
    rms = lambda x: float(np.sqrt(np.mean(x * x)))  # noqa: E731
    model_error = rms(truth.torque_ref - sim.log.torque_true)
    assert rms(rebuilt - sim.log.torque_true) < 0.6 * model_error, (rms(rebuilt - sim.log.torque_true), model_error)
