"""The two yardsticks of this machine's pace at the moment of a measurement.

    python benchmarks/yardsticks.py [--passes N]

The yardsticks ``benchmarks/bench_methods.py`` times every method against, as it defines
and times them (``lfilter_step``, ``interleaved_times``): one ``scipy.signal.lfilter`` call
with state (2nd-order Butterworth) on a 20-sample tick and ``raw``'s ``step`` on the same
tick, interleaved over the 4000 ticks of paper-quintic seed 0, ``--passes`` times; prints
the median of each. Timed next to a whole command (a default run), they say how fast the
machine ran at the time (docs/report.md, "The machine's pace against the yardsticks").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))   # the yardsticks' one definition
from bench_methods import interleaved_times  # noqa: E402


def yardsticks(passes: int) -> tuple[float, float, int]:
    """``(lfilter p50, raw step p50)`` in microseconds, and the number of ticks timed."""
    from rippleb import harness
    from rippleb.registry import Registry
    from rippleb.simulator import simulate
    from rippleb.simulator.scenario import load_scenario

    calibration = simulate(load_scenario("calibration"), 0).log
    log = simulate(load_scenario("paper-quintic"), 0).log.for_method(keep_ref=False)
    raw, _, _ = harness.fitted(Registry.discover().get("raw").load(), None, calibration)
    _, lfilter_ns, raw_ns = interleaved_times(raw, raw, log, repeats=passes)
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
