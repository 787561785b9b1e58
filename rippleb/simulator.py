"""The joint simulator: arm load, harmonic drive, strain bridge, encoder, motor current.

``simulate(scenario, seed)`` evaluates everything analytically and vectorised on the
DAQ grid ``t = k / fs``. The device (the hidden truth of one joint: gauge errors,
ripple, friction, offsets) comes from ``Device.from_seed(seed)``; the measurement
noise comes from a second generator seeded by ``(seed, scenario name)``, so the
calibration log and an evaluation log of one seed share the device but not the noise.

Every default value below is listed with its source in ``docs/physics.md``.

Sign conventions
----------------
Positive joint torque ``tau`` drives the joint in the positive ``q`` direction. The motor
angle is counted so that ``theta_m = N (q + twist(tau))`` (the gear's sign inversion is
folded into the encoder's counting direction). The motor torque that produces current is
``tau / N`` plus everything the motor must overcome on its own shaft: rotor inertia,
friction opposing the motor velocity, and cogging.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from rippleb import conditions
from rippleb.conditions import DEFAULT_CONDITION, check_condition, stable_hash
from rippleb.data import JointSpec, SensorLog
from rippleb.drive_ripple import bridge_ripple
from rippleb.errors import InputError
from rippleb.scenario import Scenario, load_scenario

# --- strain bridge and DAQ (docs/physics.md, "Strain bridge", "DAQ") ---
STRAIN_GAIN = 0.1            # V/Nm after the bridge amplifier; estimate, rated 51 Nm -> 5.1 V
STRAIN_RANGE = 10.0          # +-V of the strain ADC
STRAIN_BITS = 16
STRAIN_NOISE = 1.0e-3        # V RMS, amplifier + ADC noise at 20 kHz bandwidth; estimate
CURRENT_RANGE = 20.0         # +-A of the current ADC
CURRENT_BITS = 12
CURRENT_NOISE = 0.03         # A RMS, current-sense noise; estimate
REFERENCE_TEMPERATURE_C = 25.0

# --- ripple: orders of the wave-generator angle and nominal amplitudes in Nm ---
# (order, base amplitude [Nm], load-proportional amplitude [Nm per Nm of |tau|])
RIPPLE_ORDERS = (
    (1, 0.05, 0.002),
    (2, 0.25, 0.012),
    (4, 0.60, 0.035),        # dominant: two sensing elements x two lobes (paper Sec. II-B)
    (6, 0.05, 0.003),
    (8, 0.15, 0.008),
)
RIPPLE_PHASE_SHIFT = 0.004   # rad/Nm, sigma of the load-induced phase shift; estimate
RIPPLE_SPREAD = 0.25         # log-normal sigma of the device-to-device amplitude spread; estimate

# --- harmonic drive stiffness, size 25: a smooth fit of the catalogue's K1/K3 curve ---
STIFFNESS_LOW = 3.1e4        # Nm/rad near zero torque (catalogue K1)
STIFFNESS_HIGH = 5.7e4       # Nm/rad at high torque (catalogue K3)
STIFFNESS_KNEE = 22.0        # Nm: where the stiffness has moved half-way; fit, see physics.md

# --- motor-side friction at 25 deg C, Nm on the motor shaft ---
FRICTION = dict(coulomb=0.025, static=0.04, stribeck_speed=3.0, viscous=1.5e-4,
                load=0.12, ripple1=0.10, ripple2=0.06)
SIGN_SMOOTHING = 0.02        # rad/s: tanh width of the friction sign at the motor
VISCOUS_TEMP_COEFF = 0.025   # 1/K: viscous friction ~ exp(-c (T - 25))
COULOMB_TEMP_COEFF = 0.008   # 1/K
COGGING = 0.004              # Nm on the motor shaft
COGGING_ORDER = 24           # periods per motor revolution (8 poles, 12 slots)
# --- output (cross-roller) bearing friction, Nm on the joint side ---
OUTPUT_FRICTION = dict(coulomb=0.3, viscous=0.8)
OUTPUT_SIGN_SMOOTHING = 0.005   # rad/s at the joint: bearing pre-sliding; estimate


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed: must be a non-negative integer, got {seed!r}")
    return int(seed)


@dataclass(frozen=True)
class Device:
    """The hidden truth of one simulated joint. Methods never see it.

    Attributes
    ----------
    seed
        The seed that drew it.
    gain
        Strain bridge gain [V/Nm], including the gauge misalignment error
        (the paper's Delta_t, eq. 4).
    offset, offset_temp_coeff, drift_rate
        Bridge zero [V], its thermal shift [V/K] and the slow drift within a run [V/s].
    ripple_orders, ripple_base, ripple_load, ripple_phase, ripple_phase_shift
        The radial-strain ripple (the paper's Delta_r, eq. 5) per order of the wave
        generator angle: amplitude ``base + load |tau|`` [Nm], phase [rad] and the
        phase shift per Nm of signed torque [rad/Nm] (load turns the strain pattern).
    encoder_zero
        Motor angle [rad] when the joint is at ``q = 0`` without load.
    friction
        Motor-side friction parameters at 25 deg C (see ``FRICTION``).
    friction_phase
        Phases [rad] of the 1x and 2x friction ripple and of cogging.
    output_friction
        Output bearing friction (Coulomb [Nm], viscous [Nm s/rad]).
    current_offset
        Current-sense offset [A].
    """

    seed: int
    gain: float
    offset: float
    offset_temp_coeff: float
    drift_rate: float
    ripple_orders: tuple[int, ...]
    ripple_base: tuple[float, ...]
    ripple_load: tuple[float, ...]
    ripple_phase: tuple[float, ...]
    ripple_phase_shift: tuple[float, ...]
    encoder_zero: float
    friction: dict = field(hash=False)
    friction_phase: tuple[float, float, float]
    output_friction: tuple[float, float]
    current_offset: float

    @classmethod
    def from_seed(cls, seed: int) -> "Device":
        """Draw the device of ``seed``; the same seed always gives the same device."""
        seed = _check_seed(seed)
        rng = np.random.default_rng(np.random.SeedSequence([seed, stable_hash("device")]))
        orders = tuple(o for o, _, _ in RIPPLE_ORDERS)
        spread = lambda size: np.exp(RIPPLE_SPREAD * rng.standard_normal(size))  # noqa: E731
        k = len(orders)
        base = np.array([b for _, b, _ in RIPPLE_ORDERS]) * spread(k)
        load = np.array([s for _, _, s in RIPPLE_ORDERS]) * spread(k)
        friction = {key: value * float(np.exp(0.15 * rng.standard_normal()))
                    for key, value in FRICTION.items()}
        return cls(
            seed=seed,
            gain=STRAIN_GAIN * (1.0 + 0.05 * rng.standard_normal()),
            offset=0.05 * rng.standard_normal(),
            offset_temp_coeff=5e-4 * rng.standard_normal(),
            drift_rate=1e-3 * rng.standard_normal(),
            ripple_orders=orders,
            ripple_base=tuple(base),
            ripple_load=tuple(load),
            ripple_phase=tuple(rng.uniform(0, 2 * np.pi, k)),
            ripple_phase_shift=tuple(RIPPLE_PHASE_SHIFT * rng.standard_normal(k)),
            encoder_zero=float(rng.uniform(0, 2 * np.pi)),
            friction=friction,
            friction_phase=tuple(rng.uniform(0, 2 * np.pi, 3)),
            output_friction=tuple(v * float(np.exp(0.2 * rng.standard_normal()))
                                  for v in OUTPUT_FRICTION.values()),
            current_offset=0.02 * rng.standard_normal(),
        )

    def regauged(self, rng: np.random.Generator) -> "Device":
        """This device with its gauge error terms drawn anew from ``rng``, from the same
        population as :meth:`from_seed` (ripple amplitudes, phases, load phase shifts and
        the gain error); friction, encoder and bridge zero are kept."""
        k = len(self.ripple_orders)
        spread = lambda size: np.exp(RIPPLE_SPREAD * rng.standard_normal(size))  # noqa: E731
        return dataclasses.replace(
            self,
            gain=STRAIN_GAIN * (1.0 + 0.05 * rng.standard_normal()),
            ripple_base=tuple(np.array([b for _, b, _ in RIPPLE_ORDERS]) * spread(k)),
            ripple_load=tuple(np.array([s for _, _, s in RIPPLE_ORDERS]) * spread(k)),
            ripple_phase=tuple(rng.uniform(0, 2 * np.pi, k)),
            ripple_phase_shift=tuple(RIPPLE_PHASE_SHIFT * rng.standard_normal(k)),
        )

    def ripple(self, wave_angle: np.ndarray, torque: np.ndarray) -> np.ndarray:
        """Ripple in torque units [Nm]: a function of wave-generator angle and load only."""
        load = np.abs(torque)
        out = np.zeros_like(wave_angle)
        for o, a, b, phase, shift in zip(self.ripple_orders, self.ripple_base, self.ripple_load,
                                         self.ripple_phase, self.ripple_phase_shift):
            out += (a + b * load) * np.cos(o * wave_angle + phase + shift * torque)
        return out

    def motor_friction(self, velocity: np.ndarray, torque: np.ndarray, angle: np.ndarray,
                       temperature_c: float, gear_ratio: float) -> np.ndarray:
        """Friction torque on the motor shaft [Nm], opposing the motor velocity [rad/s].

        Load-dependent Stribeck friction ``[F_c + mu |tau|/N + (F_s - F_c) exp(-(w/w_s)^2)]
        sgn(w) + b w`` with a 1x and 2x ripple of the Coulomb part over the wave-generator
        revolution, all scaled by the lubricant temperature. ``sgn`` is ``tanh(w/eps)``,
        because the true friction at a stop is set by the stiction the load needs, not by
        a jump; the smoothing width is far below the slowest scenario speed. ``torque`` is
        the joint torque [Nm]; ``mu |tau| / N`` is the mesh loss of transmitting it.
        """
        f = self.friction
        dt = temperature_c - REFERENCE_TEMPERATURE_C
        coulomb_scale = np.exp(-COULOMB_TEMP_COEFF * dt)
        viscous_scale = np.exp(-VISCOUS_TEMP_COEFF * dt)
        p1, p2, _ = self.friction_phase
        ripple = 1.0 + f["ripple1"] * np.cos(angle + p1) + f["ripple2"] * np.cos(2 * angle + p2)
        coulomb = (f["coulomb"] + f["load"] * np.abs(torque) / gear_ratio
                   + (f["static"] - f["coulomb"]) * np.exp(-(velocity / f["stribeck_speed"]) ** 2))
        return (coulomb_scale * coulomb * ripple * np.tanh(velocity / SIGN_SMOOTHING)
                + viscous_scale * f["viscous"] * velocity)

    def cogging(self, angle: np.ndarray) -> np.ndarray:
        """Cogging torque of the motor [Nm] at motor angle ``angle``."""
        return COGGING * np.cos(COGGING_ORDER * angle + self.friction_phase[2])

    def output_bearing_friction(self, velocity: np.ndarray, temperature_c: float) -> np.ndarray:
        """Cross-roller bearing friction on the joint side [Nm] at joint velocity [rad/s]."""
        coulomb, viscous = self.output_friction
        scale = np.exp(-VISCOUS_TEMP_COEFF * (temperature_c - REFERENCE_TEMPERATURE_C))
        return coulomb * np.tanh(velocity / OUTPUT_SIGN_SMOOTHING) + scale * viscous * velocity


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
    """

    log: SensorLog
    moving: np.ndarray
    wave_angle: np.ndarray
    joint_velocity: np.ndarray
    eval_mask: np.ndarray
    scenario: Scenario
    device: Device


def twist(torque: np.ndarray) -> np.ndarray:
    """Torsional deflection of the drive [rad] under ``torque``.

    ``tau / K_high + (1/K_low - 1/K_high) T_knee tanh(tau / T_knee)``: stiffness
    ``K_low`` at zero torque rising smoothly to ``K_high``. Smooth, because the motor
    acceleration follows the second derivative of the twist; the catalogue's
    piecewise-linear curve would put impulses into the motor current at its corners.
    """
    soft = 1.0 / STIFFNESS_LOW - 1.0 / STIFFNESS_HIGH
    return torque / STIFFNESS_HIGH + soft * STIFFNESS_KNEE * np.tanh(torque / STIFFNESS_KNEE)


def quantise(values: np.ndarray, full_scale: float, bits: int) -> np.ndarray:
    """An ADC of ``+-full_scale`` and ``bits`` bits: round to a step, saturate at the rails."""
    step = 2.0 * full_scale / 2**bits
    codes = np.clip(np.round(values / step), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return codes * step


def simulate(scenario: Scenario | str, seed: int = 0, condition: str = DEFAULT_CONDITION) -> Simulation:
    """Simulate ``scenario`` (object, built-in name or TOML path) on the device of ``seed``.

    ``condition`` (see :mod:`rippleb.conditions`) says what happened to the device since
    its calibration session; ``same-session`` is the device as calibrated. A scenario with
    ``scored = false`` (``calibration``) is that calibration session, the same under
    every condition.
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    seed = _check_seed(seed)
    condition = check_condition(condition)
    spec: JointSpec = sc.spec
    session = conditions.session(Device.from_seed(seed), sc, condition)
    device = session.device
    if session.temperature_c != sc.temperature_c:
        sc = dataclasses.replace(sc, temperature_c=session.temperature_c)
    noise = np.random.default_rng(np.random.SeedSequence([seed, stable_hash(sc.name)]))

    n = max(2, int(round(sc.duration * spec.fs)))
    t = np.arange(n) / spec.fs
    q, qd, qdd = sc.trajectory(t)
    table = _load_table(sc, q)
    tau_true = (table.torque(q, qd, qdd) + device.output_bearing_friction(qd, sc.temperature_c)
                + sc.external_torque(t))
    # eq. (7) as a controller computes it: desired trajectory, nominal (identified) model
    nominal = _load_table(sc, q, nominal_seed=seed)
    tau_ref = nominal.model_torque(q, qdd) + sc.external_torque(t, known_only=True)

    N = spec.gear_ratio
    deflection = twist(tau_true)
    theta_m = N * (q + deflection) + device.encoder_zero
    # The twist changes with the load, so the motor turns a little even when q stands still.
    twist_rate = np.gradient(deflection, t)
    w_m = N * (qd + twist_rate)
    a_m = N * (qdd + np.gradient(twist_rate, t))

    strain = _strain(device, sc, t, theta_m, tau_true, noise, output_angle=q)
    current = _current(device, sc, spec, theta_m, w_m, a_m, tau_true, noise)
    absolute = np.floor(theta_m / (2 * np.pi) * spec.counts_per_rev).astype(np.int64)
    index = conditions.index_pulses(absolute, conditions.index_count(seed, spec.counts_per_rev),
                                    spec.counts_per_rev)
    # An incremental counter counts from wherever it stood when the log started.
    encoder = absolute if session.counter_start is None else absolute - absolute[0] + session.counter_start
    # the calibration session is the first session whatever the condition asked for
    meta = {"scenario": sc.name, "seed": seed, "condition": condition if sc.scored else DEFAULT_CONDITION}
    if sc.faults.active:
        # Own generator: a faulty scenario's healthy signals stay those of the same
        # scenario without faults, and scenarios without faults are untouched.
        fault_rng = np.random.default_rng(
            np.random.SeedSequence([seed, stable_hash(sc.name), stable_hash("faults")]))
        encoder = _encoder_faults(encoder, sc.faults, spec.fs, fault_rng)
        strain, encoder, current, index = _dropouts((strain, encoder, current, index), sc.faults,
                                                    spec.fs, fault_rng)
        meta["faults"] = {k: v for k, v in dataclasses.asdict(sc.faults).items() if v}

    log = SensorLog(spec=spec, t=t, strain=strain, encoder=encoder, current=current, index=index,
                    torque_true=tau_true, torque_ref=tau_ref, meta=meta)
    start, stop = sc.evaluation
    return Simulation(log=log, moving=np.abs(qd) > 1e-12, wave_angle=theta_m,
                      joint_velocity=qd, eval_mask=(t >= start) & (t <= stop),
                      scenario=sc, device=device)


def _load_table(sc: Scenario, q: np.ndarray, nominal_seed: int | None = None):
    """The true load table of the scenario's joint, or with ``nominal_seed`` the one of
    the nominal model (:func:`rippleb.robot.nominal_model`) of that robot."""
    from rippleb import robot

    model = robot.load_model(sc.robot)
    idx = model.joints[model.getJointId(sc.joint)].idx_q
    lo, hi = float(q.min()), float(q.max())
    if lo < model.lowerPositionLimit[idx] or hi > model.upperPositionLimit[idx]:
        raise InputError(f"{sc.path}: trajectory: {sc.joint} travels over [{lo:.3f}, {hi:.3f}] rad, "
                         f"outside its limits [{model.lowerPositionLimit[idx]:.3f}, "
                         f"{model.upperPositionLimit[idx]:.3f}]")
    model = None if nominal_seed is None else robot.nominal_model(sc.robot, nominal_seed)
    return robot.load_table(sc.robot, sc.joint, dict(sc.posture), (lo, hi), model=model)


def _strain(device: Device, sc: Scenario, t, theta_m, tau, noise, output_angle) -> np.ndarray:
    """Bridge voltage (paper eq. 3-5): gain x (torque + ripple) + zero + drift + noise, ADC.

    The ripple is the wave-generator ripple plus the output-locked ripple and hysteresis
    of :func:`rippleb.drive_ripple.bridge_ripple`.
    """
    zero = device.offset + device.offset_temp_coeff * (sc.temperature_c - REFERENCE_TEMPERATURE_C)
    ripple = bridge_ripple(sc.ripple, device.seed, sc.temperature_c, device.ripple(theta_m, tau),
                           output_angle, tau)
    volts = (device.gain * (tau + ripple) + zero + device.drift_rate * t
             + STRAIN_NOISE * noise.standard_normal(len(t)))
    if sc.faults.bridge_drift:   # fault: extra bridge zero drift [V/s]
        volts = volts + sc.faults.bridge_drift * t
    # fault: a lower full scale (amplifier gain set too high) clips the peaks
    return quantise(volts, sc.faults.strain_full_scale or STRAIN_RANGE, STRAIN_BITS)


def _current(device: Device, sc: Scenario, spec: JointSpec, theta_m, w_m, a_m, tau, noise):
    """Motor current [A]: (tau/N + J_m theta_m'' + friction + cogging) / K_t + offset + noise."""
    motor_torque = (tau / spec.gear_ratio + spec.rotor_inertia * a_m
                    + device.motor_friction(w_m, tau, theta_m, sc.temperature_c, spec.gear_ratio)
                    + device.cogging(theta_m))
    amps = (motor_torque / spec.torque_constant + device.current_offset
            + CURRENT_NOISE * noise.standard_normal(len(theta_m)))
    if sc.faults.current_offset:   # fault: shifted current-sense zero [A]
        amps = amps + sc.faults.current_offset
    return quantise(amps, CURRENT_RANGE, CURRENT_BITS)


def _encoder_faults(encoder: np.ndarray, faults, fs: float, rng) -> np.ndarray:
    """Missed and spurious counts of an incremental encoder counter.

    Each true count is lost with probability ``encoder_missed``; spurious counts of +-1
    arrive as a Poisson process of ``encoder_spurious_rate`` per second. A counter never
    learns of either, so both accumulate into a lasting position error.
    """
    steps = np.diff(encoder)
    if faults.encoder_missed:
        lost = rng.binomial(np.abs(steps), faults.encoder_missed)
        steps = steps - np.sign(steps) * lost
    if faults.encoder_spurious_rate:
        k = rng.poisson(faults.encoder_spurious_rate / fs, len(steps))
        steps = steps + (2 * rng.binomial(k, 0.5) - k)   # sum of k random +-1
    return encoder[0] + np.concatenate(([0], np.cumsum(steps))).astype(np.int64)


def _dropouts(channels, faults, fs: float, rng):
    """DAQ dropouts: lost frames filled with the last good sample of every channel.

    Dropouts start as a Poisson process of ``dropout_rate`` per second and last
    ``dropout_length`` seconds (at least one sample). The first sample is always good.
    The last channel is the index pulse: an event, not a level, so a filled frame
    carries 0 (a pulse inside a lost frame is lost with it, repeating it would invent
    passes of the index mark).
    """
    if not faults.dropout_rate:
        return channels
    n = len(channels[0])
    length = max(1, int(round(faults.dropout_length * fs)))
    starts = (rng.random(n) < faults.dropout_rate / fs).astype(np.int64)
    count = np.cumsum(starts)
    before = np.concatenate((np.zeros(length, dtype=np.int64), count[:-length]))[:n]
    dropped = (count - before) > 0
    dropped[0] = False
    index = np.arange(n)
    last_good = np.maximum.accumulate(np.where(dropped, 0, index))
    *levels, pulses = channels
    return (*(channel[last_good] for channel in levels), np.where(dropped, 0, pulses).astype(np.int8))
