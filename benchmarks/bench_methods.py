"""Per-tick cost of every built-in method's ``step``, next to one ``sosfilt`` call.

Run with ``python -m pytest benchmarks/bench_methods.py --benchmark-enable``. Each round is
one ``step`` on one 20-sample block (one 1 kHz tick at 20 kHz) of ``paper-quintic`` seed 0,
the blocks taken in time order and cycled so the state is realistic (rest, a whole move
through all speeds, rest). The 99th percentile of the rounds and the samples per second
go to ``extra_info`` and are printed. The ``sosfilt`` row (one second-order-section call
with ``zi`` on the same blocks) is the yardstick of "one compiled filter call" on the same
machine in the same run, so a busy machine shows up in every row: compare ratios, not
absolute times. Targets: p99 <= 100 us (order-tracking), <= 200 us (competitors).
"""

import itertools

import numpy as np
import pytest
from scipy import signal

from rippleb.registry import Registry

ROUNDS = 4000
BUILTINS = Registry.discover().names(origin="builtin")


@pytest.fixture(scope="module")
def logs():
    from rippleb.simulator import simulate

    return (simulate("calibration", 0).log.for_method(keep_ref=True),
            simulate("paper-quintic", 0).log.for_method(keep_ref=False))


def _bench_ticks(benchmark, step, log, label):
    blocks = itertools.cycle(list(log.blocks()))
    out = benchmark.pedantic(step, setup=lambda: ((next(blocks),), {}),
                             rounds=ROUNDS, iterations=1, warmup_rounds=100)
    assert len(out) == log.spec.block_size
    data = np.asarray(benchmark.stats.stats.data) * 1e6
    p50, p99 = np.median(data), np.percentile(data, 99)
    benchmark.extra_info.update(p50_us=round(p50, 1), p99_us=round(p99, 1),
                                samples_per_s=round(log.spec.block_size / (p50 * 1e-6)))
    print(f"\n{label}: p50 {p50:.1f} us, p99 {p99:.1f} us per tick, "
          f"{log.spec.block_size / p50:.2f} M samples/s at p50")


@pytest.mark.parametrize("name", BUILTINS)
def test_step_per_tick(benchmark, logs, name):
    calibration, log = logs
    method = Registry.discover().get(name).load()()
    method.fit(calibration)
    method.reset(log.spec)
    _bench_ticks(benchmark, method.step, log, f"{name} step")


def test_sosfilt_reference(benchmark, logs):
    _, log = logs
    sos = signal.butter(2, 130.0, fs=log.spec.fs, output="sos")
    zi = signal.sosfilt_zi(sos) * log.strain[0]

    def step(block):
        nonlocal zi
        out, zi = signal.sosfilt(sos, block.strain, zi=zi)
        return out

    _bench_ticks(benchmark, step, log, "sosfilt with zi")
