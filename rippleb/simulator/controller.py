"""The joint's position controller and the closed-loop run of the flexible joint.

A motor-side PD controller at ``spec.control_rate`` with zero-order hold, reading the
quantised encoder count, with the feedforward of the paper's eq. (7) reference, and an
ideal current loop (the motor current is the commanded current)::

    i = [tau_ref / N + J_m N qdd_d + K_p (theta_ref - theta_enc) + K_d (w_ref - w_enc)] / K_t

``theta_ref = N (q_d + twist(tau_ref)) + zero`` is where the motor must stand for the link
to be at ``q_d`` under the expected torque. Gains by pole placement on the rigid joint
(``J = J_m + M / N^2`` on the motor shaft): ``K_p = J w_c^2``, ``K_d = 2 zeta J w_c``, with
``w_c`` a third of the locked-motor resonance ``sqrt(K1 / M)`` and ``zeta = 1/sqrt(2)``;
``M`` is the *nominal* model's link inertia (a controller knows no better). Reasons and
values in ``docs/physics.md``, "Joint dynamics and position controller".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.data import JointSpec
from rippleb.simulator.scenario import REFERENCE_TEMPERATURE_C
from rippleb.simulator import device as device_module
from rippleb.simulator import joint
from rippleb.simulator.encoder import IDEAL_PARAMS
from rippleb.simulator.robot import LoadTable
from rippleb.simulator.transmission import IDEAL as IDEAL_GEAR, TransmissionError

#: Closed-loop bandwidth as a fraction of the locked-motor resonance: a collocated PD
#: loop is kept well below the antiresonance it cannot see, a factor 3 is the usual margin.
BANDWIDTH_FRACTION = 1.0 / 3.0
#: Samples per radian of closed-loop bandwidth at least: a sampled loop with a zero-order
#: hold keeps its bandwidth some 20 times below its sample rate (Franklin, Powell & Workman,
#: *Digital Control of Dynamic Systems*, ch. 11: 20-40 samples per rise time); binds only
#: for light links (a wrist), whose resonance a third of would be out of a 1 kHz loop's reach.
SAMPLES_PER_BANDWIDTH = 20.0
#: Damping ratio of the rigid-body closed loop: the fastest response with at most 4.3 % overshoot.
DAMPING_RATIO = 1.0 / np.sqrt(2.0)
#: Cut-off of the first-order low-pass on the encoder's difference velocity, as a multiple
#: of the loop bandwidth: far enough above it to cost little phase (atan(1/10) = 6 deg at
#: w_c), low enough to smooth the one-count steps of a 2500-count encoder read at 1 kHz.
VELOCITY_FILTER_FACTOR = 10.0
#: Current limit [A] of the ideal current loop: the current sense's +-20 A range (the
#: motor's catalogue peak current is not known; built-in scenarios stay far below).
CURRENT_LIMIT = 20.0
#: Substeps of the integrator per DAQ sample (50 us at 20 kHz); see docs/physics.md for
#: the convergence measurement that chose it.
SUBSTEPS = 2


@dataclass(frozen=True)
class Gains:
    """Motor-side PD gains and what they were designed from.

    Attributes
    ----------
    kp, kd
        Nm/rad and Nm s/rad on the motor shaft.
    bandwidth
        Designed closed-loop natural frequency ``w_c`` [rad/s].
    damping
        Designed damping ratio.
    inertia
        Rigid-body inertia on the motor shaft ``J_m + M / N^2`` [kg m^2].
    resonance
        Locked-motor resonance ``sqrt(K1 / M)`` [rad/s] of the nominal link.
    """

    kp: float
    kd: float
    bandwidth: float
    damping: float
    inertia: float
    resonance: float


def design_gains(spec: JointSpec, link_inertia: float, bandwidth_factor: float = 1.0) -> Gains:
    """Pole placement on the rigid joint of link inertia ``link_inertia`` [kg m^2]: the
    bandwidth a third of the locked-motor resonance, at most ``2 pi control_rate / 20``.

    ``bandwidth_factor`` (the ``[controller]`` table of :mod:`rippleb.simulator.mismatch`) scales the
    designed bandwidth before that cap: a stiffer (or softer) loop than the documented
    design, with the same damping ratio.
    """
    N = spec.gear_ratio
    inertia = spec.rotor_inertia + link_inertia / N**2
    resonance = np.sqrt(joint.STIFFNESS_LOW / link_inertia)
    designed = BANDWIDTH_FRACTION * resonance
    if bandwidth_factor != 1.0:
        designed = designed * bandwidth_factor
    bandwidth = min(designed, 2 * np.pi * spec.control_rate / SAMPLES_PER_BANDWIDTH)
    return Gains(kp=inertia * bandwidth**2, kd=2 * DAMPING_RATIO * inertia * bandwidth,
                 bandwidth=bandwidth, damping=DAMPING_RATIO, inertia=inertia, resonance=resonance)


def motor_params(device, temperature_c: float, spec: JointSpec, encoder=None,
                 gear: TransmissionError = IDEAL_GEAR) -> dict:
    """The device's motor and bearing friction, cogging and encoder (``encoder``: its
    :class:`~rippleb.simulator.encoder.EncoderErrors`, None for an ideal disc) as
    integrator parameters."""
    f = device.friction
    dt = temperature_c - REFERENCE_TEMPERATURE_C
    p1, p2, p3 = device.friction_phase
    out_coulomb, out_viscous = device.output_friction
    return dict(
        coulomb=f["coulomb"], static=f["static"], stribeck_speed=f["stribeck_speed"], viscous=f["viscous"],
        load=f["load"], ripple1=f["ripple1"], ripple2=f["ripple2"], phase1=p1, phase2=p2,
        coulomb_scale=np.exp(-device_module.COULOMB_TEMP_COEFF * dt),
        viscous_scale=np.exp(-device_module.VISCOUS_TEMP_COEFF * dt),
        sign_smoothing=device_module.SIGN_SMOOTHING, cogging=device_module.COGGING,
        cogging_order=device_module.COGGING_ORDER, cogging_phase=p3,
        out_coulomb=out_coulomb, out_viscous=out_viscous * np.exp(-device_module.VISCOUS_TEMP_COEFF * dt),
        out_smoothing=device_module.OUTPUT_SIGN_SMOOTHING, encoder_zero=device.encoder_zero,
        gear_ratio=spec.gear_ratio, rotor_inertia=spec.rotor_inertia, torque_constant=spec.torque_constant,
        counts_per_rev=spec.counts_per_rev, **(IDEAL_PARAMS if encoder is None else encoder.params()),
        **gear.params())


def loop_params(spec: JointSpec, gains: Gains, table: LoadTable, *, controller=True, friction=True,
                clamp_motor=False, substeps=SUBSTEPS, damping=0.0) -> dict:
    """Controller, table grid, the drive's structural damping ``damping`` [Nm s/rad] and
    switches as integrator parameters."""
    tick = 1.0 / spec.control_rate
    return dict(dt=1.0 / spec.fs, substeps=substeps, block=spec.block_size, kp=gains.kp, kd=gains.kd,
                current_limit=CURRENT_LIMIT,
                velocity_filter=1.0 - np.exp(-VELOCITY_FILTER_FACTOR * gains.bandwidth * tick),
                table_start=table.angle[0], table_step=table.angle[1] - table.angle[0],
                controller=controller, friction=friction, clamp_motor=clamp_motor, damping=damping)


def table_rows(table: LoadTable) -> np.ndarray:
    """The load table as the integrator's ``(3, m)`` rows ``M, h, G``."""
    return np.ascontiguousarray(np.vstack([table.inertia, table.velocity_coeff, table.gravity]))


def reference(spec: JointSpec, t, q_d, qd_d, qdd_d, tau_ref, encoder_zero: float) -> np.ndarray:
    """The controller's reference rows ``theta_ref, w_ref, torque_ff`` on the DAQ grid."""
    N = spec.gear_ratio
    wind = joint.twist(tau_ref)
    theta_ref = N * (q_d + wind) + encoder_zero
    w_ref = N * (qd_d + np.gradient(wind, t)) if len(t) > 1 else N * qd_d
    torque_ff = tau_ref / N + spec.rotor_inertia * N * qdd_d
    return np.vstack([theta_ref, w_ref, torque_ff])


def initial_state(spec: JointSpec, gains: Gains, table: LoadTable, q_d0: float, qd_d0: float,
                  external0: float, reference0, encoder_zero: float,
                  gear: TransmissionError = IDEAL_GEAR) -> np.ndarray:
    """``q, qd, theta_m, w_m, tau_s`` at the start: the link held by the shaft torque
    ``G(q) + tau_ext``, the motor off its reference by the position error whose ``K_p``
    makes up for the feedforward's model error (cogging and friction neglected)."""
    N = spec.gear_ratio
    theta_ref0, _, torque_ff0 = reference0
    q = q_d0
    for _ in range(3):
        tau = float(np.interp(q, table.angle, table.gravity)) + external0
        theta = theta_ref0 - (tau / N - torque_ff0) / gains.kp
        q = ((theta - encoder_zero) / N + float(gear.error(theta, N, tau))
             - float(gear.compliance_scale(theta)) * float(joint.twist(tau)))
    return np.array([q, qd_d0, theta, N * qd_d0, tau])


def run(spec: JointSpec, device, temperature_c: float, table: LoadTable, gains: Gains, t, trajectory,
        tau_ref, external, encoder=None, gear: TransmissionError = IDEAL_GEAR, **switches) -> np.ndarray:
    """Integrate the closed-loop joint over ``t``; rows ``joint.STATE``.

    ``trajectory`` is ``(q_d, qd_d, qdd_d)``, ``tau_ref`` the eq. (7) reference the
    controller feeds forward, ``external`` the true external torque; ``encoder`` the
    errors of the encoder the controller reads (None: ideal), ``gear`` the drive's
    transmission error (default: an ideal gear); ``switches`` go to
    :func:`loop_params` (``controller``, ``friction``, ``clamp_motor``, ``substeps``).
    """
    q_d, qd_d, qdd_d = trajectory
    ref = reference(spec, t, q_d, qd_d, qdd_d, tau_ref, device.encoder_zero)
    params = joint.pack_params(**motor_params(device, temperature_c, spec, encoder, gear),
                               **loop_params(spec, gains, table, **switches))
    inputs = np.ascontiguousarray(np.vstack([external, ref]))
    state0 = initial_state(spec, gains, table, float(q_d[0]), float(qd_d[0]), float(external[0]),
                           ref[:, 0], device.encoder_zero, gear)
    out = np.empty((len(joint.STATE), len(t)))
    joint.integrate(params, table_rows(table), inputs, state0, out)
    return out
