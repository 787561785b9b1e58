"""Harness overhead per control tick, with a no-op method (target: median <= 5 us).

Run: ``python -m pytest benchmarks/bench_harness.py --benchmark-enable``. The benchmark
times one whole :func:`rippleb.harness.stream` over 4000 ticks; ``extra_info`` holds
the per-tick figure (total / ticks), which includes the method call itself (an empty
Python method, ~0.1 us).
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
import pytest

from rippleb import JointSpec, Method, make_log
from rippleb.harness import prepare_blocks, stream

TICKS = 4000


class Noop(Method):
    name = "noop"

    def step(self, block):
        return block.strain   # a valid estimate that costs nothing


@pytest.fixture(scope="module")
def blocks():
    spec = JointSpec()
    n = TICKS * spec.block_size
    t = np.arange(n) / spec.fs
    log = make_log(spec, {"t": t, "strain": np.sin(t), "encoder": np.zeros(n), "current": np.zeros(n)})
    return prepare_blocks(log), n


def test_harness_overhead_per_tick(benchmark, blocks):
    blocks, n = blocks
    step = Noop().step
    benchmark(stream, step, blocks, n)
    if benchmark.stats is not None:
        per_tick = benchmark.stats.stats.median / TICKS * 1e6
        benchmark.extra_info["us_per_tick_median"] = per_tick
        print(f"\nharness overhead: {per_tick:.2f} us per tick (median of whole runs / {TICKS})")


def test_step_timer_resolution(benchmark, blocks):
    """What the per-tick timings in results.csv see for a no-op: the recorded step times."""
    blocks, n = blocks
    _, ticks = benchmark(stream, Noop().step, blocks, n)
    benchmark.extra_info["recorded_us_p50"] = float(np.median(ticks) / 1000)
