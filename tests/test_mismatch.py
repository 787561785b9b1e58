"""The physics beyond the methods' models (rippleb/simulator/mismatch.py, docs/physics.md "Beyond the
methods' models"): each effect visible in a simulated log at its documented size, measured
on the log; each off, the log is today's bit for bit."""

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rippleb  # noqa: F401  (before numpy users: the portable numeric paths)
from rippleb import InputError, simulate
from rippleb.simulator.mismatch import KNOB_BY_NAME, KNOBS, REALISTIC, Unmodelled
from rippleb.engine.rows import scenario_hash
from rippleb.simulator.scenario import load_scenario, scenario_from_dict
from rippleb.simulator import controller, daq, gauge
from rippleb.simulator.conditions import CONDITIONS, calibration_condition
from rippleb.simulator.encoder import EncoderErrors, counts
from rippleb.simulator.sensors import STRAIN_BITS, STRAIN_RANGE
from rippleb.engine.sweep import PARAMS, swept_scenario

CPR = 2500


def cruise(tables=None, wg_rev_per_s=3.0, load=20.0, seconds=1.0, temperature=40.0, name="cruise"):
    """Shoulder pan (no gravity) at constant speed under a known constant load, without the
    output-locked ripple and hysteresis (they would blur the wave-generator orders)."""
    raw = {"temperature_c": temperature, "robot": {"joint": "shoulder_pan_joint"},
           "ripple": {"output_scale": 0.0, "hysteresis_nm": 0.0},
           "trajectory": {"segment": [
               {"kind": "ramp", "velocity": wg_rev_per_s * 2 * np.pi / 100.0, "duration": 0.2},
               {"kind": "cruise", "duration": 0.2 + seconds}]},
           "load": [{"torque": load, "start": 0.0, "rise": 0.05, "known": True}]}
    raw.update(tables or {})
    return scenario_from_dict(raw, name=name)


def rest(tables=None, seconds=1.0):
    """The shoulder pan held still, no load: a quiet log for DAQ spectra."""
    raw = {"robot": {"joint": "shoulder_pan_joint"},
           "trajectory": {"segment": [{"kind": "hold", "duration": seconds}]}}
    raw.update(tables or {})
    return scenario_from_dict(raw, name="rest")


def orders_of(sim, orders=(1, 2, 4, 6, 8), start=0.4, through=None):
    """Complex amplitude [V] of each wave-generator order in the strain, by least squares
    on the true motor angle (with the torque, a constant and a ramp as nuisance columns,
    passed ``through`` a filter the log's strain went through, if any: the torque has its
    own 1x/2x content from the motor friction, which the filter turns too)."""
    sel = sim.log.t >= start
    theta = sim.wave_angle[sel]
    nuisance = [np.ones(len(sim.log.t)), sim.log.t, sim.log.torque_true]
    cols = [(c if through is None else through(c))[sel] for c in nuisance]
    for k in orders:
        cols += [np.cos(k * theta), np.sin(k * theta)]
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), sim.log.strain[sel], rcond=None)
    return {k: coef[3 + 2 * i] - 1j * coef[4 + 2 * i] for i, k in enumerate(orders)}


def wg_frequency(sim, start=0.4):
    sel = sim.log.t >= start
    theta = sim.wave_angle[sel]
    return (theta[-1] - theta[0]) / (sim.log.t[sel][-1] - sim.log.t[sel][0]) / (2 * np.pi)


def columns(sim):
    return sim.log.columns()


# --- off means today ---------------------------------------------------------------------

def test_every_knob_is_off_by_default_and_its_off_value_is_todays_physics():
    off = Unmodelled().resolve(realistic=False)
    assert not off.active and not off.ripple_active and not off.encoder_active
    assert off.adc_bits == STRAIN_BITS and off.bandwidth_factor == 1.0
    assert load_scenario("paper-quintic").unmodelled == Unmodelled()


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sets(st.sampled_from([k.name for k in KNOBS]), min_size=1))
def test_knobs_set_to_their_off_values_leave_the_log_bit_for_bit(names):
    base = simulate(cruise(seconds=0.3), 4)
    tables = {}
    for name in names:
        knob = KNOB_BY_NAME[name]
        tables.setdefault(knob.table, {})[knob.key] = knob.off
    other = simulate(cruise(tables, seconds=0.3), 4)
    for key, values in columns(base).items():
        assert np.array_equal(values, columns(other)[key]), (names, key)


def test_scenarios_without_the_tables_keep_their_published_hash():
    sc = load_scenario("paper-quintic")
    assert scenario_hash(sc) == scenario_hash(dataclasses.replace(sc, unmodelled=Unmodelled()))
    set_one = dataclasses.replace(sc, unmodelled=Unmodelled(adc_bits=12))
    assert scenario_hash(set_one) != scenario_hash(sc)


# --- the realistic condition -------------------------------------------------------------

def test_realistic_is_a_condition_and_acts_on_the_calibration_session_too():
    assert REALISTIC in CONDITIONS
    assert calibration_condition(REALISTIC) == REALISTIC
    assert {calibration_condition(c) for c in CONDITIONS if c != REALISTIC} == {"same-session"}
    same, real = simulate("calibration", 3), simulate("calibration", 3, REALISTIC)
    assert real.log.meta["condition"] == REALISTIC and same.log.meta["condition"] == "same-session"
    assert not np.array_equal(same.log.strain, real.log.strain)
    assert np.array_equal(same.log.torque_ref, real.log.torque_ref)   # the reference is eq. (7)
    assert real.log.meta["unmodelled"] == {k.name: k.realistic for k in KNOBS}


def test_a_scenario_knob_acts_under_every_condition_and_overrides_realistic():
    sc = cruise({"daq": {"adc_bits": 10}}, seconds=0.2)
    step = 2 * STRAIN_RANGE / 2**10
    for condition in ("same-session", REALISTIC):
        strain = simulate(sc, 1, condition).log.strain
        assert np.allclose(strain / step, np.round(strain / step), atol=1e-9), condition
    assert sc.unmodelled.resolve(realistic=True).antialias_hz == KNOB_BY_NAME["daq.antialias_hz"].realistic


# --- speed-dependent ripple: the flexspline mode -----------------------------------------

@pytest.mark.parametrize("mode_hz, speed", [(100.0, 3.0), (100.0, 6.0), (1500.0, 6.0)])
def test_gauge_mode_turns_each_order_as_its_response_at_the_order_frequency(mode_hz, speed):
    off = simulate(cruise(wg_rev_per_s=speed), 2)
    on = simulate(cruise({"mismatch": {"gauge_mode_hz": mode_hz}}, wg_rev_per_s=speed), 2)
    f = wg_frequency(off)
    a, b = orders_of(off), orders_of(on)
    for k in (4, 8):
        expected = gauge.mode_response(k * f, mode_hz)
        assert abs(b[k] / a[k] - expected) < 0.02 * abs(expected), (k, b[k] / a[k], expected)
    # the motion is the same: the mode is in the gauge, not in the mechanics
    assert np.array_equal(off.log.torque_true, on.log.torque_true)


def test_gauge_mode_amplifies_more_as_the_wave_generator_speeds_up():
    ratios = []
    for speed in (1.0, 3.0, 6.0):
        off = simulate(cruise(wg_rev_per_s=speed, seconds=1.0), 5)
        on = simulate(cruise({"mismatch": {"gauge_mode_hz": 100.0}}, wg_rev_per_s=speed, seconds=1.0), 5)
        ratios.append(abs(orders_of(on)[8] / orders_of(off)[8]))
    assert ratios[0] < ratios[1] < ratios[2] and ratios[2] > 1.2


# --- non-affine and flank-dependent ripple -----------------------------------------------

def test_load_saturation_bends_the_amplitude_by_the_documented_curve():
    s, seed = 2.3, 7
    off = simulate(cruise(load=12.0), seed)
    on = simulate(cruise({"mismatch": {"load_saturation": s}}, load=12.0), seed)
    dev, rated = off.gauges[0], off.scenario.spec.rated_torque
    tau = np.abs(off.log.torque_true[off.log.t >= 0.4]).mean()
    a, b = dict(zip(dev.ripple_orders, dev.ripple_base)), dict(zip(dev.ripple_orders, dev.ripple_load))
    for k in (2, 4):
        expected = (a[k] + b[k] * rated * np.tanh(s * tau / rated) / np.tanh(s)) / (a[k] + b[k] * tau)
        assert abs(orders_of(on)[k]) / abs(orders_of(off)[k]) == pytest.approx(expected, rel=0.02)


@given(st.floats(0.01, 5.0), st.floats(0.0, 1.0))
def test_saturating_load_term_is_anchored_at_rated_torque_and_above_affine_below(s, fraction):
    rated = 51.0
    value = rated * np.tanh(s * fraction) / np.tanh(s)
    assert value >= rated * fraction - 1e-9
    assert rated * np.tanh(s) / np.tanh(s) == pytest.approx(rated)


@pytest.mark.parametrize("seed", [0, 9])
def test_the_other_tooth_flank_carries_another_ripple(seed):
    sigma = 0.2
    ratio, shift = gauge.flank_draws(seed, 5, sigma)
    for load, expect_ratio, expect_shift in ((20.0, np.ones(5), np.zeros(5)), (-20.0, ratio, shift)):
        off = simulate(cruise(load=load), seed)
        on = simulate(cruise({"mismatch": {"flank_asymmetry": sigma}}, load=load), seed)
        a, b = orders_of(off), orders_of(on)
        for i, k in enumerate((2, 4)):
            j = (1, 2, 4, 6, 8).index(k)
            change = b[k] / a[k]
            assert abs(change) == pytest.approx(expect_ratio[j], rel=0.02)
            assert np.angle(change) == pytest.approx(expect_shift[j], abs=0.02)


# --- thermal drift within a session ------------------------------------------------------

def test_span_drifts_between_the_calibration_and_the_warm_session():
    coeff = 3e-4
    for temperature in (25.0, 40.0):
        off = simulate(cruise(temperature=temperature, name="warm"), 3)
        on = simulate(cruise({"thermal": {"gain_coeff": coeff}}, temperature=temperature, name="warm"), 3)
        diff = on.log.strain - off.log.strain   # c dT x (gain (tau + ripple)), same noise
        design = np.column_stack([off.log.strain, np.ones(len(diff)), off.log.t])
        change = np.linalg.lstsq(design, diff, rcond=None)[0][0]
        assert change == pytest.approx(coeff * (temperature - 25.0), abs=2e-5)


def test_warm_up_moves_the_zero_along_the_devices_thermal_coefficient():
    rate = 20.0   # K/min, far above the documented 1 K/min so the ramp shows in one second
    off = simulate(cruise(seconds=1.5), 6)
    on = simulate(cruise({"thermal": {"warmup_rate": rate}}, seconds=1.5), 6)
    slope = np.polyfit(off.log.t, on.log.strain - off.log.strain, 1)[0]
    assert slope == pytest.approx(off.device.offset_temp_coeff * rate / 60.0, abs=2e-5)


# --- the DAQ chain -----------------------------------------------------------------------

@pytest.mark.parametrize("bits", [8, 12, 20])
def test_the_strain_adc_word_length(bits):
    strain = simulate(cruise({"daq": {"adc_bits": bits}}, seconds=0.2), 0).log.strain
    step = 2 * STRAIN_RANGE / 2**bits
    assert np.allclose(strain / step, np.round(strain / step), atol=1e-6)
    assert np.min(np.diff(np.unique(strain))) == pytest.approx(step)


def test_antialias_filter_lags_each_order_by_its_response():
    off = simulate(cruise(wg_rev_per_s=6.0), 8)
    on = simulate(cruise({"daq": {"antialias_hz": 300.0}}, wg_rev_per_s=6.0), 8)
    f = wg_frequency(off)
    a, b = orders_of(off), orders_of(on, through=lambda x: daq.antialias(x, 300.0, off.log.spec.fs))
    for k in (2, 4, 8):
        expected = daq.antialias_response(k * f, 300.0)[0]
        assert abs(b[k] / a[k] - expected) < 0.02, (k, b[k] / a[k], expected)
        assert np.angle(expected) < -0.05 * k / 4   # a lag that a map fitted at creep lacks


def _line(x, fs, f0, half_width=30.0):
    spectrum = 2 * np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x)))) / np.hanning(len(x)).sum()
    freqs = np.fft.rfftfreq(len(x), 1 / fs)
    near = np.abs(freqs - f0) <= half_width
    return freqs[near][np.argmax(spectrum[near])], spectrum[near].max()


def test_pwm_pickup_folds_to_its_alias_and_the_filter_attenuates_it():
    pwm = {"pwm_mv": 20.0, "pwm_hz": 16_000.0}
    off = simulate(rest(), 1)
    bare = simulate(rest({"daq": pwm}), 1)
    fs = off.log.spec.fs
    alias = daq.alias_frequency(16_000.0, fs)
    assert alias == 4000.0
    f, amp = _line(bare.log.strain - off.log.strain, fs, alias)
    assert abs(f - alias) <= 2.0 and amp == pytest.approx(0.020, rel=0.03)
    filtered = simulate(rest({"daq": {**pwm, "antialias_hz": 2500.0}}), 1)
    f2, amp2 = _line(filtered.log.strain - simulate(rest({"daq": {"antialias_hz": 2500.0}}), 1).log.strain,
                     fs, alias)
    assert amp2 == pytest.approx(0.020 * abs(daq.antialias_response(16_000.0, 2500.0)[0]), rel=0.05)


def test_pwm_at_the_sample_rate_aliases_into_the_torque_band():
    """Equal nominal rates from two crystals: the pickup shows as a slow wander below 2 Hz."""
    pickup = daq.pwm_pickup(200_000, 20_000.0, Unmodelled(pwm_mv=10.0, pwm_hz=20_000.0, antialias_hz=0.0),
                            3, "rest")
    spectrum = np.abs(np.fft.rfft(pickup))
    freqs = np.fft.rfftfreq(len(pickup), 1 / 20_000.0)
    assert freqs[np.argmax(spectrum)] <= 2.0 * 3 + 0.2     # up to the 3rd harmonic's alias
    assert np.abs(pickup).max() <= 0.010 * (1 + 1 / 2 + 1 / 3) + 1e-12


# --- encoder imperfections ---------------------------------------------------------------

def test_edge_errors_shift_the_four_edges_of_each_line_as_drawn():
    sc = cruise({"encoder": {"edge_error": 20.0}}, wg_rev_per_s=0.4, seconds=1.5, load=0.0)
    sim = simulate(sc, 2)
    errors = EncoderErrors.draw(2, sc.unmodelled.resolve(False), CPR)
    x = sim.wave_angle / (2 * np.pi) * CPR
    up = np.flatnonzero(np.diff(sim.log.encoder) == 1) + 1
    n = sim.log.encoder[up]
    # edge of count n lies between the true positions of the samples before and at the step
    mid = 0.5 * (x[up] + x[up - 1])
    for j in range(4):
        shift = (mid - n)[n % 4 == j]
        assert shift.mean() == pytest.approx(errors.edges[j], abs=0.02)


def test_eccentricity_moves_the_motion_the_controller_makes_and_the_count_the_daq_logs():
    ecc = 5.0  # counts: large, so the once-per-revolution motion stands out of the loop's noise
    plain = simulate(cruise(wg_rev_per_s=0.4, seconds=2.5, load=0.0), 3)
    sc = cruise({"encoder": {"eccentricity": ecc}}, wg_rev_per_s=0.4, seconds=2.5, load=0.0)
    sim = simulate(sc, 3)
    errors = EncoderErrors.draw(3, sc.unmodelled.resolve(False), CPR)
    theta = sim.wave_angle
    sel = sim.log.t >= 0.4
    basis = np.column_stack([np.sin(theta + errors.phase), np.cos(theta + errors.phase), np.ones(len(theta))])[sel]
    # the DAQ count: the disc read through its eccentricity
    reading = sim.log.encoder - theta / (2 * np.pi) * CPR
    coef = np.linalg.lstsq(basis, reading[sel], rcond=None)[0]
    assert coef[0] == pytest.approx(ecc, rel=0.05) and abs(coef[1]) < 0.05 * ecc
    # the controller reads the same disc: at 0.4 rev/s (inside the loop's 5.7 Hz) it makes
    # the *reading* follow the reference, so the true angle moves by minus the error
    moved = (theta - np.interp(sim.log.t, plain.log.t, plain.wave_angle)) / (2 * np.pi) * CPR
    coef = np.linalg.lstsq(basis, moved[sel], rcond=None)[0]
    assert -coef[0] == pytest.approx(ecc, rel=0.25)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 40.0), st.floats(0.0, 3.0), st.integers(0, 10_000),
       st.floats(-50.0, 50.0), st.floats(0.01, 20.0))
def test_encoder_counts_are_monotonic_and_near_the_ideal(edge, ecc, seed, start, span):
    errors = EncoderErrors.draw(seed, Unmodelled(edge_error_deg=edge, eccentricity_counts=ecc), CPR)
    theta = np.linspace(start, start + span, 5001)
    ideal = np.floor(theta / (2 * np.pi) * CPR)
    measured = counts(theta, CPR, errors) if errors else ideal.astype(np.int64)
    assert np.all(np.diff(measured) >= 0)
    assert np.all(np.abs(measured - ideal) <= np.ceil(ecc) + 1)
    assert np.array_equal(counts(theta, CPR, None), ideal.astype(np.int64))


def test_missed_counts_make_the_daq_count_fall_behind_in_both_sessions():
    p = 1e-3
    sc = cruise({"encoder": {"missed": p}}, wg_rev_per_s=6.0, seconds=1.0)
    plain, lossy = simulate(cruise(wg_rev_per_s=6.0, seconds=1.0), 4), simulate(sc, 4)
    edges = np.abs(np.diff(plain.log.encoder)).sum()
    behind = (plain.log.encoder[-1] - plain.log.encoder[0]) - (lossy.log.encoder[-1] - lossy.log.encoder[0])
    assert abs(behind - p * edges) <= 4 * np.sqrt(p * edges) + 1
    assert behind > 0
    assert np.array_equal(plain.log.index, lossy.log.index)   # the index comes from the disc
    assert np.array_equal(plain.log.strain, lossy.log.strain)  # only the counter


# --- non-uniform wave-generator speed: the closed loop -----------------------------------

def _speed_orders(sim, start=0.6):
    fs = sim.log.spec.fs
    w = np.gradient(sim.wave_angle) * fs
    sel = (sim.log.t > start) & (sim.log.t < sim.log.t[-1] - 0.3)
    theta = sim.wave_angle[sel]
    basis = [np.ones(sel.sum())]
    for k in (1, 2, 24):
        basis += [np.cos(k * theta), np.sin(k * theta)]
    coef = np.linalg.lstsq(np.column_stack(basis), w[sel], rcond=None)[0]
    return w[sel].std(), {k: np.hypot(coef[1 + 2 * i], coef[2 + 2 * i]) for i, k in enumerate((1, 2, 24))}


def test_the_closed_loop_already_makes_the_wave_generator_speed_uneven():
    """Today's joint (factor 1): the motor friction's 1x/2x ripple and cogging (24x) modulate
    the speed within a revolution (docs/physics.md measures 0.2-0.3 rad/s)."""
    std, lines = _speed_orders(simulate(cruise(wg_rev_per_s=6.4, seconds=1.5, load=0.0), 0))
    assert 0.1 < std < 0.5
    assert lines[1] > 0.05 and lines[24] > 0.02


def test_a_stiffer_loop_rejects_the_per_revolution_ripple_but_jitters_on_the_counts():
    base = controller.design_gains(rippleb.JointSpec(), 2.69)
    stiff = controller.design_gains(rippleb.JointSpec(), 2.69, 2.0)
    assert stiff.kp == pytest.approx(4 * base.kp) and stiff.kd == pytest.approx(2 * base.kd)
    soft_std, soft = _speed_orders(simulate(cruise(wg_rev_per_s=6.4, seconds=1.5, load=0.0), 0))
    stiff_std, hard = _speed_orders(simulate(
        cruise({"controller": {"bandwidth_factor": 2.0}}, wg_rev_per_s=6.4, seconds=1.5, load=0.0), 0))
    assert hard[1] < soft[1]
    assert stiff_std > 1.2 * soft_std


# --- the scenario format and the sweeps --------------------------------------------------

@pytest.mark.parametrize("table, bad", [
    ({"daq": {"adc_bits": 12.0}}, "daq.adc_bits"),
    ({"daq": {"adc_bits": 4}}, "daq.adc_bits"),
    ({"mismatch": {"gauge_mode_hz": 20.0}}, "mismatch.gauge_mode_hz"),
    ({"mismatch": {"gauge_mode_hz": 9000.0}}, "mismatch.gauge_mode_hz"),
    ({"encoder": {"missed": 0.5}}, "encoder.missed"),
    ({"encoder": {"excentricity": 1.0}}, "encoder.excentricity"),
])
def test_bad_knob_values_are_one_clear_line(table, bad):
    with pytest.raises(InputError, match=bad.replace(".", r"\.")):
        cruise(table)


def test_every_knob_can_be_swept_within_its_range_and_reaches_the_calibration():
    for knob in KNOBS:
        param = PARAMS[knob.name]
        assert param.device and knob.low <= param.low <= knob.off <= param.high <= knob.high, knob.name
        assert param.low <= knob.realistic <= param.high, knob.name
    swept = swept_scenario("calibration", {"mismatch.flank_asymmetry": 0.3})
    assert swept.unmodelled.flank_asymmetry == 0.3
