"""``gear-aware``: the calibration's angle map, fitted beside a model of the gear's real torque.

Every angle-indexed map (``angle-adaptive``, ``kalman-ripple``'s harmonics, the notches of
``order-tracking``) removes what is locked to the wave-generator angle. The gauges' ripple
is, but so is real torque: the gear's transmission error ``e(theta)`` (docs/physics.md,
"Transmission error") moves the link by ``e`` and loads it by about ``M e''``, at orders
1 and 2 of the same angle. On the calibration log ``torque_ref`` (eq. 7) does not know it,
so a map fitted to ``y - torque_ref`` absorbs the gear's torque, at the calibration's
speeds, into the "ripple", and subtracts it from every later estimate.

The two differ in how they depend on motion: the gauges' ripple is a function of the
angle and the load (``phi(theta) . (c0 + c1 y + c2 |y|)``), the gear's torque of the
angle's *derivatives*::

    e'' = e_thth theta'^2 + e_th theta''   -> for e = A cos(k theta + p):
        -k^2 A cos(k theta + p) theta'^2 - k A sin(k theta + p) theta''

so it is linear in ``[theta'^2 cos k theta, theta'^2 sin k theta, theta'' cos k theta,
theta'' sin k theta]`` for the gear's orders ``k`` (1 and 2). ``gear-aware`` fits the
calibration's ``y - torque_ref`` on the map's rows **and** those gear rows together, then
keeps only the map: the estimate is ``angle-adaptive-frozen``'s (strain minus the map,
re-homed on the index pulse), the per-tick code is the same, and the gear's torque stays
in the estimate. It needs from the joint what the frozen map needs (a calibration log
with ``torque_ref`` and the index pulse when the logs are power-cycled) and one thing
more: a calibration that turns the wave generator at more than one speed, or the gear
rows and the map's orders 1 and 2 cannot be told apart (the built-in calibration
scenario's moves and holds do). Speeds come from the encoder's counts, differentiated over
control ticks and smoothed over ``speed_ticks`` ticks (the fit is offline: centred).
What it cannot do: keep a gear torque that the speeds of the scored log excite through a
resonance the calibration never reached (the gear rows are an inertial model), nor follow
a ripple that changed since calibration (it is frozen). Measured on the built-in devices,
it keeps no more of the gear's torque than ``angle-adaptive-frozen``: the built-in
calibration turns at many speeds, where the inertial rows change the map little
(docs/methods/gear-aware.md); ``gear-keeping`` uses the same rows online.
"""

from __future__ import annotations

import numpy as np

from rippleb.data import SensorLog
from rippleb.methods.angle_adaptive import AngleAdaptiveFrozen, map_rows


def gear_rows(angle: np.ndarray, speed: np.ndarray, accel: np.ndarray, orders) -> np.ndarray:
    """``[w^2 cos k th, w^2 sin k th, a cos k th, a sin k th]`` per gear order ``k``: the
    regressors of ``e''`` for ``e`` at those orders (``th`` in rad, ``w``, ``a`` its
    derivatives)."""
    cols = []
    for k in orders:
        c, s = np.cos(k * angle), np.sin(k * angle)
        cols += [speed ** 2 * c, speed ** 2 * s, accel * c, accel * s]
    return np.column_stack(cols)


def smooth(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples (edges: the available ones)."""
    n = max(1, int(n))
    kernel = np.ones(n)
    return np.convolve(x, kernel, "same") / np.convolve(np.ones_like(x), kernel, "same")


def fit_beside(rows: np.ndarray, gear: np.ndarray, target: np.ndarray):
    """Least squares of ``target`` on the map's ``rows`` and the ``gear`` rows together.

    Returns the map's coefficients, the gear's (the calibration's gear torque, which the
    estimate keeps) and the RMS residual [Nm]. The columns have very different scales (Nm
    against rad/s^2), so the problem is solved on unit columns."""
    design = np.hstack([rows, gear])
    scale = np.maximum(np.linalg.norm(design, axis=0), 1e-300)
    coef, *_ = np.linalg.lstsq(design / scale, target, rcond=None)
    coef = coef / scale
    return coef[:rows.shape[1]], coef[rows.shape[1]:], float(np.std(target - design @ coef))


class GearAware(AngleAdaptiveFrozen):
    """``angle-adaptive-frozen`` whose calibration map is fitted beside an inertial model of the
    gear's real torque, kept out of the map (see the module).

    Parameters
    ----------
    orders, memory_revs, prior_sd_nm, floor_sd_nm, min_counts, update_ticks, outlier_gate, max_jolt_counts, adapt
        As :class:`~rippleb.methods.angle_adaptive.AngleAdaptive` (frozen: ``adapt`` False).
    gear_orders
        Orders of the wave-generator angle where the gear's transmission error puts real
        torque: 2 (the circular spline's engagement, dominant) and 1 (the wave generator's
        eccentricity); docs/physics.md, "Transmission error".
    speed_ticks
        Control ticks over which the calibration's encoder speed is smoothed before it is
        squared and differentiated: 5 ticks (5 ms) average the count quantisation
        (1 count per tick is 2.5 rad/s at 2500 counts and 1 kHz) while the built-in moves
        change speed over hundreds of ms. Not tuned.
    """

    name = "gear-aware"
    description = ("angle-adaptive-frozen's map, fitted beside an inertial model of the gear's "
                   "transmission-error torque at orders 1 and 2; on the built-in calibration it keeps "
                   "no more of that torque than the frozen map (see gear-keeping)")

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 30.0,
                 prior_sd_nm: float = 0.3, floor_sd_nm: float = 1.0, min_counts: int = 2,
                 update_ticks: int = 10, outlier_gate: float = 4.0, max_jolt_counts: int = 2,
                 adapt: bool = False, gear_orders: tuple = (1, 2), speed_ticks: int = 5):
        super().__init__(orders=orders, memory_revs=memory_revs, prior_sd_nm=prior_sd_nm,
                         floor_sd_nm=floor_sd_nm, min_counts=min_counts, update_ticks=update_ticks,
                         outlier_gate=outlier_gate, max_jolt_counts=max_jolt_counts, adapt=adapt)
        self.gear_orders = gear_orders
        self.speed_ticks = speed_ticks

    def fit(self, calibration: SensorLog) -> None:
        """The frozen map's fit (gain, offset, home, noise level), then the map again by least
        squares of ``y - torque_ref`` on the map's rows and the gear rows together; the gear
        coefficients (``gear_coef_``) are the calibration's gear torque, not subtracted."""
        super().fit(calibration)
        spec = calibration.spec
        enc, phi, strain, tau = self._calibration_ticks(calibration)
        y = self.gain_ * strain + self.offset_
        tick_s = spec.block_size / spec.fs
        angle = enc.mean(axis=1) * 2.0 * np.pi / spec.counts_per_rev
        speed = smooth(np.gradient(angle, tick_s), self.speed_ticks)
        accel = smooth(np.gradient(speed, tick_s), self.speed_ticks)
        self.map_, self.gear_coef_, self.residual_rms_ = fit_beside(
            map_rows(phi, y), gear_rows(angle, speed, accel, self.gear_orders), y - tau)
