"""fourier-lms: the angle-indexed combiner learns the ripple, learns nothing at rest, keeps
cancelling through a reversal and a re-homing, and streams as the runner expects."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ripple_signals import (SPEC, calibration, error_rms, estimate, synthetic_log,  # noqa: F401 (fixture)
                            with_index)

from rippleb.methods._angle_map import harmonic_regressors
from rippleb.methods.fourier_lms import FourierLMS
from rippleb.methods.raw import Raw
from rippleb.testing import check_method, default_logs

N = int(3.0 * SPEC.fs)


def test_check_method():
    check_method(FourierLMS)


def test_check_method_with_index_and_power_cycle():
    """Causal and cut-independent also when the log re-homes on an index pulse mid-block."""
    calibration, log = default_logs()
    check_method(FourierLMS, log=with_index(log, 700, count_offset=1234),
                 calibration=with_index(calibration, 700))


def test_fit_recovers_the_ripple_as_fourier_coefficients(calibration):
    method = FourierLMS(orders=(2, 4, 8))
    method.fit(calibration.for_method(keep_ref=True))
    # RIPPLE: a cos(k theta + p) = a cos p cos k theta - a sin p sin k theta
    expected = [0.25 * np.cos(0.3), -0.25 * np.sin(0.3), 0.6 * np.cos(1.1), -0.6 * np.sin(1.1),
                0.15 * np.cos(-0.7), -0.15 * np.sin(-0.7)]
    np.testing.assert_allclose(method.map_, expected, atol=1e-3)
    assert method.gain_ == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("speed", [5.0, -5.0, 15.0])
def test_learns_the_ripple_from_zero_weights(calibration, speed):
    """Vaz & Thakor's cold start: after 2 s the ripple is down to a tenth. The bias weight
    is set slower than the ripple (3 Hz): ripple inside its band is taken by the bias and
    reaches the harmonic weights only in part, so they learn it slowly (the cold start is
    not the method's operating point, the warm start is)."""
    log = synthetic_log(np.full(N, speed), 3.0)
    raw = error_rms(Raw(), calibration, log, skip_s=2.0)
    cold = FourierLMS(warm_start=False, mu=0.5, bias_hz=3.0)
    assert error_rms(cold, calibration, log, skip_s=2.0) < 0.1 * raw


def test_after_a_reversal_the_ripple_stays_cancelled(calibration):
    speed = np.r_[np.full(N // 2, 5.0), np.full(N // 2, -5.0)]
    log = synthetic_log(speed, 3.0)
    assert error_rms(FourierLMS(), calibration, log) < 0.15 * error_rms(Raw(), calibration, log)


def test_re_homing_after_a_power_cycle_restores_the_calibration_map(calibration):
    """The counts start 1000 off (0.4 turn); from the first index pulse the map is right."""
    log = with_index(synthetic_log(np.full(N, 2.0), 3.0), 700, count_offset=1000)
    method = FourierLMS(mu=0.0)
    method.fit(with_index(calibration, 700).for_method(keep_ref=True))
    out = estimate(method, log)
    first = int(np.flatnonzero(log.index)[0])
    after = np.sqrt(np.mean((out[first:] - log.torque_true[first:]) ** 2))
    before = np.sqrt(np.mean((out[:first] - log.torque_true[:first]) ** 2))
    assert after < 0.02 and before > 0.3


@settings(max_examples=25, deadline=None)
@given(count=st.integers(-10_000, 10_000), seed=st.integers(0, 2 ** 16),
       level=st.floats(-40.0, 40.0, allow_subnormal=False))
def test_nothing_is_learned_at_rest(calibration, count, seed, level):
    """At a standing count the references stand still: whatever the strain does, the
    harmonic weights keep their value, and the estimate is the strain minus the map there."""
    n = 2000
    strain = level + np.random.default_rng(seed).normal(0.0, 5.0, n)
    method = FourierLMS(mu=1.0)
    method.fit(calibration.for_method(keep_ref=True))
    method.reset(SPEC)
    out = np.empty(n)
    method._run(strain, np.full(n, count, dtype=np.int64), out)
    np.testing.assert_array_equal(method.w_, method.map_)
    x = harmonic_regressors(np.array([count]), np.asarray(method.orders), SPEC.counts_per_rev)
    np.testing.assert_allclose(out, method.gain_ * strain + method.offset_ - x @ method.map_,
                               atol=1e-9)


def test_bad_parameters_name_the_method(calibration):
    method = FourierLMS(bias_hz=0.0)
    method.fit(calibration.for_method(keep_ref=True))
    with pytest.raises(ValueError, match="fourier-lms: needs mu >= 0"):
        method.reset(SPEC)


def test_declares_its_tunable_parameters():
    params = FourierLMS().get_params()
    for name, (low, high, scale) in FourierLMS.tunable.items():
        assert name in params and low < high and scale in ("log", "linear", "int")
        assert low <= params[name] <= high
