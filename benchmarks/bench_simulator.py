"""Simulator speed: paper-quintic including the robot model load, and linear scaling.

Run with ``python -m pytest benchmarks/bench_simulator.py --benchmark-enable``.
"""

import pytest

from rippleb import load_scenario, simulate
from rippleb import robot
from rippleb.scenario import scenario_from_dict


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
