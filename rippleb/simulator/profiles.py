"""Time profiles of a scenario: the joint trajectory's segments and the external loads.

Both are evaluated analytically at any times ``t``; :mod:`rippleb.simulator.scenario` reads them
from a file and checks them. ``docs/scenarios.md`` describes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_RISE = 0.01


@dataclass(frozen=True)
class Segment:
    """One piece of the joint trajectory, fully resolved.

    ``kind`` is ``hold``, ``move`` (quintic rest-to-rest over ``distance``), ``ramp``
    (velocity from ``v0`` to ``v1``, ``smooth`` quintic or ``linear`` shape) or
    ``cruise`` (constant velocity ``v0``). ``t0`` [s], ``q0`` [rad] and ``v0`` [rad/s]
    are the state at the segment's start.
    """

    kind: str
    t0: float
    duration: float
    q0: float
    v0: float
    v1: float = 0.0
    distance: float = 0.0
    shape: str = "smooth"

    @property
    def t1(self) -> float:
        """End time [s]."""
        return self.t0 + self.duration

    @property
    def q1(self) -> float:
        """End position [rad]."""
        if self.kind == "move":
            return self.q0 + self.distance
        if self.kind == "ramp":
            # Both shapes cover the mean of start and end velocity.
            return self.q0 + 0.5 * (self.v0 + self.v1) * self.duration
        return self.q0 + self.v0 * self.duration

    @property
    def end_velocity(self) -> float:
        """Velocity at the end [rad/s]."""
        return self.v1 if self.kind == "ramp" else (0.0 if self.kind in ("hold", "move") else self.v0)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at times ``t`` inside the segment."""
        tau = t - self.t0
        zero = np.zeros_like(tau)
        if self.kind == "hold":
            return zero + self.q0, zero, zero
        if self.kind == "cruise":
            return self.q0 + self.v0 * tau, zero + self.v0, zero
        T = self.duration
        s = np.clip(tau / T, 0.0, 1.0)
        if self.kind == "move":
            d = self.distance
            return (self.q0 + d * _smooth(s), d / T * _smooth_d1(s), d / T**2 * _smooth_d2(s))
        dv = self.v1 - self.v0
        if self.shape == "linear":
            return (self.q0 + self.v0 * tau + 0.5 * dv * T * s * s,
                    self.v0 + dv * s, zero + dv / T)
        return (self.q0 + self.v0 * tau + dv * T * _smooth_integral(s),
                self.v0 + dv * _smooth(s), dv / T * _smooth_d1(s))


def _smooth(s):
    """Quintic rest-to-rest shape 10 s^3 - 15 s^4 + 6 s^5 (zero slope and curvature at ends)."""
    return s**3 * (10.0 - 15.0 * s + 6.0 * s * s)


def _smooth_d1(s):
    return 30.0 * s * s * (1.0 - s) ** 2


def _smooth_d2(s):
    return 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s)


def _smooth_integral(s):
    """Integral of :func:`_smooth` from 0 to ``s``."""
    return s**4 * (2.5 - 3.0 * s + s * s)


@dataclass(frozen=True)
class Load:
    """An external torque on the joint [Nm], switched on at ``start`` and off at ``stop``.

    It rises and falls smoothly over ``rise`` seconds (a contact is never a perfect step).
    ``known`` loads (payloads, calibration weights, a test rig's shaker) enter
    ``torque_ref``; unknown ones (contact) only ``torque_true``.

    ``kind = "step"`` holds ``torque`` between the edges. ``kind = "chirp"`` is a
    logarithmic swept sine whose amplitude [Nm] (the file's ``amplitude``) is held in
    ``torque``, and whose frequency rises from ``f0`` at
    ``start`` to ``f1`` [Hz] at ``stop`` (and stays at ``f1`` while it fades over
    ``rise``): ``f(t) = f0 (f1/f0)^((t - start)/(stop - start))``. A log sweep spends
    equal time per octave, so every octave of 0.5-80 Hz is excited alike.
    """

    torque: float
    start: float
    stop: float = float("inf")
    rise: float = DEFAULT_RISE
    known: bool = False
    kind: str = "step"
    f0: float = 0.0
    f1: float = 0.0

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        """The torque at times ``t`` [Nm]."""
        on = _smooth(np.clip((t - self.start) / self.rise, 0.0, 1.0))
        off = _smooth(np.clip((t - self.stop) / self.rise, 0.0, 1.0)) if np.isfinite(self.stop) else 0.0
        envelope = self.torque * (on - off)
        if self.kind == "chirp":
            return envelope * np.sin(self.chirp_phase(t))
        return envelope

    def chirp_phase(self, t: np.ndarray) -> np.ndarray:
        """Phase [rad] of the swept sine: ``2 pi`` times the integral of ``f(t)`` from ``start``."""
        span = self.stop - self.start
        ratio = self.f1 / self.f0
        s = np.clip((np.asarray(t, float) - self.start) / span, 0.0, None)
        sweep = self.f0 * span * (ratio ** np.minimum(s, 1.0) - 1.0) / np.log(ratio)
        return 2.0 * np.pi * (sweep + self.f1 * span * np.maximum(s - 1.0, 0.0))


def evaluate_segments(segments, t: np.ndarray):
    """Evaluate a resolved segment list at times ``t``, vectorised per segment.

    The parser ends every list with an open ``cruise`` at the final velocity, so times
    after the last planned segment keep that velocity (a hold if it is zero).
    """
    q, qd, qdd = (np.empty_like(t) for _ in range(3))
    starts = np.array([seg.t0 for seg in segments])
    index = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(segments) - 1)
    for i, seg in enumerate(segments):
        sel = index == i
        if sel.any():
            q[sel], qd[sel], qdd[sel] = seg.evaluate(t[sel])
    return q, qd, qdd
