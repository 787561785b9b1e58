"""``fourier-lms``: an angle-indexed Fourier linear combiner (LMS harmonic canceller).

Vaz, Kong & Thakor (IEEE Trans. Signal Process. 42(1), 1994) estimate a periodic signal of
known period by tracking its Fourier coefficients with the LMS algorithm: reference
harmonics ``x = [cos k theta, sin k theta]`` at the known fundamental and a bias
reference ``x_0 = 1``, an estimate ``s = w_0 + w . x``, and per sample::

    e = y - w_0 - w . x
    w <- w + 2 mu e x,  w_0 <- w_0 + 2 mu_0 e

with a step size per component (their Sec. V: larger steps for the components that
change faster). Here the bias is the torque: it changes fast and arbitrarily, so its step
``mu_0`` is per sample, a first-order tracker of bandwidth ``bias_hz``; without it the
whole torque stays in ``e`` and shakes the harmonic weights by ``mu |tau|`` within every
revolution. The torque estimate is the strain with the harmonics removed, ``y - w . x``
(the bias is torque, not ripple).

Riviere, Rader & Thakor's weighted-frequency variant (WFLC, IEEE Trans. Biomed. Eng.
45(7), 1998) also adapts the fundamental, because a tremor's frequency is unknown. Here
the phase is known exactly: the ripple is periodic in the wave-generator (motor) angle,
which the encoder counts, so ``theta`` is the encoder angle and the combiner needs no
frequency weight. What is kept of the WFLC is its frequency-weighted step: the update is
taken per radian the wave generator turned, ``mu dtheta``, not per sample, so the weights
learn at the same rate per revolution at every speed, and at rest, where the references
stand still and the torque could be mistaken for ripple, they do not learn at all (a
time-stepped LMS would fold the torque into the weight of the resting angle).

The weights start from the calibration log's least-squares map (``fit``) in the count
frame of the calibration; a run re-homed on the encoder's index pulse restarts from it
(:mod:`rippleb.methods._angle_map`). See ``docs/methods/fourier-lms.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types

from rippleb.data import JointSpec, SensorLog
from rippleb.dsp import F8, IN_F8, IN_I8, compiled
from rippleb.methods._angle_map import HomedMapMethod, fit_gain_and_ripple
from rippleb.methods._homing import index_mark

IN_C16 = types.Array(types.complex128, 1, "A", readonly=True)
I8 = types.int64[:]


@compiled(types.void(IN_F8, IN_I8, F8, types.float64, types.float64, IN_I8, IN_C16, types.float64,
                     types.float64, types.int64, F8, F8, I8))
def combine(strain, counts, out, gain, offset, orders, table, mu, mu0, max_step, w, bias, last):
    """Cancel the combiner's harmonics from every sample; adapt them per radian turned.

    ``out = y - w . x(theta)`` and the error ``e = out - bias``; the bias steps every
    sample, ``bias += mu0 e``; when the count moved by ``d`` since the previous sample,
    ``w += mu * min(d, max_step) * (2 pi / cpr) * e * x`` (a jump of more counts than the
    joint can turn in one sample is a counting fault, not motion). ``bias`` (1,) and
    ``last``, ``[previous count, started]``, carry over between calls; the bias starts on
    the first sample's ``out``.
    """
    cpr = len(table)
    m = len(orders)
    per_count = 2.0 * math.pi / cpr
    x = np.empty(2 * m)
    for s in range(len(strain)):
        y = gain * strain[s] + offset
        count = counts[s]
        estimate = 0.0
        for i in range(m):
            z = table[(count * orders[i]) % cpr]
            x[2 * i], x[2 * i + 1] = z.real, z.imag
            estimate += w[2 * i] * z.real + w[2 * i + 1] * z.imag
        out[s] = y - estimate
        if not last[1]:
            bias[0] = y - estimate
        error = y - estimate - bias[0]
        bias[0] += mu0 * error
        moved = abs(count - last[0]) if last[1] else 0
        last[0], last[1] = count, 1
        if moved:
            step = mu * min(moved, max_step) * per_count * error
            for a in range(2 * m):
                w[a] += step * x[a]


class FourierLMS(HomedMapMethod):
    """Fourier linear combiner on the encoder angle (Vaz & Thakor; Riviere et al.).

    Parameters
    ----------
    orders
        Harmonics of the wave-generator angle in the reference (``docs/physics.md``:
        1, 2, 4, 6, 8).
    mu
        LMS step per radian of wave-generator angle [1/rad]: each weight's error decays
        as ``exp(-mu theta / 2)`` at small steps (Vaz & Thakor's decoupled convergence,
        with reference power 1/2), so ``4 pi / mu`` is the memory in radians (tuned on
        calibration; ``docs/methods/fourier-lms.md``).
    bias_hz
        Bandwidth of the bias weight that tracks the torque [Hz]: ``mu_0 = 1 -
        exp(-2 pi bias_hz / fs)`` (tuned on calibration).
    max_step_counts
        Largest count change per sample taken as motion: 50 000 counts/s (20 rev/s,
        above every scenario's speed) at 20 kHz is 2.5 counts, so 4.
    warm_start
        Start from the calibration map (True) or from zero weights (Vaz & Thakor's start).
    """

    name = "fourier-lms"
    description = ("a Fourier linear combiner on the encoder angle, warm-started from calibration, "
                   "adapted by LMS per radian turned (mu=0.2) (Vaz & Thakor; Riviere et al.)")
    #: constructor parameters worth tuning and their ranges (for a tuner shared by all methods)
    tunable = {"mu": (1e-3, 1.0, "log"), "bias_hz": (1.0, 300.0, "log")}

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), mu: float = 0.2, bias_hz: float = 10.0,
                 max_step_counts: int = 4, warm_start: bool = True):
        self.orders = orders
        self.mu = mu
        self.bias_hz = bias_hz
        self.max_step_counts = max_step_counts
        self.warm_start = warm_start

    def fit(self, calibration: SensorLog) -> None:
        """Gain, offset and the starting weights from the calibration log: least squares
        of the strain on ``[torque_ref, 1, x(theta)]`` (:func:`fit_gain_and_ripple`)."""
        self.gain_, self.offset_, self.map_ = fit_gain_and_ripple(calibration, self.orders, self.name)
        cpr = int(calibration.spec.counts_per_rev)
        self.index_mark_ = index_mark(calibration.encoder, calibration.index, cpr)

    def reset(self, spec: JointSpec) -> None:
        """Weights back to the calibration map (or zero); no previous count."""
        if not (self.mu >= 0 and self.bias_hz > 0 and int(self.max_step_counts) >= 1):
            raise ValueError(f"{self.name}: needs mu >= 0, bias_hz > 0 and max_step_counts >= 1, "
                             f"got mu={self.mu}, bias_hz={self.bias_hz}, "
                             f"max_step_counts={self.max_step_counts}")
        super().reset(spec)
        cpr = int(spec.counts_per_rev)
        self.orders_ = np.asarray(self.orders, dtype=np.int64)
        self.table_ = np.exp(2j * np.pi * np.arange(cpr) / cpr)
        self.last_ = np.zeros(2, dtype=np.int64)
        self.bias_ = np.zeros(1)
        self.mu0_ = float(-np.expm1(-2.0 * np.pi * self.bias_hz / spec.fs))
        self._restart_map()

    def _restart_map(self) -> None:
        self.w_ = self.map_.copy() if self.warm_start else np.zeros_like(self.map_)
        # the count before a re-homing is in the old frame: no motion is read across it
        self.last_[1] = 0

    def _run(self, strain, counts, out) -> None:
        combine(strain, counts, out, self.gain_, self.offset_, self.orders_, self.table_,
                float(self.mu), self.mu0_, int(self.max_step_counts), self.w_, self.bias_,
                self.last_)
