"""Ripple physics beyond the wave-generator orders: output-locked ripple, the ripple's
temperature coefficient and strain hysteresis.

Each is a term of the bridge's torque reading (``docs/physics.md``, "Output-locked ripple,
temperature, hysteresis"), drawn for a device from its own random stream so the rest of
the device is unchanged, and settable per scenario in a ``[ripple]`` table
(:class:`RippleSettings`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from rippleb.simulator.scenario import RippleSettings

#: Orders of the output (circular-spline) angle and their nominal amplitudes
#: ``(order, base [Nm], per Nm of |tau|)``. **Estimate**, see docs/physics.md.
OUTPUT_ORDERS = ((1, 0.15, 0.004), (2, 0.10, 0.003))
OUTPUT_SPREAD = 0.25              # log-normal sigma of the device-to-device amplitude spread
_SALT = int.from_bytes(hashlib.sha256(b"drive-ripple").digest()[:8], "little")


@dataclass(frozen=True)
class OutputRipple:
    """The output-locked ripple of one device: amplitudes ``base + load |tau|`` [Nm] and
    phases [rad] per order of the output angle."""

    orders: tuple[int, ...]
    base: tuple[float, ...]
    load: tuple[float, ...]
    phase: tuple[float, ...]

    @classmethod
    def from_seed(cls, seed: int) -> "OutputRipple":
        """The device of ``seed``; its own stream, so the rest of the device is unchanged."""
        rng = np.random.default_rng(np.random.SeedSequence([seed, _SALT]))
        k = len(OUTPUT_ORDERS)
        spread = np.exp(OUTPUT_SPREAD * rng.standard_normal((2, k)))
        return cls(orders=tuple(o for o, _, _ in OUTPUT_ORDERS),
                   base=tuple(np.array([b for _, b, _ in OUTPUT_ORDERS]) * spread[0]),
                   load=tuple(np.array([s for _, _, s in OUTPUT_ORDERS]) * spread[1]),
                   phase=tuple(rng.uniform(0, 2 * np.pi, k)))

    def __call__(self, output_angle: np.ndarray, torque: np.ndarray) -> np.ndarray:
        """Ripple [Nm] at output angle [rad] and torque [Nm]."""
        load = np.abs(torque)
        out = np.zeros_like(np.asarray(output_angle, float))
        for order, a, b, phase in zip(self.orders, self.base, self.load, self.phase):
            out += (a + b * load) * np.cos(order * output_angle + phase)
        return out


def hysteresis(torque: np.ndarray, width: float) -> np.ndarray:
    """Strain hysteresis [Nm]: ``p - tau`` for the play operator ``p`` of ``width``.

    ``p[n] = clip(p[n-1], tau[n] - width/2, tau[n] + width/2)``, ``p[0] = tau[0]``: the
    reading lags the torque by up to half the width, ``-width/2`` while the torque rises
    and ``+width/2`` while it falls, so a load cycle draws a loop ``width`` wide and the
    sign follows the torque rate.

    The operator has memory, but on a run where the torque does not fall it is
    ``p = max(p_start, tau - width/2)`` (and on one where it does not rise
    ``min(p_start, tau + width/2)``), so it is evaluated run by run: the true torque is
    smooth and has few turning points.
    """
    tau = np.asarray(torque, float)
    if width <= 0 or len(tau) == 0:
        return np.zeros_like(tau)
    half = 0.5 * width
    step = np.sign(np.diff(tau))
    moving = np.flatnonzero(step)
    # a run starts at each sample whose step direction differs from the last non-zero one
    turns = moving[1:][step[moving[1:]] != step[moving[:-1]]] if len(moving) else moving
    bounds = np.concatenate(([0], turns + 1, [len(tau)]))
    out = np.empty_like(tau)
    p = tau[0]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        seg = tau[lo:hi]
        direction = step[lo - 1] if lo else (step[moving[0]] if len(moving) else 1.0)
        if direction > 0:
            out[lo:hi] = np.maximum(p, np.maximum.accumulate(seg - half))
        else:
            out[lo:hi] = np.minimum(p, np.minimum.accumulate(seg + half))
        p = out[hi - 1]
    return out - tau


def _hysteresis_reference(torque: np.ndarray, width: float) -> np.ndarray:
    """The play operator sample by sample (the definition; for tests)."""
    tau = np.asarray(torque, float)
    half, out, p = 0.5 * width, np.empty_like(tau), tau[0] if len(tau) else 0.0
    for i, value in enumerate(tau.tolist()):
        p = min(max(p, value - half), value + half)
        out[i] = p
    return out - tau


def bridge_ripple(settings: RippleSettings, seed: int, temperature_c: float, wave_ripple: np.ndarray,
                  output_angle: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """Everything the bridge reads besides the torque itself [Nm].

    ``(wave_ripple + output ripple) x temperature scale + hysteresis``: ``wave_ripple`` is
    the device's ripple over the wave-generator angle, the output ripple that of
    :class:`OutputRipple` of ``seed`` at ``output_angle`` (the joint angle [rad]).
    """
    locked = OutputRipple.from_seed(seed)(output_angle, torque) if settings.output_scale else 0.0
    return (settings.temperature_scale(temperature_c) * (wave_ripple + settings.output_scale * locked)
            + hysteresis(torque, settings.hysteresis_nm))
