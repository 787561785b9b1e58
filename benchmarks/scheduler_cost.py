"""What choosing the next job costs the runner over a whole run of the publication's shape
(docs/scale.md, "Choosing the next job").

    python benchmarks/scheduler_cost.py [--seeds 50]

Builds the plan of ``rippleb run --conditions all --seeds N`` (every built-in, every scored
scenario and condition) in the runner's case-major order and drives
:func:`rippleb.engine.scheduler._start_next` through it with a pool that runs nothing: each
simulation and fit ends as soon as it is started, and each row is recorded as soon as it
starts. Prints the CPU seconds spent choosing jobs, in total and per job: what the runner
pays on top of the jobs themselves. It also runs against a scheduler from before
2026-11-27 (which found the next job by a pass over every pending row), to compare.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)


class _Pool:
    """Takes each job and ends it at once (the caller finishes it)."""

    memory_mb = None
    server = None

    def __init__(self):
        self.last = None

    def submit(self, key, *args, **kwargs):
        self.last = key


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass


def plan_of_publication(seeds: int):
    from rippleb.engine.rows import CALIBRATION, FITTING, SCORED, Case, RowKey
    from rippleb.engine.scheduler import Plan
    from rippleb.registry import Registry
    from rippleb.simulator.conditions import CONDITIONS, calibration_condition
    from rippleb.simulator.scenario import scored_scenarios

    plan = Plan(calibration_label=CALIBRATION)
    methods = Registry.discover().names("builtin")
    for seed in range(seeds):
        for condition in CONDITIONS:
            cal = Case(CALIBRATION, "c", calibration_condition(condition), seed, FITTING)
            plan.add_sim(None, cal)
            for scenario in scored_scenarios():
                case = Case(scenario, "s", condition, seed, SCORED)
                plan.add_sim(None, case)
                for method in methods:
                    plan.add_row(RowKey(method, scenario, condition, seed), case, cal)
    return plan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=50)
    args = parser.parse_args()

    from rippleb.engine import scheduler
    from rippleb.engine.cache import Artefact
    from rippleb.engine.results import ResultsFile
    from rippleb.engine.rows import Case
    from rippleb.registry import Registry

    plan = plan_of_publication(args.seeds)
    rows = sorted(plan.rows, key=lambda k: (k.seed, k.scenario, k.extra, k.condition, k.method))
    with tempfile.TemporaryDirectory() as cache:
        state = scheduler.State(plan, Registry.discover(), ResultsFile(None), Path(cache), None, None, "bench", rows)
        scheduler.prepare_cases(state)
        # a row that starts is recorded at once, with no log to read and nothing to score
        scheduler._evaluation_log = lambda state, case: None
        scheduler._row_job = lambda *a: None
        scheduler._fit_job = lambda *a: None
        state.lengths = {c: (1, 1) for key in rows for c in plan.rows[key]}
        pool, jobs, spent = _Pool(), 0, 0.0
        while state.pending:
            t0 = time.process_time()
            started = scheduler._start_next(pool, state, _NoBar())
            spent += time.process_time() - t0
            if not started:
                raise SystemExit("the scheduler stopped with rows pending")
            jobs += 1
            key = pool.last
            if isinstance(key, tuple):         # a simulation: its logs exist
                for role in plan.sims[key][1]:
                    state.artefacts[Case(*key, role)] = Artefact("unused", "0" * 64)
                state.sims[key] = "done"
                if hasattr(scheduler, "release_rows"):   # a scheduler before it found rows by a pass
                    scheduler.release_rows(state, key)
            elif isinstance(key, scheduler.Fit):
                state.fits[key] = {"status": "ok"}
                if hasattr(scheduler, "release_fit"):
                    scheduler.release_fit(state, key)
            else:
                scheduler._record(state, key, _NoBar(), status="ok")
    print(f"{len(plan.rows)} rows, {jobs} jobs: {spent:.2f} CPU s choosing them, {spent / jobs * 1e6:.1f} us a job")


if __name__ == "__main__":
    main()
