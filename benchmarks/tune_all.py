"""Tune every built-in method by one protocol with one budget (rippleb/tuning.py).

For each built-in that declares ``tunable`` ranges: the default and ``budget - 1`` Sobol
points, each fitted and scored on the ``calibration`` log of each seed against
``torque_ref`` (never ``torque_true``, never a scored scenario), mean over the seeds. Prints
per method the default's score, the best point and its score, and writes them as JSON.

Run: ``python benchmarks/tune_all.py --budget 16 --seeds 100-102 --out runs/tuning.json``
"""

from __future__ import annotations

import argparse
import json
import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

from calibration_tuning import calibration_logs, mean_score  # beside this script: one scoring

from rippleb.registry import Registry
from rippleb.tuning import candidates, check_tunable


def evaluate(cls, params: dict, sims) -> float:
    """Mean ``rms_error_ref_nm`` of ``cls(**params)`` fitted and scored on each calibration log."""
    return mean_score(cls, params, sims)["rms_error_ref_nm"]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=16, help="calibration evaluations per method")
    parser.add_argument("--seeds", default="100-102")
    parser.add_argument("--methods", default=None, help="comma-separated (default: every built-in)")
    parser.add_argument("--out", default=None, help="JSON file for the results")
    args = parser.parse_args(argv)
    lo, hi = (int(v) for v in args.seeds.split("-"))
    sims = calibration_logs(range(lo, hi + 1))
    registry = Registry.discover()
    names = args.methods.split(",") if args.methods else registry.names("builtin")
    report = {"budget": args.budget, "seeds": [lo, hi], "criterion": "rms_error_ref_nm on calibration",
              "methods": {}}
    for name in names:
        cls = registry.get(name).load()
        tunable = getattr(cls, "tunable", None)
        if tunable is None:
            report["methods"][name] = {"status": "declares no tunable ranges"}
            print(f"{name}: declares no tunable ranges", flush=True)
            continue
        check_tunable(name, tunable)
        start = time.perf_counter()
        tried = [(evaluate(cls, p, sims), i, p) for i, p in enumerate(candidates(tunable, cls().get_params(),
                                                                              args.budget))]
        best = min(tried, key=lambda r: (r[0], r[1]))
        report["methods"][name] = {"tunable": {k: list(v) for k, v in tunable.items()},
                                   "default": tried[0][2], "default_score": tried[0][0],
                                   "best": best[2], "best_score": best[0], "evaluations": len(tried),
                                   "seconds": time.perf_counter() - start}
        print(f"{name}: default {tried[0][0]:.3f}, best {best[0]:.3f} at {best[2]} "
              f"({len(tried)} evaluations)", flush=True)
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(report, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
