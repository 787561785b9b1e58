import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rippleb.scoring.metrics import (Truth, _lag_correlation, bandwidth_hz, delay_ms, max_error,
                                     moving_from_encoder, restart_max_error, rms_error, score,
                                     step_latency_ms, tick_stats)
from support import load_script

FS = 20_000.0


def _truth(n=4000, seed=0):
    # a smooth random signal: broadband enough for an unambiguous correlation peak
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(size=n))


def _info(n, moving=None, wave=None, true=None, ref=None):
    return Truth(fs=FS, eval_mask=np.ones(n, bool),
                 moving=np.ones(n, bool) if moving is None else moving,
                 wave_angle=np.zeros(n) if wave is None else wave, torque_true=true, torque_ref=ref)


@pytest.mark.parametrize("lag", [0, 1, 20, 333, 2000])
def test_pure_delay_gives_its_delay(lag):
    x = _truth(12_000)
    y = np.concatenate([np.full(lag, x[0]), x[: len(x) - lag]])
    assert delay_ms(y, x, np.ones(len(x), bool), FS) == pytest.approx(1000 * lag / FS)


def test_delay_beyond_100_ms_is_not_reported_as_one_inside_the_range():
    # 150 ms: the correlation still rises at the range's end, so no lag in it fits
    # distinctly better than its neighbours 25 ms away
    x = _truth(12_000)
    y = np.concatenate([np.full(3000, x[0]), x[:-3000]])
    assert np.isnan(delay_ms(y, x, np.ones(len(x), bool), FS))


def test_all_zero_estimate_gives_the_rms_of_the_truth():
    x = _truth()
    row = score(np.zeros_like(x), _info(len(x), true=x, ref=x))
    assert row["rms_error_nm"] == pytest.approx(np.sqrt(np.mean(x ** 2)))
    assert row["max_error_nm"] == pytest.approx(np.max(np.abs(x)))


def test_perfect_estimate_gives_zero_error():
    x = _truth()
    row = score(x.copy(), _info(len(x), true=x, ref=x + 1.0))
    assert row["rms_error_nm"] == 0 and row["max_error_nm"] == 0
    assert row["delay_ms"] == 0
    assert row["rms_error_ref_nm"] == pytest.approx(1.0)


def test_window_selects_the_samples():
    x = np.zeros(100)
    y = np.zeros(100)
    y[:10] = 5.0
    mask = np.zeros(100, bool)
    mask[10:] = True
    assert rms_error(y, x, mask) == 0
    assert max_error(y, x, ~mask) == 5


def test_missing_truth_gives_nan():
    x = _truth()
    row = score(x, _info(len(x), ref=x))
    assert np.isnan(row["rms_error_nm"]) and row["rms_error_ref_nm"] == 0


def test_restart_error_stops_after_two_wave_generator_revolutions():
    n = 1000
    moving = np.ones(n, bool)
    moving[:100] = False
    wave = np.concatenate([np.zeros(100), np.linspace(0, 6 * np.pi, n - 100)])
    truth = np.zeros(n)
    est = np.zeros(n)
    travel_4pi = 100 + int(np.ceil((4 * np.pi) / (6 * np.pi) * (n - 101)))
    est[travel_4pi - 5] = 3.0   # inside the two revolutions: counts
    est[travel_4pi + 20] = 9.0  # after them: does not
    est[50] = 7.0               # before the restart: does not
    assert restart_max_error(est, truth, _info(n, moving=moving, wave=wave)) == 3.0


def test_restart_and_rest_metrics_are_nan_when_undefined():
    x = _truth()
    row = score(x, _info(len(x), true=x))
    assert np.isnan(row["restart_max_error_nm"])
    assert np.isnan(row["stopped_rms_error_nm"])


def test_stopped_rms_uses_only_samples_at_rest():
    n = 200
    moving = np.arange(n) >= 100
    est = np.where(moving, 10.0, 2.0)
    row = score(est, _info(n, moving=moving, true=np.zeros(n)))
    assert row["stopped_rms_error_nm"] == pytest.approx(2.0)


def test_moving_from_encoder_holds_for_10_ms():
    enc = np.zeros(2000, np.int64)
    enc[500:] = 1
    moving = moving_from_encoder(enc, FS)
    assert not moving[:500].any()
    assert moving[500:700].all() and not moving[700:].any()


def test_tick_stats():
    stats = tick_stats(np.array([1000, 2000, 3000]), 60)
    assert stats["us_per_tick_p50"] == 2.0
    assert stats["samples_per_s"] == pytest.approx(60 / 6e-6)


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=50, deadline=None)
@given(arrays(float, st.integers(2, 300), elements=finite), arrays(float, 1, elements=finite))
def test_error_metrics_invariants(truth, shift):
    mask = np.ones(len(truth), bool)
    est = truth + shift[0]
    # a constant offset gives exactly that RMS and max error, whatever the truth
    assert rms_error(est, truth, mask) == pytest.approx(abs(shift[0]), abs=1e-9)
    assert max_error(est, truth, mask) == pytest.approx(abs(shift[0]), abs=1e-9)
    assert rms_error(truth, truth, mask) == 0
    assert rms_error(est, truth, mask) <= max_error(est, truth, mask) + 1e-12


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2000), st.integers(0, 10_000), st.floats(0.1, 100), st.floats(-50, 50))
def test_delay_ignores_gain_and_offset(lag, seed, gain, offset):
    x = _truth(8000, seed)
    y = gain * np.concatenate([np.full(lag, x[0]), x[: len(x) - lag]]) + offset
    assert delay_ms(y, x, np.ones(len(x), bool), FS) == pytest.approx(1000 * lag / FS)


# --------------------------------------------------------------- bandwidth and step latency

CHIRP_FS = 2000.0


def _chirp_case(seconds=6.0):
    """A truth of two 8 Nm log sweeps 0.5-80 Hz on a slow drift, and its Truth."""
    from rippleb.simulator.scenario import Load

    t = np.arange(int(seconds * CHIRP_FS)) / CHIRP_FS
    loads = [Load(torque=8.0, start=0.2, stop=2.9, kind="chirp", f0=0.5, f1=80.0),
             Load(torque=8.0, start=3.1, stop=5.8, kind="chirp", f0=0.5, f1=80.0)]
    truth = 3.0 * np.sin(2 * np.pi * 0.1 * t) + sum(load.evaluate(t) for load in loads)
    chirps = np.array([[ld.start, ld.stop + ld.rise, ld.f0, ld.f1] for ld in loads])
    info = Truth(fs=CHIRP_FS, eval_mask=np.ones(len(t), bool), moving=np.ones(len(t), bool),
                 wave_angle=np.zeros(len(t)), torque_true=truth, chirps=chirps)
    return truth, info


def test_bandwidth_of_an_exact_estimate_is_the_top_of_the_sweep():
    truth, info = _chirp_case()
    assert bandwidth_hz(truth.copy(), truth, info) == pytest.approx(80.0)
    assert score(truth.copy(), info)["bandwidth_hz"] == pytest.approx(80.0)


@settings(max_examples=12, deadline=None)
@given(st.floats(3.0, 60.0), st.integers(1, 4))
def test_bandwidth_of_a_butterworth_is_its_cutoff(cutoff, order):
    from scipy.signal import butter, sosfilt

    truth, info = _chirp_case()
    estimate = sosfilt(butter(order, cutoff, fs=CHIRP_FS, output="sos"), truth)
    assert bandwidth_hz(estimate, truth, info) == pytest.approx(cutoff, rel=0.08)


def test_bandwidth_ignores_offset_and_uncorrelated_ripple():
    from scipy.signal import butter, sosfilt

    truth, info = _chirp_case()
    t = np.arange(len(truth)) / CHIRP_FS
    ripple = 0.6 * np.cos(2 * np.pi * 19.0 * t) + 0.1 * np.random.default_rng(1).normal(size=len(t))
    estimate = sosfilt(butter(2, 30.0, fs=CHIRP_FS, output="sos"), truth) + 5.0 + ripple
    assert bandwidth_hz(estimate, truth, info) == pytest.approx(30.0, rel=0.08)


def test_bandwidth_bounds_and_nan():
    truth, info = _chirp_case()
    # half the gain everywhere: below -3 dB from the lowest analysed band on
    low = bandwidth_hz(0.5 * truth, truth, info)
    assert 1.0 < low < 2.0
    # no chirp, or one outside the window: undefined
    assert np.isnan(score(truth, _info(len(truth), true=truth))["bandwidth_hz"])
    outside = Truth(**{**info.__dict__, "eval_mask": np.arange(len(truth)) > 1000})
    assert bandwidth_hz(truth, truth, outside) == pytest.approx(80.0)   # the second sweep remains
    assert np.isnan(bandwidth_hz(truth, None, info))


def _step_case(delay_s=0.0, lost=()):
    """Steps of +10 (at 0.2 s) and -10 Nm (at 0.6 s) with 10 ms rise; estimate delayed."""
    from rippleb.simulator.scenario import Load

    t = np.arange(int(1.0 * FS)) / FS
    load = Load(torque=10.0, start=0.2, stop=0.6, rise=0.01)
    truth = load.evaluate(t) + 2.0
    estimate = load.evaluate(t - delay_s) + 2.0
    for k in lost:
        estimate[int(FS * k):] = estimate[int(FS * k) - 1]
    steps = np.array([[0.2, 0.01, 10.0], [0.6, 0.01, -10.0]])
    info = Truth(fs=FS, eval_mask=np.ones(len(t), bool), moving=np.zeros(len(t), bool),
                 wave_angle=np.zeros(len(t)), torque_true=truth, steps=steps)
    return estimate, info


@pytest.mark.parametrize("delay_ms_", [0.0, 0.5, 7.5, 40.0])
def test_step_latency_of_a_delayed_estimate_is_its_delay(delay_ms_):
    estimate, info = _step_case(delay_ms_ / 1000)
    assert step_latency_ms(estimate, info) == pytest.approx(delay_ms_, abs=1000 / FS)
    assert score(estimate, info)["step_latency_ms"] == pytest.approx(delay_ms_, abs=1000 / FS)


def test_a_missed_step_counts_the_horizon_and_no_step_is_nan():
    estimate, info = _step_case(0.0, lost=[0.55])   # frozen before the second step
    assert step_latency_ms(estimate, info) == pytest.approx((0.0 + 200.0) / 2, abs=0.1)
    x = _truth()
    assert np.isnan(score(x, _info(len(x), true=x))["step_latency_ms"])
    slow = Truth(**{**info.__dict__, "steps": np.array([[0.2, 0.3, 10.0]])})   # a ramp, not a step
    assert np.isnan(step_latency_ms(estimate, slow))


def test_delay_is_nan_on_a_slow_torque_with_ripple():
    # creep-like: a 0.05 Hz torque under 1.6 Hz ripple; every lag fits about as well
    t = np.arange(int(4 * FS)) / FS
    x = 20.0 * np.sin(2 * np.pi * 0.05 * t)
    y = x + 0.6 * np.cos(2 * np.pi * 1.6 * t)
    assert np.isnan(delay_ms(y, x, np.ones(len(t), bool), FS))
    # the same torque with steps on it has a distinct peak
    x2 = x + 10.0 * (np.floor(t * 2) % 2)
    y2 = x2 + 0.6 * np.cos(2 * np.pi * 1.6 * t)
    assert delay_ms(np.concatenate([np.full(100, y2[0]), y2[:-100]]), x2, np.ones(len(t), bool),
                    FS) == pytest.approx(5.0, abs=0.1)


@settings(max_examples=40, deadline=None)
@given(st.integers(4, 300), st.integers(0, 10_000), st.floats(0.0, 1.0))
def test_lag_correlation_is_pearson_on_each_overlap(n, seed, reach):
    """The FFT correlation (circular, of length >= n + max lag) equals the definition, lag
    by lag, up to the largest lag, which may come within two samples of the window's end."""
    rng = np.random.default_rng(seed)
    x, y = np.cumsum(rng.standard_normal((2, n)), axis=1)
    max_lag = int(reach * (n - 2))
    r = _lag_correlation(y, x, np.ones(n, bool), 1.0, float(max_lag))
    for lag in range(max_lag + 1):
        expected = np.corrcoef(y[lag:], x[: n - lag])[0, 1]
        assert r[lag] == pytest.approx(expected, abs=1e-9)


def test_the_gear_floor_script_splits_raws_former_share_over_the_strains_terms():
    """benchmarks/gear_floor.py (docs/metrics.md's table): the terms sum to raw's former
    share by construction, so what is checked is that they are the physics' terms: the
    hysteresis takes a positive share (it lags a rising torque and flattens the gear's
    oscillations: +0.25 on this device), the ripple at orders 1-2 the device's own (-0.62
    here), gain, offset, drift and noise little (|rest| 0.013), and raw removes nothing."""
    floor = load_script("benchmarks/gear_floor.py")
    table = floor.measure([2000], ["paper-quintic"])
    parts = {k: v[0] for k, v in table["paper-quintic"].items()}
    assert parts["hysteresis"] > 0.05
    assert abs(parts["rest"]) < 0.05
    assert abs(parts["ripple 1-2"]) > abs(parts["ripple 4-8"])
    assert abs(parts["removed"]) < 1e-9
    assert "| paper-quintic |" in floor.markdown(table)
