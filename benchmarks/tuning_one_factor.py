"""Which of the parameters a re-tuning moved made its score move: every mix of the former and
the adopted values, scored by the one tuning protocol (docs/tuning.md, "What moved and why").

    python benchmarks/tuning_one_factor.py METHOD --former p=v,q=w --adopted p=v2,q=w2 [--seeds 100-119] [--jobs 2]

Each of the ``2^k`` points that takes each of the ``k`` moved parameters either at its former
or at its adopted value is fitted on the calibration log of each tuning device and scored
against ``torque_ref``, exactly as ``rippleb tune`` scores a point
(:func:`rippleb.engine.tuner.tune`). Prints a Markdown table: each point's mean, its paired
difference from the former point and on how many devices it is lower. A point here that the
tuning did not try is an explanation, never a candidate: the protocol adopts only the points
of its budget.
"""

from __future__ import annotations

import argparse
import itertools

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np


def _point(text: str) -> dict:
    pairs = (item.split("=", 1) for item in text.split(","))
    return {name.strip(): _number(value) for name, value in pairs}


def _number(text: str) -> int | float:
    try:
        return int(text)
    except ValueError:
        return float(text)


def _seeds(text: str) -> list[int]:
    low, _, high = text.partition("-")
    return list(range(int(low), int(high or low) + 1))


def mixes(former: dict, adopted: dict) -> list[dict]:
    """Every point taking each parameter at its former or adopted value, the former first."""
    names = list(former)
    return [{n: (adopted if pick else former)[n] for n, pick in zip(names, picks)}
            for picks in itertools.product((False, True), repeat=len(names))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("method")
    parser.add_argument("--former", required=True, type=_point, help="the former defaults, p=v,q=w")
    parser.add_argument("--adopted", required=True, type=_point, help="the adopted point, same parameters")
    parser.add_argument("--seeds", default="100-119", type=_seeds, help="tuning devices (default 100-119)")
    parser.add_argument("--jobs", default=2, type=int)
    args = parser.parse_args()
    if set(args.former) != set(args.adopted):
        parser.error("--former and --adopted must name the same parameters")

    from rippleb.engine.tuner import plan, tune
    from rippleb.registry import Registry

    registry = Registry.discover()
    tunable, _, note = plan([args.method], registry, budget=1)[args.method]
    points = mixes(args.former, args.adopted)
    found = tune({args.method: (tunable, points, note)}, args.seeds, jobs=args.jobs, registry=registry)
    scores = [np.asarray(p["scores"]) for p in found[args.method]["points"]]
    print(f"| {' | '.join(f'`{n}`' for n in args.former)} | mean [Nm] | minus the former point [Nm] | lower on |")
    print("|" + "---|" * (len(args.former) + 3))
    for point, score in zip(points, scores):
        diff = score - scores[0]
        values = " | ".join(f"{point[n]:g}" for n in args.former)
        print(f"| {values} | {score.mean():.4f} | {diff.mean():+.4f} | {(diff < 0).sum()}/{len(diff)} |")


if __name__ == "__main__":
    main()
