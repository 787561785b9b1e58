"""gear-aware (methods/gear_aware.py): the calibration map keeps the gear's real torque out."""

import numpy as np
import pytest

from rippleb import JointSpec, make_log
from rippleb.methods.angle_adaptive import AngleAdaptiveFrozen, angle_regressors, phasor_table, ripple
from rippleb.methods.gear_aware import GearAware, gear_rows, smooth
from rippleb.testing import check_method

SPEC = JointSpec()


def _calibration(gear_amplitude: float):
    """Moves at several speeds, strain = torque + an order-4 ripple + an order-2 gear torque
    ``M e''`` with ``e = A cos(2 theta + 0.7)``, M = 3 kg m^2; torque_ref knows no gear."""
    fs = SPEC.fs
    t = np.arange(int(8.0 * fs)) / fs
    speed = 40.0 + 35.0 * np.sin(2 * np.pi * t / 4.0) * np.sign(np.sin(2 * np.pi * t / 2.7))   # rad/s of theta
    theta = np.cumsum(speed) / fs
    accel = np.gradient(speed, t)
    e_dd = -4 * gear_amplitude * np.cos(2 * theta + 0.7) * speed**2 - 2 * gear_amplitude * np.sin(2 * theta + 0.7) * accel
    torque = 10.0 * np.sin(2 * np.pi * 0.3 * t)
    gear = 3.0 * e_dd
    ripple = 0.6 * np.cos(4 * theta + 0.2)
    counts = np.floor(theta / (2 * np.pi) * SPEC.counts_per_rev)
    log = make_log(SPEC, {"t": t, "strain": 0.1 * (torque + gear + ripple), "encoder": counts,
                          "current": torque / (SPEC.gear_ratio * SPEC.torque_constant), "torque_ref": torque})
    return log, theta, gear


def _map_at(method, theta, y):
    """The map the method subtracts, at angles ``theta`` and loads ``y`` [Nm]."""
    counts = np.floor(theta / (2 * np.pi) * SPEC.counts_per_rev).astype(np.int64)
    phi = angle_regressors(counts, np.asarray(method.orders, dtype=np.int64), phasor_table(SPEC.counts_per_rev))
    return ripple(phi, y, method.map_)


def test_the_map_leaves_the_gear_torque_out_where_the_frozen_map_absorbs_it():
    log, theta, gear = _calibration(1e-4)
    ours, frozen = GearAware(), AngleAdaptiveFrozen()
    ours.fit(log)
    frozen.fit(log)
    order2 = np.column_stack([np.cos(2 * theta), np.sin(2 * theta)])

    def order2_amplitude(method):
        coef = np.linalg.lstsq(order2, _map_at(method, theta, log.torque_ref), rcond=None)[0]
        return float(np.hypot(*coef))
    assert order2_amplitude(frozen) > 0.05                       # the gear torque taken for ripple
    assert order2_amplitude(ours) < 0.2 * order2_amplitude(frozen)
    # the order-4 ripple is found by both
    order4 = np.column_stack([np.cos(4 * theta), np.sin(4 * theta)])
    for method in (ours, frozen):
        amp = np.hypot(*np.linalg.lstsq(order4, _map_at(method, theta, log.torque_ref), rcond=None)[0])
        assert amp == pytest.approx(0.6, rel=0.1)


def test_without_a_gear_torque_it_is_the_frozen_map():
    log, theta, _ = _calibration(0.0)
    ours, frozen = GearAware(), AngleAdaptiveFrozen()
    ours.fit(log)
    frozen.fit(log)
    assert np.allclose(_map_at(ours, theta, log.torque_ref), _map_at(frozen, theta, log.torque_ref), atol=5e-3)


def test_gear_rows_are_the_second_derivative_of_a_cosine_error():
    theta = np.linspace(0, 20, 2001)
    w, a = 3.0 + 0 * theta, 0.5 + 0 * theta
    rows = gear_rows(theta, w, a, (2,))
    expected = -4 * np.cos(2 * theta) * w**2 - 2 * np.sin(2 * theta) * a   # e = cos(2 theta)
    assert np.allclose(rows @ np.array([-4.0, 0.0, 0.0, -2.0]), expected)
    assert np.allclose(smooth(np.arange(10.0), 3)[1:-1], np.arange(10.0)[1:-1])


def test_gear_aware_passes_the_conformance_kit():
    check_method(GearAware)
