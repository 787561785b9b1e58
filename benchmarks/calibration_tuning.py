"""Re-tune a method's free parameters on the ``calibration`` scenario only.

One procedure for every method, so each gets the same effort: for each point of the
method's grid, fit on the calibration log of each seed and score the estimate on that same
log against ``torque_ref`` (the only torque a real calibration run knows; never
``torque_true``, never a scored scenario), averaged over the seeds. Prints one row per grid
point and the point of lowest mean RMS. The grids are those the method pages list. Each
point runs as ``rippleb tune`` runs it: a sandboxed row (rippleb.engine.tuner.tuning_plan).

Run: ``python benchmarks/calibration_tuning.py METHOD [--seeds 100-104]``
"""

from __future__ import annotations

import argparse
import itertools

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

from rippleb.engine.runner import run_plan
from rippleb.engine.tuner import tuning_plan
from rippleb.registry import Registry
from rippleb.variants import label

#: method -> {parameter: candidates}; see each method's page in docs/methods/.
GRIDS = {
    "order-tracking": {"q": (5, 10, 20, 30, 50),
                       "stop_after_s": (0.0005, 0.001, 0.0015, 0.002, 0.003, 0.005)},
    "switched-notch": {"min_speed": (1.0, 2.0, 3.0), "q": (4.0, 8.0, 16.0),
                       "speed_window": (40, 80, 160)},
    "current-based": {"velocity_cutoff": (100.0, 200.0, 400.0), "accel_cutoff": (10.0, 25.0, 50.0),
                      "sign_width": (0.2, 0.5, 1.0)},
    "lowpass": {"cutoff_hz": (2, 5, 10, 20, 30, 50, 100, 200)},
    "spatial-filter": {"q": (2.0, 4.0, 8.0, 16.0, 32.0), "fade_speed": (0.5, 1.6, 4.0, 8.0, 16.0),
                       "speed_window": (2, 5, 10, 40)},
    "fourier-lms": {"mu": (0.005, 0.02, 0.05, 0.2, 0.5), "bias_hz": (3.0, 10.0, 30.0, 100.0)},
    "periodic-dob": {"bins": (250, 500, 1250), "memory_revs": (3.0, 10.0, 30.0, 100.0),
                     "nominal_hz": (2.0, 10.0, 30.0)},
}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("method", choices=sorted(GRIDS))
    parser.add_argument("--seeds", default="100-104")
    args = parser.parse_args(argv)
    lo, hi = (int(v) for v in args.seeds.split("-"))
    grid = GRIDS[args.method]
    names = list(grid)
    points = {label(args.method, dict(zip(names, values))): values for values in itertools.product(*grid.values())}
    frame = run_plan(Registry.discover(), tuning_plan(list(points), range(lo, hi + 1)), jobs=2)
    means = frame.groupby("method")[["rms_error_ref_nm", "max_error_ref_nm"]].mean()
    print("| " + " | ".join(names) + " | rms_error_ref_nm | max_error_ref_nm |")
    print("|---" * (len(names) + 2) + "|")
    rows = []
    for lab, values in points.items():
        mean = means.loc[lab]
        rows.append((mean["rms_error_ref_nm"], values))
        print("| " + " | ".join(f"{v:g}" for v in values)
              + f" | {mean['rms_error_ref_nm']:.3f} | {mean['max_error_ref_nm']:.3f} |", flush=True)
    best = min(rows)
    print(f"\nlowest mean rms_error_ref_nm {best[0]:.3f}: " + ", ".join(
        f"{n} = {v:g}" for n, v in zip(names, best[1])))


if __name__ == "__main__":
    main()
