"""Tests of ``kalman-ripple`` (methods/kalman_ripple.py).

Synthetic logs here are built from a known torque, known ripple harmonics of a known
wave-generator angle and white noise, so that the filter can be checked against the truth
without the simulator; the conformance and filterpy checks use simulated logs.
"""

import dataclasses

import numpy as np
import pytest

from rippleb import JointSpec, make_log, read_log, write_log
from rippleb.methods._kalman_ripple_filter import pairwise_sum
from rippleb.methods.kalman_ripple import KalmanRipple, kf_step, phasor_table, tick_regressors

SPEC = JointSpec()
GAIN = 40.0       # Nm/V of the synthetic bridge
OFFSET_V = 0.1    # V
NOISE = 0.05      # Nm rms per sample
ORDERS = np.array([1, 2, 4, 8])
AMP0 = np.array([0.1, 0.6, 1.5, 0.4])         # Nm at no load
AMP1 = np.array([0.002, 0.01, 0.03, 0.008])   # Nm per Nm of |load|
PHASE = np.array([0.3, 1.1, -0.7, 0.5])


def synthetic(t, motor_angle, tau, seed=0):
    """A log with strain = (tau + sum_k (A0 + A1 |tau|) cos(k theta + p) + noise) / GAIN + offset."""
    rng = np.random.default_rng(seed)
    counts = np.floor(motor_angle / (2 * np.pi) * SPEC.counts_per_rev).astype(np.int64)
    amp = AMP0[:, None] + AMP1[:, None] * np.abs(tau)
    ripple = (amp * np.cos(ORDERS[:, None] * motor_angle + PHASE[:, None])).sum(axis=0)
    strain = (tau + ripple + rng.normal(0.0, NOISE, len(t))) / GAIN + OFFSET_V
    return make_log(SPEC, {"t": t, "strain": strain, "encoder": counts, "current": np.zeros_like(t),
                           "torque_true": tau, "torque_ref": tau})


def synthetic_calibration(seed=0):
    """Constant motor speed (5 rev/s) both ways under five known loads, 0.5 s each."""
    t = np.arange(int(5.0 * SPEC.fs)) / SPEC.fs
    segment = (t // 0.5).astype(int)
    tau = np.array([-30.0, -10.0, 0.0, 10.0, 30.0] * 2)[segment]
    speed = np.where(segment < 5, 1.0, -1.0) * 2 * np.pi * 5.0
    return synthetic(t, np.cumsum(speed) / SPEC.fs, tau, seed)


def synthetic_move(seed=1, duration=2.0):
    """A joint that moves (motor up to 50 rad/s) under a sinusoidal torque."""
    t = np.arange(int(duration * SPEC.fs)) / SPEC.fs
    speed = 50.0 * np.sin(np.pi * t / duration) + 10.0
    tau = 20.0 * np.sin(2 * np.pi * 0.7 * t) - 5.0
    return synthetic(t, np.cumsum(speed) / SPEC.fs, tau, seed)


def estimate(method, log, block_size=None):
    method.reset(log.spec)
    return np.concatenate([method.step(b) for b in log.for_method(keep_ref=False).blocks(block_size)])


@pytest.fixture(scope="module")
def fitted():
    method = KalmanRipple()
    method.fit(synthetic_calibration().for_method(keep_ref=True))
    return method


def test_fit_recovers_gain_offset_and_noise(fitted):
    assert fitted.gain_ == pytest.approx(GAIN, rel=1e-3)
    assert fitted.offset_ == pytest.approx(-GAIN * OFFSET_V, abs=0.05)
    # tick mean of white noise: NOISE^2 / samples per tick
    assert fitted.r_ == pytest.approx(NOISE ** 2 / SPEC.block_size, rel=0.3)
    # the no-load map: amplitude of order 4 (the dominant one)
    a, b = fitted.c0_[4:6]
    assert np.hypot(a, b) == pytest.approx(AMP0[2], rel=0.05)


def test_converges_to_the_torque_and_removes_the_ripple(fitted):
    log = synthetic_move()
    est = estimate(fitted, log)
    settled = slice(int(0.1 * SPEC.fs), None)
    error = (est - log.torque_true)[settled]
    raw_error = (fitted.gain_ * log.strain + fitted.offset_ - log.torque_true)[settled]
    assert np.sqrt(np.mean(raw_error ** 2)) > 1.0            # the ripple is there
    assert np.sqrt(np.mean(error ** 2)) < 0.15 * np.sqrt(np.mean(raw_error ** 2))
    assert abs(np.mean(error)) < 0.05
    # no ripple left in the error: its order-4 content is small
    angle = 2 * np.pi * log.encoder[settled] / SPEC.counts_per_rev
    order4 = np.abs(np.mean(error * np.exp(-4j * angle))) * 2
    assert order4 < 0.05 * AMP0[2]


def test_torque_change_at_rest_goes_to_the_torque(fitted):
    # move for 1 s, stop, then a 10 Nm step while at rest
    t = np.arange(int(2.0 * SPEC.fs)) / SPEC.fs
    speed = np.where(t < 1.0, 40.0, 0.0)
    tau = np.where(t < 1.5, 5.0, 15.0)
    log = synthetic(t, np.cumsum(speed) / SPEC.fs, tau, seed=3)
    est = estimate(fitted, log)
    before, after = slice(int(1.4 * SPEC.fs), int(1.5 * SPEC.fs)), slice(int(1.6 * SPEC.fs), None)
    step = est[after].mean() - est[before].mean()
    assert step == pytest.approx(10.0, abs=0.3)


def test_output_does_not_depend_on_block_cutting(fitted):
    log = synthetic_move(duration=0.5)
    base = estimate(fitted, log)
    for size in (1, 7, 33, 1000):
        np.testing.assert_allclose(estimate(fitted, log, size), base, rtol=0, atol=1e-9)


def test_columns_of_other_dtypes_give_the_same_estimate(fitted):
    """A block of int32 counts and float32 strain (not a log's dtypes) is filtered as the
    log's columns would be."""
    log = synthetic_move(duration=0.2).for_method(keep_ref=False)
    base = estimate(fitted, log)
    fitted.reset(log.spec)
    other = [dataclasses.replace(b, encoder=b.encoder.astype(np.int32)) for b in log.blocks()]
    np.testing.assert_array_equal(np.concatenate([fitted.step(b) for b in other]), base)
    fitted.reset(log.spec)
    assert len(fitted.step(dataclasses.replace(other[0], strain=other[0].strain[:0],
                                               encoder=other[0].encoder[:0]))) == 0


@pytest.mark.parametrize("n", [1, 3, 7, 8, 9, 16, 20, 23, 100, 128, 129, 200, 257, 1000])
def test_pairwise_sum_is_numpys_sum_bit_for_bit(n):
    """The tick means of the compiled step equal numpy's ``sum(axis=1)`` they replaced."""
    rng = np.random.default_rng(n)
    a = rng.normal(size=3 * n) * 10.0 ** rng.integers(-4, 5, size=3 * n)
    rows = a.reshape(3, n).sum(axis=1)
    assert [0.0 + pairwise_sum(a, j * n, n) for j in range(3)] == list(rows)
    assert np.signbit(0.0 + pairwise_sum(np.array([-0.0]), 0, 1)) == np.signbit(np.sum([-0.0]))


def test_reset_before_fit_is_refused():
    with pytest.raises(RuntimeError, match="fit"):
        KalmanRipple().reset(SPEC)


def test_tick_regressors_are_block_means_of_cos_sin():
    counts = np.array([[0, 100, 900, 2400], [3, -7, 12345, 5]])
    phi = tick_regressors(counts, np.array([2, 4]), phasor_table(2500))
    angle = 2 * np.pi * counts / 2500
    expected = np.stack([np.cos(2 * angle).mean(1), np.sin(2 * angle).mean(1),
                         np.cos(4 * angle).mean(1), np.sin(4 * angle).mean(1)], axis=1)
    np.testing.assert_allclose(phi, expected, atol=1e-12)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A simulated calibration and stop-restart log, written to Parquet and read back."""
    simulator = pytest.importorskip("rippleb.simulator")
    folder = tmp_path_factory.mktemp("recorded")
    logs = []
    for name, seconds in (("calibration", None), ("stop-restart", 1.5)):
        log = simulator.simulate(name, 0).log
        stop = len(log) if seconds is None else int(seconds * log.spec.fs)
        columns = {k: v[:stop] for k, v in log.columns().items()}
        log = make_log(log.spec, columns)
        logs.append(read_log(write_log(log, folder / f"{name}.parquet"), spec=log.spec))
    return logs


@pytest.mark.parametrize("torque_rate", [False, True])
def test_matches_filterpy_kalmanfilter(recorded, torque_rate):
    from filterpy.kalman import KalmanFilter

    calibration, log = recorded
    method = KalmanRipple(torque_rate=torque_rate)
    method.fit(calibration)
    est = estimate(method, log)

    D = method.tick_
    ticks = len(log) // D
    counts = log.encoder[:ticks * D].reshape(ticks, D)
    phi = tick_regressors(counts, method.orders_, method.table_)
    y = method.gain_ * log.strain[:ticks * D].reshape(ticks, D).mean(axis=1) + method.offset_
    turns = method._turns(counts, counts[0, 0])
    x0, P0 = method._initial_state()
    kf = KalmanFilter(dim_x=len(x0), dim_z=1)
    kf.x, kf.P, kf.F = x0[:, None].copy(), P0.copy(), method.F_.copy()
    Q, Q_turn = method._q_torque_matrix(method.q_torque_), method._q_ripple_matrix(method.q_ripple_)
    torque = np.empty(ticks)
    for j in range(ticks):
        kf.Q = Q + turns[j] * Q_turn
        kf.predict()
        h = method._rows(phi[j:j + 1], kf.x[0])
        kf.update(y[j], R=method.r_, H=h)
        torque[j] = kf.x[0, 0]
        if torque_rate:
            # the output at a tick's last sample extrapolates from the tick centre
            torque[j] += kf.x[1, 0] * 0.5 * (D - 1) / log.spec.fs
    np.testing.assert_allclose(est[np.arange(ticks) * D + D - 1], torque, rtol=0, atol=1e-6)
    np.testing.assert_allclose(method.P_, kf.P, rtol=0, atol=1e-6)
    assert np.ptp(torque) > 5.0  # the log does exercise the filter


def test_kf_step_is_the_kalman_equations():
    rng = np.random.default_rng(0)
    n = 5
    A = rng.normal(size=(n, n))
    P0 = A @ A.T + np.eye(n)
    x0, h, q, F = rng.normal(size=n), rng.normal(size=n), rng.uniform(0.1, 1, n), rng.normal(size=(n, n))
    x, P = x0.copy(), P0.copy()
    kf_step(x, P, F, True, q, h, 0.7, 0.2)
    Pp = F @ P0 @ F.T + np.diag(q)
    K = Pp @ h / (h @ Pp @ h + 0.2)
    np.testing.assert_allclose(x, F @ x0 + K * (0.7 - h @ F @ x0), atol=1e-12)
    np.testing.assert_allclose(P, (np.eye(n) - np.outer(K, h)) @ Pp, atol=1e-12)


@pytest.mark.slow
def test_conforms_to_the_runner_contract():
    testing = pytest.importorskip("rippleb.testing")
    testing.check_method(KalmanRipple)
