"""Physical validity: what a scenario may ask of the joint, and whether a simulation stayed physical.

Two checks, each bound with its source here and in ``docs/physics.md`` ("Physical validity"):

* :func:`check_bounds` and :func:`check_motion`, before anything runs (``rippleb run``,
  ``sweep`` and ``simulate`` call them through :func:`rippleb.engine.checks.check_scenario`): a
  scenario that asks for what the joint cannot do is refused with one line naming its file
  and field: more segments or loads than a scenario is meant to hold, a held joint outside
  its limits, loads beyond the drive's peak torque, a move too fast for the motor.
* :func:`check_simulation`, once per simulated log (:func:`rippleb.engine.jobs.simulate_case`):
  a log whose true torque leaves the drive's repeated peak torque, or whose strain clips at
  the ADC, is not a joint that exists (a closed loop that went unstable, e.g. at a 100 Hz
  control rate); every row scored on it, or calibrated on it, is ``invalid`` with the reason.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rippleb.errors import InputError
from rippleb.simulator.sensors import CURRENT_RANGE, STRAIN_BITS, STRAIN_RANGE

#: Limit for repeated peak torque over rated torque of a size-25 harmonic drive: the
#: Harmonic Drive CSF-25-100 catalogue (the unit whose stiffness docs/physics.md uses)
#: gives 157 Nm repeated peak against 67 Nm rated at 2000 rpm input; the CSG-25-100 gives
#: 204 against 87 Nm, the same ratio. Scaled to the joint's own ``rated_torque`` (51 Nm by
#: default: 119.5 Nm), so a scenario that declares another drive gets its own bound.
REPEATED_PEAK_RATIO = 157.0 / 67.0
#: Most trajectory segments and loads a scenario may hold. **Estimate**: the trajectory is
#: evaluated per segment over every sample and each load over every sample, so the cost
#: grows with segments (or loads) x samples: 1000 segments over the longest log the format
#: allows (10^7 samples) take 18 s and 100 loads 86 s, the order of simulating such a log;
#: 200 000 segments did not finish in 600 s. The built-ins hold at most 54 segments
#: (``calibration``) and 3 loads.
MAX_SEGMENTS = 1000
MAX_LOADS = 100
#: The quintic ``10 s^3 - 15 s^4 + 6 s^5`` (moves, smooth ramps): its largest slope, at
#: ``s = 1/2``, and its largest curvature, at ``s = 1/2 -+ sqrt(3)/6``.
QUINTIC_PEAK_SLOPE = 1.875
QUINTIC_PEAK_CURVATURE = 10.0 / math.sqrt(3.0)
#: Points per load edge where the sum of the loads is evaluated (the edges are smooth).
_EDGE_POINTS = 17


def peak_torque(spec) -> float:
    """The drive's limit for repeated peak torque [Nm] (:data:`REPEATED_PEAK_RATIO` x rated)."""
    return REPEATED_PEAK_RATIO * spec.rated_torque


# ----------------------------------------------------------------------------- before a run


def check_bounds(scenario, model) -> None:
    """Refuse a scenario whose size, posture or loads are out of physical bounds, with one line.

    Called before the trajectory is sampled (whose cost grows with the segment count
    squared); :func:`check_motion` follows it.

    Parameters
    ----------
    scenario
        A parsed :class:`~rippleb.simulator.scenario.Scenario`.
    model
        The Pinocchio model of its robot (:func:`rippleb.simulator.robot.load_model`).

    Raises
    ------
    InputError
        ``<file>: <field>: <what is out of bounds, and the bound>``.
    """
    _check_counts(scenario)
    _check_posture(scenario, model)
    _check_loads(scenario)


def _check_counts(scenario) -> None:
    planned = len(scenario.segments) - 1   # the parser adds an open cruise after the last
    if planned > MAX_SEGMENTS:
        raise InputError(f"{scenario.path}: trajectory.segment: {planned} segments, more than the "
                         f"{MAX_SEGMENTS} a scenario may hold; split it into shorter scenarios")
    if len(scenario.loads) > MAX_LOADS:
        raise InputError(f"{scenario.path}: load: {len(scenario.loads)} loads, more than the "
                         f"{MAX_LOADS} a scenario may hold")


def _check_posture(scenario, model) -> None:
    """Each held joint within its URDF position limits."""
    for name, value in scenario.posture:
        if not math.isfinite(value):
            raise InputError(f"{scenario.path}: posture: {name} = {value} is not a finite angle")
        idx = model.joints[model.getJointId(name)].idx_q
        lo, hi = float(model.lowerPositionLimit[idx]), float(model.upperPositionLimit[idx])
        if not lo <= value <= hi:
            raise InputError(f"{scenario.path}: robot.posture.{name}: {value:g} rad is outside the "
                             f"joint's limits [{lo:.3f}, {hi:.3f}]")


def _check_loads(scenario) -> None:
    """The external loads acting at once within the drive's repeated peak torque: a load
    beyond it breaks the drive whatever the arm does."""
    t = _load_times(scenario)
    steps = sum((_envelope(load, t) for load in scenario.loads if load.kind == "step"), np.zeros_like(t))
    # A chirp swings by its envelope either way: count it with the sign that adds.
    chirps = sum((np.abs(_envelope(load, t)) for load in scenario.loads if load.kind == "chirp"),
                 np.zeros_like(t))
    total = np.abs(steps) + chirps
    worst = int(np.argmax(total))
    limit = peak_torque(scenario.spec)
    if total[worst] > limit:
        at = t[worst:worst + 1]
        acting = [f"load[{i}]" for i, load in enumerate(scenario.loads) if _envelope(load, at)[0] != 0]
        raise InputError(f"{scenario.path}: load: {', '.join(acting)} add up to {total[worst]:.4g} Nm at "
                         f"t = {t[worst]:.4g} s, beyond the drive's repeated peak torque of {limit:.4g} Nm "
                         f"({REPEATED_PEAK_RATIO:.3g} x rated_torque)")


def _envelope(load, t: np.ndarray) -> np.ndarray:
    """A load's torque without a chirp's sine: its level between the smooth edges [Nm]."""
    return dataclasses.replace(load, kind="step").evaluate(t)


def _load_times(scenario) -> np.ndarray:
    """Times within the log where the loads' sum can peak: along every edge of every load
    (each edge is a smooth rise), and where a load is fully on."""
    times = [np.array([0.0, scenario.duration])]
    for load in scenario.loads:
        times.append(np.linspace(load.start, load.start + load.rise, _EDGE_POINTS))
        if math.isfinite(load.stop):
            times.append(np.linspace(load.stop, load.stop + load.rise, _EDGE_POINTS))
    t = np.concatenate(times)
    return np.unique(t[(t >= 0.0) & (t <= scenario.duration)])


def check_motion(scenario, model) -> None:
    """Refuse a segment whose exact peak speed exceeds the joint's URDF velocity limit, or
    whose peak acceleration exceeds what the motor gives at its current limit.

    The sampled trajectory check (:func:`rippleb.engine.rows.check_trajectory`) can step over a
    short segment (a move of 1e-300 s has no sample); the peaks here come from the
    segment's formula. Arguments and error as :func:`check_bounds`.
    """
    spec = scenario.spec
    joint = model.joints[model.getJointId(scenario.joint)]
    speed_limit = float(model.velocityLimit[joint.idx_v])
    accel_limit = _acceleration_limit(scenario, spec)
    for i, seg in enumerate(scenario.segments[:-1]):
        if seg.t0 >= scenario.duration:
            break   # never reached: the log ends first
        speed, accel = segment_peaks(seg)
        where = f"{scenario.path}: trajectory.segment[{i}]"
        if speed > speed_limit:
            raise InputError(f"{where}: a {seg.kind} over {seg.duration:.4g} s needs {speed:.4g} rad/s at "
                             f"the joint, beyond its velocity limit of {speed_limit:.4g} rad/s")
        if accel > accel_limit:
            raise InputError(f"{where}: a {seg.kind} over {seg.duration:.4g} s needs {accel:.4g} rad/s^2 at "
                             f"the joint; the motor gives at most {accel_limit:.4g} rad/s^2 "
                             f"({CURRENT_RANGE:g} A x {spec.torque_constant:g} Nm/A through the "
                             f"{spec.gear_ratio:g}:1 gear against the rotor's and the link's inertia)")


def segment_peaks(seg) -> tuple[float, float]:
    """Largest joint speed [rad/s] and acceleration [rad/s^2] of a segment, exactly."""
    if seg.kind == "move":  # divided twice: a duration of 1e-300 s squared would be 0
        speed = abs(seg.distance) / seg.duration
        return QUINTIC_PEAK_SLOPE * speed, QUINTIC_PEAK_CURVATURE * speed / seg.duration
    if seg.kind == "ramp":
        change = abs(seg.v1 - seg.v0) / seg.duration
        return max(abs(seg.v0), abs(seg.v1)), change * (1.0 if seg.shape == "linear" else QUINTIC_PEAK_SLOPE)
    return abs(seg.v0), 0.0   # hold (v0 = 0) and cruise


def _acceleration_limit(scenario, spec) -> float:
    """``N K_t I_max / (J_m N^2 + M)`` [rad/s^2]: the joint acceleration the motor's largest
    current gives against the rotor's and the lightest link inertia of the joint (over a
    whole turn, with the others at the posture), gravity and friction left aside, so
    whatever it refuses is impossible."""
    from rippleb.simulator.robot import load_table

    table = load_table(scenario.robot, scenario.joint, dict(scenario.posture), (-math.pi, math.pi), points=65)
    link = float(np.min(table.inertia))
    n = spec.gear_ratio
    return n * spec.torque_constant * CURRENT_RANGE / (spec.rotor_inertia * n * n + link)


# ----------------------------------------------------------------------------- after a simulation


def strain_rails(full_scale: float = STRAIN_RANGE, bits: int = STRAIN_BITS) -> tuple[float, float]:
    """The lowest and highest value the strain ADC reads [V] (what ``quantise`` clips to)."""
    step = 2.0 * full_scale / 2**bits
    return -(2 ** (bits - 1)) * step, (2 ** (bits - 1) - 1) * step


def check_simulation(sim) -> str | None:
    """Why a simulated log is not a joint that exists, in one line; None if it is.

    Its true torque must stay finite and within the drive's repeated peak torque
    (:func:`peak_torque`), and its strain off the rails of the healthy ±10 V ADC. A scenario
    that sets ``faults.strain_full_scale`` asked for a clipping ADC: that clipping is the
    fault under study, not a sign of divergence, and is not checked.
    """
    log = sim.log
    tau = log.torque_true
    if not np.isfinite(tau).all():
        return "its true torque is not finite (the simulation diverged)"
    worst = int(np.argmax(np.abs(tau)))
    limit = peak_torque(log.spec)
    if abs(tau[worst]) > limit:
        return (f"its true torque reaches {tau[worst]:.4g} Nm at t = {log.t[worst]:.4g} s, beyond the drive's "
                f"repeated peak torque of {limit:.4g} Nm (an unstable loop, or loads and gravity beyond "
                f"the rating)")
    scenario = getattr(sim, "scenario", None)   # a stand-in may have none
    faults = getattr(scenario, "faults", None)
    if getattr(faults, "strain_full_scale", None) is None:
        # the word length a scenario's `daq.adc_bits` knob sets moves the positive rail
        bits = getattr(getattr(scenario, "unmodelled", None), "adc_bits", None) or STRAIN_BITS
        lo, hi = strain_rails(bits=bits)
        clipped = (log.strain <= lo) | (log.strain >= hi)
        if clipped.any():
            first = int(np.argmax(clipped))
            return (f"its strain clips at the ADC's ±{STRAIN_RANGE:g} V on {int(clipped.sum())} samples "
                    f"(first at t = {log.t[first]:.4g} s)")
    return None
