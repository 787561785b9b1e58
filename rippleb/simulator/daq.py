"""The strain channel's analog front end beyond the documented ideal sampler: the
amplifier's anti-alias filter and the motor drive's PWM pickup, sampled at ``fs``.

Today the bridge voltage is sampled as it is (its content lies far below the Nyquist
frequency, and the documented noise is white at ``fs``). A real channel low-pass filters
the amplified bridge signal before its ADC, and the motor drive's switching couples into
the bridge leads (capacitively through the edges' dv/dt, magnetically through the phase
currents' ripple; Vishay Micro-Measurements Tech Note TN-501, "Noise control in strain gage
measurements"). What the filter leaves of the pickup above ``fs / 2`` folds down on
sampling. ``docs/physics.md``, "Beyond the methods' models", gives the magnitudes.

Where each acts: the filter on the analog signal (torque, ripple, zero, drift), the pickup
enters before the filter and is filtered with it; the documented 1 mV noise is the noise
*at the ADC* and is added after the filter (it is not lowered by it); then the ADC of
``adc_bits``. With both knobs off :func:`front_end` returns its input unchanged.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from rippleb.simulator.conditions import stream

#: Order of the anti-alias filter: a two-pole Butterworth (one Sallen-Key stage after the
#: instrumentation amplifier), the usual filter of a bridge amplifier board. Estimate.
ANTIALIAS_ORDER = 2
#: Harmonics of the switching frequency in the pickup, amplitude 1/h of the fundamental:
#: the spectrum of a train of switching edges falls as 1/h.
PWM_HARMONICS = 3
#: Relative frequency error between the drive's PWM clock and the DAQ's sample clock,
#: uniform in +-this per device: two independent crystal oscillators of +-50 ppm each.
CLOCK_TOLERANCE = 1.0e-4


def antialias_design(cutoff_hz: float):
    """The analog Butterworth anti-alias filter ``(b, a)`` in ``s`` (rad/s)."""
    return signal.butter(ANTIALIAS_ORDER, 2 * np.pi * cutoff_hz, analog=True)


def antialias_response(frequency_hz, cutoff_hz: float) -> np.ndarray:
    """Complex response of the anti-alias filter at ``frequency_hz`` (1 without a filter)."""
    f = np.atleast_1d(np.asarray(frequency_hz, float))
    if not cutoff_hz:
        return np.ones(len(f), complex)
    b, a = antialias_design(cutoff_hz)
    return signal.freqs(b, a, worN=2 * np.pi * f)[1]


def antialias(volts: np.ndarray, cutoff_hz: float, fs: float) -> np.ndarray:
    """The sampled bridge voltage through the anti-alias filter.

    The analog filter is discretised by the bilinear transform at ``fs`` (without
    pre-warping: the signal it acts on here, torque and ripple, lies below a few hundred
    Hz, where the transform's frequency warping is below 1e-3 whatever the cut-off), and
    starts in the steady state of the first sample.
    """
    b, a = antialias_design(cutoff_hz)
    bz, az = signal.bilinear(b, a, fs)
    zi = signal.lfilter_zi(bz, az) * volts[0]
    return signal.lfilter(bz, az, volts, zi=zi)[0]


def pwm_pickup(n: int, fs: float, knobs, seed: int, log_name: str) -> np.ndarray:
    """The drive's PWM pickup [V] as the ADC samples it: filtered, then aliased.

    Harmonic ``h`` of amplitude ``pwm_mv / h`` at ``h f_pwm (1 + delta)``, ``delta`` the
    device's clock mismatch (uniform in +-:data:`CLOCK_TOLERANCE`); each passes the
    anti-alias filter (its analog response at that frequency) and is sampled at
    ``t = k / fs``, where a tone above ``fs / 2`` shows at its alias. With the switching
    frequency equal to the sample rate, the alias lies within a few Hz of DC: a slow
    wander inside the torque's band. Phases per log (the two clocks start unrelated).
    """
    delta = stream(seed, "pwm-clock").uniform(-CLOCK_TOLERANCE, CLOCK_TOLERANCE)
    phases = stream(seed, "pwm-phase", log_name).uniform(0.0, 2 * np.pi, PWM_HARMONICS)
    k = np.arange(n, dtype=float)
    out = np.zeros(n)
    for h in range(1, PWM_HARMONICS + 1):
        f = h * knobs.pwm_hz * (1.0 + delta)
        gain = antialias_response(f, knobs.antialias_hz)[0]
        # the phase in turns, wrapped before it is scaled: exact for logs of 1e7 samples
        turns = np.mod(k * (f / fs), 1.0)
        out += (1e-3 * knobs.pwm_mv / h) * abs(gain) * np.cos(2 * np.pi * turns + phases[h - 1] + np.angle(gain))
    return out


def alias_frequency(f_hz: float, fs: float) -> float:
    """Where a tone at ``f_hz`` shows after sampling at ``fs`` (0 .. fs / 2)."""
    folded = np.mod(f_hz, fs)
    return float(min(folded, fs - folded))


def front_end(volts: np.ndarray, knobs, fs: float, seed: int, log_name: str) -> np.ndarray:
    """The analog bridge voltage plus the PWM pickup, through the anti-alias filter, as
    sampled (before the ADC noise and the ADC)."""
    if knobs.antialias_hz:
        volts = antialias(volts, knobs.antialias_hz, fs)
    if knobs.pwm_mv:
        volts = volts + pwm_pickup(len(volts), fs, knobs, seed, log_name)
    return volts
