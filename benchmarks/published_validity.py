"""Would any row of the published comparison change status under the physical-validity checks?

Issue 25 item 4 made physical validity a status: a scenario out of physical bounds is
refused before it runs (:func:`rippleb.simulator.validity.check_bounds`), and a simulated
log whose true torque leaves the drive's repeated peak torque or whose strain clips is
``invalid`` (:func:`rippleb.simulator.validity.check_simulation`). The published rows are
built-in scenarios within range by design; this script checks it, case by case, for every
case ``results/`` was made from (docs/report.md): every scored built-in x the four
conditions x seeds 0-19, each seed's calibration log, and the two published sweeps
(``joint.counts_per_rev`` = 500, 1000, 2500, 10000 and ``ripple.drift`` = 0, 0.5, 1, 2, 3
under ``aged``, on ``paper-quintic`` and ``stop-restart``, seeds 0-9). It prints every case
that fails and the largest true torque and strain met, and exits 1 if any case fails.

    python benchmarks/published_validity.py [--seeds N] [--sweep-seeds N]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def cases(seeds: int, sweep_seeds: int):
    """``(label, scenario, seed, condition)`` of every published case."""
    from rippleb.simulator.scenario import load_scenario, scored_scenarios
    from rippleb.simulator.conditions import CONDITIONS
    from rippleb.engine.sweep import swept_scenario

    for seed in range(seeds):
        yield "calibration", load_scenario("calibration"), seed, "same-session"
        for name in scored_scenarios():
            for condition in CONDITIONS:
                yield name, load_scenario(name), seed, condition
    sweeps = [({"joint.counts_per_rev": v}, "same-session") for v in (500, 1000, 2500, 10000)]
    sweeps += [({"ripple.drift": v}, "aged") for v in (0.0, 0.5, 1.0, 2.0, 3.0)]
    for point, condition in sweeps:
        device = {k: v for k, v in point.items() if k.startswith("joint.")}
        for seed in range(sweep_seeds):
            yield f"calibration {device}", swept_scenario("calibration", device), seed, "same-session"
            for name in ("paper-quintic", "stop-restart"):
                yield f"{name} {point}", swept_scenario(name, point), seed, condition


def main(argv=None) -> int:
    from rippleb.engine.checks import check_scenario
    from rippleb.errors import InputError
    from rippleb.simulator import simulate
    from rippleb.simulator.validity import check_simulation, peak_torque

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds of the comparison (published: 20)")
    parser.add_argument("--sweep-seeds", type=int, default=10, help="seeds of each sweep (published: 10)")
    args = parser.parse_args(argv)
    failed, checked, worst_tau, worst_strain = [], 0, 0.0, 0.0
    refused = {}
    for label, scenario, seed, condition in cases(args.seeds, args.sweep_seeds):
        if label not in refused:
            try:
                check_scenario(scenario)
                refused[label] = None
            except InputError as exc:
                refused[label] = str(exc)
                failed.append(f"{label}: refused: {exc}")
        if refused[label]:
            continue
        sim = simulate(scenario, seed, condition=condition)
        checked += 1
        worst_tau = max(worst_tau, float(np.abs(sim.log.torque_true).max()))
        worst_strain = max(worst_strain, float(np.abs(sim.log.strain).max()))
        reason = check_simulation(sim)
        if reason:
            failed.append(f"{label} seed {seed} {condition}: invalid: {reason}")
    print(f"{checked} simulated cases checked; largest |torque_true| {worst_tau:.2f} Nm "
          f"(bound {peak_torque(scenario.spec):.1f} Nm), largest |strain| {worst_strain:.3f} V (rails +-10 V)")
    for line in failed:
        print(line)
    print("no published case changes status" if not failed else f"{len(failed)} case(s) would change status")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
