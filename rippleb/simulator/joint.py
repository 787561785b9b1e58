"""The joint's mechanics: the drive's torsional compliance, the arm load it carries, and
the two-mass joint (motor, transmission, link) integrated in time.

The arm load comes from :mod:`rippleb.simulator.robot` (Pinocchio), tabulated over the
moving joint's angle; the nominal model of eq. (7) is the same arm with identification
errors (:func:`rippleb.simulator.robot.nominal_model`). The position controller that
drives the motor is :mod:`rippleb.simulator.controller`.

The joint (``docs/physics.md``, "Joint dynamics and position controller")::

    link:          M(q) q'' + h(q) q'^2 + G(q) + F_out(q') + tau_ext(t) = tau_s
    transmission:  tau_s = twist^-1(d / s(theta_m)) + c d',   d = theta_m / N + e(theta_m, tau_s) - q
    motor:         J_m theta_m'' = K_t i - tau_s (1/N + de/dtheta_m) + s'(theta_m) W*(tau) - F_m(theta_m', tau_s, theta_m) - cogging(theta_m)

``e`` is the gear's transmission error, ``s`` the flexspline's compliance varying over the
wave-generator angle and ``c`` the drive's structural damping
(:mod:`rippleb.simulator.transmission`); ``W*(tau) = tau twist(tau) - E(tau)`` is the
spring's complementary energy, whose change with ``s`` the motor feels (virtual work).

:func:`integrate` advances it on the DAQ grid with semi-implicit (symplectic) Euler
substeps; both frictions are taken implicitly (a scalar safeguarded Newton solve per
substep), because the motor friction's sign ``tanh(w / 0.02 rad/s)`` on the rotor's
6e-5 kg m^2 has a time constant of some 1e-5 s, shorter than a substep.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types

from rippleb.dsp import F8_2D_C, IN_F8, IN_F8_2D, compiled
from rippleb.errors import InputError
from rippleb.simulator import robot

# --- harmonic drive stiffness, size 25: a smooth fit of the catalogue's K1/K3 curve ---
STIFFNESS_LOW = 3.1e4        # Nm/rad near zero torque (catalogue K1)
STIFFNESS_HIGH = 5.7e4       # Nm/rad at high torque (catalogue K3)
STIFFNESS_KNEE = 22.0        # Nm: where the stiffness has moved half-way; fit, see physics.md
_SOFT = 1.0 / STIFFNESS_LOW - 1.0 / STIFFNESS_HIGH


def twist(torque: np.ndarray) -> np.ndarray:
    """Torsional deflection of the drive [rad] under ``torque``.

    ``tau / K_high + (1/K_low - 1/K_high) T_knee tanh(tau / T_knee)``: stiffness
    ``K_low`` at zero torque rising smoothly to ``K_high``. Smooth, because the motor
    acceleration follows the second derivative of the twist; the catalogue's
    piecewise-linear curve would put impulses into the motor current at its corners.
    """
    return torque / STIFFNESS_HIGH + _SOFT * STIFFNESS_KNEE * np.tanh(torque / STIFFNESS_KNEE)


def stiffness(torque: np.ndarray) -> np.ndarray:
    """Tangent stiffness ``d tau / d twist`` [Nm/rad] at ``torque``."""
    return 1.0 / (1.0 / STIFFNESS_HIGH + _SOFT / np.cosh(np.asarray(torque) / STIFFNESS_KNEE) ** 2)


def spring_energy(torque: np.ndarray) -> np.ndarray:
    """Energy stored in the twisted drive [J] at ``torque``: ``int tau d twist``."""
    tau = np.asarray(torque, float)
    return (tau * twist(tau) - tau**2 / (2 * STIFFNESS_HIGH)
            - _SOFT * STIFFNESS_KNEE**2 * np.log(np.cosh(tau / STIFFNESS_KNEE)))


@compiled(types.float64(types.float64, types.float64))
def torque_of_twist(deflection, guess):
    """The torque [Nm] that twists the drive by ``deflection`` [rad]: Newton on the
    monotonic :func:`twist` from ``guess`` (the last substep's torque: 2-3 steps)."""
    tau = guess
    for _ in range(30):
        th = math.tanh(tau / STIFFNESS_KNEE)
        err = tau / STIFFNESS_HIGH + _SOFT * STIFFNESS_KNEE * th - deflection
        step = err / (1.0 / STIFFNESS_HIGH + _SOFT * (1.0 - th * th))
        tau -= step
        if abs(step) < 1e-12 * (1.0 + abs(tau)):
            break
    return tau


def load_table(sc: Scenario, q: np.ndarray, nominal_seed: int | None = None):  # noqa: F821
    """The true load table of the scenario's joint, or with ``nominal_seed`` the one of
    the nominal model (:func:`rippleb.simulator.robot.nominal_model`) of that robot."""
    model = robot.load_model(sc.robot)
    idx = model.joints[model.getJointId(sc.joint)].idx_q
    lo, hi = float(q.min()), float(q.max())
    if lo < model.lowerPositionLimit[idx] or hi > model.upperPositionLimit[idx]:
        raise InputError(f"{sc.path}: trajectory: {sc.joint} travels over [{lo:.3f}, {hi:.3f}] rad, "
                         f"outside its limits [{model.lowerPositionLimit[idx]:.3f}, "
                         f"{model.upperPositionLimit[idx]:.3f}]")
    model = None if nominal_seed is None else robot.nominal_model(sc.robot, nominal_seed)
    return robot.load_table(sc.robot, sc.joint, dict(sc.posture), (lo, hi), model=model)


# --- the integrator's parameter vector: one float64 array, indexed by these names ---
PARAMS = ("dt", "substeps", "block", "gear_ratio", "rotor_inertia", "torque_constant",
          "kp", "kd", "current_limit", "counts_per_rev", "velocity_filter",
          "coulomb", "static", "stribeck_speed", "viscous", "load", "ripple1", "ripple2",
          "phase1", "phase2", "coulomb_scale", "viscous_scale", "sign_smoothing",
          "cogging", "cogging_order", "cogging_phase",
          "out_coulomb", "out_viscous", "out_smoothing",
          "table_start", "table_step", "encoder_zero", "controller", "friction", "clamp_motor",
          "encoder_errors", "edge0", "edge1", "edge2", "edge3", "eccentricity", "eccentricity_phase",
          "te2", "te2_phase", "te1", "te1_phase", "te_out", "te_out_phase", "te4", "te4_phase",
          "te_load", "compliance", "compliance_phase", "damping")
(DT, SUBSTEPS, BLOCK, GEAR, JM, KT, KP, KD, IMAX, CPR, VFILT, FC, FS, WS, FV, MU, R1, R2, PH1, PH2,
 CSCALE, VSCALE, EPS, COG, COGORD, COGPH, OC, OV, OEPS, TSTART, TSTEP, ZERO, CTRL, FRIC,
 CLAMP, ENCERR, EDGE0, EDGE1, EDGE2, EDGE3, ECC, ECCPH,
 TE2, TE2PH, TE1, TE1PH, TEO, TEOPH, TE4, TE4PH, TELOAD, COMPL, COMPLPH, DAMP) = range(len(PARAMS))
#: Rows of the integrator's output: joint angle and velocity, motor angle and velocity,
#: transmitted (shaft) torque and commanded current.
STATE = ("q", "qd", "theta_m", "w_m", "tau_s", "current")
#: Rows of its input on the DAQ grid: external torque and the controller's reference.
INPUTS = ("external", "theta_ref", "w_ref", "torque_ff")


def pack_params(**values) -> np.ndarray:
    """The parameter vector of :func:`integrate` from keyword values named as ``PARAMS``."""
    missing = set(PARAMS) - set(values)
    if missing:
        raise ValueError(f"integrator parameters missing: {sorted(missing)}")
    return np.array([float(values[name]) for name in PARAMS])


@compiled(types.UniTuple(types.float64, 2)(IN_F8, types.float64, types.float64))
def transmission(P, th, tau):
    """The gear's transmission error ``e`` [rad] at wave-generator angle ``th`` under the
    shaft torque ``tau`` [Nm], and its slope ``de/dth``
    (:class:`rippleb.simulator.transmission.TransmissionError`): the order-2 amplitude grows
    by ``P[TELOAD]`` per Nm of ``|tau|``."""
    out_angle = th / P[GEAR]
    a2 = P[TE2] * (1.0 + P[TELOAD] * abs(tau))
    e = (a2 * math.cos(2.0 * th + P[TE2PH]) + P[TE1] * math.cos(th + P[TE1PH])
         + P[TEO] * math.cos(out_angle + P[TEOPH]) + P[TE4] * math.cos(4.0 * th + P[TE4PH]))
    slope = -(2.0 * a2 * math.sin(2.0 * th + P[TE2PH]) + P[TE1] * math.sin(th + P[TE1PH])
              + P[TEO] / P[GEAR] * math.sin(out_angle + P[TEOPH]) + 4.0 * P[TE4] * math.sin(4.0 * th + P[TE4PH]))
    return e, slope


@compiled(types.UniTuple(types.float64, 2)(IN_F8, types.float64))
def compliance(P, th):
    """The flexspline's compliance factor ``s`` at wave-generator angle ``th`` (the drive
    twists ``s twist(tau)`` under ``tau``) and its slope ``ds/dth``."""
    angle = 2.0 * th + P[COMPLPH]
    return 1.0 + P[COMPL] * math.cos(angle), -2.0 * P[COMPL] * math.sin(angle)


@compiled(types.float64(types.float64))
def complementary_energy(tau):
    """``tau twist(tau) - E(tau)`` [J]: the spring's complementary energy at ``tau``."""
    x = abs(tau) / STIFFNESS_KNEE     # log cosh x = x + log1p(exp(-2x)) - log 2, without overflow
    return tau * tau / (2.0 * STIFFNESS_HIGH) + _SOFT * STIFFNESS_KNEE ** 2 * (x + math.log1p(math.exp(-2.0 * x))
                                                                                - math.log(2.0))


@compiled(types.float64(IN_F8, types.float64, types.float64))
def encoder_count(P, th, step_angle):
    """The count the encoder shows at motor angle ``th`` [rad], as a float: an ideal disc's
    ``floor(th / step_angle)``, or with ``P[ENCERR]`` the disc read through its
    eccentricity and count ``n`` starting at ``n + P[EDGE0 + n mod 4]`` counts
    (:func:`rippleb.simulator.encoder.counts`, the same rule for the logged count)."""
    if P[ENCERR] == 0.0:
        return math.floor(th / step_angle)
    x = (th + P[ECC] * math.sin(th + P[ECCPH])) / step_angle
    n = math.floor(x)
    if x < n + P[EDGE0 + int(n % 4.0)]:
        return n - 1.0
    if x >= n + 1.0 + P[EDGE0 + int((n + 1.0) % 4.0)]:
        return n + 1.0
    return n


@compiled(types.float64(IN_F8, types.float64, types.float64))
def motor_coulomb_scale(P, angle, tau):
    """The factor of the motor friction's Coulomb level that the substep holds fixed:
    temperature x the 1x/2x ripple over the wave-generator turn."""
    return P[CSCALE] * (1.0 + P[R1] * math.cos(angle + P[PH1]) + P[R2] * math.cos(2.0 * angle + P[PH2]))


@compiled(types.UniTuple(types.float64, 2)(types.float64, IN_F8, types.float64, types.float64,
                                           types.boolean))
def friction(v, P, scale, tau, motor):
    """Friction [Nm] at velocity ``v`` and its slope in ``v``: the motor's (as
    :meth:`~rippleb.simulator.device.Device.motor_friction`, ``scale`` from
    :func:`motor_coulomb_scale`) or the output bearing's (as
    :meth:`~rippleb.simulator.device.Device.output_bearing_friction`)."""
    if motor:
        stribeck = (P[FS] - P[FC]) * math.exp(-(v / P[WS]) ** 2)
        level = scale * (P[FC] + P[MU] * abs(tau) / P[GEAR] + stribeck)
        slope_level = scale * stribeck * (-2.0 * v / P[WS] ** 2)
        sign = math.tanh(v / P[EPS])
        return (level * sign + P[VSCALE] * P[FV] * v,
                slope_level * sign + level * (1.0 - sign * sign) / P[EPS] + P[VSCALE] * P[FV])
    sign = math.tanh(v / P[OEPS])
    return P[OC] * sign + P[OV] * v, P[OC] * (1.0 - sign * sign) / P[OEPS] + P[OV]


@compiled(types.float64(types.float64, types.float64, types.float64, IN_F8, types.float64,
                        types.float64, types.boolean))
def _implicit_velocity(mass_over_h, v0, force, P, scale, tau, motor):
    """Solve ``m (v - v0) / h + friction(v) = force`` for ``v``: the friction taken at
    the end of the substep. The left side rises monotonically in ``v`` (``m / h``
    outweighs the Stribeck dip), so Newton steps kept inside a shrinking bracket
    converge whatever the slope of the friction's sign."""
    if motor:
        bound = abs(scale) * (max(P[FC], P[FS]) + P[MU] * abs(tau) / P[GEAR])
        viscous = P[VSCALE] * P[FV]
    else:
        bound, viscous = P[OC], P[OV]
    centre = mass_over_h * v0 + force
    lo = (centre - bound) / (mass_over_h + viscous)
    hi = (centre + bound) / (mass_over_h + viscous)
    v = min(max(v0, lo), hi)
    for _ in range(60):
        f, df = friction(v, P, scale, tau, motor)
        g = mass_over_h * (v - v0) + f - force
        if g > 0.0:
            hi = v
        else:
            lo = v
        step = g / (mass_over_h + df)
        if abs(step) < 1e-11 * (1.0 + abs(v)):
            return v - step
        v -= step
        if not lo < v < hi:
            v = 0.5 * (lo + hi)
    return v


@compiled(types.UniTuple(types.float64, 3)(IN_F8_2D, IN_F8, types.float64))
def _load(table, P, q):
    """``M(q)``, ``h(q)``, ``G(q)`` linearly interpolated on the uniform angle grid
    (``np.interp``'s values; clamped at the ends)."""
    x = (q - P[TSTART]) / P[TSTEP]
    last = table.shape[1] - 1
    if x <= 0.0:
        return table[0, 0], table[1, 0], table[2, 0]
    if x >= last:
        return table[0, last], table[1, last], table[2, last]
    i = int(x)
    w = x - i
    return ((1 - w) * table[0, i] + w * table[0, i + 1], (1 - w) * table[1, i] + w * table[1, i + 1],
            (1 - w) * table[2, i] + w * table[2, i + 1])


@compiled(types.void(IN_F8, IN_F8_2D, IN_F8_2D, IN_F8, F8_2D_C))
def integrate(P, table, inputs, state0, out):
    """Integrate the joint over the DAQ grid; ``out[:, k]`` (rows ``STATE``) is the state
    at sample ``k`` and the current commanded over it; ``out[:, 0]`` is ``state0``.

    Parameters
    ----------
    P
        Parameter vector (:func:`pack_params`).
    table
        Rows ``M``, ``h``, ``G`` of the load table on its uniform grid.
    inputs
        Rows ``INPUTS`` on the DAQ grid; the external torque is held over a sample.
    state0
        ``q, qd, theta_m, w_m, tau_s`` at the first sample; ``theta_m`` is the absolute
        motor angle (the deflection is ``(theta_m - encoder_zero) / N + e(theta_m) - q``) and
        ``tau_s`` only the inverse twist's first guess.
    out
        ``(6, n)``, written.

    Each sample is ``P[SUBSTEPS]`` substeps of semi-implicit Euler: the shaft torque from
    the positions, then both velocities with the frictions implicit, then the positions
    with the new velocities. The controller runs every ``P[BLOCK]`` samples, on the
    encoder count of the motor angle, and its current is held until the next tick.
    """
    n = out.shape[1]
    q, qd, th, w, spring = state0[0], state0[1], state0[2], state0[3], state0[4]
    N, Jm = P[GEAR], P[JM]
    sub = max(1, int(P[SUBSTEPS]))
    h = P[DT] / sub
    block = max(1, int(P[BLOCK]))
    tick = block * P[DT]
    step_angle = 2.0 * math.pi / P[CPR]
    friction_on, clamp = P[FRIC] != 0.0, P[CLAMP] != 0.0
    current = 0.0
    w_filtered = inputs[2, 0]
    last_angle = encoder_count(P, th, step_angle) * step_angle
    zero = P[ZERO]
    for k in range(n):
        for s in range(sub):
            # the shaft torque from the positions (the spring, its compliance at this angle)
            # and the deflection's rate (the drive's structural damping)
            e, slope = transmission(P, th, spring)
            scale, scale_slope = compliance(P, th)
            spring = torque_of_twist(((th - zero) / N + e - q) / scale, spring)
            tau = spring + P[DAMP] * (w / N + slope * w - qd)
            if s == 0:
                if P[CTRL] != 0.0 and k % block == 0:
                    angle = encoder_count(P, th, step_angle) * step_angle     # what the encoder counts
                    if k > 0:
                        w_filtered += P[VFILT] * ((angle - last_angle) / tick - w_filtered)
                    last_angle = angle
                    torque = (inputs[3, k] + P[KP] * (inputs[1, k] - angle) + P[KD] * (inputs[2, k] - w_filtered))
                    current = min(max(torque / P[KT], -P[IMAX]), P[IMAX])
                out[0, k], out[1, k], out[2, k], out[3, k], out[4, k], out[5, k] = q, qd, th, w, tau, current
            M, hq, G = _load(table, P, q)
            link_force = tau - hq * qd * qd - G - inputs[0, k]
            if friction_on:
                qd = _implicit_velocity(M / h, qd, link_force, P, 1.0, tau, False)
            else:
                qd += h * link_force / M
            if clamp:
                w = 0.0
            else:
                # the shaft torque reaches the rotor through the same kinematics (virtual
                # work): tau d(twist)/d(theta_m) = tau (1/N + e'), and a compliance that
                # varies with the angle adds s' W*(tau)
                # (tau / N + tau e', not tau (1/N + e'): an ideal gear keeps its last bits)
                motor_force = (P[KT] * current - tau / N - tau * slope
                               - P[COG] * math.cos(P[COGORD] * th + P[COGPH]))
                if scale_slope != 0.0:
                    motor_force += scale_slope * complementary_energy(spring)
                if friction_on:
                    w = _implicit_velocity(Jm / h, w, motor_force, P, motor_coulomb_scale(P, th, tau), tau, True)
                else:
                    w += h * motor_force / Jm
            q += h * qd
            th += h * w
