"""The hidden truth of one joint: gauge errors, wave-generator ripple, friction, offsets.

``Device.from_seed(seed)`` draws one joint from the population the defaults below
describe; the same seed always gives the same device. Methods never see a device: the
runner keeps it with the truth. Every default is listed with its source in
``docs/physics.md``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from rippleb.errors import InputError
from rippleb.simulator.scenario import REFERENCE_TEMPERATURE_C
from rippleb.simulator.conditions import stable_hash

STRAIN_GAIN = 0.1            # V/Nm after the bridge amplifier; estimate, rated 51 Nm -> 5.1 V

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


def check_seed(seed) -> int:
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
        seed = check_seed(seed)
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
