"""Simulator speed: every built-in scenario, the robot model load, and linear scaling.

Run with ``python -m pytest benchmarks/bench_simulator.py --benchmark-enable -s``.

Each scenario's simulation (seed 0, the robot model already loaded) is reported with its
samples per second of simulated log and, as a yardstick measured in the same run, next to
one ``scipy.signal.lfilter`` pass (2nd order) over a log of the same length: on a loaded
machine the ratio holds where the absolute time does not.
"""

import time

import numpy as np
import pytest
from scipy import signal

from rippleb import builtin_scenarios, load_scenario, simulate
from rippleb.simulator import robot
from rippleb.scenario import scenario_from_dict


def _lfilter_seconds(n: int, fs: float) -> float:
    """Best of three ``lfilter`` passes over ``n`` samples [s]."""
    b, a = signal.butter(2, 130.0, fs=fs)
    x = np.random.default_rng(0).normal(size=n)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        signal.lfilter(b, a, x)
        best = min(best, time.perf_counter() - t0)
    return best


@pytest.mark.parametrize("name", builtin_scenarios())
def test_every_scenario(benchmark, name):
    scenario = load_scenario(name)
    simulate(scenario, 0)                       # the robot model, loaded once per process
    t0 = time.perf_counter()
    sim = benchmark.pedantic(simulate, args=(scenario, 0), rounds=3, iterations=1)
    elapsed = time.perf_counter() - t0              # one round when benchmarks are disabled
    n = len(sim.log)
    seconds = benchmark.stats.stats.median if benchmark.stats else elapsed
    yardstick = _lfilter_seconds(n, scenario.spec.fs)
    benchmark.extra_info.update(samples=n, msamples_per_s=round(n / seconds / 1e6, 3),
                                over_one_lfilter_pass=round(seconds / yardstick, 1))
    print(f"\n{name}: {n} samples in {seconds * 1e3:.0f} ms, {n / seconds / 1e6:.2f} M samples/s, "
          f"{seconds / yardstick:.0f}x one lfilter pass over the same length")
    assert n == int(round(scenario.duration * scenario.spec.fs))


def _cold_paper_quintic():
    # A fresh process-level cache: the URDF is parsed and the model built every round.
    robot.load_model.cache_clear()
    return simulate(load_scenario("paper-quintic"), 0)


def test_paper_quintic_cold(benchmark):
    sim = benchmark(_cold_paper_quintic)
    assert len(sim.log) == 80_000


def _cruise(seconds: float):
    """A constant-speed run of ``seconds`` plus fixed ramps, scaled 1x/4x/16x."""
    return scenario_from_dict({"trajectory": {"start": -2.0, "segment": [
        {"kind": "ramp", "velocity": 0.05, "duration": 0.1},
        {"kind": "cruise", "duration": seconds - 0.1}]}}, name="scaling")


@pytest.mark.parametrize("factor", [1, 4, 16])
def test_scaling_with_duration(benchmark, factor):
    scenario = _cruise(2.0 * factor)
    benchmark.extra_info["samples"] = int(2.0 * factor * scenario.spec.fs)
    sim = benchmark(simulate, scenario, 0)
    assert len(sim.log) == int(round(2.0 * factor * scenario.spec.fs))
