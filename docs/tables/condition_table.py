"""Mean RMS error per method under each deployment condition, straight from the simulator.

For each seed every method is fitted once on that seed's ``calibration`` log (the first
session, the same under every condition) and streamed over each scenario simulated under
each condition; the table gives the mean ``rms_error_nm`` over the seeds. Use it to see how
a method copes with a condition without the runner.

Run: ``python docs/tables/condition_table.py [--seeds 900-904] [--scenarios paper-quintic,stop-restart]
[--methods ...] [--calibration calibration]``
"""

from __future__ import annotations

import argparse
import copy

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

from rippleb.simulator.conditions import CONDITIONS
from rippleb.scoring.metrics import Truth, score
from rippleb.registry import Registry
from rippleb.simulator import simulate
from rippleb.harness import prepare_blocks, stream

DEFAULT_METHODS = "raw,lowpass,current-based,switched-notch,order-tracking,kalman-ripple"


def seeds_of(text: str) -> list[int]:
    """``900-904`` or ``1,2,3``."""
    if "-" in text:
        lo, hi = (int(v) for v in text.split("-"))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(",")]


def table(methods, scenarios, conditions, seeds, calibration="calibration") -> dict:
    """``{(method, scenario, condition): [rms_error_nm per seed]}``."""
    registry = Registry.discover()
    out: dict = {}
    for seed in seeds:
        cal = simulate(calibration, seed).log.for_method(keep_ref=True)
        fitted = {}
        for name in methods:
            method = registry.get(name).load()()
            method.fit(cal)
            fitted[name] = method
        for scenario in scenarios:
            for condition in conditions:
                sim = simulate(scenario, seed, condition)
                blocks = prepare_blocks(sim.log.for_method(keep_ref=False))
                for name in methods:
                    rms = rms_error(fitted[name], sim, blocks)
                    out.setdefault((name, scenario, condition), []).append(rms)
    return out


def rms_error(fitted, sim, blocks=None) -> float:
    """``rms_error_nm`` of a copy of the ``fitted`` method streamed over ``sim``'s log as
    the runner does (``reset``, then one ``step`` per tick); ``blocks`` from
    :func:`~rippleb.harness.prepare_blocks` of the visible log, when already cut."""
    visible = sim.log.for_method(keep_ref=False)
    method = copy.deepcopy(fitted)
    method.reset(visible.spec)
    blocks = prepare_blocks(visible) if blocks is None else blocks
    estimate, _ = stream(method.step, blocks, len(visible))
    return score(estimate, Truth.from_simulation(sim))["rms_error_nm"]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="900-904")
    parser.add_argument("--scenarios", default="paper-quintic,stop-restart")
    parser.add_argument("--methods", default=DEFAULT_METHODS)
    parser.add_argument("--conditions", default=",".join(CONDITIONS))
    parser.add_argument("--calibration", default="calibration")
    args = parser.parse_args(argv)
    methods, scenarios = args.methods.split(","), args.scenarios.split(",")
    conditions = args.conditions.split(",")
    result = table(methods, scenarios, conditions, seeds_of(args.seeds), args.calibration)
    for scenario in scenarios:
        print(f"\n{scenario}: mean rms_error_nm over seeds {args.seeds}\n")
        print("| method | " + " | ".join(conditions) + " |")
        print("|---" * (len(conditions) + 1) + "|")
        for name in methods:
            cells = [f"{np.mean(result[name, scenario, c]):.3f}" for c in conditions]
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
