"""Cost of every built-in method's ``step``, as ratios to ``lfilter`` and ``raw`` in one run.

Run with ``python -m pytest benchmarks/bench_methods.py --benchmark-enable -n 0 -s``
(``-n 0``: one process; under the suite's default ``-n auto`` pytest-benchmark disables
itself, the workers time each other's load and ``-s`` prints nothing).

Per tick (``test_step_per_tick``): the 20-sample blocks (one 1 kHz tick at 20 kHz) of
``paper-quintic`` seeds 901-902 (rest, a whole move through all speeds, rest), in time
order. Every block is fed to the method's ``step`` and, interleaved with it on the same
block, to two yardsticks: one ``scipy.signal.lfilter`` call (2nd-order Butterworth, with
state) -- "one compiled filter call" -- and the ``raw`` method's ``step`` -- the floor of a
Python method call. Interleaving makes the yardsticks see the same machine load as the
method, so the ratios hold on a busy machine where the absolute times do not.

Long blocks (``test_one_second_blocks``): the same logs cut into 1-second blocks
(20 000 samples), five passes; samples per second of the median call of the method next
to ``raw`` and ``lfilter`` on the same blocks (the 4-second paper-quintic logs cut into
four full blocks each).

The numbers go to ``extra_info`` and are printed. Targets (issue 14): p50 within 4x and
p99 within 6x of ``lfilter``; >= 5 M samples/s on 1-second blocks. Issue 33 tightens them
to p50 within 2x of ``lfilter`` and >= 10 M samples/s, met by the methods it added
(``spatial-filter``, ``fourier-lms``, ``periodic-dob``: each one compiled loop per call);
the run prints every built-in, so one run compares them all. No target is asserted: the
times are the machine's, the ratios are what to read.
"""

from __future__ import annotations

import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
import pytest
from scipy import signal

from rippleb.methods.raw import Raw
from rippleb.registry import Registry

SEEDS = (901, 902)
REPEATS = 2          # passes over the ticks of each seed (the first also warms caches)
LONG_REPEATS = 5     # passes over each seed in 1-second blocks
BUILTINS = Registry.discover().names(origin="builtin")


@pytest.fixture(scope="module")
def logs():
    from rippleb.simulator import simulate

    calibration = simulate("calibration", 0).log.for_method(keep_ref=True)
    runs = [simulate("paper-quintic", seed).log.for_method(keep_ref=False) for seed in SEEDS]
    return calibration, runs


def lfilter_step(fs: float):
    """A ``step``-like call: one 2nd-order ``lfilter`` with state on the block's strain."""
    b, a = signal.butter(2, 130.0, fs=fs)
    state = {"zi": None}

    def step(block):
        if state["zi"] is None:
            state["zi"] = signal.lfilter_zi(b, a) * block.strain[0]
        y, state["zi"] = signal.lfilter(b, a, block.strain, zi=state["zi"])
        return y

    return step


def interleaved_times(method, raw, log, size=None, repeats=REPEATS):
    """Nanoseconds of each call of method, ``lfilter`` and ``raw``, block by block.

    Returns
    -------
    ndarray, shape ``(3, calls)``
        Rows: method, lfilter, raw.
    """
    clock = time.perf_counter_ns
    blocks = list(log.blocks(size))
    times = []
    for _ in range(repeats):
        method.reset(log.spec)
        raw.reset(log.spec)
        reference = lfilter_step(log.spec.fs)
        for block in blocks:
            row = []
            for step in (method.step, reference, raw.step):
                t0 = clock()
                step(block)
                row.append(clock() - t0)
            times.append(row)
    return np.array(times, dtype=float).T


def _fitted(name, calibration):
    method = Registry.discover().get(name).load()()
    method.fit(calibration)
    raw = Raw()
    raw.fit(calibration)
    return method, raw


@pytest.mark.parametrize("name", BUILTINS)
def test_step_per_tick(benchmark, logs, name):
    calibration, runs = logs
    method, raw = _fitted(name, calibration)

    def measure():
        return np.hstack([interleaved_times(method, raw, log) for log in runs])

    times = benchmark.pedantic(measure, rounds=1, iterations=1) / 1000.0   # us
    p50, p99 = np.median(times, axis=1), np.percentile(times, 99, axis=1)
    info = dict(p50_us=p50[0], p99_us=p99[0], lfilter_p50_us=p50[1], lfilter_p99_us=p99[1],
                raw_p50_us=p50[2], p50_over_lfilter=p50[0] / p50[1],
                p99_over_lfilter=p99[0] / p99[1], p50_over_raw=p50[0] / p50[2])
    benchmark.extra_info.update({k: round(float(v), 2) for k, v in info.items()})
    print(f"\n{name}: p50 {p50[0]:.1f} us ({info['p50_over_lfilter']:.2f}x lfilter, "
          f"{info['p50_over_raw']:.1f}x raw), p99 {p99[0]:.1f} us "
          f"({info['p99_over_lfilter']:.2f}x lfilter); "
          f"lfilter p50 {p50[1]:.1f} p99 {p99[1]:.1f} us, "
          f"raw p50 {p50[2]:.1f} us")
    assert times.shape[1] == REPEATS * sum(-(-len(log) // log.spec.block_size) for log in runs)


@pytest.mark.parametrize("name", BUILTINS)
def test_one_second_blocks(benchmark, logs, name):
    calibration, runs = logs
    method, raw = _fitted(name, calibration)
    size = int(runs[0].spec.fs)

    def measure():
        return np.hstack([interleaved_times(method, raw, log, size, repeats=LONG_REPEATS)
                          for log in runs])

    times = benchmark.pedantic(measure, rounds=1, iterations=1)
    # the median call: a few calls per pass, so one preempted call must not set the figure
    rate = size / np.median(times, axis=1) * 1e3       # M samples/s
    info = dict(msamples_per_s=rate[0], lfilter_msamples_per_s=rate[1],
                raw_msamples_per_s=rate[2])
    benchmark.extra_info.update({k: round(float(v), 2) for k, v in info.items()})
    print(f"\n{name} on 1-second blocks: {rate[0]:.2f} M samples/s "
          f"(lfilter {rate[1]:.0f}, raw {rate[2]:.0f} M samples/s)")
    assert np.all(rate > 0)
