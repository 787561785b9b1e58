"""current-based: friction identification, the load-dependent inversion, the 130 Hz low-pass."""

import numpy as np
import pytest

from rippleb import JointSpec, SensorLog
from rippleb.methods.current_based import (CurrentBased, identify_friction, joint_torque,
                                           soft_sign, stribeck)

SPEC = JointSpec()
# a made-up joint, not the simulator's: Nm on the motor shaft, rad/s
TRUE = dict(coulomb=0.03, static=0.05, speed=4.0, viscous=2e-4, offset=0.002, scale=1.02,
            load=0.1)


def _motor_current(w, a, tau, p=TRUE, spec=SPEC):
    """Current of the model the method assumes, with sgn(w) exact."""
    s = np.sign(w)
    motor = (p["scale"] * tau / spec.gear_ratio + p["load"] * s * np.abs(tau) / spec.gear_ratio
             + stribeck(w, p["coulomb"], p["static"], p["speed"], p["viscous"]) + p["offset"]
             + spec.rotor_inertia * a)
    return motor / spec.torque_constant


def _log(levels, seconds, load, spec=SPEC, p=TRUE):
    """A log at the motor speeds ``levels`` [rad/s], smoothly blended, under ``load(t)``."""
    fs = spec.fs
    t = np.arange(int(seconds * fs)) / fs
    edges = np.linspace(0, seconds, len(levels) + 1)
    k = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(levels) - 1)
    w = np.array(levels, dtype=float)[k]
    # blend each change over 50 ms with a raised cosine so acceleration stays finite
    width = int(0.05 * fs)
    kernel = np.hanning(width)
    w = np.convolve(np.pad(w, (width, width), mode="edge"), kernel / kernel.sum(), "same")[width:-width]
    a = np.gradient(w) * fs
    angle = np.cumsum(w) / fs
    tau = load(t)
    counts = np.floor(angle / (2 * np.pi) * spec.counts_per_rev).astype(np.int64)
    current = _motor_current(w, a, tau, p, spec)
    return SensorLog(spec=spec, t=t, strain=np.zeros_like(t), encoder=counts, current=current,
                     torque_ref=tau), w, tau


def _calibration():
    levels = [2.0, 5.0, 10.0, 25.0, 60.0, -2.0, -5.0, -10.0, -25.0, -60.0] * 3
    return _log(levels, 15.0, lambda t: 20.0 * np.sin(2 * np.pi * 0.23 * t) + 5.0)[0]


def _stream(method, log, size=None):
    method.reset(log.spec)
    return np.concatenate([method.step(b) for b in log.blocks(size)])


def test_identification_recovers_a_known_friction_model():
    # with the velocity and acceleration filters before the tuning protocol (200 and 25 Hz):
    # its slower speed filters (87.8 and 7.3 Hz, then 60.2 and 22.5 Hz) delay the speed enough
    # to bias the viscous term, which the calibration score against torque_ref does not
    # penalise (docs/tuning.md, docs/methods/current-based.md)
    method = CurrentBased(velocity_cutoff=200.0, accel_cutoff=25.0, sign_width=0.5)
    method.fit(_calibration())
    f = method.friction_
    assert f["coulomb"] == pytest.approx(TRUE["coulomb"], abs=0.003)
    assert f["static"] == pytest.approx(TRUE["static"], abs=0.005)
    assert f["speed"] == pytest.approx(TRUE["speed"], rel=0.25)
    assert f["viscous"] == pytest.approx(TRUE["viscous"], abs=5e-5)
    assert f["scale"] == pytest.approx(TRUE["scale"], abs=0.01)
    assert f["load"] == pytest.approx(TRUE["load"], abs=0.01)


def test_identification_on_exact_regressors_is_exact():
    rng = np.random.default_rng(0)
    w = rng.choice([-1, 1], 4000) * rng.uniform(1.0, 60.0, 4000)
    load = rng.uniform(-0.3, 0.3, 4000)
    p = TRUE
    residual = (p["scale"] * load + p["load"] * np.sign(w) * np.abs(load) + p["offset"]
                + stribeck(w, p["coulomb"], p["static"], p["speed"], p["viscous"]))
    got = identify_friction(w, load, residual, [2.0, 4.0, 8.0], sign_width=0.5)
    for name in ("coulomb", "static", "speed", "viscous", "offset", "scale", "load"):
        assert got[name] == pytest.approx(p[name], rel=1e-6, abs=1e-9), name


def test_plain_exponential_model_fixes_scale_and_load_term():
    method = CurrentBased(load_dependent=False)
    method.fit(_calibration())
    assert method.friction_["scale"] == pytest.approx(1.0, abs=1e-9)
    assert method.friction_["load"] == pytest.approx(0.0, abs=1e-9)


def test_estimate_follows_torque_when_the_model_holds():
    method = CurrentBased()
    method.fit(_calibration())
    log, w, tau = _log([0.0, 15.0, 40.0, -15.0, -40.0, 0.0], 3.0,
                       lambda t: 25.0 * np.sin(2 * np.pi * 0.5 * t))
    y = _stream(method, log)
    # cruising for 60 ms or more: the acceleration estimate lags the 50 ms speed
    # changes (an honest weakness, measured on the scenarios, not asserted here)
    accel = np.abs(np.gradient(w)) > 1e-9
    recent = np.convolve(accel, np.ones(int(0.06 * SPEC.fs)))[: len(w)] > 0
    moving = (np.abs(w) > 5.0) & ~recent
    err = (y - tau)[moving]
    assert np.sqrt(np.mean(err ** 2)) < 0.5
    # without friction compensation the same log is far off
    bare = CurrentBased()
    bare.reset(SPEC)
    y_bare = _stream(bare, log)
    assert np.sqrt(np.mean((y_bare - tau)[moving] ** 2)) > 5 * np.sqrt(np.mean(err ** 2))


def test_load_dependent_friction_is_inverted_for_driving_and_back_driving():
    method = CurrentBased()
    method.friction_ = dict(TRUE)
    method.reset(SPEC)
    w = np.full(4, 30.0)
    tau = np.array([20.0, -20.0, 20.0, -20.0])
    w[2:] = -30.0
    current = _motor_current(w, np.zeros(4), tau)
    estimate = [joint_torque(i, v, 0.0, method.model_) for i, v in zip(current, w)]
    np.testing.assert_allclose(estimate, tau, rtol=1e-12)


@pytest.mark.parametrize("freq, gain", [(5.0, 1.0), (130.0, 2 ** -0.5), (1000.0, 0.017)])
def test_output_low_pass_is_130_hz(freq, gain):
    """At rest no friction is compensated: the output is N K_t i through the low-pass."""
    fs = SPEC.fs
    t = np.arange(int(1.0 * fs)) / fs
    current = np.sin(2 * np.pi * freq * t)
    log = SensorLog(spec=SPEC, t=t, strain=np.zeros_like(t), encoder=np.zeros(len(t), np.int64),
                    current=current)
    method = CurrentBased()
    y = _stream(method, log) / (SPEC.gear_ratio * SPEC.torque_constant)
    steady = y[int(0.5 * fs):]
    amplitude = np.sqrt(2 * np.mean(steady ** 2))
    assert amplitude == pytest.approx(gain, rel=0.03, abs=0.002)


def test_soft_sign_is_zero_at_rest_and_saturates():
    np.testing.assert_allclose(soft_sign(np.array([-5.0, -0.25, 0.0, 0.25, 5.0]), 0.5),
                               [-1.0, -0.5, 0.0, 0.5, 1.0])


def test_block_size_does_not_change_the_estimate():
    method = CurrentBased()
    method.fit(_calibration())
    log = _log([0.0, 20.0, -30.0], 0.6, lambda t: 10.0 * np.cos(3 * t))[0]
    y20 = _stream(method, log)
    np.testing.assert_allclose(_stream(method, log, 7), y20, atol=1e-8)
    np.testing.assert_allclose(_stream(method, log, 64), y20, atol=1e-8)


def test_fit_refuses_a_log_without_motion():
    t = np.arange(2000) / SPEC.fs
    log = SensorLog(spec=SPEC, t=t, strain=np.zeros_like(t), encoder=np.zeros(2000, np.int64),
                    current=np.zeros_like(t), torque_ref=np.zeros_like(t))
    with pytest.raises(ValueError, match="no motion"):
        CurrentBased().fit(log)


def test_conformance():
    testing = pytest.importorskip("rippleb.testing")
    testing.check_method(CurrentBased)


def test_fit_on_a_log_that_turns_one_way_says_why_and_what_to_do():
    # e.g. the scored paper-quintic log used as its own calibration (run --log without
    # --calibration): Coulomb friction and the current offset are the same regressor
    log = _log([5.0, 20.0, 40.0], 1.5, lambda t: 10.0 * np.sin(t))[0]
    with pytest.raises(ValueError, match="one direction only.*--calibration"):
        CurrentBased().fit(log)
