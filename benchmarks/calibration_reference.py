"""What each method loses to the error of its calibration reference.

Methods are fitted on the ``calibration`` log against ``torque_ref``, the paper's eq. (7)
computed from the desired trajectory with the nominal model; a real joint's torque differs
from it by model error, friction and the joint's own dynamics. This script fits every method
twice per seed, once as the benchmark does and once on the same log with ``torque_ref``
replaced by the simulated true torque (an oracle no real calibration has), and prints the
mean RMS error of each over the scored scenarios. The difference is what the reference's
error costs each method: an analysis of the benchmark, never a way to run a method.

Run: ``python benchmarks/calibration_reference.py [--seeds 0-2] [--scenarios paper-quintic,stop-restart]
[--methods ...]``
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

from rippleb.registry import Registry
from rippleb.simulator import simulate

# The condition table's script (docs/tables/) streams and scores a fitted method as this
# analysis needs: one copy of that sequence, shared.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "tables"))
from condition_table import rms_error, seeds_of  # noqa: E402

DEFAULT_METHODS = "angle-adaptive,angle-adaptive-frozen,kalman-ripple,order-tracking,switched-notch"


def calibrations(seed: int) -> dict:
    """The calibration log of ``seed`` as methods see it: with eq. (7) and with the truth."""
    full = simulate("calibration", seed).log
    oracle = dataclasses.replace(full, torque_ref=full.torque_true)
    return {"eq. (7)": full.for_method(keep_ref=True), "true torque": oracle.for_method(keep_ref=True)}


def table(methods, scenarios, seeds) -> dict:
    """``{(method, reference): [rms_error_nm per seed and scenario]}``."""
    registry = Registry.discover()
    out: dict = {}
    for seed in seeds:
        sims = [simulate(scenario, seed) for scenario in scenarios]
        for reference, cal in calibrations(seed).items():
            for name in methods:
                fitted = registry.get(name).load()()
                fitted.fit(cal)
                for sim in sims:
                    out.setdefault((name, reference), []).append(rms_error(fitted, sim))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-2")
    parser.add_argument("--scenarios", default="paper-quintic,stop-restart")
    parser.add_argument("--methods", default=DEFAULT_METHODS)
    args = parser.parse_args(argv)
    methods = args.methods.split(",")
    result = table(methods, args.scenarios.split(","), seeds_of(args.seeds))
    print("| method | fitted against eq. (7) | fitted against the true torque | cost of the reference |")
    print("|---|---:|---:|---:|")
    for name in methods:
        ref, oracle = (float(np.mean(result[(name, r)])) for r in ("eq. (7)", "true torque"))
        print(f"| {name} | {ref:.3f} | {oracle:.3f} | {ref - oracle:+.3f} |")


if __name__ == "__main__":
    main()
