"""Where the time of a finished run went: simulation, fit, stream, row process, scoring.

    python benchmarks/run_time_breakdown.py runs/published

Reads the run's ``results.csv`` and ``provenance.json`` (wall time, jobs) and times, in
this process, what the rows do not record: one simulation of every scenario of the run
(seed 0, each condition once) and the runner's scoring of one row per scenario. Prints a
Markdown table of CPU seconds per part; docs/report.md quotes it.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
import pandas as pd


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def breakdown(run_dir: Path) -> pd.DataFrame:
    from rippleb.scoring.metrics import Truth, score
    from rippleb.engine.results import read_rows
    from rippleb.simulator import simulate

    rows = pd.DataFrame(read_rows(run_dir / "results.csv"))
    for name in ("wall_s", "fit_s", "n_samples", "samples_per_s"):
        rows[name] = pd.to_numeric(rows[name], errors="coerce")
    ok = rows[rows["status"] == "ok"]
    stream = (ok["n_samples"] / ok["samples_per_s"]).sum()
    fits = ok.drop_duplicates(["method", "seed"])["fit_s"].sum()
    seeds = rows["seed"].nunique()
    sims, scoring = 0.0, 0.0
    for (scenario, condition), group in rows.groupby(["scenario", "condition"]):
        sim_s = _timed(lambda: simulate(scenario, 0, condition))
        sim = simulate(scenario, 0, condition)
        truth = Truth.from_simulation(sim)
        estimate = sim.log.torque_true + 0.05
        score(estimate, truth)   # warm: imports and caches are not the row's cost
        scoring += _timed(lambda: score(estimate, truth)) * len(group)
        sims += sim_s * seeds
    sims += _timed(lambda: simulate("calibration", 0)) * seeds
    row_wall = ok["wall_s"].sum()
    parts = [
        ("simulations (one per scenario x condition x seed, and the calibration per seed)", sims),
        ("fits (one per method x seed; fit_s)", fits),
        ("rows: streaming the log through step (n_samples / samples_per_s)", stream),
        ("rows: the rest of each row's processes (start, isolation, loading and verifying "
         "its inputs, reset, sending the estimate)", row_wall - stream),
        ("runner: scoring every row (measured here per scenario)", scoring),
    ]
    frame = pd.DataFrame(parts, columns=["part", "cpu_s"])
    frame["share"] = frame["cpu_s"] / frame["cpu_s"].sum()
    return frame


def main(argv: list[str]) -> int:
    run_dir = Path(argv[0] if argv else "runs/published")
    frame = breakdown(run_dir)
    prov = json.loads((run_dir / "provenance.json").read_text()) if (run_dir / "provenance.json").is_file() else {}
    print(f"{run_dir}: {len(pd.read_csv(run_dir / 'results.csv'))} rows, wall {prov.get('wall_s', float('nan')):.0f} s, "
          f"jobs {prov.get('jobs', '?')}\n")
    print(frame.to_markdown(index=False, floatfmt=".3g"))
    print(f"\ntotal {frame['cpu_s'].sum():.0f} CPU s")
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main(sys.argv[1:]))
