"""The two yardsticks of this machine's pace at the moment of a measurement.

    python benchmarks/yardsticks.py [--passes N]

One ``scipy.signal.lfilter`` call with state (2nd-order Butterworth) on a 20-sample tick,
and ``raw``'s ``step`` on the same tick, interleaved over the 4000 ticks of paper-quintic
seed 0, ``--passes`` times; prints the median of each. Timed next to a whole command (a
default run), they say how fast the machine ran at the time, so that times taken in
different sittings can be compared in these units (docs/report.md, "The machine's pace
against the yardsticks"); ``benchmarks/bench_methods.py`` times every method against them.
"""

from __future__ import annotations

import argparse
import sys
import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
from scipy import signal


def yardsticks(passes: int) -> tuple[float, float, int]:
    """``(lfilter p50, raw step p50)`` in microseconds, and the number of ticks timed."""
    from rippleb import harness
    from rippleb.registry import Registry
    from rippleb.simulator import simulate
    from rippleb.simulator.scenario import load_scenario

    calibration = simulate(load_scenario("calibration"), 0).log
    log = simulate(load_scenario("paper-quintic"), 0).log.for_method(keep_ref=False)
    raw, _, _ = harness.fitted(Registry.discover().get("raw").load(), None, calibration)
    raw.reset(log.spec)
    b, a = signal.butter(2, 0.1)
    state = signal.lfilter_zi(b, a)
    blocks = harness.prepare_blocks(log)
    clock = time.perf_counter_ns
    lfilter_ns, raw_ns = [], []
    for _ in range(passes):
        for block in blocks:
            t0 = clock()
            _, state = signal.lfilter(b, a, block.strain, zi=state)
            t1 = clock()
            raw.step(block)
            t2 = clock()
            lfilter_ns.append(t1 - t0)
            raw_ns.append(t2 - t1)
    return float(np.median(lfilter_ns)) / 1e3, float(np.median(raw_ns)) / 1e3, len(lfilter_ns)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--passes", type=int, default=5, help="passes over the log's ticks (default 5)")
    args = parser.parse_args(argv)
    lfilter_us, raw_us, ticks = yardsticks(args.passes)
    print(f"lfilter p50 {lfilter_us:.2f} us, raw step p50 {raw_us:.2f} us ({ticks} ticks)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
