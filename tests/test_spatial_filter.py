"""spatial-filter: the angle-stepped resonators null the ripple orders, hold still and fade
out at rest, pass the torque, and stream as the runner expects."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ripple_signals import SPEC, calibration, error_rms, estimate, synthetic_log  # noqa: F401 (fixture)

from rippleb.methods.spatial_filter import SpatialFilter
from rippleb.methods.raw import Raw
from rippleb.testing import check_method

SECONDS = 3.0
N = int(SECONDS * SPEC.fs)


def test_check_method():
    check_method(SpatialFilter)


@pytest.mark.parametrize("speed", [5.0, 10.0, 15.0])
def test_cancels_the_ripple_orders_at_a_steady_speed(calibration, speed):
    """After a second at constant speed (above ``fade_speed``, 4 rev/s) the ripple of
    orders 2, 4, 8 is gone down to the calibration's gain error (raw: 0.47 Nm RMS)."""
    log = synthetic_log(np.full(N, speed), 3.0)
    raw = error_rms(Raw(), calibration, log, skip_s=1.0)
    assert error_rms(SpatialFilter(), calibration, log, skip_s=1.0) < 0.15 * raw


def test_each_resonator_nulls_its_order_despite_its_neighbours(calibration):
    """The cross-fed harmonics: a lone order is removed as well as the sum (a bank of plain
    parallel band-passes at q = 2 would leave 30 % of order 2 through the order-4 one)."""
    for order in (2, 4, 8):
        log = synthetic_log(np.full(N, 5.0), 3.0, ripple={order: (1.0, 0.4)})
        assert error_rms(SpatialFilter(q=2.0), calibration, log, skip_s=1.0) < 0.08


def test_at_rest_the_filter_fades_out_to_the_calibrated_strain(calibration):
    speed = np.r_[np.full(N // 2, 5.0), np.zeros(N // 2)]
    log = synthetic_log(speed, 3.0)
    method = SpatialFilter()
    method.fit(calibration.for_method(keep_ref=True))
    out = estimate(method, log)
    rest = slice(N // 2 + int(0.1 * SPEC.fs), N)       # past the speed window
    np.testing.assert_allclose(out[rest], method.gain_ * log.strain[rest] + method.offset_,
                               atol=1e-12)
    assert method.scalars_[0] == 0.0                   # fade


def test_after_a_reversal_the_ripple_is_cancelled_again(calibration):
    speed = np.r_[np.full(N // 2, 5.0), np.full(N // 2, -5.0)]
    log = synthetic_log(speed, 3.0)
    raw = error_rms(Raw(), calibration, log, skip_s=2.0)
    assert error_rms(SpatialFilter(), calibration, log, skip_s=2.0) < 0.15 * raw


@settings(max_examples=25, deadline=None)
@given(q=st.floats(0.5, 20.0), speed=st.floats(0.5, 18.0), torque=st.floats(-40.0, 40.0, allow_subnormal=False),
       window=st.integers(1, 80))
def test_a_constant_torque_passes_unchanged(calibration, q, speed, torque, window):
    """No band-pass has gain at order 0: without ripple, a constant torque comes out as it
    went in, at any speed, quality and speed window."""
    log = synthetic_log(np.full(4000, speed), torque, ripple={})
    method = SpatialFilter(q=q, speed_window=window)
    method.fit(calibration.for_method(keep_ref=True))
    out = estimate(method, log)
    expected = method.gain_ * log.strain + method.offset_
    np.testing.assert_allclose(out, expected, atol=1e-9 * max(1.0, abs(torque)))


def test_bad_parameters_name_the_method():
    method = SpatialFilter(q=0.0)
    method.gain_, method.offset_ = 1.0, 0.0
    with pytest.raises(ValueError, match="spatial-filter: needs q > 0"):
        method.reset(SPEC)


def test_declares_its_tunable_parameters():
    params = SpatialFilter().get_params()
    for name, (low, high, scale) in SpatialFilter.tunable.items():
        assert name in params and low < high and scale in ("log", "linear", "int")
        assert low <= params[name] <= high
