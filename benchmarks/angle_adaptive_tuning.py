"""Choose the free parameters of ``angle-adaptive`` on the ``calibration`` scenario only.

A map fitted and scored on the same calibration log is already the best map for that log,
so scoring there alone would always choose "do not adapt". Each candidate is therefore
scored twice on the calibration log of a seed, against ``torque_ref`` (the only torque a
real calibration run knows; never ``torque_true``, never a scored scenario):

* ``own``: warm-started from the map fitted on that log (adaptation must not hurt);
* ``wrong``: warm-started from the map of *another* device (the calibration log of the
  next seed), which stands in for a map that no longer fits (re-assembly, ageing, an
  unknown angle origin). The gain and offset stay those of the device itself.

The objective is the mean of the two RMS errors over the seeds. The chosen values are the
defaults of :class:`rippleb.methods.angle_adaptive.AngleAdaptive`;
``docs/methods/angle-adaptive.md`` shows the table this prints.

Run: ``python benchmarks/angle_adaptive_tuning.py [--seeds 100,101,102]``; with ``--measure``
it prints the convergence time in revolutions and the drift tracking instead (nothing tuned),
with ``--power-cycle SCENARIOS`` the scores under an emulated power cycle, with ``--speed``
the per-tick cost against an ``lfilter`` yardstick.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

from rippleb.methods.angle_adaptive import AngleAdaptive, rotation
from rippleb.scoring.metrics import Truth, score
from rippleb.simulator import simulate

MEMORY_REVS = (3.0, 10.0, 30.0, 100.0)
PRIOR_SD_NM = (0.01, 0.03, 0.1, 0.3, 1.0)
MIN_COUNTS = (2,)


def calibration_score(params: dict, sim, other_map=None) -> float:
    """RMS error vs ``torque_ref`` of ``AngleAdaptive(**params)`` on the calibration ``sim``."""
    method = AngleAdaptive(**params)
    method.fit(sim.log.for_method(keep_ref=True))
    if other_map is not None:
        method.map_ = other_map.copy()
    method.reset(sim.log.spec)
    visible = sim.log.for_method(keep_ref=False)
    estimate = np.concatenate([method.step(b) for b in visible.blocks(int(visible.spec.fs))])
    return score(estimate, Truth.from_simulation(sim))["rms_error_ref_nm"]


def other_device_map(seed: int) -> np.ndarray:
    """The calibration map of the device of ``seed + 1`` (the wrong map)."""
    method = AngleAdaptive()
    method.fit(simulate("calibration", seed + 1).log.for_method(keep_ref=True))
    return method.map_


# ---------------------------------------------------------------- measurements (not tuning)
def revolutions_to(fraction: float, seed: int = 100, shift_counts: int | None = None) -> float:
    """Wave-generator revolutions until the map error falls below ``fraction`` of its start.

    On the calibration log of ``seed``: the estimate of ``angle-adaptive`` warm-started
    from a wrong map (another device's, or the own map with its angle origin moved by
    ``shift_counts``) is compared with that of the frozen own map, per revolution turned;
    no torque is needed. Returns NaN if it never gets there.
    """
    sim = simulate("calibration", seed)
    own = AngleAdaptive(adapt=False)
    own.fit(sim.log.for_method(keep_ref=True))
    wrong = other_device_map(seed) if shift_counts is None else shifted_map(own, shift_counts)
    visible = sim.log.for_method(keep_ref=False)
    estimates = {}
    for name, params, start in (("own", {"adapt": False}, None), ("frozen", {"adapt": False}, wrong),
                                ("adaptive", {}, wrong)):
        method = AngleAdaptive(**params)
        method.fit(sim.log.for_method(keep_ref=True))
        if start is not None:
            method.map_ = start.copy()
        method.reset(sim.log.spec)
        estimates[name] = np.concatenate([method.step(b) for b in visible.blocks(int(visible.spec.fs))])
    turned = np.concatenate([[0], np.cumsum(np.abs(np.diff(visible.encoder)))]) / visible.spec.counts_per_rev
    rev = np.floor(turned).astype(int)
    moving = np.concatenate([[False], np.diff(visible.encoder) != 0])
    start = np.sqrt(np.mean((estimates["frozen"] - estimates["own"])[moving] ** 2))
    for k in range(rev.max()):
        sel = (rev == k) & moving
        if sel.sum() < 20:
            continue
        err = np.sqrt(np.mean((estimates["adaptive"] - estimates["own"])[sel] ** 2))
        if err < fraction * start:
            return float(k + 1)
    return float("nan")


def shifted_map(fitted: AngleAdaptive, shift_counts: int) -> np.ndarray:
    """The fitted map with its angle origin moved (an unknown origin after a power cycle)."""
    return rotation(fitted.orders_ if hasattr(fitted, "orders_") else np.asarray(fitted.orders),
                    shift_counts, 2500) @ fitted.map_


def measure(seeds) -> None:
    """Print convergence (revolutions to 10 % map error) on the calibration logs."""
    for rate in (1.0, 5.0, 20.0):
        print(f"drift over {60 * rate:.0f} revolutions at {rate:g} rev/s, RMS error over the last third:",
              {k: round(v, 4) for k, v in drift(rate).items()}, flush=True)
    print("| seed | wrong map: other device | wrong map: origin moved 611 counts |")
    print("|---|---|---|")
    for s in seeds:
        print(f"| {s} | {revolutions_to(0.1, s):.0f} | {revolutions_to(0.1, s, 611):.0f} |", flush=True)


def index_from_counts(encoder: np.ndarray, index_count: int, counts_per_rev: int) -> np.ndarray:
    """1 where the count crosses ``index_count`` modulo a revolution: a fixed motor angle."""
    rev = np.floor_divide(encoder - index_count, counts_per_rev)
    pulse = np.zeros(len(encoder), dtype=np.int8)
    pulse[1:] = rev[1:] != rev[:-1]
    return pulse


def power_cycled(log, index_count: int, count_offset: int):
    """``log`` with an index column built from its own (true-angle) counts, then the counts
    shifted by ``count_offset``: what a power cycle does to an incremental encoder."""
    index = index_from_counts(log.encoder, index_count, int(log.spec.counts_per_rev))
    return dataclasses.replace(log, index=index, encoder=log.encoder + count_offset)


def emulate_power_cycle(seeds, scenarios, methods) -> None:
    """Score ``methods`` with the evaluation log's encoder counts shifted by a random offset.

    Emulates the ``power-cycled`` condition before the simulator has it: the calibration
    log of the device gets an index column (index at a device-drawn count), the evaluation
    log the same index and counts shifted by a random offset (both drawn from the seed).
    Prints the mean ``rms_error_nm`` per scenario and method, same-session beside it.
    """
    from rippleb.registry import Registry
    from rippleb.engine.runner import evaluate

    registry = Registry.discover()
    print("| scenario | method | same-session | power-cycled (emulated) |")
    print("|---|---|---|---|")
    for scenario in scenarios:
        rows = {m: ([], []) for m in methods}
        for seed in seeds:
            rng = np.random.default_rng([seed, 13])
            index_count, offset = int(rng.integers(0, 2500)), int(rng.integers(0, 10**6))
            cal = simulate("calibration", seed).log
            sim = simulate(scenario, seed)
            truth = Truth.from_simulation(sim)
            cal_i = power_cycled(cal, index_count, 0)
            cycled = power_cycled(sim.log, index_count, offset)
            same = power_cycled(sim.log, index_count, 0)
            for m in methods:
                cls = registry.get(m).load()
                rows[m][0].append(evaluate(cls, cal_i, same, truth)["rms_error_nm"])
                rows[m][1].append(evaluate(cls, cal_i, cycled, truth)["rms_error_nm"])
        for m in methods:
            print(f"| {scenario} | {m} | {np.mean(rows[m][0]):.3f} | {np.mean(rows[m][1]):.3f} |", flush=True)


def drift(rev_per_s: float = 5.0, seconds: float = 60.0, seed: int = 0) -> dict:
    """RMS error [Nm] while the ripple map drifts from one device's map to another's.

    A synthetic joint turning at ``rev_per_s`` whose strain follows the method's model
    exactly, plus 0.01 Nm of white noise and a slow torque swing; the map coefficients move
    linearly from the calibration map of seed 100 to that of seed 101 over the whole run
    (``seconds * rev_per_s`` revolutions). Returns the RMS error over the last third for
    ``angle-adaptive`` and ``angle-adaptive-frozen`` (warm-started from the first map).
    """
    from rippleb.data import make_log
    from rippleb.methods.angle_adaptive import angle_regressors, map_rows, phasor_table

    fitted = AngleAdaptive()
    fitted.fit(simulate("calibration", 100).log.for_method(keep_ref=True))
    start, end = fitted.map_, other_device_map(100)
    spec = simulate("calibration", 100).log.spec
    n = int(seconds * spec.fs)
    t = np.arange(n) / spec.fs
    encoder = np.floor(rev_per_s * t * spec.counts_per_rev).astype(np.int64)
    base = 5.0 + 10.0 * np.sin(2 * np.pi * 0.2 * t)
    phi = angle_regressors(encoder, np.asarray(fitted.orders), phasor_table(int(spec.counts_per_rev)))
    w = start + (t / seconds)[:, None] * (end - start)
    strain = base + np.sum(map_rows(phi, base) * w, axis=1)
    tau = strain - np.sum(map_rows(phi, strain) * w, axis=1)
    strain = strain + np.random.default_rng(seed).normal(0, 0.01, n)
    log = make_log(spec, {"t": t, "strain": (strain - fitted.offset_) / fitted.gain_, "encoder": encoder,
                          "current": np.zeros(n), "torque_true": tau}, source="drift")
    tail = slice(2 * n // 3, n)
    out = {}
    for name, adapt in (("angle-adaptive", True), ("angle-adaptive-frozen", False)):
        method = AngleAdaptive(adapt=adapt)
        method.gain_, method.offset_, method.map_, method.r_ = fitted.gain_, fitted.offset_, start, fitted.r_
        method.home_ = None
        method.reset(spec)
        estimate = np.concatenate([method.step(b) for b in log.blocks(int(spec.fs))])
        out[name] = float(np.sqrt(np.mean((estimate - tau)[tail] ** 2)))
    return out


def speed(rounds: int = 5000) -> None:
    """Per-tick cost against one ``scipy.signal.lfilter`` call with state, same blocks, same run.

    One ``step`` per 20-sample control tick of stop-restart (seed 0), ``rounds`` ticks, for
    both angle-adaptive classes, ``kalman-ripple`` and ``order-tracking``; then the
    throughput on 1-second blocks. The machine may be loaded: read the ratios.
    """
    import time

    import scipy.signal

    from rippleb.registry import Registry

    registry = Registry.discover()
    calibration = simulate("calibration", 0).log.for_method(keep_ref=True)
    visible = simulate("stop-restart", 0).log.for_method(keep_ref=False)
    blocks = list(visible.blocks())[:rounds]
    b, a = scipy.signal.butter(2, 0.05)
    state = np.zeros(2)
    ticks = []
    for block in blocks:
        t0 = time.perf_counter()
        _, state = scipy.signal.lfilter(b, a, block.strain, zi=state)
        ticks.append(time.perf_counter() - t0)
    yard = np.array(ticks)
    print(f"lfilter with state, 20 samples: p50 {np.median(yard) * 1e6:.1f} us, "
          f"p99 {np.percentile(yard, 99) * 1e6:.1f} us")
    for name in ("angle-adaptive", "angle-adaptive-frozen", "kalman-ripple", "order-tracking"):
        method = registry.get(name).load()()
        method.fit(calibration)
        method.reset(visible.spec)
        ticks = []
        for block in blocks:
            t0 = time.perf_counter()
            method.step(block)
            ticks.append(time.perf_counter() - t0)
        ticks = np.array(ticks)
        method.reset(visible.spec)
        t0 = time.perf_counter()
        for block in visible.blocks(int(visible.spec.fs)):
            method.step(block)
        rate = len(visible) / (time.perf_counter() - t0)
        print(f"{name}: p50 {np.median(ticks) * 1e6:.1f} us ({np.median(ticks) / np.median(yard):.1f}x), "
              f"mean {ticks.mean() * 1e6:.1f} us ({ticks.mean() / yard.mean():.1f}x), "
              f"p99 {np.percentile(ticks, 99) * 1e6:.1f} us "
              f"({np.percentile(ticks, 99) / np.percentile(yard, 99):.1f}x); "
              f"1-s blocks {rate / 1e6:.2f} M samples/s", flush=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100,101,102")
    parser.add_argument("--measure", action="store_true",
                        help="measure the convergence in revolutions instead of tuning")
    parser.add_argument("--power-cycle", metavar="SCENARIOS",
                        help="score angle-adaptive(-frozen), kalman-ripple, order-tracking on these "
                             "scored scenarios under an emulated power cycle (a measurement, not tuning)")
    parser.add_argument("--speed", action="store_true", help="measure the per-tick cost instead")
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    if args.speed:
        speed()
        return
    if args.power_cycle:
        emulate_power_cycle(seeds, args.power_cycle.split(","),
                            ["angle-adaptive", "angle-adaptive-frozen", "kalman-ripple", "order-tracking"])
        return
    if args.measure:
        measure(seeds)
        return
    sims = {s: simulate("calibration", s) for s in seeds}
    wrong = {s: other_device_map(s) for s in seeds}
    frozen = [(calibration_score({"adapt": False}, sims[s]),
               calibration_score({"adapt": False}, sims[s], wrong[s])) for s in seeds]
    print(f"frozen (no adaptation): own {np.mean([f[0] for f in frozen]):.3f}, "
          f"wrong {np.mean([f[1] for f in frozen]):.3f}")
    print("| memory_revs | prior_sd_nm | min_counts | own | wrong | mean |")
    print("|---|---|---|---|---|---|")
    rows = []
    for memory, prior, counts in itertools.product(MEMORY_REVS, PRIOR_SD_NM, MIN_COUNTS):
        params = {"memory_revs": memory, "prior_sd_nm": prior, "min_counts": counts}
        own = np.mean([calibration_score(params, sims[s]) for s in seeds])
        bad = np.mean([calibration_score(params, sims[s], wrong[s]) for s in seeds])
        rows.append(((own + bad) / 2, params))
        print(f"| {memory:g} | {prior:g} | {counts} | {own:.3f} | {bad:.3f} | {(own + bad) / 2:.3f} |",
              flush=True)
    best = min(rows, key=lambda r: r[0])
    print(f"\nlowest mean: {best[1]} ({best[0]:.3f} Nm)")


if __name__ == "__main__":
    main()
