"""``spatial-filter``: band-pass resonators stepped in angle, their harmonics subtracted.

After Chawda & Niemeyer (IROS 2017, "Toward torque control of a KUKA LBR IIWA for physical
human-robot interaction"), who found the iiwa's torque ripple to be a spatially periodic
motor-to-joint deflection and removed it with a "matching spatial filter": a filter
designed in the angle domain, so its pass band sits on the ripple's spatial frequency at
every speed. Open code of this family steps a second-order band-pass by ``|dq| Ts`` instead
of ``Ts``, subtracts its output, and fades it out below 0.1 rad/s. Written here from that
idea:

For each ripple order ``k`` (cycles per wave-generator revolution) a band-pass of centre
``k`` and quality ``q`` in the angle ``theta`` [rad]::

    H_k(s) = (k / q) s / (s^2 + (k / q) s + k^2),   s = d/dtheta

fed with the strain minus the other orders' outputs, integrated by the trapezoidal rule with the angle step ``dtheta = 2 pi |v| / fs`` of each
sample (``v`` [rev/s] the encoder speed of the last ``speed_window`` ticks, updated once
per tick), in the state-variable form whose states stand still when the step is zero
(:func:`resonate`). The estimate is ``y - fade(|v|) sum_k H_k y`` with
``fade = min(|v| / fade_speed, 1)``: as the joint stops the spatial filter's frequency
falls into the torque band, where it would remove torque with the ripple. See
``docs/methods/spatial-filter.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.dsp import F8, IN_F8, IN_I8, compiled
from rippleb.methods._angle_map import fit_gain_and_ripple
from rippleb.method import Method

I8 = types.int64[:]
#: positions in the ``counters`` array: samples into the open tick, marks held, oldest mark
PHASE, N_MARKS, OLDEST = range(3)
#: positions in the ``scalars`` array: fade, 1/q, fade speed [rev/s]
FADE, INV_Q, FADE_SPEED = range(3)


@compiled(types.void(F8, IN_F8, types.float64, types.float64))
def angle_coefficients(coef, orders, revs_per_sample, inv_q):
    """Trapezoidal state-variable coefficients of every resonator for one angle step.

    ``g = tan(k dtheta / 2)`` is the prewarped integrator gain of order ``k`` for the step
    ``dtheta = 2 pi revs_per_sample``; ``coef[3i:3i+3] = a1, a2, a3`` of
    :func:`resonate`. A step at or beyond half a period of an order (never reached: order 8
    at 20 kHz would need 1250 rev/s) is clamped to 0.49 of it.
    """
    for i in range(len(orders)):
        half = min(math.pi * orders[i] * revs_per_sample, 0.49 * math.pi)
        g = math.tan(half)
        a1 = 1.0 / (1.0 + g * (g + inv_q))
        coef[3 * i], coef[3 * i + 1], coef[3 * i + 2] = a1, g * a1, g * g * a1


@compiled(types.void(IN_F8, IN_I8, F8, types.float64, types.float64, IN_F8, types.int64,
                     types.float64, types.float64, F8, F8, F8, F8, I8, I8, F8))
def resonate(strain, counts, out, gain, offset, orders, tick, fs, counts_per_rev, coef, band,
             low, harmonic, marks, counters, scalars):
    """Subtract the faded band-pass outputs from every sample; re-tune once per tick.

    Each resonator is the trapezoidal state-variable filter (Zavalishin's topology-
    preserving form) with integrator states ``band`` (band-pass) and ``low``
    (low-pass)::

        v3 = y - low;  v1 = a1 band + a2 v3;  v2 = low + a2 band + a3 v3
        band <- 2 v1 - band;  low <- 2 v2 - low;   harmonic = v1 / q

Each resonator is fed the strain minus the other resonators' harmonics of the previous
sample (``harmonic``): the harmonics are subtracted from one another, so a band-pass does
not also pass the neighbouring orders it overlaps (at ``q = 2`` the order-4 band-pass
passes 32 % of order 2); the bank then nulls every order exactly, as parallel resonators
with cross-feedback do (the structure of multiple second-order generalised integrators).
    With a zero step (``g = 0``: ``a1 = 1``, ``a2 = a3 = 0``) both states stand still, so
    at rest the filter holds, in angle, exactly where it stopped. At the end of each tick
    the speed over the ring ``marks`` of tick-end counts sets the next tick's step and fade.
    """
    m = len(orders)
    fade, inv_q = scalars[FADE], scalars[INV_Q]
    size = len(marks)
    for s in range(len(strain)):
        y = gain * strain[s] + offset
        previous = 0.0
        for i in range(m):
            previous += harmonic[i]
        total = 0.0
        for i in range(m):
            a1, a2, a3 = coef[3 * i], coef[3 * i + 1], coef[3 * i + 2]
            v3 = y - (previous - harmonic[i]) - low[i]
            v1 = a1 * band[i] + a2 * v3
            v2 = low[i] + a2 * band[i] + a3 * v3
            band[i] = 2.0 * v1 - band[i]
            low[i] = 2.0 * v2 - low[i]
            harmonic[i] = inv_q * v1
            total += harmonic[i]
        out[s] = y - fade * total
        counters[PHASE] += 1
        if counters[PHASE] < tick:
            continue
        counters[PHASE] = 0
        if counters[N_MARKS] < size:
            marks[(counters[OLDEST] + counters[N_MARKS]) % size] = counts[s]
            counters[N_MARKS] += 1
        else:
            marks[counters[OLDEST]] = counts[s]
            counters[OLDEST] = (counters[OLDEST] + 1) % size
        ticks = counters[N_MARKS] - 1
        speed = abs(counts[s] - marks[counters[OLDEST]]) / counts_per_rev * fs / (ticks * tick)
        fade = min(speed / scalars[FADE_SPEED], 1.0)
        angle_coefficients(coef, orders, speed / fs, inv_q)
    scalars[FADE] = fade


class SpatialFilter(Method):
    """Matching spatial filter: angle-stepped band-passes, subtracted (Chawda & Niemeyer).

    Parameters
    ----------
    orders
        Ripple orders given a resonator, in cycles per wave-generator revolution: the
        paper's dominant orders 2, 4, 8 (the small orders 1 and 6, 0.05 Nm, are left, as
        the notch methods leave them).
    q
        Quality of every band-pass in the angle domain (centre over -3 dB width); its
        settling in angle is ``q / (pi k)`` revolutions (tuned on calibration).
    fade_speed
        Wave-generator speed [rev/s] below which the subtraction fades linearly to zero.
        The source fades below 0.1 rad/s of the joint, 1.6 rev/s of the wave generator at
        the gear ratio 100 of ``JointSpec``; tuned on calibration to 4 rev/s.
    speed_window
        Control ticks over which the encoder speed that steps the filters is measured (a
        count difference; 1 ms per tick).
    """

    name = "spatial-filter"
    description = ("band-passes at orders 2, 4, 8 stepped by the angle increment (q=8.0), subtracted, "
                   "faded out below fade_speed=4.0 rev/s (Chawda & Niemeyer's matching spatial filter)")
    #: constructor parameters worth tuning and their ranges (for a tuner shared by all methods)
    tunable = {"q": (0.5, 50.0, "log"), "fade_speed": (0.1, 20.0, "log"),
               "speed_window": (1, 80, "int")}

    def __init__(self, orders: tuple = (2, 4, 8), q: float = 8.0, fade_speed: float = 4.0,
                 speed_window: int = 2):
        self.orders = orders
        self.q = q
        self.fade_speed = fade_speed
        self.speed_window = speed_window

    def fit(self, calibration: SensorLog) -> None:
        """Gain and offset: least squares of the strain on ``[torque_ref, 1]`` and a Fourier
        ripple of the filter's orders (:func:`fit_gain_and_ripple`), so the ripple does not
        bias the gain; the ripple coefficients themselves are not used."""
        self.gain_, self.offset_, _ = fit_gain_and_ripple(calibration, self.orders, self.name)

    def reset(self, spec: JointSpec) -> None:
        """Resonators at rest; speed unknown (taken as zero) until the first tick ends."""
        if not hasattr(self, "gain_"):
            raise RuntimeError(f"{self.name} needs fit(calibration) before reset")
        if not (self.q > 0 and self.fade_speed > 0 and int(self.speed_window) >= 1):
            raise ValueError(f"{self.name}: needs q > 0, fade_speed > 0 and speed_window >= 1, got "
                             f"q={self.q}, fade_speed={self.fade_speed}, "
                             f"speed_window={self.speed_window}")
        super().reset(spec)
        self.orders_ = np.asarray(self.orders, dtype=float)
        m = len(self.orders_)
        self.coef_ = np.tile([1.0, 0.0, 0.0], m)       # zero step until the first speed
        self.band_ = np.zeros(m)
        self.harmonic_ = np.zeros(m)                    # each resonator's latest output
        self.low_ = None                                # set on the first sample
        self.marks_ = np.zeros(int(self.speed_window) + 1, dtype=np.int64)
        self.counters_ = np.zeros(3, dtype=np.int64)
        self.scalars_ = np.array([0.0, 1.0 / self.q, float(self.fade_speed)])

    def step(self, block: SensorBlock) -> np.ndarray:
        """One torque estimate [Nm] per sample: the strain minus the faded resonators."""
        out = np.empty(len(block.strain))
        if self.low_ is None and len(out):
            # at rest on the first sample: each low-pass state holds it, no band content
            self.low_ = np.full(len(self.orders_), self.gain_ * block.strain[0] + self.offset_)
            self.marks_[0] = block.encoder[0]
            self.counters_[N_MARKS] = 1
        resonate(block.strain, block.encoder, out, self.gain_, self.offset_, self.orders_,
                 int(self.spec_.block_size), float(self.spec_.fs), float(self.spec_.counts_per_rev),
                 self.coef_, self.band_, self.low_, self.harmonic_, self.marks_, self.counters_, self.scalars_)
        return out
