"""Synthetic logs with a known ripple at the harmonic drive's orders, for the method tests.

The strain is ``torque + sum_k a_k cos(k theta + p_k)`` (gain 1 V/Nm, no offset) at the
wave-generator angle ``theta`` of an encoder that counts a given speed profile; the ripple
of a test is therefore known exactly, unlike the simulator's.
"""

from __future__ import annotations

import numpy as np
import pytest

from rippleb import JointSpec
from rippleb.data import make_log

SPEC = JointSpec()
#: order -> (amplitude [Nm], phase [rad]) of the synthetic ripple (the WG orders 2, 4, 8)
RIPPLE = {2: (0.25, 0.3), 4: (0.6, 1.1), 8: (0.15, -0.7)}


def ripple_at(counts: np.ndarray, ripple: dict = RIPPLE) -> np.ndarray:
    theta = 2.0 * np.pi * counts / SPEC.counts_per_rev
    return sum(a * np.cos(k * theta + p) for k, (a, p) in ripple.items())


def synthetic_log(speed_rev_s, torque, ripple: dict = RIPPLE, start_count: int = 0,
                  noise: float = 0.0, seed: int = 0):
    """A log from per-sample wave-generator speed [rev/s] and torque [Nm] arrays.

    ``torque_ref`` and ``torque_true`` hold the torque, so it serves as calibration too.
    """
    speed = np.asarray(speed_rev_s, dtype=float)
    n = len(speed)
    turns = np.cumsum(speed) / SPEC.fs
    counts = np.floor(turns * SPEC.counts_per_rev).astype(np.int64) + start_count
    torque = np.broadcast_to(np.asarray(torque, dtype=float), (n,)).copy()
    strain = torque + ripple_at(counts, ripple)
    strain += np.random.default_rng(seed).normal(0.0, noise, n) if noise else 0.0
    columns = dict(t=np.arange(n) / SPEC.fs, strain=strain, encoder=counts.astype(float),
                   current=np.zeros(n), torque_ref=torque, torque_true=torque)
    return make_log(SPEC, columns, source="synthetic")


def calibration_log(seconds: float = 8.0):
    """Both directions at 2 and 6 rev/s under changing loads: every angle many times."""
    n = int(seconds * SPEC.fs)
    t = np.arange(n) / SPEC.fs
    speed = np.where(t % 4 < 2, 2.0, 6.0) * np.where(t % 2 < 1, 1.0, -1.0)
    torque = 5.0 * np.sin(2 * np.pi * 0.3 * t)
    return synthetic_log(speed, torque)


def error_rms(method, calibration, log, skip_s: float = 0.0) -> float:
    """RMS [Nm] of the estimate minus the torque, after ``skip_s`` seconds."""
    from rippleb.harness import run_method

    estimate, _ = run_method(method, calibration, log)
    k = int(skip_s * SPEC.fs)
    return float(np.sqrt(np.mean((estimate[k:] - log.torque_true[k:]) ** 2)))


def with_index(log, index_count: int, count_offset: int = 0):
    """``log`` with an index pulse where its counts cross ``index_count`` (modulo a turn),
    then its counts shifted by ``count_offset`` (the joint was power-cycled)."""
    import dataclasses

    turn = np.floor_divide(log.encoder - index_count, SPEC.counts_per_rev)
    pulse = np.zeros(len(log.encoder), dtype=np.int8)
    pulse[1:] = turn[1:] != turn[:-1]
    return dataclasses.replace(log, index=pulse, encoder=log.encoder + count_offset)


def estimate(method, log, size=None) -> np.ndarray:
    """Reset a fitted ``method`` and stream ``log`` (without its truth) in blocks of ``size``."""
    method.reset(log.spec)
    visible = log.for_method(keep_ref=False)
    return np.concatenate([method.step(b) for b in visible.blocks(size)])


@pytest.fixture(scope="module")
def calibration():
    """The synthetic calibration log, made once per test module that imports this fixture."""
    return calibration_log()
