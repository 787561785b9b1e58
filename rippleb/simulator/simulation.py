"""One simulated run: ``simulate(scenario, seed, condition)`` puts the parts together.

``simulate(scenario, seed)`` integrates the closed-loop flexible joint on the DAQ grid
``t = k / fs`` (:mod:`rippleb.simulator.controller`, :mod:`rippleb.simulator.joint`): the
motor under a position controller that follows the scenario's trajectory drives the
link through the drive's compliance, so the joint angle, the shaft torque, the motor angle
and the current are simulated, not prescribed. The sensors then read that motion. The
device (the hidden truth of one joint: gauge errors, ripple, friction, offsets) comes
from ``Device.from_seed(seed)``; the measurement noise comes from a second generator
seeded by ``(seed, scenario name)``, so the calibration log and an evaluation log of one
seed share the device but not the noise.

Every default value of the parts is listed with its source in ``docs/physics.md``.

Sign conventions
----------------
Positive joint torque ``tau`` drives the joint in the positive ``q`` direction. The motor
angle is counted so that ``theta_m = N (q + twist(tau))`` (the gear's sign inversion is
folded into the encoder's counting direction). The motor's current accelerates its rotor
against ``tau / N``, the friction opposing the motor velocity, and cogging.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np

from rippleb.data import JointSpec, SensorLog
from rippleb.layouts import GaugeSettings
from rippleb.simulator.scenario import Scenario, load_scenario
from rippleb.simulator import conditions, controller
from rippleb.simulator.mismatch import describe
from rippleb.simulator.conditions import DEFAULT_CONDITION, calibration_condition, check_condition, stable_hash
from rippleb.simulator.device import Device, check_seed
from rippleb.simulator.flexspline import channel_devices
from rippleb.simulator.encoder import EncoderErrors, counts, missed_counts
from rippleb.simulator.joint import load_table
from rippleb.simulator.sensors import current_sense, dropouts, encoder_faults, gauge_channels
from rippleb.simulator.transmission import IDEAL as IDEAL_GEAR, TransmissionError, structural_damping


@dataclass(frozen=True, eq=False)
class Simulation:
    """One simulated run: the log plus the truth the runner and metrics need.

    Attributes
    ----------
    log
        :class:`~rippleb.data.SensorLog` with all seven columns;
        ``meta = {"scenario": name, "seed": seed, "condition": condition}``; the log also
        has the ``index`` column (encoder index pulse).
    moving
        Per sample: the commanded joint velocity is non-zero.
    wave_angle
        True wave-generator (= motor) angle [rad].
    joint_velocity
        True joint velocity [rad/s].
    eval_mask
        Per sample: inside the scenario's evaluation window.
    scenario, device
        What was simulated.
    gear
        The drive's transmission error (:mod:`rippleb.simulator.transmission`).
    torque_gear
        What that error adds to ``torque_true`` [Nm]: :func:`gear_torque`, the real torque
        of this joint minus that of the same joint with an ideal gear, both read through a
        fine encoder (zero when the error is off; None for an unscored session, the
        calibration, where no row is scored). Computed when first read: the pair is two
        more integrations of the joint, which a caller that never scores the session (a
        figure, a spectrum, a physics test of the log) does not pay for.
    gauges
        Per amplifier channel of the gauge layout, the device as that channel reads it (its
        ripple terms are the channel's; :mod:`rippleb.simulator.flexspline`): ``gauges[0]``
        is the bridge of a one-channel layout.
    """

    log: SensorLog
    moving: np.ndarray
    wave_angle: np.ndarray
    joint_velocity: np.ndarray
    eval_mask: np.ndarray
    scenario: Scenario
    device: Device
    gear: TransmissionError = IDEAL_GEAR
    gauges: tuple = ()
    #: How to compute ``torque_gear`` (:func:`gear_torque` with this session's loop), or None.
    gear_pair: functools.partial | None = field(default=None, repr=False)
    _torque_gear: np.ndarray | None = field(default=None, repr=False)

    @property
    def torque_gear(self) -> np.ndarray | None:
        if self._torque_gear is None and self.gear_pair is not None:
            object.__setattr__(self, "_torque_gear", self.gear_pair())   # once, then kept
        return self._torque_gear


def simulate(scenario: Scenario | str, seed: int = 0, condition: str = DEFAULT_CONDITION) -> Simulation:
    """Simulate ``scenario`` (object, built-in name or TOML path) on the device of ``seed``.

    ``condition`` (see :mod:`rippleb.conditions`) says what happened to the device since
    its calibration session; ``same-session`` is the device as calibrated. A scenario with
    ``scored = false`` (``calibration``) is that calibration session, the same under
    every deployment condition; ``realistic`` (the joint with the physics no method
    models, :mod:`rippleb.simulator.mismatch`) acts on it too.
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    seed = check_seed(seed)
    condition = check_condition(condition)
    spec: JointSpec = sc.spec
    session = conditions.session(Device.from_seed(seed), sc, condition)
    device = session.device
    if session.temperature_c != sc.temperature_c:
        sc = dataclasses.replace(sc, temperature_c=session.temperature_c)
    noise = np.random.default_rng(np.random.SeedSequence([seed, stable_hash(sc.name)]))

    n = max(2, int(round(sc.duration * spec.fs)))
    t = np.arange(n) / spec.fs
    trajectory = sc.trajectory(t)
    q_d, qd_d = trajectory[0], trajectory[1]
    # eq. (7) as a controller computes it: desired trajectory, nominal (identified) model
    nominal = load_table(sc, q_d, nominal_seed=seed)
    tau_ref = nominal.model_torque(q_d, trajectory[2]) + sc.external_torque(t, known_only=True)
    # the physics beyond the methods' models: the scenario's knobs, the rest at their
    # documented magnitudes under `realistic`, off otherwise (rippleb/simulator/mismatch.py)
    knobs = sc.unmodelled.resolve(realistic=session.realistic)
    errors = EncoderErrors.draw(seed, knobs, spec.counts_per_rev)
    gains = controller.design_gains(spec, float(np.mean(nominal.inertia)), knobs.bandwidth_factor)
    gear = TransmissionError.draw(seed, sc.transmission_error, sc.order2_share, order4=knobs.order4_error,
                                  load=knobs.load_error, compliance=knobs.compliance_variation,
                                  rated_torque=spec.rated_torque)
    table = load_table(sc, q_d)
    loop = (spec, device, sc.temperature_c, table, gains, t, trajectory, tau_ref - _excitation(sc, t),
            sc.external_torque(t))
    drive = dict(encoder=errors, damping=structural_damping(knobs.loss_factor, table))
    q, qd, theta_m, _, tau_true, commanded = controller.run(*loop, gear=gear, **drive)
    # What the gear's error adds to the real torque (the metrics' gear columns; never
    # streamed to a method). Only for a scored session: no row is scored on the
    # calibration log, and its twin runs would be the longest integrations of every case.
    gear_pair, torque_gear = None, None
    if sc.scored and gear.active:
        gear_pair = functools.partial(gear_torque, loop, gear, **drive)
    elif sc.scored:
        torque_gear = np.zeros(n)

    gauges = tuple(channel_devices(device, sc.gauges, sc.temperature_c, session.rebonded))
    strain, channels = gauge_channels(gauges, sc, t, theta_m, tau_true, noise, output_angle=q, knobs=knobs)
    current = current_sense(sc, commanded, device.current_offset, noise)
    absolute = counts(theta_m, spec.counts_per_rev, errors)
    index = conditions.index_pulses(absolute, conditions.index_count(seed, spec.counts_per_rev),
                                    spec.counts_per_rev)
    if knobs.missed:   # the DAQ's counter loses edges: its count drifts off the disc's
        absolute = missed_counts(absolute, knobs.missed, seed, sc.name)
    # An incremental counter counts from wherever it stood when the log started.
    encoder = absolute if session.counter_start is None else absolute - absolute[0] + session.counter_start
    # the calibration session is the first session whatever a deployment condition asked for
    meta = {"scenario": sc.name, "seed": seed,
            "condition": condition if sc.scored else calibration_condition(condition)}
    if knobs.active:
        meta["unmodelled"] = describe(knobs)
    if sc.gauges != GaugeSettings():
        meta["gauges"] = dataclasses.asdict(sc.gauges)
    if sc.faults.active:
        # Own generator: a faulty scenario's healthy signals stay those of the same
        # scenario without faults, and scenarios without faults are untouched.
        fault_rng = np.random.default_rng(
            np.random.SeedSequence([seed, stable_hash(sc.name), stable_hash("faults")]))
        encoder = encoder_faults(encoder, sc.faults, spec.fs, fault_rng)
        levels = (strain, encoder, current) if channels is None else (strain, encoder, current, channels)
        strain, encoder, current, *kept, index = dropouts((*levels, index), sc.faults, spec.fs, fault_rng)
        channels = kept[0] if kept else None
        meta["faults"] = {k: v for k, v in dataclasses.asdict(sc.faults).items() if v}

    log = SensorLog(spec=spec, t=t, strain=strain, encoder=encoder, current=current, index=index,
                    channels=channels, torque_true=tau_true, torque_ref=tau_ref, meta=meta)
    start, stop = sc.evaluation
    return Simulation(log=log, moving=np.abs(qd_d) > 1e-12, wave_angle=theta_m,
                      joint_velocity=qd, eval_mask=(t >= start) & (t <= stop),
                      scenario=sc, device=device, gear=gear, gauges=gauges,
                      gear_pair=gear_pair, _torque_gear=torque_gear)


#: Encoder counts per motor revolution of the pair :func:`gear_torque` compares: so fine
#: that no count edge moves by a measurable time when the gear's error moves the motor
#: (the integrator reads ``floor(theta / step) step``; at 2**40 counts the step is 6e-12
#: rad, and motor angles up to 1e3 rad stay below 2**53 steps, exact in a double).
FINE_COUNTS_PER_REV = 2**40


def gear_torque(loop: tuple, gear: TransmissionError, **drive) -> np.ndarray:
    """The real torque [Nm] the gear's transmission error adds: the joint with ``gear``
    minus the same joint with an ideal gear, both under their own loop read through an
    encoder of :data:`FINE_COUNTS_PER_REV` counts (``loop``: :func:`controller.run`'s
    arguments before the drive's, ``drive`` the rest of the drive as :func:`controller.run`
    takes it: the encoder's errors and the structural damping).

    Not the logged joint minus its ideal-gear twin: both read the 2500-count encoder, and
    any change of the motion, however small, moves their count edges and current steps
    differently, a jitter of 0.08-0.21 Nm RMS that stays when the error is scaled down
    1e5 times (docs/physics.md, "Transmission error"). With the fine encoder the
    difference is the loop's smooth response to the error, proportional to it at small
    sizes (``tests/test_transmission.py``); the logged joint's own count-edge torque,
    which is there with any gear, stays in ``torque_true - torque_gear``.
    """
    fine = (dataclasses.replace(loop[0], counts_per_rev=FINE_COUNTS_PER_REV),) + tuple(loop[1:])
    return controller.run(*fine, gear=gear, **drive)[4] - controller.run(*fine, **drive)[4]


def _excitation(sc: Scenario, t: np.ndarray) -> np.ndarray:
    """The known chirp loads: a test rig's excitation of the link. They belong to the
    reference of eq. (7) the benchmark scores against, but not to the controller's
    feedforward: the robot carries its payloads (known steps), a shaker acts on it from
    outside (docs/physics.md, "Joint dynamics and position controller")."""
    total = np.zeros_like(t)
    for load in sc.loads:
        if load.known and load.kind == "chirp":
            total = total + load.evaluate(t)
    return total
