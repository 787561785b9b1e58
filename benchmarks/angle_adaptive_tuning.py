"""Choose the free parameters of ``angle-adaptive`` on the ``calibration`` scenario only.

A map fitted and scored on the same calibration log is already the best map for that log,
so scoring there alone would always choose "do not adapt". Each candidate is therefore
scored twice on the calibration log of a seed, against ``torque_ref`` (the only torque a
real calibration run knows; never ``torque_true``, never a scored scenario):

* ``own``: warm-started from the map fitted on that log (adaptation must not hurt);
* ``wrong``: warm-started from the map of *another* device (the calibration log of the
  next seed), which stands in for a map that no longer fits (re-assembly, ageing, an
  unknown angle origin). The gain and offset stay those of the device itself.

The objective is the mean of the two RMS errors over the seeds. The chosen values are the
defaults of :class:`rippleb.methods.angle_adaptive.AngleAdaptive`;
``docs/methods/angle-adaptive.md`` shows the table this prints.

Run: ``python benchmarks/angle_adaptive_tuning.py [--seeds 100,101,102]``
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from rippleb.methods.angle_adaptive import AngleAdaptive
from rippleb.metrics import Truth, score
from rippleb.simulator import simulate

MEMORY_REVS = (3.0, 10.0, 30.0, 100.0, 300.0)
PRIOR_SD_NM = (0.003, 0.01, 0.03, 0.1)
MIN_COUNTS = (1, 2, 5)


def calibration_score(params: dict, sim, other_map=None) -> float:
    """RMS error vs ``torque_ref`` of ``AngleAdaptive(**params)`` on the calibration ``sim``."""
    method = AngleAdaptive(**params)
    method.fit(sim.log.for_method(keep_ref=True))
    if other_map is not None:
        method.map_ = other_map.copy()
    method.reset(sim.log.spec)
    visible = sim.log.for_method(keep_ref=False)
    estimate = np.concatenate([method.step(b) for b in visible.blocks(int(visible.spec.fs))])
    return score(estimate, Truth.from_simulation(sim))["rms_error_ref_nm"]


def other_device_map(seed: int) -> np.ndarray:
    """The calibration map of the device of ``seed + 1`` (the wrong map)."""
    method = AngleAdaptive()
    method.fit(simulate("calibration", seed + 1).log.for_method(keep_ref=True))
    return method.map_


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100,101,102")
    seeds = [int(s) for s in parser.parse_args(argv).seeds.split(",")]
    sims = {s: simulate("calibration", s) for s in seeds}
    wrong = {s: other_device_map(s) for s in seeds}
    frozen = [(calibration_score({"adapt": False}, sims[s]),
               calibration_score({"adapt": False}, sims[s], wrong[s])) for s in seeds]
    print(f"frozen (no adaptation): own {np.mean([f[0] for f in frozen]):.3f}, "
          f"wrong {np.mean([f[1] for f in frozen]):.3f}")
    print("| memory_revs | prior_sd_nm | min_counts | own | wrong | mean |")
    print("|---|---|---|---|---|---|")
    rows = []
    for memory, prior, counts in itertools.product(MEMORY_REVS, PRIOR_SD_NM, MIN_COUNTS):
        params = {"memory_revs": memory, "prior_sd_nm": prior, "min_counts": counts}
        own = np.mean([calibration_score(params, sims[s]) for s in seeds])
        bad = np.mean([calibration_score(params, sims[s], wrong[s]) for s in seeds])
        rows.append(((own + bad) / 2, params))
        print(f"| {memory:g} | {prior:g} | {counts} | {own:.3f} | {bad:.3f} | {(own + bad) / 2:.3f} |",
              flush=True)
    best = min(rows, key=lambda r: r[0])
    print(f"\nlowest mean: {best[1]} ({best[0]:.3f} Nm)")


if __name__ == "__main__":
    main()
