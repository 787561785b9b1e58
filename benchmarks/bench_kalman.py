"""Per-tick cost of ``kalman-ripple``'s ``step``, next to one ``scipy.signal.sosfilt`` call.

Run with ``python -m pytest benchmarks/bench_kalman.py --benchmark-enable``. Each round
is one ``step`` on one 20-sample block (one 1 kHz tick at 20 kHz) of a simulated
stop-restart log, the blocks taken in time order so the filter state is realistic. The
99th percentile of the rounds is stored in ``extra_info["p99_us"]`` and printed; the
target is 200 us. The ``sosfilt`` row (a 4th-order Butterworth low-pass with ``zi`` on
the same blocks) shows what a single compiled call costs on the same machine in the same
run, so a slow or busy machine shows up in both rows.
"""

import itertools

import numpy as np
import pytest
from scipy import signal

from rippleb.methods.kalman_ripple import KalmanRipple

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


@pytest.mark.parametrize("torque_rate", [False, True], ids=["random-walk", "torque-rate"])
def test_kalman_ripple_step(benchmark, logs, torque_rate):
    calibration, log = logs
    method = KalmanRipple(torque_rate=torque_rate)
    method.fit(calibration)
    method.reset(log.spec)
    blocks = _blocks(log)
    out = benchmark.pedantic(method.step, setup=lambda: ((next(blocks),), {}),
                             rounds=ROUNDS, iterations=1, warmup_rounds=100)
    assert len(out) == log.spec.block_size
    _report_p99(benchmark, f"kalman-ripple step ({'torque rate' if torque_rate else 'random walk'})")


def test_sosfilt_reference(benchmark, logs):
    _, log = logs
    sos = signal.butter(4, 130.0, fs=log.spec.fs, output="sos")
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
