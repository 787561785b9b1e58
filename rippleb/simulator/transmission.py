"""The gear's transmission (kinematic) error: real torque at the wave generator's orders.

A harmonic drive does not turn its output by exactly ``theta_m / N``: machining and
assembly errors of the wave generator, flexspline and circular spline add a position
error ``e`` that repeats with the wave generator (twice per revolution, the circular
spline's engagement with the two-lobed flexspline, dominant; once per revolution, the
wave generator's eccentricity) and with the output (once per output revolution, the
splines' runout). Tuttle & Seering (1996) and Jia et al. (Mech. Mach. Theory 155, 2021)
measure and model these components; Ghorbel et al. (J. Mech. Des. 123, 2001) put the
error inside the drive's kinematics, as here::

    twist = theta_m / N + e(theta_m) - q          (the drive's deflection)
    e(theta) = A2 cos(2 theta + p2) + A1 cos(theta + p1) + Ao cos(theta / N + po)

so ``e`` reaches the shaft torque, the strain, the motor current and the joint's
mode through the closed-loop dynamics (:func:`rippleb.simulator.joint.integrate`), and the
motor feels the torque through the same kinematics, ``tau_s (1/N + e'(theta_m))``
(virtual work). Chawda & Niemeyer (IROS 2017) identified this spatially periodic
deflection as the source of vibration in the joint torque of the KUKA LBR iiwa. Neither
the controller, nor eq. (7)'s ``torque_ref``, nor any method knows it.

Magnitudes (``docs/physics.md``, "Transmission error"): the Harmonic Drive CSF catalogue
rates the positioning accuracy of size 25, ratio >= 50, at 2.9e-4 rad (1 arcmin) peak to
peak over an output revolution in its standard class, 1.5e-4 rad in its special class.
That figure bounds the sum of the components; how a drive splits it is an **estimate**
(below), and each device's error is a random fraction of its class, as real drives sit
below their rating.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.scenario_types import TRANSMISSION_ERROR_PP
from rippleb.simulator.conditions import stable_hash

#: Share of the half peak-to-peak error each component may take: twice per wave-generator
#: turn (dominant in Tuttle & Seering's and Jia et al.'s spectra), once per turn, once per
#: output turn. **Estimate**: the sources show the ranking, not a split valid for every
#: drive; the shares sum to 1 so that the components' worst-case sum meets the class.
SHARES = {"wg2": 0.5, "wg1": 0.2, "output": 0.3}
#: A device's error as a fraction of its class's limit, uniform. **Estimate**: a rating is
#: a bound every unit meets, so units spread below it.
FRACTION_RANGE = (0.4, 1.0)
#: The joint-side parameters of :func:`rippleb.simulator.joint.integrate` it sets.
PARAM_NAMES = ("te2", "te2_phase", "te1", "te1_phase", "te_out", "te_out_phase")


@dataclass(frozen=True)
class TransmissionError:
    """One drive's transmission error: amplitudes [rad] and phases [rad] of its three
    components, ``e(theta) = wg2 cos(2 theta + p2) + wg1 cos(theta + p1) + output
    cos(theta / N + po)`` with ``theta`` the wave-generator (motor) angle."""

    wg2: float = 0.0
    wg2_phase: float = 0.0
    wg1: float = 0.0
    wg1_phase: float = 0.0
    output: float = 0.0
    output_phase: float = 0.0

    @classmethod
    def draw(cls, seed: int, class_pp: float = TRANSMISSION_ERROR_PP) -> "TransmissionError":
        """The error of device ``seed`` in a drive of accuracy class ``class_pp`` [rad peak
        to peak]. Its own generator: the device's other parameters are those of a drive
        without it, and ``class_pp`` only scales the same error (a sweep keeps the device)."""
        rng = np.random.default_rng(np.random.SeedSequence([seed, stable_hash("transmission")]))
        half = 0.5 * class_pp * rng.uniform(*FRACTION_RANGE)
        p2, p1, po = rng.uniform(0.0, 2.0 * np.pi, 3)
        return cls(wg2=SHARES["wg2"] * half, wg2_phase=float(p2), wg1=SHARES["wg1"] * half,
                   wg1_phase=float(p1), output=SHARES["output"] * half, output_phase=float(po))

    @property
    def active(self) -> bool:
        return bool(self.wg2 or self.wg1 or self.output)

    def params(self) -> dict[str, float]:
        """The integrator's parameters (``PARAM_NAMES``)."""
        return dict(zip(PARAM_NAMES, (self.wg2, self.wg2_phase, self.wg1, self.wg1_phase,
                                      self.output, self.output_phase)))

    def error(self, wave_angle, gear_ratio: float) -> np.ndarray:
        """``e`` [rad] at the wave-generator angle ``wave_angle`` [rad] (as the integrator
        computes it, for tests and figures)."""
        th = np.asarray(wave_angle, float)
        return (self.wg2 * np.cos(2.0 * th + self.wg2_phase) + self.wg1 * np.cos(th + self.wg1_phase)
                + self.output * np.cos(th / gear_ratio + self.output_phase))


#: The ideal gear: no error (the integrator's parameters when none is given).
IDEAL = TransmissionError()
