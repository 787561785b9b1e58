"""Output-locked ripple, strain hysteresis and the ripple's temperature coefficient."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rippleb import simulate
from rippleb.simulator.scenario import HYSTERESIS_NM, RippleSettings
from rippleb.simulator.ripple import (OutputRipple, _hysteresis_reference,
                                    bridge_ripple, hysteresis)
from rippleb.simulator.scenario import scenario_from_dict

LOAD_NM = 20.0


def _spin(ripple=None, seed=0):
    """Shoulder pan (no gravity) turning two output revolutions at 1 rad/s under 20 Nm."""
    raw = {"robot": {"joint": "shoulder_pan_joint"},
           "trajectory": {"start": -6.0, "segment": [
               {"kind": "ramp", "velocity": 1.0, "duration": 0.3},
               {"kind": "cruise", "duration": 12.1}]},
           "load": [{"torque": LOAD_NM, "start": 0.0, "rise": 0.05, "known": True}]}
    if ripple is not None:
        raw["ripple"] = ripple
    return simulate(scenario_from_dict(raw, name="spin"), seed)


def _output_order_spectrum(sim):
    """Strain [Nm] re-sampled on the output angle the encoder gives (counts / cpr / N)."""
    log = sim.log
    sel = np.flatnonzero(log.t > 0.4)
    out_rev = log.encoder[sel] / log.spec.counts_per_rev / log.spec.gear_ratio
    first = np.flatnonzero(np.diff(out_rev)) + 1      # one sample per new count
    # the bridge's slow zero drift (device truth, known to the test) is not a ripple
    reading = (log.strain - sim.device.drift_rate * log.t) / sim.device.gain
    angle, value = out_rev[first], reading[sel][first]
    points = 2048
    grid = angle[0] + np.arange(points) / points     # one whole output revolution
    x = np.interp(grid, angle, value)
    x = x - x.mean()
    orders = np.fft.rfftfreq(points, 1 / points)
    return orders, 2 * np.abs(np.fft.rfft(x)) / points


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_output_locked_ripple_shows_in_the_output_angle_spectrum(seed):
    sim = _spin(seed=seed)
    orders, amps = _output_order_spectrum(sim)
    floor = np.median(amps[(orders > 3) & (orders < 40)])
    locked = OutputRipple.from_seed(seed)
    for k, order in enumerate(locked.orders):
        expected = locked.base[k] + locked.load[k] * LOAD_NM
        peak = amps[np.argmin(np.abs(orders - order))]
        assert peak > 10 * floor, (order, peak, floor)
        assert peak == pytest.approx(expected, rel=0.1)
    # switched off in the scenario, the lines are gone
    orders, amps = _output_order_spectrum(_spin({"output_scale": 0.0}, seed=seed))
    for k, order in enumerate(locked.orders):
        assert amps[np.argmin(np.abs(orders - order))] < 0.1 * (locked.base[k] + locked.load[k] * LOAD_NM)


def _push(hysteresis_nm=None):
    """At rest; a known 20 Nm load rises over 0.8 s and falls over 0.8 s."""
    raw = {"robot": {"joint": "shoulder_pan_joint"},
           "trajectory": {"segment": [{"kind": "hold", "duration": 2.0}]},
           "load": [{"torque": LOAD_NM, "start": 0.2, "stop": 1.0, "rise": 0.8, "known": True}]}
    if hysteresis_nm is not None:
        raw["ripple"] = {"hysteresis_nm": hysteresis_nm}
    return simulate(scenario_from_dict(raw, name="push"), 2)


@pytest.mark.parametrize("width", [None, 0.0, 1.5])
def test_hysteresis_loop_of_the_reading_is_as_wide_as_set(width):
    sim = _push(width)
    log = sim.log
    reading = log.strain / sim.device.gain
    rising = (log.t > 0.2) & (log.t < 1.0)
    falling = (log.t > 1.0) & (log.t < 1.8)

    def at(sel, level):   # reading where the true torque crosses level, over +-0.5 Nm
        near = sel & (np.abs(log.torque_true - level) < 0.5)
        return np.mean(reading[near] - log.torque_true[near])

    expected = HYSTERESIS_NM if width is None else width
    for level in (5.0, 10.0, 15.0):
        assert at(falling, level) - at(rising, level) == pytest.approx(expected, abs=0.03)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-30, 30), min_size=2, max_size=40), st.floats(0.01, 5.0))
def test_hysteresis_is_bounded_and_follows_the_torque_rate(turns, width):
    # piecewise-linear torque through the turning points
    tau = np.concatenate([np.linspace(a, b, 50) for a, b in zip(turns[:-1], turns[1:])])
    h = hysteresis(tau, width)
    assert np.all(np.abs(h) <= width / 2 + 1e-12)
    rate = np.diff(tau)
    # once the torque has moved a full width in one direction, the reading lags by half of it
    for i in range(1, len(tau)):
        back = tau[max(0, i - 200): i + 1]
        if rate[i - 1] > 0 and tau[i] - back.min() >= width and np.all(np.diff(back[np.argmin(back):]) >= 0):
            assert h[i] == pytest.approx(-width / 2)
        if rate[i - 1] < 0 and back.max() - tau[i] >= width and np.all(np.diff(back[np.argmax(back):]) <= 0):
            assert h[i] == pytest.approx(width / 2)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-30, 30), min_size=1, max_size=300), st.floats(0.01, 5.0), st.integers(1, 4))
def test_run_by_run_hysteresis_is_the_play_operator(values, width, repeat):
    # repeated values make plateaus, where the run's direction must carry over
    tau = np.repeat(np.array(values), repeat)
    assert np.allclose(hysteresis(tau, width), _hysteresis_reference(tau, width), atol=1e-12)


def test_temperature_coefficient_scales_every_ripple_but_not_the_hysteresis():
    angle = np.linspace(0, 20, 1000)
    tau = 10 * np.sin(angle)
    wave = 0.6 * np.cos(4 * angle * 100)
    warm = RippleSettings(temperature_coeff=-0.004)
    flat = RippleSettings(temperature_coeff=0.0)
    scale = 1 - 0.004 * (40 - 25)
    assert warm.temperature_scale(40.0) == pytest.approx(scale)
    no_hyst = bridge_ripple(RippleSettings(hysteresis_nm=0.0, temperature_coeff=-0.004), 0, 40.0,
                            wave, angle, tau)
    assert np.allclose(no_hyst, scale * bridge_ripple(RippleSettings(hysteresis_nm=0.0), 0, 40.0,
                                                      wave, angle, tau))
    diff = bridge_ripple(warm, 0, 40.0, wave, angle, tau) - scale * bridge_ripple(flat, 0, 40.0, wave, angle, tau)
    assert np.allclose(diff, (1 - scale) * hysteresis(tau, HYSTERESIS_NM))
