"""periodic-dob: the angle comb learns the ripple, holds it at rest, keeps its mean out, and
streams as the runner expects."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ripple_signals import (SPEC, calibration, error_rms, estimate, synthetic_log,  # noqa: F401 (fixture)
                            with_index)

from rippleb.methods.periodic_dob import PeriodicDOB
from rippleb.methods.raw import Raw
from rippleb.testing import check_method, default_logs

N = int(3.0 * SPEC.fs)


def test_check_method():
    check_method(PeriodicDOB)


def test_check_method_with_index_and_power_cycle():
    calibration, log = default_logs()
    check_method(PeriodicDOB, log=with_index(log, 700, count_offset=1000),
                 calibration=with_index(calibration, 700))


@pytest.mark.parametrize("speed", [2.0, 5.0, -5.0])
def test_learns_the_ripple_from_an_empty_table(calibration, speed):
    """No calibration map: after a few turns the comb holds the ripple (to its bins). The
    nominal torque is set slower than the ripple (1 Hz): ripple inside its band is taken
    for torque and reaches the table only in part."""
    log = synthetic_log(np.full(N, speed), 3.0)
    raw = error_rms(Raw(), calibration, log, skip_s=2.0)
    cold = PeriodicDOB(warm_start=False, memory_revs=2.0, nominal_hz=1.0)
    assert error_rms(cold, calibration, log, skip_s=2.0) < 0.15 * raw


def test_at_rest_the_ripple_of_the_resting_angle_is_still_removed(calibration):
    speed = np.r_[np.full(N // 2, 5.0), np.zeros(N // 2)]
    log = synthetic_log(speed, 3.0)
    rest = int(0.6 * N)
    assert error_rms(PeriodicDOB(), calibration, log, skip_s=rest / SPEC.fs) < 0.03


def test_re_homing_after_a_power_cycle_restores_the_calibration_table(calibration):
    log = with_index(synthetic_log(np.full(N, 2.0), 3.0), 700, count_offset=1000)
    method = PeriodicDOB(memory_revs=1e9)                  # no learning: the table alone
    method.fit(with_index(calibration, 700).for_method(keep_ref=True))
    out = estimate(method, log)
    first = int(np.flatnonzero(log.index)[0])
    error = out - log.torque_true
    assert np.sqrt(np.mean(error[first:] ** 2)) < 0.03 < 0.3 < np.sqrt(np.mean(error[:first] ** 2))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 16), bins=st.integers(1, 2500), memory=st.floats(0.5, 100.0),
       offset=st.floats(-50.0, 50.0, allow_subnormal=False))
def test_the_table_never_takes_an_offset(calibration, seed, bins, memory, offset):
    """The comb's zero-order tooth is removed and the nominal torque starts on the first
    estimate: a strain offset reaches the estimate whole, along any path of the angle."""
    rng = np.random.default_rng(seed)
    n = 3000
    strain = rng.normal(10.0, 5.0, n)
    counts = np.cumsum(rng.integers(-3, 4, n)).astype(np.int64)
    method = PeriodicDOB(bins=bins, memory_revs=memory)
    method.fit(calibration.for_method(keep_ref=True))
    outputs = []
    for shift in (0.0, offset):
        method.reset(SPEC)
        out = np.empty(n)
        method._run(strain + shift / method.gain_, counts, out)
        outputs.append(out)
    np.testing.assert_allclose(outputs[1] - outputs[0], offset, atol=1e-8 * (1 + abs(offset)))


def test_bad_bins_name_the_method_and_the_range(calibration):
    with pytest.raises(ValueError, match=r"periodic-dob: bins=3000 must lie in 1\.\.2500"):
        PeriodicDOB(bins=3000).fit(calibration.for_method(keep_ref=True))


def test_bad_parameters_name_the_method(calibration):
    method = PeriodicDOB(memory_revs=0.0)
    method.fit(calibration.for_method(keep_ref=True))
    with pytest.raises(ValueError, match="periodic-dob: needs memory_revs > 0"):
        method.reset(SPEC)


def test_declares_its_tunable_parameters():
    params = PeriodicDOB().get_params()
    for name, (low, high, scale) in PeriodicDOB.tunable.items():
        assert name in params and low < high and scale in ("log", "linear", "int")
        assert low <= params[name] <= high
