"""Per-tick cost of the competitors' ``step`` (switched-notch, current-based), next to sosfilt.

Run with ``python -m pytest benchmarks/bench_competitors.py --benchmark-enable``. Each
round is one ``step`` on one 20-sample block (one 1 kHz tick at 20 kHz) of a simulated
stop-restart log, the blocks taken in time order so the state is realistic (the log runs
from rest through moves, a stop and a restart, so every switched-notch band change is
in the sample). The 99th percentile of the rounds goes to ``extra_info["p99_us"]`` and is
printed; the target is 200 us. The ``sosfilt`` row (one second-order-section call with
``zi`` on the same blocks) shows what a single compiled call costs on the same machine
in the same run, so a busy machine shows up in every row.
"""

import itertools

import numpy as np
import pytest
from scipy import signal

from rippleb.methods.current_based import CurrentBased
from rippleb.methods.switched_notch import SwitchedNotch

ROUNDS = 5000


@pytest.fixture(scope="module")
def logs():
    from rippleb.simulator import simulate

    return (simulate("calibration", 0).log.for_method(keep_ref=True),
            simulate("stop-restart", 0).log.for_method(keep_ref=False))


def _blocks(log):
    """Blocks of one tick, in time order, cycled."""
    return itertools.cycle(list(log.blocks()))


def _report_p99(benchmark, label):
    stats = getattr(benchmark, "stats", None)
    data = getattr(getattr(stats, "stats", None), "data", None)
    if data:
        p99 = float(np.percentile(np.asarray(data) * 1e6, 99))
        benchmark.extra_info["p99_us"] = round(p99, 1)
        print(f"\n{label}: p50 {np.median(data) * 1e6:.1f} us, p99 {p99:.1f} us per tick")


def _bench_step(benchmark, method, logs, label):
    calibration, log = logs
    method.fit(calibration)
    method.reset(log.spec)
    blocks = _blocks(log)
    out = benchmark.pedantic(method.step, setup=lambda: ((next(blocks),), {}),
                             rounds=ROUNDS, iterations=1, warmup_rounds=100)
    assert len(out) == log.spec.block_size
    _report_p99(benchmark, label)


def test_switched_notch_step(benchmark, logs):
    _bench_step(benchmark, SwitchedNotch(), logs, "switched-notch step")


def test_current_based_step(benchmark, logs):
    _bench_step(benchmark, CurrentBased(), logs, "current-based step")


def test_sosfilt_reference(benchmark, logs):
    _, log = logs
    sos = signal.butter(2, 130.0, fs=log.spec.fs, output="sos")
    zi = signal.sosfilt_zi(sos) * log.strain[0]
    blocks = _blocks(log)

    def step(block):
        nonlocal zi
        out, zi = signal.sosfilt(sos, block.strain, zi=zi)
        return out

    out = benchmark.pedantic(step, setup=lambda: ((next(blocks),), {}),
                             rounds=ROUNDS, iterations=1, warmup_rounds=100)
    assert len(out) == log.spec.block_size
    _report_p99(benchmark, "sosfilt with zi")
