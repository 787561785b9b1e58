"""switched-notch: bank design, band selection with hysteresis, ripple removal, streaming."""

import numpy as np
import pytest
from scipy import signal

from rippleb import JointSpec, SensorLog
from rippleb.methods.switched_notch import (OFF, SwitchedNotch, band_centres, bank_size,
                                            bank_spacing, notch_modes, select_band)

SPEC = JointSpec()


def _response(method, band, freqs):
    """Frequency response of band ``band`` of a reset ``method`` at ``freqs`` [Hz], from
    its modes: ``d + sum (r w / (1 - p w) + conj)`` with ``w = 1/z`` and ``r`` half the weight."""
    w = np.exp(-2j * np.pi * np.asarray(freqs, dtype=float) / SPEC.fs)[:, None]
    p = method.poles_[method.band_modes_[band]]
    r = (method.c0_[band] + 1j * method.c1_[band]) / 2
    modes = r * w / (1 - p * w) + r.conj() * w / (1 - p.conj() * w)
    return method.d_[band] + modes.sum(axis=1)


def _notches(centre, orders, q, freqs):
    """The same band as ``iirnotch`` sections in series (``scipy.signal.freqz``)."""
    out = np.ones(len(freqs), dtype=complex)
    for k in orders:
        if k * centre < 0.45 * SPEC.fs:
            out *= signal.freqz(*signal.iirnotch(k * centre, q, fs=SPEC.fs), worN=freqs, fs=SPEC.fs)[1]
    return out


def test_every_band_notches_each_order_deeply_and_passes_dc():
    method = SwitchedNotch(q=4.0)
    method.reset(SPEC)
    for band in range(0, len(method.centres_), 10):
        centre = method.centres_[band]
        notches = np.abs(_response(method, band, [k * centre for k in method.orders]))
        assert notches.max() < 1e-3, f"band at {centre:.3g} rev/s leaves {notches.max():.2g}"
        assert abs(_response(method, band, [0.0])[0]) == pytest.approx(1.0, abs=1e-9)


def test_each_band_is_its_notches_in_series():
    """The shared modes and partial-fraction weights give each band the response of its
    ``iirnotch`` sections in series, across the spectrum."""
    method = SwitchedNotch()
    method.reset(SPEC)
    freqs = np.geomspace(0.5, 0.45 * SPEC.fs, 300)
    for band in (0, 57, 200, len(method.centres_) - 1):
        expected = _notches(method.centres_[band], method.orders, method.q, freqs)
        np.testing.assert_allclose(_response(method, band, freqs), expected, atol=1e-8)


def test_octaves_share_their_modes():
    """With a whole number of bands per octave, orders 2, 4, 8 of the bank need one pole
    pair per band plus two octaves, not three per band."""
    method = SwitchedNotch()
    method.reset(SPEC)
    per_octave = round(np.log(2) / np.log(method.centres_[1] / method.centres_[0]))
    assert len(method.poles_) == len(method.centres_) + 2 * per_octave
    assert (method.band_modes_[:-per_octave, 1] == method.band_modes_[per_octave:, 0]).all()
    # orders that are no octave apart keep modes of their own
    odd = SwitchedNotch(orders=(2, 3))
    odd.reset(SPEC)
    assert len(odd.poles_) == 2 * len(odd.centres_)


def test_neighbouring_bands_overlap():
    """The -3 dB width of each notch reaches past the centre of the next band."""
    q = 4.0
    centres = band_centres(1.0, 50.0, bank_spacing(q, 0.2))
    half_width = 1.0 / (2.0 * q)                       # relative half -3 dB width of a notch
    upper_edge = centres[:-1] * (1 + half_width)
    lower_edge = centres[1:] * (1 - half_width)
    assert (upper_edge > lower_edge).all()
    assert (upper_edge > centres[1:]).all()


def test_bank_is_dense_enough_for_the_residual_target():
    """At a switching point (0.5 + h spacings from centre) a notch leaves <= ~10 %."""
    q, h = 2.0, 0.2
    centres = band_centres(1.0, 50.0, bank_spacing(q, h))
    spacing = np.log(centres[1] / centres[0])
    mistuned = centres[20] * np.exp((0.5 + h) * spacing)
    assert abs(_notches(centres[20], (4,), q, [4 * mistuned])[0]) < 0.11
    # and a coarser bank would not meet it: the count is the smallest that does
    assert bank_size(1.0, 50.0, q, h) > bank_size(1.0, 50.0, q / 2, h)


def test_orders_near_nyquist_are_dropped_not_aliased():
    poles, band_modes, weights, direct = notch_modes(np.array([1000.0, 2000.0]), (2, 4, 8), 8.0,
                                                     20_000.0)
    assert (weights[1] != 0).tolist() == [True, True, False]   # 8 * 2 kHz > 0.45 fs
    assert len(poles) == 3                                     # 2, 4, 8 kHz, shared by both


def test_a_notch_without_a_pole_pair_is_refused_by_name():
    """A wide notch close to Nyquist has two real poles, which no 2-state rotation mode can
    hold: the design says so instead of building a wrong bank."""
    with pytest.raises(ValueError, match="8000 Hz with q=2.0 has real poles"):
        notch_modes(np.array([1000.0, 2000.0]), (2, 4, 8), 2.0, 20_000.0)


def test_a_bank_without_two_bands_is_refused_by_name():
    with pytest.raises(ValueError, match="n_bands=1; a bank needs at least 2 bands"):
        SwitchedNotch(n_bands=1).reset(SPEC)
    with pytest.raises(ValueError, match="min_speed=5.0, max_speed=2.0"):
        SwitchedNotch(min_speed=5.0, max_speed=2.0).reset(SPEC)


def test_selection_follows_speed_with_hysteresis():
    centres = band_centres(1.0, 8.0, 2.0)                 # 1, 2, 4, 8 rev/s: spacing x2
    edge = np.sqrt(2.0)                                  # half-way from band 0 to band 1
    assert select_band(1.0, OFF, centres, 0.2) == 0
    assert select_band(edge * 1.05, 0, centres, 0.2) == 0     # inside the hysteresis
    assert select_band(edge * 2 ** 0.25, 0, centres, 0.2) == 1  # 0.75 spacing: past it
    assert select_band(edge * 0.95, 1, centres, 0.2) == 1
    assert select_band(0.5, 0, centres, 0.2) == OFF              # below the lowest band
    assert select_band(0.0, 0, centres, 0.2) == OFF
    assert select_band(100.0, 3, centres, 0.2) == 3              # above the top: stays on


def test_speed_dithering_on_an_edge_does_not_chatter():
    centres = band_centres(1.0, 8.0, 2.0)
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
