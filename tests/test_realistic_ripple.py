"""The ripple no method models, added under `realistic` by issue 31: orders the methods
do not notch or map (`mismatch.extra_orders`), and a ripple that follows the load's
history (`mismatch.load_history`); rippleb/simulator/gauge.py, docs/physics.md."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, strategies as st

from rippleb.simulator.mismatch import Unmodelled
from rippleb.simulator.device import Device
from rippleb.simulator.gauge import EXTRA_ORDERS, play, wave_ripple
from rippleb.data import JointSpec

SPEC = JointSpec()


def _ripple(device, angle, torque, **knobs):
    return wave_ripple(device, dataclasses.replace(Unmodelled().resolve(False), **knobs), angle, torque, SPEC)


@given(st.lists(st.floats(-100, 100), min_size=1, max_size=300), st.floats(0.0, 20.0))
def test_play_stays_within_half_its_width_and_moves_only_when_pushed(values, width):
    x = np.array(values)
    y = np.empty_like(x)
    play(x, width, y)
    assert np.all(np.abs(y - x) <= width / 2 + 1e-9)
    moved = np.flatnonzero(np.diff(y) != 0) + 1
    assert np.allclose(np.abs(y[moved] - x[moved]), width / 2)   # dragged by the input's edge


def test_loading_and_unloading_give_two_ripples_at_one_load():
    device = Device.from_seed(4)
    angle = np.full(400, 1.3)                                     # one angle, the load up then down
    torque = np.concatenate([np.linspace(0, 40, 200), np.linspace(40, 0, 200)])
    plain = _ripple(device, angle, torque)
    history = _ripple(device, angle, torque, load_history_nm=5.0)
    rise, fall = np.argmin(np.abs(torque[:200] - 20)), 200 + np.argmin(np.abs(torque[200:] - 20))
    assert plain[rise] == pytest.approx(plain[fall], abs=1e-2)      # |tau| alone: one value
    # the ripple follows a load that lags by half the width: 2.5 Nm below while loading,
    # above while unloading
    tau = torque[rise]
    expected = sum(b * 5.0 * np.cos(o * 1.3 + p + s * tau) for o, b, p, s in
                   zip(device.ripple_orders, device.ripple_load, device.ripple_phase, device.ripple_phase_shift))
    assert history[fall] - history[rise] == pytest.approx(expected, abs=2e-2)
    assert abs(expected) > 0.05


def test_extra_orders_put_the_order_8_amplitude_at_order_3_and_the_bearing_order():
    device = Device.from_seed(2)
    angle = np.linspace(0, 2 * np.pi * 200, 400_000)            # 200 turns at constant load
    torque = np.full_like(angle, 10.0)
    added = _ripple(device, angle, torque, extra_orders=1.0) - _ripple(device, angle, torque)
    i = device.ripple_orders.index(8)
    expected = device.ripple_base[i] + device.ripple_load[i] * 10.0
    for order in EXTRA_ORDERS:
        fit = np.linalg.lstsq(np.column_stack([np.cos(order * angle), np.sin(order * angle)]), added,
                              rcond=None)[0]
        assert np.hypot(*fit) == pytest.approx(expected, rel=0.02), order
    assert any(o != int(o) for o in EXTRA_ORDERS)                  # one is not periodic per turn


def test_both_knobs_off_leave_the_ripple_bit_for_bit():
    device = Device.from_seed(1)
    angle = np.linspace(0, 60, 5000)
    torque = 20 * np.sin(angle / 7)
    assert np.array_equal(_ripple(device, angle, torque), device.ripple(angle, torque))
