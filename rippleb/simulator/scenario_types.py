"""What a scenario is: :class:`Scenario` and its tables, with the physical defaults.

Read from a TOML file by :mod:`rippleb.simulator.scenario` (``load_scenario``), which also
re-exports every name here; the simulator takes them from there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rippleb.data import JointSpec
from rippleb.errors import InputError
from rippleb.layouts import GaugeSettings
from rippleb.simulator.mismatch import Unmodelled
from rippleb.simulator.profiles import Load, Segment, evaluate_segments


#: Defaults: the paper's joint (UR5 shoulder lift stands in for its arm) at a warm
#: operating temperature. See docs/physics.md for the sources.
DEFAULT_ROBOT = "ur5"
DEFAULT_JOINT = "shoulder_lift_joint"
DEFAULT_TEMPERATURE_C = 40.0
#: The temperature catalogue values refer to; friction and ripple scale from it.
REFERENCE_TEMPERATURE_C = 25.0
#: Width of the strain hysteresis loop [Nm] (1 % of the 51 Nm rating). **Estimate**, see
#: docs/physics.md, "Output-locked ripple, temperature, hysteresis".
HYSTERESIS_NM = 0.5
#: Relative change of every ripple amplitude per kelvin from 25 degC. Off: no source.
RIPPLE_TEMP_COEFF = 0.0
#: The drive's transmission-error class [rad, peak to peak over an output revolution]:
#: the Harmonic Drive CSF catalogue's positioning accuracy of size 25, ratio >= 50, in
#: the standard class (1 arcmin; the special class is 1.5e-4 rad). Scenario key
#: ``[gear] transmission_error``; the physics is :mod:`rippleb.simulator.transmission`.
TRANSMISSION_ERROR_PP = 2.9e-4
#: Share of that class the twice-per-wave-generator-turn component takes (``[gear]
#: order2_share``). **Estimate** held to the paper's Fig. 2 (order 4 the largest line of the
#: strain at every speed): at the former 0.5 the gear's order-2 torque outgrew the gauges'
#: order-4 ripple on most devices above 15 rev/s; docs/physics.md, "Transmission error".
ORDER2_SHARE = 0.25


@dataclass(frozen=True)
class RippleSettings:
    """What a scenario's ``[ripple]`` table sets (all optional); the defaults are the
    simulator's physics (:mod:`rippleb.simulator.ripple`).

    Attributes
    ----------
    output_scale
        Multiplies the output-locked ripple amplitudes (0 turns it off).
    hysteresis_nm
        Width [Nm] of the strain hysteresis loop (0 turns it off).
    temperature_coeff
        Relative change of all ripple amplitudes per kelvin above 25 degC [1/K].
    drift
        How far the joint drifted since calibration under the ``aged`` condition, in
        multiples of the documented estimate (:mod:`rippleb.simulator.conditions`): the
        ripple amplitude, ripple phase and bridge zero changes of each device are scaled
        by it (0: no drift, 1: the estimate). No effect under other conditions.
    """

    output_scale: float = 1.0
    hysteresis_nm: float = HYSTERESIS_NM
    temperature_coeff: float = RIPPLE_TEMP_COEFF
    drift: float = 1.0

    def temperature_scale(self, temperature_c: float) -> float:
        """Factor on every ripple amplitude at ``temperature_c``."""
        return 1.0 + self.temperature_coeff * (temperature_c - REFERENCE_TEMPERATURE_C)


@dataclass(frozen=True)
class Faults:
    """Faulty sensors, all off by default. ``docs/scenarios.md`` says what each models.

    Attributes
    ----------
    encoder_missed
        Probability that one encoder count is lost by the counter (0-1): noise on the
        A/B lines or an input filter too slow for the edge rate. The count falls behind
        and stays behind.
    encoder_spurious_rate
        Spurious counts per second (Poisson), each +1 or -1: EMI glitches that the
        quadrature decoder takes for an edge. They accumulate too.
    strain_full_scale
        Full scale of the strain ADC [+-V] instead of 10 V: an amplifier gain set too
        high, so torque peaks clip at the rails.
    dropout_rate, dropout_length
        DAQ dropouts per second (Poisson) and the length of each [s]: lost frames that
        the acquisition fills by holding the last good sample of every channel, so the
        time grid stays unbroken.
    bridge_drift
        Extra bridge zero drift [V/s] (self-heating, moisture in the gauge adhesive).
    current_offset
        Extra current-sensor offset [A] (a shifted current-sense amplifier zero).
    """

    encoder_missed: float = 0.0
    encoder_spurious_rate: float = 0.0
    strain_full_scale: float | None = None
    dropout_rate: float = 0.0
    dropout_length: float = 0.0
    bridge_drift: float = 0.0
    current_offset: float = 0.0

    @property
    def active(self) -> bool:
        """True if any fault is configured."""
        return self != Faults()


@dataclass(frozen=True)
class Scenario:
    """One scenario: the joint, its trajectory, the external loads and the scored window.

    Attributes
    ----------
    name, path, description
        File name without suffix, the file it came from, and what it is for.
    spec
        The joint's datasheet values (:class:`~rippleb.data.JointSpec`).
    duration
        Length of the log [s].
    scored
        Whether ``rippleb run`` scores it by default (``calibration`` is not).
    evaluation
        The scored window ``(start, stop)`` [s].
    temperature_c
        Joint (lubricant) temperature [deg C]; friction depends on it.
    robot, joint, posture
        The ``example-robot-data`` arm, its moving joint, and the angles [rad] of the others.
    segments, loads
        The resolved trajectory and the external torques.
    faults
        Faulty sensors (:class:`Faults`); none by default.
    ripple
        Output-locked ripple, hysteresis and the ripple's temperature coefficient
        (:class:`RippleSettings`); the documented defaults.
    unmodelled
        The physics beyond the methods' models that the scenario switches on
        (:class:`~rippleb.simulator.mismatch.Unmodelled`; tables ``[mismatch]``, ``[thermal]``,
        ``[daq]``, ``[encoder]``, ``[controller]``); none by default.
    transmission_error
        The drive's transmission-error class [rad peak to peak] (``[gear]
        transmission_error``; :mod:`rippleb.simulator.transmission`), 0: an ideal gear.
    order2_share
        The share of that class the twice-per-turn component takes (``[gear] order2_share``).
    gauges
        The strain-gauge layout on the flexspline and the size of its installation errors
        (``[gauges]``; :class:`~rippleb.layouts.GaugeSettings`); the paper's by default.
    """

    name: str
    path: Path
    description: str
    spec: JointSpec
    duration: float
    scored: bool
    evaluation: tuple[float, float]
    temperature_c: float
    robot: str
    joint: str
    posture: tuple[tuple[str, float], ...]
    segments: tuple[Segment, ...]
    loads: tuple[Load, ...]
    faults: Faults = Faults()
    ripple: RippleSettings = RippleSettings()
    unmodelled: Unmodelled = Unmodelled()
    transmission_error: float = TRANSMISSION_ERROR_PP
    order2_share: float = ORDER2_SHARE
    gauges: GaugeSettings = GaugeSettings()

    def trajectory(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Commanded joint position, velocity, acceleration at times ``t``."""
        return evaluate_segments(self.segments, np.asarray(t, dtype=float))

    def check_limits(self) -> "Scenario":
        """Refuse a trajectory that leaves the moving joint's URDF limits, before any
        simulation (``simulate`` checks the sampled one again). Sampled densely per
        segment, so a ramp through a turning point is caught too.

        Raises
        ------
        InputError
            ``<file>: trajectory: <joint> travels over [lo, hi] rad, outside its limits``.
        """
        from rippleb.simulator import robot as arm

        model = arm.load_model(self.robot)
        idx = model.joints[model.getJointId(self.joint)].idx_q
        lo_lim, hi_lim = float(model.lowerPositionLimit[idx]), float(model.upperPositionLimit[idx])
        t = np.concatenate([np.linspace(seg.t0, min(seg.t1, self.duration), 65)
                            for seg in self.segments if seg.t0 <= self.duration])
        q = self.trajectory(t)[0]
        lo, hi = float(q.min()), float(q.max())
        if lo < lo_lim or hi > hi_lim:
            raise InputError(f"{self.path}: trajectory: {self.joint} travels over [{lo:.3f}, {hi:.3f}] "
                             f"rad, outside its limits [{lo_lim:.3f}, {hi_lim:.3f}]")
        return self

    def step_edges(self) -> np.ndarray:
        """The edges of the step loads: rows ``(start, rise, change)`` [s, s, Nm], by time.

        A step load has two edges, on at ``start`` (change ``+torque``) and off at
        ``stop`` (change ``-torque``; none if never released).
        """
        edges = [(load.start, load.rise, load.torque) for load in self.loads if load.kind == "step"]
        edges += [(load.stop, load.rise, -load.torque) for load in self.loads
                  if load.kind == "step" and np.isfinite(load.stop)]
        return np.array(sorted(edges), float).reshape(-1, 3)

    def chirp_windows(self) -> np.ndarray:
        """The time spans of the chirp loads: rows ``(start, stop + rise)`` [s], by time."""
        spans = [(load.start, load.stop + load.rise) for load in self.loads if load.kind == "chirp"]
        return np.array(sorted(spans), float).reshape(-1, 2)

    def chirp_bands(self) -> np.ndarray:
        """The frequency ranges of the chirp loads: rows ``(f0, f1)`` [Hz], in the order of
        :meth:`chirp_windows`."""
        bands = [(load.start, load.f0, load.f1) for load in self.loads if load.kind == "chirp"]
        return np.array([b[1:] for b in sorted(bands)], float).reshape(-1, 2)

    def external_torque(self, t: np.ndarray, *, known_only: bool = False) -> np.ndarray:
        """Sum of the external torques at ``t`` [Nm] (only known ones if ``known_only``)."""
        total = np.zeros_like(np.asarray(t, dtype=float))
        for load in self.loads:
            if load.known or not known_only:
                total = total + load.evaluate(t)
        return total


# ----------------------------------------------------------------------------- loading
