"""Choose the notch width ``q`` and the stop threshold ``stop_after_s`` of ``order-tracking``.

On the ``calibration`` scenario only (never on a scored scenario): for each candidate, fit on
the calibration log of a seed and score the estimate on that same log against
``torque_ref`` (the only torque a real calibration run knows), averaged over the seeds.
The chosen values are the defaults of :class:`rippleb.methods.order_tracking.OrderTracking`;
``docs/methods/order-tracking.md`` shows the table this prints.

Run: ``python benchmarks/order_tracking_tuning.py [--seeds 100,101,102,103,104]``
"""

from __future__ import annotations

import argparse
import itertools

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

from rippleb.methods.order_tracking import OrderTracking
from rippleb.scoring.metrics import Truth, score
from rippleb.simulator import simulate

QS = (3, 5, 10, 15, 20, 30, 50)
STOPS_S = (0.0001, 0.0002, 0.0005, 0.001, 0.002, 0.005, 0.02)


def calibration_score(params: dict, seed: int) -> dict:
    """Fit and score ``OrderTracking(**params)`` on the calibration log of ``seed``."""
    sim = simulate("calibration", seed)
    method = OrderTracking(**params)
    method.fit(sim.log.for_method(keep_ref=True))
    method.reset(sim.log.spec)
    visible = sim.log.for_method(keep_ref=False)
    estimate = np.concatenate([method.step(b) for b in visible.blocks()])
    return score(estimate, Truth.from_simulation(sim))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100,101,102,103,104")
    seeds = [int(s) for s in parser.parse_args(argv).seeds.split(",")]
    print("| q | stop_after_s [ms] | rms_error_ref_nm | max_error_ref_nm |")
    print("|---|---|---|---|")
    rows = []
    for q, stop in itertools.product(QS, STOPS_S):
        scores = [calibration_score({"q": q, "stop_after_s": stop}, s) for s in seeds]
        mean = {k: float(np.mean([r[k] for r in scores])) for k in scores[0]}
        rows.append((mean["rms_error_ref_nm"], q, stop))
        print(f"| {q} | {stop * 1e3:g} | {mean['rms_error_ref_nm']:.3f} | {mean['max_error_ref_nm']:.3f} |",
              flush=True)
    best = min(rows)
    print(f"\nlowest mean rms_error_ref_nm: q = {best[1]}, stop_after_s = {best[2]} ({best[0]:.3f} Nm)")


if __name__ == "__main__":
    main()
