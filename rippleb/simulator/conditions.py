"""Deployment conditions: what happened to a joint between calibration and scoring.

A condition is the fourth axis of a result row (method x scenario x condition x seed).
The calibration log is always recorded in the *first* session of the device; the
condition says what changed before the scored session was recorded. Each condition's
physics and magnitudes are documented in ``docs/physics.md`` ("Deployment conditions").

Every condition changes one thing, so that a change of ranking can be traced to one
mechanism. Each draws from its own random generators: the device draw
(``Device.from_seed``) and the measurement noise of a log are the same under every
condition, and ``same-session`` reproduces the logs of earlier versions bit for bit.

This module also holds the encoder's index pulse, which every simulated log carries.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass

import numpy as np

from rippleb.errors import InputError
from rippleb.registry import unknown_name

#: name -> one-line description (shown by ``rippleb list``)
CONDITIONS = {
    "same-session": "calibrated just before scoring, same power-on: the most favourable case",
    "power-cycled": "powered off and on: the incremental encoder counts from an arbitrary "
                    "start, the session may run at another temperature",
    "aged": "months of use since calibration: ripple amplitudes, phases and bridge zero drifted",
    "re-assembled": "flexspline re-mounted or drive swapped: gauge errors (ripple, gain) redrawn",
    "realistic": "same session, but the joint has the physics no method models (gauge dynamics, "
                 "non-affine, flank- and load-history-dependent ripple, ripple at orders no method "
                 "models, span drift, DAQ chain, encoder errors, the gear's angle-locked torque beyond "
                 "its error; today's position loop), in its "
                 "calibration log too",
}
DEFAULT_CONDITION = "same-session"
#: Conditions that change the joint itself, not what happened after its calibration: its
#: calibration log is recorded under them too (docs/physics.md, "Beyond the methods' models").
SAME_JOINT_CONDITIONS = ("realistic",)

# --- power-cycled (docs/physics.md, "Deployment conditions") ---
#: The session runs this many kelvin below the scenario's temperature, drawn uniformly:
#: after a power cycle the joint may start anywhere between cold (workshop temperature,
#: 15 K below the 40 degC of a warm joint) and its working temperature. Estimate.
POWER_CYCLE_COOLING_K = 15.0
#: Joint travel [rad] between power-on (counter cleared to 0) and the log start, drawn
#: uniformly in +-this: the joint is moved to the scenario's start from an arbitrary pose.
POWER_CYCLE_TRAVEL_RAD = np.pi / 2

# --- aged: drift per device since calibration; estimates, see docs/physics.md ---
AGED_AMPLITUDE_SIGMA = 0.15   # log-normal sigma of each order's ripple amplitude ratio
AGED_PHASE_SIGMA = 0.15       # rad, normal sigma of each order's ripple phase change
AGED_ZERO_SIGMA = 0.02        # V, normal sigma of the bridge zero change (0.2 Nm at 0.1 V/Nm)


def check_condition(name: str) -> str:
    """Return ``name`` if it is a known condition, else raise one clear line."""
    if name not in CONDITIONS:
        raise InputError(unknown_name("condition", name, list(CONDITIONS)))
    return name


def calibration_condition(condition: str) -> str:
    """The condition of the calibration log that rows of ``condition`` are fitted on.

    The calibration is the device's first session, before anything happened to it, so it
    is ``same-session`` for the deployment conditions; a condition of the joint itself
    (``realistic``: the same joint with the physics no method models) acts on the
    calibration session as on every other.
    """
    return condition if condition in SAME_JOINT_CONDITIONS else DEFAULT_CONDITION


def stable_hash(text: str) -> int:
    """A 64-bit hash of ``text`` that is the same in every process (unlike ``hash``)."""
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little")


def stream(seed: int, *words: str) -> np.random.Generator:
    """An independent generator for ``seed`` and the purpose named by ``words``."""
    return np.random.default_rng(np.random.SeedSequence([seed] + [stable_hash(w) for w in words]))


@dataclass(frozen=True)
class Session:
    """What the scored session of a condition changes against the calibration session.

    Attributes
    ----------
    device
        The device as it is in this session (aged or re-assembled, else as drawn).
    temperature_c
        Joint temperature of the session [degC].
    counter_start
        Count of the incremental encoder at the first sample, or None when the counter
        continues the calibration session's (absolute) count.
    realistic
        The unset knobs of :mod:`rippleb.simulator.mismatch` take their documented magnitudes.
    rebonded
        The gauges' installation errors are drawn anew (``re-assembled``;
        :mod:`rippleb.simulator.flexspline`).
    """

    device: object
    temperature_c: float
    counter_start: int | None = None
    realistic: bool = False
    rebonded: bool = False


def session(device, scenario, condition: str) -> Session:
    """The session of ``scenario`` under ``condition`` for ``device`` (drawn by its seed).

    A scenario with ``scored = false`` (``calibration``) is the calibration session
    itself: recorded first, before anything happened to the joint, so no deployment
    condition changes it; ``realistic`` describes the joint, so it acts there too.
    """
    condition = check_condition(condition)
    same = Session(device=device, temperature_c=scenario.temperature_c)
    if condition in SAME_JOINT_CONDITIONS:   # the joint itself, in every session
        return dataclasses.replace(same, realistic=True)
    if condition == "same-session" or not scenario.scored:
        return same
    if condition == "power-cycled":
        rng = stream(device.seed, "power-cycled", scenario.name)
        cooling = rng.uniform(0.0, POWER_CYCLE_COOLING_K)
        spec = scenario.spec
        span = POWER_CYCLE_TRAVEL_RAD * spec.gear_ratio * spec.counts_per_rev / (2 * np.pi)
        start = int(rng.integers(-int(span), int(span) + 1))
        return Session(device=device, temperature_c=scenario.temperature_c - cooling,
                       counter_start=start)
    if condition == "aged":
        return dataclasses.replace(same, device=aged(device, scenario.ripple.drift))
    return dataclasses.replace(same, device=re_assembled(device), rebonded=True)


def aged(device, drift: float = 1.0):
    """``device`` after months of service: each ripple order's amplitude scaled by
    ``exp(drift AGED_AMPLITUDE_SIGMA n)``, its phase moved by ``drift AGED_PHASE_SIGMA n``
    and the bridge zero moved by ``drift AGED_ZERO_SIGMA n`` [V], ``n ~ N(0, 1)`` each.

    One draw per device: every scored scenario of a seed sees the same aged joint. The
    draws ``n`` do not depend on ``drift`` (the scenario's ``[ripple] drift``), so a sweep
    of it moves each device further along one direction of drift.
    """
    rng = stream(device.seed, "aged")
    k = len(device.ripple_orders)
    ratio = np.exp(drift * AGED_AMPLITUDE_SIGMA * rng.standard_normal(k))
    phase = drift * AGED_PHASE_SIGMA * rng.standard_normal(k)
    return dataclasses.replace(
        device,
        ripple_base=tuple(np.asarray(device.ripple_base) * ratio),
        ripple_load=tuple(np.asarray(device.ripple_load) * ratio),
        ripple_phase=tuple(np.asarray(device.ripple_phase) + phase),
        offset=device.offset + drift * AGED_ZERO_SIGMA * rng.standard_normal(),
    )


def re_assembled(device):
    """``device`` after its flexspline was re-mounted: the gauge error terms (ripple
    amplitudes, phases, load phase shifts and the gain error) redrawn from the device
    population, everything else (friction, encoder, bridge zero) kept."""
    return device.regauged(stream(device.seed, "re-assembled"))


# --- the encoder's index pulse ---------------------------------------------------------

def index_count(seed: int, counts_per_rev: int) -> int:
    """Absolute encoder count of the device's index mark: the pulse fires when the
    count steps between ``index_count - 1`` and ``index_count`` (mod ``counts_per_rev``).

    Fixed per device (the code disc is mounted once), drawn uniformly from its own stream.
    """
    return int(stream(seed, "encoder-index").integers(0, counts_per_rev))


def index_pulses(counts: np.ndarray, mark: int, counts_per_rev: int) -> np.ndarray:
    """0/1 per sample: 1 where the index mark was passed since the previous sample.

    ``counts`` are the true absolute counts. The index channel is gated to one count
    edge (the mark) and latched by the counter, as quadrature decoders do: a pass in
    either direction between two samples is reported once, on the later sample, however
    fast the motor turns; a shaft at rest on the mark reports nothing more (the level
    may stay high, the latch fires on the edge). A pass and a return within one sample
    interval (50 us) cancel and are not reported. The first sample has no predecessor
    and reports 0.
    """
    revolution = np.floor_divide(counts - mark, counts_per_rev)
    out = np.zeros(len(counts), dtype=np.int8)
    out[1:] = revolution[1:] != revolution[:-1]
    return out
