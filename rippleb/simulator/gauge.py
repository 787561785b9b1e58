"""The flexspline gauge beyond the methods' models: its dynamic response, a ripple that
bends with load and changes with the tooth flank, and a span that drifts with temperature.

The device's ripple (:meth:`~rippleb.simulator.device.Device.ripple`) is a Fourier series
in the motor angle whose amplitudes are affine in ``|tau|``: exactly the model class of the
angle-indexed methods. The knobs of :mod:`rippleb.simulator.mismatch` bend it where a real flexspline
does (``docs/physics.md``, "Beyond the methods' models"). With every knob off,
:func:`wave_ripple` *is* ``device.ripple`` (the same call), so logs stay bit for bit.

Per-device draws come from their own streams (``conditions.stream(seed, purpose)``), so
switching a knob on changes nothing else of the device, and the draws do not depend on the
knob's size: a sweep moves one joint further along one direction.
"""

from __future__ import annotations

import numpy as np
from numba import types
from scipy import signal

from rippleb.dsp import F8, IN_F8, compiled

from rippleb.simulator.scenario import REFERENCE_TEMPERATURE_C
from rippleb.simulator.conditions import stream

#: Damping ratio of the flexspline mode that filters the ripple. **Estimate**: a lightly
#: damped steel shell (structural damping of steel is below 0.01) in grease, which adds
#: some; 0.05 puts a +20 dB peak at the mode.
GAUGE_MODE_DAMPING = 0.05
#: Load [fraction of rated torque] over which the tooth contact moves from one flank to the
#: other: the catalogue's lost-motion test torque, +-4 % of rated (Harmonic Drive
#: catalogues measure lost motion at that torque: below it the teeth change contact side).
FLANK_WIDTH = 0.04
#: Ripple orders no method models (``mismatch.extra_orders``): an odd order, and the wave
#: generator's flexible bearing's outer-race ball-pass order ``(z / 2)(1 - d/D)`` in wave-
#: generator turns. **Estimate**: a size-25 wave-generator bearing has some 21 balls with
#: ``d/D`` about 0.12 (thin-section bearings of that bore), so 9.24; order 3 stands for the
#: odd orders an imperfect ellipse or gauge placement leaves (the paper's spectra show
#: small odd lines).
EXTRA_ORDERS = (3.0, 9.24)


@compiled(types.void(IN_F8, types.float64, F8))
def play(x, width, out):
    """The play (backlash) operator of ``width``: ``out`` follows ``x`` only once ``x``
    has moved ``width / 2`` away from it, so a rising and a falling ``x`` give two values."""
    half = 0.5 * width
    y = x[0]
    for i in range(len(x)):
        if x[i] > y + half:
            y = x[i] - half
        elif x[i] < y - half:
            y = x[i] + half
        out[i] = y


def wave_ripple(device, knobs, wave_angle: np.ndarray, torque: np.ndarray, spec) -> np.ndarray:
    """The ripple [Nm] the gauges see over the wave-generator angle, before the amplifier.

    Parameters
    ----------
    device
        The :class:`~rippleb.simulator.device.Device`; its ``ripple`` is the affine map.
    knobs
        Resolved :class:`~rippleb.simulator.mismatch.Unmodelled`.
    wave_angle, torque
        True motor angle [rad] and shaft torque [Nm] per sample.
    spec
        The joint's :class:`~rippleb.data.JointSpec` (rated torque, ``fs``).

    Notes
    -----
    ``load_saturation`` ``s`` replaces the load term ``b |tau|`` of each order by
    ``b L tanh(s |tau| / L) / tanh(s)`` with ``L`` the rated torque: the same amplitude at
    rated torque (where docs/physics.md anchors it), more at part load, a growth that
    slows as the tooth contact spreads. ``flank_asymmetry`` gives each order another
    amplitude (``x exp(sigma n)``) and phase (``+ sigma n'``) when the load is carried by
    the other tooth flank (``tau < 0``), blended over ``+-FLANK_WIDTH`` of rated torque.
    ``gauge_mode_hz`` passes the result through the flexspline's mode (:func:`mode_filter`).
    """
    if not knobs.ripple_active:
        return device.ripple(wave_angle, torque)
    rated = spec.rated_torque
    load = np.abs(torque)
    if knobs.load_history_nm:   # the contact pattern settles with friction: it lags the load
        followed = np.empty_like(load)
        play(np.ascontiguousarray(load), knobs.load_history_nm, followed)
        load = followed
    s = knobs.load_saturation
    if s:
        load = rated * np.tanh(s * load / rated) / np.tanh(s)
    k = len(device.ripple_orders)
    if knobs.flank_asymmetry:
        ratio, shift = flank_draws(device.seed, k, knobs.flank_asymmetry)
        positive = 0.5 * (1.0 + np.tanh(torque / (FLANK_WIDTH * rated)))
    out = np.zeros_like(wave_angle)
    for i, (o, a, b, phase, slope) in enumerate(zip(device.ripple_orders, device.ripple_base,
                                                    device.ripple_load, device.ripple_phase,
                                                    device.ripple_phase_shift)):
        amplitude = a + b * load
        angle = o * wave_angle + phase + slope * torque
        term = amplitude * np.cos(angle)
        if knobs.flank_asymmetry:
            other = amplitude * ratio[i] * np.cos(angle + shift[i])
            term = positive * term + (1.0 - positive) * other
        out += term
    if knobs.extra_orders:
        out += extra_orders(device, knobs.extra_orders, wave_angle, load)
    if knobs.gauge_mode_hz:
        out = mode_filter(out, knobs.gauge_mode_hz, spec.fs)
    return out


def extra_orders(device, scale: float, wave_angle: np.ndarray, load: np.ndarray) -> np.ndarray:
    """Ripple [Nm] at :data:`EXTRA_ORDERS`, each ``scale`` x the device's order-8 amplitude
    (base and load terms) with its own random phase (own stream)."""
    i = device.ripple_orders.index(8)
    amplitude = scale * (device.ripple_base[i] + device.ripple_load[i] * load)
    phases = stream(device.seed, "extra-orders").uniform(0.0, 2.0 * np.pi, len(EXTRA_ORDERS))
    return sum(amplitude * np.cos(order * wave_angle + phase) for order, phase in zip(EXTRA_ORDERS, phases))


def flank_draws(seed: int, orders: int, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude ratio and phase offset [rad] of each order on the negative tooth flank.

    One draw ``n, n' ~ N(0, 1)`` per order and device (own stream), scaled by ``sigma``:
    ``exp(sigma n)`` and ``sigma n'``.
    """
    n = stream(seed, "flank-asymmetry").standard_normal((2, orders))
    return np.exp(sigma * n[0]), sigma * n[1]


def mode_response(frequency_hz, mode_hz: float, damping: float = GAUGE_MODE_DAMPING) -> np.ndarray:
    """Complex response of the flexspline mode, ``w_n^2 / (s^2 + 2 zeta w_n s + w_n^2)``, at
    ``frequency_hz`` (unit gain at rest: the static strain pattern is the documented one)."""
    s = 2j * np.pi * np.asarray(frequency_hz, float)
    wn = 2 * np.pi * mode_hz
    return wn**2 / (s**2 + 2 * damping * wn * s + wn**2)


def mode_filter(ripple: np.ndarray, mode_hz: float, fs: float,
                damping: float = GAUGE_MODE_DAMPING) -> np.ndarray:
    """The quasi-static ripple through the flexspline's mode, in time.

    The wave generator drives the flexspline's wall at ``k`` times its rotation rate; a
    lightly damped shell mode in the low kHz turns each order's amplitude and phase by
    :func:`mode_response` at that rate, so the ripple seen at speed differs from the
    ripple at creep. The continuous mode is discretised by the bilinear transform at
    ``fs``: at the order frequencies (below a few hundred Hz) its warping is below
    1e-3, and the filter starts in the steady state of the first sample (no start-up
    transient that a real, long-running joint would not show).
    """
    wn = 2 * np.pi * mode_hz
    b, a = signal.bilinear([wn**2], [1.0, 2 * damping * wn, wn**2], fs)
    zi = signal.lfilter_zi(b, a) * ripple[0]
    return signal.lfilter(b, a, ripple, zi=zi)[0]


def gauge_temperature(knobs, temperature_c: float, t: np.ndarray):
    """The gauge temperature [degC] over the log: the session's, plus the warm-up ramp
    (``warmup_k_per_min``) of a joint whose motor heats it during the log; a scalar when
    there is no warm-up."""
    if not knobs.warmup_k_per_min:
        return temperature_c
    return temperature_c + knobs.warmup_k_per_min * np.asarray(t) / 60.0


def span(device, knobs, temperature) -> np.ndarray | float:
    """Bridge gain [V/Nm] at the gauge ``temperature`` [degC]: the device's gain times
    ``1 + c (T - 25 degC)``, ``c = gain_temp_coeff`` (the steel's modulus and the gauge
    factor change with temperature; docs/physics.md)."""
    if not knobs.gain_temp_coeff:
        return device.gain
    return device.gain * (1.0 + knobs.gain_temp_coeff * (np.asarray(temperature) - REFERENCE_TEMPERATURE_C))
