"""How much of the calibration log's gear torque gear-keeping's model explains.

gear-keeping fits its map beside a model of the gear's torque that is a function of the
encoder angle, speed and acceleration (``methods/gear_keeping.py``: per gear order
``[w cos, w sin, w^2 cos, w^2 sin, a cos, a sin]``, the error's rate and second derivative). This script simulates each device's calibration
session, computes its gear torque ``g`` as the metrics do
(:func:`rippleb.simulator.simulation.gear_torque`; the simulator keeps it for scored
sessions only, so the calibration is simulated as if scored: the same log), takes its tick means and prints, over the ticks:

- ``g``: the RMS of the gear torque [Nm];
- ``locked``: the RMS of its part at orders 1 and 2 of the angle with an amplitude and
  phase free in every 0.1 s window (the angle-locked part, however it moves);
- what is left after the least-squares fit to ``g`` alone (with the method's own tracked
  speed) of the model's columns (``dynamic``), of its inertial columns only (``w^2``, ``a``:
  ``M e''``) and of its rate columns only (``w``: ``c e'``, a damping's answer to the
  error's rate): what those functions of angle, speed and acceleration cannot explain.

    python benchmarks/gear_model_fit.py --seeds 2000-2003

docs/methods/gear-keeping.md copies the output; tests/test_gear_keeping.py runs one device.
"""

from __future__ import annotations

import argparse
import dataclasses

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

WINDOW_TICKS = 100   # 0.1 s at the 1 kHz control rate


def calibration_gear_torque(seed: int):
    """The calibration log of device ``seed`` and its gear torque [Nm] per sample: the
    calibration scenario simulated as if scored (the same log: its noise is drawn from the
    seed and the scenario's name), for which the simulator keeps ``torque_gear``."""
    from rippleb.simulator.scenario import load_scenario
    from rippleb.simulator import simulate

    sim = simulate(dataclasses.replace(load_scenario("calibration"), scored=True), seed)
    return sim.log, sim.torque_gear


def explained(seed: int) -> dict[str, float]:
    """``g``, ``locked`` and what each fit leaves, RMS [Nm], of device ``seed`` (see the module)."""
    from rippleb.methods._angle_adaptive_law import GEAR_TERMS
    from rippleb.methods.gear_keeping import GearKeeping, gear_columns, tracked_speeds

    log, gear = calibration_gear_torque(seed)
    method = GearKeeping()
    method.fit(log.for_method(keep_ref=True))
    enc, phi, strain, _ = method._calibration_ticks(log)
    ticks = len(phi)
    g = gear[: ticks * log.spec.block_size].reshape(ticks, -1).mean(axis=1)
    ends = np.ascontiguousarray(enc[:, -1], dtype=np.int64)
    speed, accel = np.empty(ticks), np.empty(ticks)
    tracked_speeds(ends, method._speed_state(log.spec), int(log.spec.counts_per_rev), speed, accel)
    y = method.gain_ * strain + method.offset_
    columns = gear_columns(phi, method.orders, method.gear_orders, speed, accel, y)
    terms = np.arange(columns.shape[1]) % GEAR_TERMS
    fits = {"dynamic": terms < 6, "inertial": (terms >= 2) & (terms < 6), "rate": terms < 2}
    left = {}
    for name, keep in fits.items():
        x = columns[:, keep]
        left[name] = g - x @ np.linalg.lstsq(x, g, rcond=None)[0]
    locked = np.zeros(ticks)
    angle = enc.mean(axis=1) * 2 * np.pi / log.spec.counts_per_rev
    orders12 = [list(method.orders).index(k) for k in (1, 2)]
    for start in range(0, ticks, WINDOW_TICKS):
        window = slice(start, start + WINDOW_TICKS)
        if np.ptp(angle[window]) < 2 * np.pi:   # less than a turn: no order is resolved
            continue
        basis = np.column_stack([phi[window, 2 * i + j] for i in orders12 for j in (0, 1)])
        locked[window] = basis @ np.linalg.lstsq(basis, g[window], rcond=None)[0]
    rms = lambda x: float(np.sqrt(np.mean(x ** 2)))   # noqa: E731
    return {"g": rms(g), "locked": rms(locked)} | {f"left by {k}": rms(v) for k, v in left.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="2000-2003", help="devices, A-B inclusive")
    args = parser.parse_args(argv)
    first, _, last = args.seeds.partition("-")
    print("| device | g RMS [Nm] | angle-locked part (orders 1, 2 per 0.1 s) | left by the dynamic model "
          "| left by its inertial terms alone | left by its rate terms alone |")
    print("|---|---|---|---|---|---|")
    for seed in range(int(first), int(last or first) + 1):
        r = explained(seed)
        print(f"| {seed} | {r['g']:.3f} | {r['locked']:.3f} | {r['left by dynamic']:.3f} "
              f"| {r['left by inertial']:.3f} | {r['left by rate']:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
