"""switched-notch: bank design, band selection with hysteresis, ripple removal, streaming."""

import numpy as np
import pytest
from scipy import signal

from rippleb import JointSpec, SensorLog
from rippleb.methods.switched_notch import (OFF, SwitchedNotch, band_centres, band_filter,
                                            bank_size, select_band)

SPEC = JointSpec()


def _response(system, freqs, fs):
    """Frequency response of a state-space band filter at ``freqs`` [Hz]."""
    A, B, C, D = system
    z = np.exp(2j * np.pi * np.asarray(freqs) / fs)
    n = A.shape[0]
    return np.array([(C @ np.linalg.solve(zk * np.eye(n) - A, B))[0] + D[0] for zk in z])


def test_every_band_notches_each_order_deeply_and_passes_dc():
    method = SwitchedNotch(q=4.0)
    method.reset(SPEC)
    for centre, band in zip(method.centres_[::10], method.bands_[::10]):
        notches = np.abs(_response(band, [k * centre for k in method.orders], SPEC.fs))
        assert notches.max() < 1e-3, f"band at {centre:.3g} rev/s leaves {notches.max():.2g}"
        assert abs(_response(band, [0.0], SPEC.fs)[0]) == pytest.approx(1.0, abs=1e-9)


def test_neighbouring_bands_overlap():
    """The -3 dB width of each notch reaches past the centre of the next band."""
    q = 4.0
    centres = band_centres(1.0, 50.0, bank_size(1.0, 50.0, q, 0.2))
    half_width = 1.0 / (2.0 * q)                       # relative half -3 dB width of a notch
    upper_edge = centres[:-1] * (1 + half_width)
    lower_edge = centres[1:] * (1 - half_width)
    assert (upper_edge > lower_edge).all()
    assert (upper_edge > centres[1:]).all()


def test_bank_is_dense_enough_for_the_residual_target():
    """At a switching point (0.5 + h spacings from centre) a notch leaves <= ~10 %."""
    q, h = 2.0, 0.2
    centres = band_centres(1.0, 50.0, bank_size(1.0, 50.0, q, h))
    spacing = np.log(centres[1] / centres[0])
    mistuned = centres[20] * np.exp((0.5 + h) * spacing)
    band = band_filter(centres[20], (4,), q, SPEC.fs)
    assert abs(_response(band, [4 * mistuned], SPEC.fs)[0]) < 0.11
    # and a coarser bank would not meet it: the count is the smallest that does
    assert bank_size(1.0, 50.0, q, h) > bank_size(1.0, 50.0, q / 2, h)


def test_orders_near_nyquist_are_dropped_not_aliased():
    band = band_filter(2000.0, (2, 4, 8), 2.0, 20_000.0)
    assert band[0].shape == (4, 4)                      # 8 * 2 kHz > 0.45 fs


def test_selection_follows_speed_with_hysteresis():
    centres = band_centres(1.0, 8.0, 4)                 # 1, 2, 4, 8 rev/s: spacing x2
    edge = np.sqrt(2.0)                                  # half-way from band 0 to band 1
    assert select_band(1.0, OFF, centres, 0.2) == 0
    assert select_band(edge * 1.05, 0, centres, 0.2) == 0     # inside the hysteresis
    assert select_band(edge * 2 ** 0.25, 0, centres, 0.2) == 1  # 0.75 spacing: past it
    assert select_band(edge * 0.95, 1, centres, 0.2) == 1
    assert select_band(0.5, 0, centres, 0.2) == OFF              # below the lowest band
    assert select_band(0.0, 0, centres, 0.2) == OFF
    assert select_band(100.0, 3, centres, 0.2) == 3              # above the top: stays on


def test_speed_dithering_on_an_edge_does_not_chatter():
    centres = band_centres(1.0, 8.0, 4)
    band, switches = 0, 0
    for speed in np.sqrt(2.0) * (1 + 0.05 * np.sin(np.arange(200))):
        new = select_band(speed, band, centres, 0.2)
        switches += new != band
        band = new
    assert switches == 0
    band, switches = 0, 0
    for speed in np.sqrt(2.0) * (1 + 0.05 * np.sin(np.arange(200))):
        new = select_band(speed, band, centres, 0.0)
        switches += new != band
        band = new
    assert switches > 10                                 # without hysteresis it chatters


def _ripple_log(speeds, seconds, torque=5.0, swing=2.0, spec=SPEC):
    """Strain = torque + ripple at orders 2, 4, 8 of a wave generator at ``speeds``."""
    fs = spec.fs
    t = np.arange(int(seconds * fs)) / fs
    speed = np.interp(t, np.linspace(0, seconds, len(speeds)), speeds)
    angle = 2 * np.pi * np.cumsum(speed) / fs
    tau = torque + swing * np.sin(2 * np.pi * 0.7 * t)
    ripple = 0.5 * np.sin(2 * angle) + 1.5 * np.sin(4 * angle + 1.0) + 0.3 * np.sin(8 * angle)
    strain = 0.1 * (tau + ripple) + 0.2                 # gain 10 Nm/V, offset -2 Nm
    counts = np.floor(angle / (2 * np.pi) * spec.counts_per_rev).astype(np.int64)
    log = SensorLog(spec=spec, t=t, strain=strain, encoder=counts, current=np.zeros_like(t),
                    torque_ref=tau)
    return log, tau, ripple


def _fitted(**params):
    """A method fitted on a calibration log whose torque swings far (a well-posed fit)."""
    method = SwitchedNotch(**params)
    method.fit(_ripple_log([4.0, 4.0], 3.0, torque=0.0, swing=30.0)[0])
    return method


def _stream(method, log, size=None):
    method.reset(log.spec)
    return np.concatenate([method.step(b) for b in log.blocks(size)])


def test_removes_ripple_at_constant_speed():
    log, tau, ripple = _ripple_log([8.0, 8.0], 2.0)
    method = _fitted()
    y = _stream(method, log)
    steady = slice(int(0.5 * SPEC.fs), None)
    residual = np.sqrt(np.mean((y - tau)[steady] ** 2))
    assert residual < 0.1 * np.sqrt(np.mean(ripple ** 2))
    assert method.gain_ == pytest.approx(10.0, rel=0.02)


def test_passes_strain_through_at_rest():
    log, tau, ripple = _ripple_log([0.0, 0.0], 0.2)
    method = _fitted()
    y = _stream(method, log)
    assert method.band_ == OFF
    np.testing.assert_allclose(y, method.gain_ * log.strain + method.offset_, atol=1e-9)


def test_tracks_an_acceleration_through_the_bank():
    log, tau, ripple = _ripple_log([0.0, 2.0, 20.0, 20.0], 3.0)
    method = _fitted()
    y = _stream(method, log)
    late = slice(int(2.0 * SPEC.fs), None)
    assert np.sqrt(np.mean((y - tau)[late] ** 2)) < 0.1 * np.sqrt(np.mean(ripple ** 2))
    assert method.centres_[method.band_] == pytest.approx(20.0, rel=0.05)


@pytest.mark.slow
def test_block_size_does_not_change_the_estimate():
    log, _, _ = _ripple_log([0.0, 5.0, 12.0, 1.0], 1.0)
    method = SwitchedNotch()
    method.fit(log)
    y20 = _stream(method, log)
    y7 = _stream(method, log, 7)
    y53 = _stream(method, log, 53)
    np.testing.assert_allclose(y7, y20, atol=1e-7)
    np.testing.assert_allclose(y53, y20, atol=1e-7)


def test_bank_matches_lfilter_of_the_active_band():
    """The active band's output (from its modes) equals running its notches with lfilter."""
    log, _, _ = _ripple_log([6.0, 6.0], 0.5)
    method = SwitchedNotch(min_speed=0.5)
    method.fit(log)
    y = _stream(method, log)
    band = method.band_
    start = np.flatnonzero(np.diff(_bands(method, log)) != 0).max() + 1
    u = log.strain
    ref = u.copy()
    # run from steady state at the first sample, like the method
    for k in method.orders:
        b, a = signal.iirnotch(k * method.centres_[band], method.q, fs=SPEC.fs)
        ref = signal.lfilter(b, a, ref, zi=signal.lfilter_zi(b, a) * ref[0])[0]
    seg = slice(start * SPEC.block_size, None)
    np.testing.assert_allclose(y[seg], method.gain_ * ref[seg] + method.offset_, atol=1e-6)


def _bands(method, log):
    method.reset(log.spec)
    out = []
    for b in log.blocks():
        out.append(method.band_)
        method.step(b)
    return np.array(out)


@pytest.mark.slow
def test_conformance():
    testing = pytest.importorskip("rippleb.testing")
    testing.check_method(SwitchedNotch)
