"""What a row's processes cost beyond its method's work, measured through the runner's own
scheduler, pool and fork server (docs/report.md, "Where the time of the run goes").

    python benchmarks/row_process_cost.py [--methods a,b] [--scenario NAME] [--cases K1,K2] [--jobs N]

Runs the rows of ``--methods`` on ``K`` scored cases (the same simulated log, given to the
scheduler as ready cases, as a recorded log is) twice, with ``K1`` and then ``K2`` cases,
and takes the difference of the CPU time of the two runs (this process, the fork server
and every job process, user and system): what the fork server's start, the fits and the
imports cost cancels, and what is left is ``(K2 - K1) x methods`` rows, each with the share
of its case (storing and handing out its log) that a run of 14 methods per case pays.
Subtracting what the method does itself, timed in this process (its streaming through
:func:`rippleb.harness.stream` and the runner's scoring, CPU seconds), leaves the per-row
process cost: forks, namespaces, walls, inputs, unpickling, ``reset``, blocks, the
estimate's way back and the runner's bookkeeping. CPU seconds, so that a shared machine
inflates every part alike; the wall time per row is printed beside them.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np


def _cpu_seconds() -> float:
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                  resource.getrusage(resource.RUSAGE_CHILDREN)))


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass


def run_cases(registry, methods: list[str], log, truth, calibration, n_cases: int, jobs: int) -> tuple[float, float, list]:
    """``(CPU s, wall s, rows)`` of scheduling ``methods`` on ``n_cases`` ready cases, fork
    server included (started and closed inside)."""
    from rippleb.engine.process import isolation
    from rippleb.engine.process.forkserver import ForkServer
    from rippleb.engine.process.pool import Pool
    from rippleb.engine.results import ResultsFile
    from rippleb.engine.rows import CALIBRATION, FITTING, SCORED, Case, RowKey
    from rippleb.engine.plan import Plan, State, prepare_cases
    from rippleb.engine.scheduler import schedule
    from rippleb.simulator.conditions import DEFAULT_CONDITION

    plan = Plan(calibration_label=CALIBRATION)
    cal_case = Case(CALIBRATION, "bench-calibration", DEFAULT_CONDITION, 0, FITTING)
    plan.ready[cal_case] = (calibration, None)
    for seed in range(n_cases):
        case = Case("bench", "bench", DEFAULT_CONDITION, seed, SCORED)
        plan.ready[case] = (log, truth)
        for method in methods:
            plan.add_row(RowKey(method, "bench", DEFAULT_CONDITION, seed), case, cal_case)
    cpu0, wall0 = _cpu_seconds(), time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rippleb-cache-") as cache, \
            tempfile.TemporaryDirectory(prefix="rippleb-scratch-") as scratch, isolation.undumpable():
        with ForkServer.start(registry, preload=lambda: registry.load_builtins(methods)) as server:
            results = ResultsFile(None)
            state = State(plan, registry, results, Path(cache), None, 300.0, "bench", list(plan.rows),
                          scratch=Path(scratch))
            prepare_cases(state)
            schedule(Pool(jobs, 4096.0, server=server), state, _NoBar())
    return _cpu_seconds() - cpu0, time.perf_counter() - wall0, results.rows


def method_cpu(registry, method: str, log, truth, calibration, repeats: int = 3) -> float:
    """CPU seconds of one row's own work in this process: streaming and scoring (the best of ``repeats``)."""
    from rippleb import harness
    from rippleb.scoring.row import score_row
    from rippleb.variants import split_label

    name, params = split_label(method)
    instance, _, _ = harness.fitted(registry.get(name).load(), params, calibration)
    visible = log.for_method(keep_ref=False)
    best = float("inf")
    for _ in range(repeats):
        instance.reset(visible.spec)
        blocks = harness.prepare_blocks(visible)
        t0 = time.process_time()
        estimate, ticks = harness.stream(instance.step, blocks, len(visible))
        score_row({"estimate": estimate, "ticks": ticks}, truth, len(visible), len(ticks))
        best = min(best, time.process_time() - t0)
    return best


def main(argv: list[str]) -> int:
    from rippleb.registry import Registry
    from rippleb.scoring.metrics import Truth
    from rippleb.simulator import simulate

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", default="raw", help="comma-separated; 'builtins' for every built-in")
    parser.add_argument("--scenario", default="paper-quintic")
    parser.add_argument("--cases", default="2,12", help="K1,K2: the two numbers of cases")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    registry = Registry.discover()
    methods = (sorted(n for n, e in registry.entries.items() if e.origin == "builtin")
               if args.methods == "builtins" else args.methods.split(","))
    k1, k2 = (int(k) for k in args.cases.split(","))
    sim, calibration = simulate(args.scenario, 0), simulate("calibration", 0).log
    truth = Truth.from_simulation(sim)
    own = float(np.mean([method_cpu(registry, m, sim.log, truth, calibration) for m in methods]))
    (cpu1, wall1, rows1), (cpu2, wall2, rows2) = (run_cases(registry, methods, sim.log, truth, calibration, k, args.jobs)
                                                  for k in (k1, k2))
    bad = [r for r in rows1 + rows2 if r["status"] != "ok"]
    if bad:
        print(f"rows not ok: {[(r['method'], r['status'], r['message']) for r in bad[:3]]}", file=sys.stderr)
        return 1
    n = (k2 - k1) * len(methods)
    per_row = (cpu2 - cpu1) / n
    print(f"{', '.join(methods)} on {args.scenario} ({len(sim.log)} samples), --jobs {args.jobs}, {n} rows "
          f"({k1} and {k2} cases): {1e3 * per_row:.1f} CPU ms a row, of which the method's streaming and its "
          f"scoring {1e3 * own:.1f} ms in this process; the row's processes {1e3 * (per_row - own):.1f} ms; "
          f"wall {1e3 * (wall2 - wall1) / n:.1f} ms a row")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
