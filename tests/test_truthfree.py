"""The truth-free scores (rippleb/scoring/truthfree.py) on signals whose answer is known."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from rippleb.engine.results import read_rows
from rippleb.scoring.metrics import Truth
from rippleb.scoring.truthfree import (MIN_REST_S, POINTS_PER_REV, TRUTH_FREE_COLUMNS, _segment_spectra, rest_std_nm,
                                       ripple_wg_nm,
                                       strain_delay_ms, truth_free_scores)

FS = 20_000.0
CPR = 2500


def _turning(revs_per_s=2.0, seconds=3.0, reverse_at=None):
    """Encoder angle [rad] of a motor turning at constant speed (quantised to CPR counts),
    reversing at ``reverse_at`` seconds if given; and the true angle."""
    t = np.arange(int(seconds * FS)) / FS
    true = 2 * np.pi * revs_per_s * t
    if reverse_at is not None:
        turn = 2 * np.pi * revs_per_s * reverse_at
        true = np.where(t < reverse_at, true, 2 * turn - true)
    counts = np.floor(true * CPR / (2 * np.pi))
    return t, counts * (2 * np.pi / CPR), true


def _ripple(angle, amplitudes, phases):
    return sum(a * np.cos(k * angle + p) for k, a, p in zip((2, 4, 8), amplitudes, phases))


@settings(max_examples=25, deadline=None)
@given(amplitudes=st.tuples(*[st.floats(0.0, 2.0)] * 3), phases=st.tuples(*[st.floats(0, 2 * np.pi)] * 3),
       offset=st.floats(-50, 50), slope=st.floats(-5, 5))
def test_ripple_is_the_rms_of_the_harmonics_whatever_the_slow_torque(amplitudes, phases, offset, slope):
    t, angle, true = _turning()
    estimate = offset + slope * t + _ripple(true, amplitudes, phases)
    expected = np.sqrt(sum(a * a for a in amplitudes) / 2)
    # the encoder quantises the angle by 1/2500 rev: a phase error of up to 2 pi 8 / 2500 at order 8
    assert ripple_wg_nm(estimate, angle, FS) == pytest.approx(expected, abs=0.01 + 0.01 * expected)


def test_ripple_is_found_in_both_directions_of_a_reversal():
    t, angle, true = _turning(seconds=4.0, reverse_at=2.0)
    estimate = 10.0 + _ripple(true, (0.0, 1.0, 0.0), (0.0, 1.0, 0.0))
    assert ripple_wg_nm(estimate, angle, FS) == pytest.approx(np.sqrt(0.5), rel=0.02)


def test_other_orders_are_not_counted():
    t, angle, true = _turning()
    estimate = np.cos(1 * true) + np.cos(3 * true) + np.cos(6 * true)   # orders 1, 3, 6 only
    assert ripple_wg_nm(estimate, angle, FS) < 0.02


def test_no_ripple_score_without_a_whole_revolution():
    t, angle, true = _turning(revs_per_s=0.2, seconds=3.0)   # 0.6 rev
    assert np.isnan(ripple_wg_nm(np.cos(4 * true), angle, FS))
    assert np.isnan(ripple_wg_nm(np.ones(100), np.zeros(100), FS))


def test_rest_spread_is_the_noise_at_rest_and_ignores_motion_and_short_rests():
    rng = np.random.default_rng(0)
    _, moving_angle, true = _turning(seconds=1.0)
    rest = np.full(int(FS), moving_angle[-1])
    blip = np.full(int(0.5 * MIN_REST_S * FS), moving_angle[-1] + 1.0)   # a rest too short to count
    angle = np.concatenate([moving_angle, rest, moving_angle[-1] + 1.0 + moving_angle, blip])
    estimate = np.concatenate([5 * np.cos(4 * true), 3.0 + 0.2 * rng.standard_normal(len(rest)),
                               5 * np.cos(4 * true), np.linspace(-40, 40, len(blip))])
    assert rest_std_nm(estimate, angle, FS) == pytest.approx(0.2, rel=0.05)


def test_no_rest_score_when_the_joint_never_rests():
    t, angle, true = _turning()
    assert np.isnan(rest_std_nm(np.cos(true), angle, FS))


def _band_noise(n, seed=0):
    b, a = signal.butter(2, 5 / (FS / 2))
    return 100 * signal.lfilter(b, a, np.random.default_rng(seed).standard_normal(n))


@pytest.mark.parametrize("lag", [0, 20, 100, 160])
@pytest.mark.parametrize("bridge_sign", [1.0, -1.0])
def test_strain_delay_is_a_pure_delay_whatever_the_gain_and_the_bridges_sign(lag, bridge_sign):
    strain = _band_noise(200_000)
    estimate = 3.0 * np.concatenate([np.zeros(lag), strain[: len(strain) - lag]]) + 1.0
    assert strain_delay_ms(estimate, bridge_sign * strain, FS) == pytest.approx(1000 * lag / FS, abs=0.05)


def test_strain_delay_of_a_causal_lowpass_is_its_low_frequency_group_delay():
    strain = _band_noise(200_000)
    b, a = signal.butter(2, 30 / (FS / 2))
    group = signal.group_delay((b, a), w=[1.0], fs=FS)[1][0] / FS * 1000
    assert strain_delay_ms(signal.lfilter(b, a, strain), strain, FS) == pytest.approx(group, rel=0.05)


def test_no_strain_delay_when_nothing_is_coherent():
    rng = np.random.default_rng(1)
    assert np.isnan(strain_delay_ms(rng.standard_normal(100_000), rng.standard_normal(100_000), FS))
    assert np.isnan(strain_delay_ms(np.ones(100_000), _band_noise(100_000), FS))


def _truth(estimate_len, angle, strain, **torques):
    return Truth(fs=FS, eval_mask=np.ones(estimate_len, bool), moving=np.ones(estimate_len, bool),
                 wave_angle=angle, strain=strain, encoder_angle=angle, **torques)


def test_the_scores_never_read_a_torque_column():
    t, angle, true = _turning()
    # a torque slow against the ripple's frequencies (orders 2-8 at 2 rev/s: 4-16 Hz)
    strain = 20 * np.sin(2 * np.pi * 0.25 * t) + _ripple(true, (0.3, 1.0, 0.2), (0, 1, 2))
    estimate = strain - _ripple(true, (0.3, 0.5, 0.2), (0, 1, 2))
    without = truth_free_scores(estimate, _truth(len(t), angle, strain))
    garbage = np.random.default_rng(2).standard_normal(len(t)) * 1e3
    with_torques = truth_free_scores(estimate, _truth(len(t), angle, strain, torque_true=garbage, torque_ref=garbage))
    assert set(without) == set(TRUTH_FREE_COLUMNS)
    np.testing.assert_equal(without, with_torques)   # NaN equals NaN here
    assert without["ripple_wg_nm"] == pytest.approx(np.sqrt(0.5 * 0.5 ** 2), rel=0.05)


def test_the_scores_cover_the_evaluation_window_only():
    t, angle, true = _turning()
    estimate = 4.0 * np.cos(4 * true)
    truth = _truth(len(t), angle, _band_noise(len(t)))
    quiet = estimate.copy()
    quiet[: len(t) // 2] = 0.0
    window = dataclasses.replace(truth, eval_mask=np.arange(len(t)) >= len(t) // 2)
    assert truth_free_scores(quiet, window)["ripple_wg_nm"] == \
        pytest.approx(truth_free_scores(estimate, window)["ripple_wg_nm"])


def test_a_truth_without_the_sensor_columns_scores_nan():
    n = 1000
    truth = Truth(fs=FS, eval_mask=np.ones(n, bool), moving=np.ones(n, bool), wave_angle=np.zeros(n))
    assert all(np.isnan(v) for v in truth_free_scores(np.zeros(n), truth).values())


def test_points_per_revolution_resolve_order_8():
    assert POINTS_PER_REV > 2 * 8


@pytest.mark.parametrize("cells, kept", [({"rms_error_nm": "", "rms_error_ref_nm": "", "ripple_wg_nm": "0.2"}, 1),
                                         ({"rms_error_nm": "", "rms_error_ref_nm": "", "ripple_wg_nm": ""}, 0)])
def test_an_ok_row_needs_an_error_or_a_truth_free_score(tmp_path, cells, kept):
    from rippleb.engine.results import COLUMNS

    row = {c: "" for c in COLUMNS} | {"method": "raw", "scenario": "log:x.csv", "condition": "same-session",
                                        "seed": "0", "status": "ok"} | cells
    path = tmp_path / "results.csv"
    path.write_text(",".join(COLUMNS) + "\n" + ",".join(row[c] for c in COLUMNS) + "\n")
    if kept:
        assert len(read_rows(path)) == 1
    else:
        with pytest.warns(Warning, match="without an RMS error or a truth-free score"):
            assert read_rows(path) == []


def test_the_strain_side_remembered_for_the_next_estimate_gives_the_same_delay():
    t, angle, true = _turning()
    strain = _band_noise(len(t))
    truth = _truth(len(t), angle, strain)
    b, a = signal.butter(2, 30 / (FS / 2))
    for estimate in (signal.lfilter(b, a, strain), -2.0 * strain):   # the second reuses the first's strain side
        assert strain_delay_ms(estimate, strain, FS, memo=truth) == strain_delay_ms(estimate, strain, FS)


def test_the_welch_spectra_are_scipys():
    x, y = _band_noise(50_000, seed=3), _band_noise(50_000, seed=4) + 0.5 * _band_noise(50_000, seed=3)
    n = 4000
    freq, xs, pxx = _segment_spectra(x, n, FS)
    _, ys, pyy = _segment_spectra(y, n, FS)
    f, coherence = signal.coherence(x, y, FS, nperseg=n)
    keep = f <= freq[-1]
    mine = np.abs(np.sum(np.conj(xs) * ys, axis=0)) ** 2 / (pxx * pyy)
    np.testing.assert_allclose(mine[1:], coherence[keep][1:], rtol=1e-9)
    _, pxy = signal.csd(x, y, FS, nperseg=n)
    np.testing.assert_allclose(np.angle(np.sum(np.conj(xs) * ys, axis=0))[1:], np.angle(pxy[keep])[1:], atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 3000), seed=st.integers(0, 2**32 - 1), step=st.sampled_from([0, 1, 3, 400]),
       gain=st.floats(0.1, 10.0), offset=st.floats(-100.0, 100.0))
def test_any_log_scores_without_raising_and_scales_with_the_estimate(n, seed, step, gain, offset):
    """Whatever the encoder does (still, creeping, jumping back and forth), each score is NaN
    or a number; ripple and rest spread scale with the estimate's gain, the delay not at all."""
    rng = np.random.default_rng(seed)
    counts = np.cumsum(rng.integers(-step, step + 1, n)) if step else np.zeros(n)
    angle = counts * (2 * np.pi / 64)
    strain = rng.standard_normal(n).cumsum()
    estimate = strain + rng.standard_normal(n)
    truth = Truth(fs=2000.0, eval_mask=np.ones(n, bool), moving=np.ones(n, bool), wave_angle=angle,
                  strain=strain, encoder_angle=angle)
    base = truth_free_scores(estimate, truth)
    scaled = truth_free_scores(gain * estimate + offset, truth)
    for name in ("ripple_wg_nm", "rest_std_nm"):
        assert np.isnan(base[name]) or base[name] >= 0
        np.testing.assert_allclose(scaled[name], gain * base[name], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(scaled["strain_delay_ms"], base["strain_delay_ms"], rtol=1e-6, atol=1e-6)
