"""Sensors and DAQ: the strain bridge, the motor-current sense, the encoder counter, ADCs
and the faults a scenario may switch on.

Each sensor turns a true signal of the simulated joint into what the DAQ records; the
measurement noise comes from the log's own generator. Sources in ``docs/physics.md``
("Strain bridge", "DAQ").
"""

from __future__ import annotations

import numpy as np

from rippleb.simulator.scenario import REFERENCE_TEMPERATURE_C, Scenario
from rippleb.simulator.mismatch import Unmodelled
from rippleb.simulator import daq, gauge
from rippleb.simulator.conditions import stream
from rippleb.simulator.device import Device
from rippleb.simulator.ripple import bridge_ripple

# --- strain bridge and DAQ (docs/physics.md, "Strain bridge", "DAQ") ---
STRAIN_GAIN = 0.1            # V/Nm after the bridge amplifier; estimate, rated 51 Nm -> 5.1 V
STRAIN_RANGE = 10.0          # +-V of the strain ADC
STRAIN_BITS = 16
STRAIN_NOISE = 1.0e-3        # V RMS, amplifier + ADC noise at 20 kHz bandwidth; estimate
CURRENT_RANGE = 20.0         # +-A of the current ADC
CURRENT_BITS = 12
CURRENT_NOISE = 0.03         # A RMS, current-sense noise; estimate


def quantise(values: np.ndarray, full_scale: float, bits: int) -> np.ndarray:
    """An ADC of ``+-full_scale`` and ``bits`` bits: round to a step, saturate at the rails."""
    step = 2.0 * full_scale / 2**bits
    codes = np.clip(np.round(values / step), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return codes * step


#: The physics of today's bridge: every knob of :mod:`rippleb.simulator.mismatch` off.
IDEAL = Unmodelled().resolve(realistic=False)


def strain_bridge(device: Device, sc: Scenario, t, theta_m, tau, noise, output_angle,
                  knobs: Unmodelled = IDEAL) -> np.ndarray:
    """Bridge voltage (paper eq. 3-5): gain x (torque + ripple) + zero + drift + noise, ADC.

    The ripple is the wave-generator ripple plus the output-locked ripple and hysteresis
    of :func:`rippleb.simulator.ripple.bridge_ripple`. ``knobs`` (resolved) add the
    physics beyond the methods' models where it acts: the gauge's dynamics and the
    ripple's shape (:func:`rippleb.simulator.gauge.wave_ripple`), the span and zero at the
    gauge's temperature over the log, the amplifier's anti-alias filter and the drive's
    PWM pickup (:func:`rippleb.simulator.daq.front_end`) before the ADC noise, and the
    ADC's word length.
    """
    temperature = gauge.gauge_temperature(knobs, sc.temperature_c, t)
    zero = device.offset + device.offset_temp_coeff * (temperature - REFERENCE_TEMPERATURE_C)
    ripple = bridge_ripple(sc.ripple, device.seed, sc.temperature_c,
                           gauge.wave_ripple(device, knobs, theta_m, tau, sc.spec), output_angle, tau)
    analog = gauge.span(device, knobs, temperature) * (tau + ripple) + zero + device.drift_rate * t
    if knobs.antialias_hz or knobs.pwm_mv:
        analog = daq.front_end(analog, knobs, sc.spec.fs, device.seed, sc.name)
    volts = analog + STRAIN_NOISE * noise.standard_normal(len(t))
    if sc.faults.bridge_drift:   # fault: extra bridge zero drift [V/s]
        volts = volts + sc.faults.bridge_drift * t
    # fault: a lower full scale (amplifier gain set too high) clips the peaks
    return quantise(volts, sc.faults.strain_full_scale or STRAIN_RANGE, knobs.adc_bits)


def gauge_channels(devices, sc: Scenario, t, theta_m, tau, noise, output_angle,
                   knobs: Unmodelled = IDEAL) -> tuple[np.ndarray, np.ndarray | None]:
    """``(strain, channels)`` [V]: the bridge of each channel of the scenario's gauge layout
    through :func:`strain_bridge`, ``devices`` the device each channel reads
    (:func:`rippleb.simulator.flexspline.channel_devices`), and their mean as the ``strain``
    column; ``channels`` (samples x channels) only for a layout with several.

    The first channel's noise comes from the log's ``noise`` generator (so a one-channel
    layout draws what the one bridge always drew), each further channel's from its own
    stream: the current's noise, drawn after, is the same whatever the layout.
    """
    noises = [noise] + [stream(d.seed, sc.name, "gauge-channel", str(c)) for c, d in enumerate(devices) if c]
    volts = [strain_bridge(d, sc, t, theta_m, tau, rng, output_angle, knobs) for d, rng in zip(devices, noises)]
    if len(volts) == 1:
        return volts[0], None
    channels = np.column_stack(volts)
    return channels.mean(axis=1), channels


def current_sense(sc: Scenario, commanded: np.ndarray, offset: float, noise) -> np.ndarray:
    """Motor current [A]: the commanded current (the current loop is ideal) + the
    sense's offset + noise, through the ADC."""
    amps = commanded + offset + CURRENT_NOISE * noise.standard_normal(len(commanded))
    if sc.faults.current_offset:   # fault: shifted current-sense zero [A]
        amps = amps + sc.faults.current_offset
    return quantise(amps, CURRENT_RANGE, CURRENT_BITS)


def encoder_faults(encoder: np.ndarray, faults, fs: float, rng) -> np.ndarray:
    """Missed and spurious counts of an incremental encoder counter.

    Each true count is lost with probability ``encoder_missed``; spurious counts of +-1
    arrive as a Poisson process of ``encoder_spurious_rate`` per second. A counter never
    learns of either, so both accumulate into a lasting position error.
    """
    steps = np.diff(encoder)
    if faults.encoder_missed:
        lost = rng.binomial(np.abs(steps), faults.encoder_missed)
        steps = steps - np.sign(steps) * lost
    if faults.encoder_spurious_rate:
        k = rng.poisson(faults.encoder_spurious_rate / fs, len(steps))
        steps = steps + (2 * rng.binomial(k, 0.5) - k)   # sum of k random +-1
    return encoder[0] + np.concatenate(([0], np.cumsum(steps))).astype(np.int64)


def dropouts(channels, faults, fs: float, rng):
    """DAQ dropouts: lost frames filled with the last good sample of every channel.

    Dropouts start as a Poisson process of ``dropout_rate`` per second and last
    ``dropout_length`` seconds (at least one sample). The first sample is always good.
    The last channel is the index pulse: an event, not a level, so a filled frame
    carries 0 (a pulse inside a lost frame is lost with it, repeating it would invent
    passes of the index mark).
    """
    if not faults.dropout_rate:
        return channels
    n = len(channels[0])
    length = max(1, int(round(faults.dropout_length * fs)))
    starts = (rng.random(n) < faults.dropout_rate / fs).astype(np.int64)
    count = np.cumsum(starts)
    before = np.concatenate((np.zeros(length, dtype=np.int64), count[:-length]))[:n]
    dropped = (count - before) > 0
    dropped[0] = False
    index = np.arange(n)
    last_good = np.maximum.accumulate(np.where(dropped, 0, index))
    *levels, pulses = channels
    return (*(channel[last_good] for channel in levels), np.where(dropped, 0, pulses).astype(np.int8))
