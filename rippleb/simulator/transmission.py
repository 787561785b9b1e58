"""The real torque locked to the wave-generator angle: the gear's transmission (kinematic)
error, the flexspline's compliance varying over the angle, and the drive's damping.

A harmonic drive does not turn its output by exactly ``theta_m / N``: machining and
assembly errors of the wave generator, flexspline and circular spline add a position
error ``e`` that repeats with the wave generator (twice per revolution, the circular
spline's engagement with the two-lobed flexspline; once per revolution, the wave
generator's eccentricity; four times, the ellipse's second harmonic) and with the output
(once per output revolution, the splines' runout). Tuttle & Seering (1996) and Jia et al.
(Mech. Mach. Theory 155, 2021) measure and model these components; Ghorbel et al. (J. Mech.
Des. 123, 2001) put the error inside the drive's kinematics, as here, and show that the
drive's flexibility colours it: the error measured under load depends on the load.
Taghirad & Belanger model the flexspline's compliance as varying with the wave generator's
position. So::

    d = theta_m / N + e(theta_m, tau) - q                      (the drive's deflection)
    tau = twist^-1(d / s(theta_m)) + c d'                      (the shaft torque)
    e = A2 (1 + l |tau|) cos(2 theta + p2) + A1 cos(theta + p1) + Ao cos(theta / N + po)
        + A4 cos(4 theta + p4)
    s = 1 + k cos(2 theta + pc)

and ``e`` and ``s`` reach the shaft torque, the strain, the motor current and the joint's
mode through the closed-loop dynamics (:func:`rippleb.simulator.joint.integrate`); the motor
feels them through the same kinematics, ``tau (1/N + de/dtheta) - s' W*(tau)`` (virtual
work, ``W*`` the spring's complementary energy). Chawda & Niemeyer (IROS 2017) identified
this spatially periodic deflection as the source of vibration in the joint torque of the
KUKA LBR iiwa. Neither the controller, nor eq. (7)'s ``torque_ref``, nor any method knows it.

Magnitudes (``docs/physics.md``, "Transmission error"): the Harmonic Drive CSF catalogue
rates the positioning accuracy of size 25, ratio >= 50, at 2.9e-4 rad (1 arcmin) peak to
peak over an output revolution in its standard class, 1.5e-4 rad in its special class.
That figure bounds the sum of the components; how a drive splits it is an **estimate**
held to the paper's Fig. 2 (:mod:`rippleb.simulator.spectrum`), and each device's error is a
random fraction of its class, as real drives sit below their rating. ``A4``, ``l``, ``k``
and the damping ``c`` are the ``[gear]`` knobs of :mod:`rippleb.simulator.mismatch` (off but under
``realistic``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.simulator.scenario_types import ORDER2_SHARE, TRANSMISSION_ERROR_PP
from rippleb.simulator import joint
from rippleb.simulator.conditions import stable_hash, stream

#: Share of the half peak-to-peak error the once-per-turn and the once-per-output-turn
#: components take. **Estimate**: the sources rank the components (twice per turn, then
#: output-locked, then once per turn) but give no split valid for every drive. The twice-per-
#: turn share is the scenario's (``[gear] order2_share``, ``ORDER2_SHARE`` of
#: :mod:`rippleb.simulator.scenario_types`); up to 0.5 of it, the worst-case sum meets the class.
SHARES = {"wg1": 0.2, "output": 0.3}
#: A device's error as a fraction of its class's limit, uniform. **Estimate**: a rating is
#: a bound every unit meets, so units spread below it.
FRACTION_RANGE = (0.4, 1.0)
#: The joint-side parameters of :func:`rippleb.simulator.joint.integrate` it sets.
PARAM_NAMES = ("te2", "te2_phase", "te1", "te1_phase", "te_out", "te_out_phase", "te4", "te4_phase",
               "te_load", "compliance", "compliance_phase")


@dataclass(frozen=True)
class TransmissionError:
    """One drive's real torque locked to the wave-generator angle ``theta``: its transmission
    error ``e(theta, tau) = wg2 (1 + load |tau|) cos(2 theta + p2) + wg1 cos(theta + p1) +
    output cos(theta / N + po) + wg4 cos(4 theta + p4)`` [rad] and its flexspline's
    compliance varying at twice the angle, ``s(theta) = 1 + compliance cos(2 theta + pc)``
    (the drive twists ``s twist(tau)``)."""

    wg2: float = 0.0
    wg2_phase: float = 0.0
    wg1: float = 0.0
    wg1_phase: float = 0.0
    output: float = 0.0
    output_phase: float = 0.0
    wg4: float = 0.0
    wg4_phase: float = 0.0
    load: float = 0.0
    compliance: float = 0.0
    compliance_phase: float = 0.0

    @classmethod
    def draw(cls, seed: int, class_pp: float = TRANSMISSION_ERROR_PP, order2_share: float = ORDER2_SHARE,
             order4: float = 0.0, load: float = 0.0, compliance: float = 0.0,
             rated_torque: float = 51.0) -> "TransmissionError":
        """The error of device ``seed`` in a drive of accuracy class ``class_pp`` [rad peak
        to peak], ``order2_share`` of it twice per turn.

        The WG-locked terms beyond the kinematic error (``[gear]`` knobs of
        :mod:`rippleb.simulator.mismatch`): ``order4`` the order-4 amplitude in multiples of the
        order-2 one, ``load`` the growth of the order-2 amplitude at ``rated_torque`` [Nm]
        (relative), ``compliance`` the relative variation of the flexspline's compliance
        at twice the wave-generator angle.

        Each part draws from its own generator: the device's other parameters are those of
        a drive without it, and the sizes only scale the same draws (a sweep keeps the
        device)."""
        rng = np.random.default_rng(np.random.SeedSequence([seed, stable_hash("transmission")]))
        half = 0.5 * class_pp * rng.uniform(*FRACTION_RANGE)
        p2, p1, po = rng.uniform(0.0, 2.0 * np.pi, 3)
        wg2 = order2_share * half
        p4 = stream(seed, "transmission-order4").uniform(0.0, 2.0 * np.pi) if order4 else 0.0
        pc = stream(seed, "flexspline-compliance").uniform(0.0, 2.0 * np.pi) if compliance else 0.0
        return cls(wg2=wg2, wg2_phase=float(p2), wg1=SHARES["wg1"] * half, wg1_phase=float(p1),
                   output=SHARES["output"] * half, output_phase=float(po),
                   wg4=order4 * wg2, wg4_phase=float(p4), load=load / rated_torque,
                   compliance=compliance, compliance_phase=float(pc))

    @property
    def active(self) -> bool:
        return bool(self.wg2 or self.wg1 or self.output or self.wg4 or self.compliance)

    def params(self) -> dict[str, float]:
        """The integrator's parameters (``PARAM_NAMES``)."""
        return dict(zip(PARAM_NAMES, (self.wg2, self.wg2_phase, self.wg1, self.wg1_phase,
                                      self.output, self.output_phase, self.wg4, self.wg4_phase,
                                      self.load, self.compliance, self.compliance_phase)))

    def error(self, wave_angle, gear_ratio: float, torque=0.0) -> np.ndarray:
        """``e`` [rad] at the wave-generator angle ``wave_angle`` [rad] under the shaft
        torque ``torque`` [Nm] (as the integrator computes it, for tests and figures)."""
        th = np.asarray(wave_angle, float)
        wg2 = self.wg2 * (1.0 + self.load * np.abs(torque))
        return (wg2 * np.cos(2.0 * th + self.wg2_phase) + self.wg1 * np.cos(th + self.wg1_phase)
                + self.output * np.cos(th / gear_ratio + self.output_phase)
                + self.wg4 * np.cos(4.0 * th + self.wg4_phase))

    def compliance_scale(self, wave_angle) -> np.ndarray:
        """``s``: the drive twists ``s twist(tau)`` under ``tau`` at ``wave_angle`` [rad]."""
        return 1.0 + self.compliance * np.cos(2.0 * np.asarray(wave_angle, float) + self.compliance_phase)


#: The ideal gear: no error (the integrator's parameters when none is given).
IDEAL = TransmissionError()


def structural_damping(loss_factor: float, table) -> float:
    """The drive's structural damping [Nm s/rad]: the viscous damper that dissipates, at the
    joint's own mode ``w = sqrt(K1 / M)``, what a hysteretic loss factor ``loss_factor``
    dissipates (``c = eta K1 / w = eta sqrt(K1 M)``, ``M`` the link's mean inertia on the
    load ``table``; docs/physics.md, "Transmission error")."""
    if not loss_factor:
        return 0.0
    return float(loss_factor * np.sqrt(joint.STIFFNESS_LOW * np.mean(table.inertia)))
