"""``gear-keeping``: an adaptive ripple map that keeps the gear's real torque, by physics.

The gauges' ripple and the gear's transmission-error torque sit at the same orders of the
wave-generator angle, but they depend on the motion differently (docs/physics.md,
"Transmission error"): the ripple is a function of the angle and the load that exists at
any speed, at rest too; the gear's torque is dynamic, the joint's answer to the kinematic
error ``e(theta)``: to first order an inertial load ``M e''`` with::

    e'' = e_thth theta'^2 + e_th theta''   -> for e = A cos(k theta + p):
        -k^2 A cos(k theta + p) theta'^2 - k A sin(k theta + p) theta''

which grows with the speed squared and vanishes at rest. ``angle-adaptive`` learns its map
from whatever is locked to the angle at the speeds it turns at, so it learns the gear's
torque as ripple and erases it, the more the faster (issue 38).

``gear-keeping`` is ``angle-adaptive`` (the same map ``phi(theta) . (c0 + c1 y + c2 |y|)``
subtracted per sample, the same RLS with stabilised forgetting on second differences of
control ticks, re-homed on the index pulse) with two changes that follow from that physics:

1. **A model of the gear's torque, which the learning takes out and the estimate keeps.**
   On the calibration log the map is fitted beside the gear's regressors (as ``gear-aware``
   does), so the gear's torque at the calibration's speeds is not taken for ripple; per gear
   order ``k`` (1 and 2, the transmission error's)::

       [w^2 cos k th, w^2 sin k th, a cos k th, a sin k th, y w^2 cos k th, y w^2 sin k th]

   with ``w``, ``a`` the wave generator's speed and acceleration from the encoder and ``y``
   the load: the inertial terms of ``e''`` above, and a load-proportional one for a drive
   whose error grows with the load it carries (a compliance that varies with the angle
   twists the flexspline by ``tau / K(theta)``: Taghirad & Belanger's model). Every column
   vanishes at rest. Online, each control tick's predicted gear torque is taken out of the
   strain that the RLS learns from, never out of the estimate.
2. **Learning only where that model was identified; held at speed.** A tick turned faster
   than the calibration ever turned (``speed_cover`` times its top speed) is neither learned
   from nor counted in the forgetting: where the gear's torque is largest and its model
   an extrapolation, the map stands as learned at lower speeds. (Slower than ``min_counts``
   per tick nothing is learned either, as in ``angle-adaptive``: the angle barely moves.)

Speeds come from the encoder's end count of each tick, tracked by a first-order filter of
gain ``speed_gain`` per tick (:func:`~rippleb.methods._angle_adaptive_law.track_speed`), in
the calibration fit and online alike. The per-sample work is ``angle-adaptive``'s; the gear
model adds a few multiplications per tick. What it cannot do: keep a gear torque that the
scored speeds excite through a resonance the calibration never reached (it learns nothing
there, but the map it holds may already hold a part of it), or tell ripple that itself
changes with speed (gauge dynamics, ``realistic``) from the gear's torque.
docs/methods/gear-keeping.md.
"""

from __future__ import annotations

import numpy as np
from numba import types

from rippleb.data import JointSpec, SensorLog
from rippleb.dsp import F8, IN_I8, compiled
from rippleb.methods._angle_adaptive_law import (GEAR_TERMS, LAW_MAX_COUNTS, SPEED_A, SPEED_GAIN,
                                                 SPEED_TICK_S, track_speed)
from rippleb.methods.angle_adaptive import AngleAdaptive, map_rows
from rippleb.methods.gear_aware import fit_beside

#: The gear models: dynamic (speed, speed squared and acceleration terms per gear order:
#: the error's rate and its second derivative), the same with load-proportional ``y w^2``
#: terms, or none (``angle-adaptive``'s learning with the speed gate alone).
GEAR_MODELS = ("dynamic", "dynamic+load", "none")
#: Share of the calibration's moving ticks turned at most as fast as the speed the gear
#: model is taken to cover: the 99th percentile of the counts per tick, so that a few ticks
#: of a jolt do not set it.
COVER_QUANTILE = 99.0


@compiled(types.void(IN_I8, F8, types.int64, F8, F8))
def tracked_speeds(ends, speed, counts_per_rev, w, a):
    """Speed and acceleration of the wave generator after each tick ending at ``ends``, as
    :func:`~rippleb.methods._angle_adaptive_law.track_speed` tracks them online."""
    for j in range(len(ends)):
        w[j] = track_speed(speed, ends[j], counts_per_rev)
        a[j] = speed[SPEED_A]


def gear_columns(phi: np.ndarray, orders, gear_orders, speed: np.ndarray, accel: np.ndarray,
                 load: np.ndarray) -> np.ndarray:
    """The gear model's regressors per tick (:data:`GEAR_TERMS` per gear order, in the order
    :func:`~rippleb.methods._angle_adaptive_law.gear_torque` weighs them), from the tick-mean
    ``phi`` of the map's ``orders``."""
    cols = []
    for k in gear_orders:
        i = list(orders).index(k)
        c, s = phi[:, 2 * i], phi[:, 2 * i + 1]
        w2 = speed ** 2
        cols += [speed * c, speed * s, w2 * c, w2 * s, accel * c, accel * s, load * w2 * c, load * w2 * s]
    return np.column_stack(cols) if cols else np.zeros((len(speed), 0))


class GearKeeping(AngleAdaptive):
    """``angle-adaptive`` that learns its map beside a model of the gear's dynamic torque,
    which it keeps, and only up to the speeds that model was identified at (see the module).

    Parameters
    ----------
    orders, memory_revs, prior_sd_nm, floor_sd_nm, min_counts, update_ticks, outlier_gate, max_jolt_counts, adapt
        As :class:`~rippleb.methods.angle_adaptive.AngleAdaptive`, at its tuned defaults
        (``methods/tuning.json``); ``adapt`` False: the calibration map only.
    gear_orders
        Orders of the wave-generator angle where the gear's transmission error puts real
        torque: 2 (the circular spline's engagement, dominant) and 1 (the wave generator's
        eccentricity); docs/physics.md, "Transmission error". Each must be in ``orders``.
    speed_gain
        Gain per control tick of the filter that tracks the encoder's speed and
        acceleration: 0.2, a time constant of 5 ticks (5 ms) that averages the count
        quantisation (1 count per tick is 2.5 rad/s at 2500 counts and 1 kHz) while the
        built-in moves change speed over hundreds of ms; ``gear-aware``'s ``speed_ticks``.
        Not tuned.
    speed_cover
        Nothing is learned on a tick turned faster than this multiple of the calibration's
        top speed (the 99th percentile of its counts per tick): 1.0, the speeds where the
        gear model was identified. Not tuned: the tuning protocol scores on calibration
        logs, which never turn faster than themselves.
    gear_model
        ``"dynamic"`` (default): per gear order ``[w cos, w sin, w^2 cos, w^2 sin, a cos,
        a sin]``, the terms of a damping ``c e'`` and of ``M e''``. ``"dynamic+load"`` adds ``[y w^2 cos, y w^2 sin]``, for a drive
        whose error grows with its load (a compliance that varies with the angle): on the
        built-in joints, whose error does not, those terms cost the calibration map 0.06 Nm
        (docs/methods/gear-keeping.md). ``"none"``: no model, the speed gate alone (the
        ablation).
    """

    name = "gear-keeping"
    description = ("angle-adaptive whose map is learned beside an encoder model of the gear's dynamic torque "
                   "(gear_model=dynamic, orders 1 and 2; the estimate keeps it), and only up to the "
                   "calibration's top speed (speed_cover=1.0); held above it (memory_revs=139.0)")
    #: the online law's ranges, as angle-adaptive's (rippleb/tuning.py)
    tunable = {"memory_revs": (3.0, 300.0, "log"), "prior_sd_nm": (0.03, 3.0, "log"),
               "min_counts": (1, 5, "int")}

    def __init__(self, orders: tuple = (1, 2, 4, 6, 8), memory_revs: float = 139.0,
                 prior_sd_nm: float = 0.0446, floor_sd_nm: float = 1.0, min_counts: int = 2,
                 update_ticks: int = 10, outlier_gate: float = 4.0, max_jolt_counts: int = 2,
                 adapt: bool = True, gear_orders: tuple = (1, 2), speed_gain: float = 0.2,
                 speed_cover: float = 1.0, gear_model: str = "dynamic"):
        super().__init__(orders=orders, memory_revs=memory_revs, prior_sd_nm=prior_sd_nm,
                         floor_sd_nm=floor_sd_nm, min_counts=min_counts, update_ticks=update_ticks,
                         outlier_gate=outlier_gate, max_jolt_counts=max_jolt_counts, adapt=adapt)
        self.gear_orders = gear_orders
        self.speed_gain = speed_gain
        self.speed_cover = speed_cover
        self.gear_model = gear_model

    def fit(self, calibration: SensorLog) -> None:
        """``angle-adaptive``'s fit (gain, offset, home, noise level), then the map again by
        least squares of ``y - torque_ref`` on the map's rows beside the gear model's
        (``gear_coef_``, kept out of the map), and the top speed it covers (``cover_counts_``,
        counts per tick)."""
        if self.gear_model not in GEAR_MODELS:
            raise ValueError(f"{self.name}: gear_model must be one of {', '.join(GEAR_MODELS)}, "
                             f"got {self.gear_model!r}")
        missing = [k for k in self._gear_orders() if k not in self.orders]
        if missing:
            raise ValueError(f"{self.name}: gear_orders {missing} are not among orders {self.orders}")
        super().fit(calibration)
        spec = calibration.spec
        enc, phi, strain, tau = self._calibration_ticks(calibration)
        y = self.gain_ * strain + self.offset_
        ends = np.ascontiguousarray(enc[:, -1], dtype=np.int64)
        speed, accel = np.empty(len(ends)), np.empty(len(ends))
        tracked_speeds(ends, self._speed_state(spec), int(spec.counts_per_rev), speed, accel)
        gear = gear_columns(phi, self.orders, self._gear_orders(), speed, accel, y)
        keep = np.ones(gear.shape[1], bool)
        if self.gear_model != "dynamic+load":
            keep[6::GEAR_TERMS] = keep[7::GEAR_TERMS] = False
        self.map_, coef, self.residual_rms_ = fit_beside(map_rows(phi, y), gear[:, keep], y - tau)
        self.gear_coef_ = np.zeros(gear.shape[1])
        self.gear_coef_[keep] = coef
        steps = np.abs(np.diff(ends))
        moving = steps[steps >= max(int(self.min_counts), 1)]
        self.cover_counts_ = float(np.percentile(moving, COVER_QUANTILE)) if len(moving) else 0.0

    def _gear_orders(self) -> tuple:
        """The orders the gear model has terms at: none with ``gear_model="none"``."""
        return () if self.gear_model == "none" else tuple(self.gear_orders)

    def _speed_state(self, spec: JointSpec) -> np.ndarray:
        """A fresh speed-tracking state (positions ``SPEED_*`` of the law)."""
        state = np.zeros(6)
        state[SPEED_GAIN] = float(self.speed_gain)
        state[SPEED_TICK_S] = spec.block_size / spec.fs
        return state

    def reset(self, spec: JointSpec) -> None:
        """``angle-adaptive``'s reset, with the gear model and the speed gate switched in."""
        super().reset(spec)
        self.law_[LAW_MAX_COUNTS] = float(self.speed_cover) * self.cover_counts_
        self.gear_ = np.asarray(self.gear_coef_, float)
        self.gear_index_ = np.array([list(self.orders).index(k) for k in self._gear_orders()], dtype=np.int64)
        self.speed_ = self._speed_state(spec)
