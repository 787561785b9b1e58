"""Where the CPU time of a finished run went: simulations, fits, streaming, scoring, and
the rest, which is what running each row in its own isolated processes costs.

    python benchmarks/run_time_breakdown.py DIR [--cpu-s SECONDS]

The run's own CPU time (its runner and every process it started, user and system) is
``cpu_s`` in ``DIR/provenance.json``; ``--cpu-s`` gives it for a run recorded before
rippleb kept it (e.g. from ``/usr/bin/time``). This script times again, in its own
process and in CPU seconds (``time.process_time``: a loaded machine inflates them as it
inflated the run, and no process waiting for a core is counted), each thing the run did
once per seed, at the run's first seed, and multiplies it by the number of seeds:

* one simulation per scenario and condition, and the calibration per calibration condition;
* one fit per method and calibration condition;
* per method, scenario and condition: the log streamed through ``step`` (the harness's
  timed loop, :func:`rippleb.harness.stream`), and the runner's scoring of that estimate
  (:func:`rippleb.scoring.row.score_row`), once per row.

The rest of the run's CPU time is the rows' processes: starting and ending them (the
forks, the namespaces, the walls), handing them their inputs, unpickling the fitted
method, ``reset``, cutting the log into blocks, sending the estimate back, and the
runner's bookkeeping (scheduling, writing rows). Prints a Markdown table; docs/report.md
("Where the time of the run goes") quotes it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
import pandas as pd


def _cpu(fn):
    """``(result, CPU seconds)`` of ``fn()`` in this process."""
    t0 = time.process_time()
    result = fn()
    return result, time.process_time() - t0


def breakdown(run_dir: Path, cpu_s: float) -> tuple[pd.DataFrame, dict]:
    """The table of parts (CPU seconds and share of ``cpu_s``) and facts of the run."""
    from rippleb import harness
    from rippleb.engine.results import read_rows
    from rippleb.registry import Registry
    from rippleb.scoring.metrics import Truth
    from rippleb.scoring.row import score_row
    from rippleb.simulator import simulate
    from rippleb.simulator.conditions import calibration_condition
    from rippleb.variants import split_label

    rows = pd.DataFrame(read_rows(run_dir / "results.csv"))
    ok = rows[rows["status"] == "ok"]
    seeds = sorted(rows["seed"].astype(int).unique())
    first, n_seeds = int(seeds[0]), len(seeds)
    registry = Registry.discover()
    sims = fits = stream = scoring = 0.0
    calibrations = {}
    for condition in sorted({calibration_condition(c) for c in rows["condition"]}):
        calibrations[condition], spent = _cpu(lambda: simulate("calibration", first, condition))
        sims += spent * n_seeds
    fitted = {}
    for method, condition in sorted({(m, calibration_condition(c)) for m, c in zip(ok["method"], ok["condition"])}):
        name, params = split_label(method)
        cls = registry.get(name).load()
        (fitted[method, condition], _, _), spent = _cpu(
            lambda: harness.fitted(cls, params, calibrations[condition].log))
        fits += spent * n_seeds
    for (scenario, condition), group in ok.groupby(["scenario", "condition"]):
        sim, spent = _cpu(lambda: simulate(scenario, first, condition))
        sims += spent * n_seeds
        truth = Truth.from_simulation(sim)
        visible = sim.log.for_method(keep_ref=False)
        for method, rows_of in group.groupby("method"):
            instance = fitted[method, calibration_condition(condition)]
            instance.reset(visible.spec)
            blocks = harness.prepare_blocks(visible)
            (estimate, ticks), spent = _cpu(lambda: harness.stream(instance.step, blocks, len(visible)))
            stream += spent * len(rows_of)
            _, spent = _cpu(lambda: score_row({"estimate": estimate, "ticks": ticks}, truth, len(visible), len(ticks)))
            scoring += spent * len(rows_of)
    measured = sims + fits + stream + scoring
    parts = [
        ("simulations (one per scenario x condition x seed, and the calibration per calibration condition and seed)", sims),
        ("fits (one per method x calibration condition x seed)", fits),
        ("rows: streaming the log through step (the harness's timed loop)", stream),
        ("rows: the rest of each row's processes (start and end, isolation and walls, inputs, unpickling the "
         "fitted method, reset, blocks, sending the estimate) and the runner's bookkeeping", cpu_s - measured),
        ("runner: scoring every row", scoring),
    ]
    frame = pd.DataFrame(parts, columns=["part", "cpu_s"])
    frame["per_row_ms"] = 1e3 * frame["cpu_s"] / len(rows)
    frame["share"] = frame["cpu_s"] / cpu_s
    return frame, {"rows": len(rows), "seeds": n_seeds}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--cpu-s", type=float, help="the run's CPU seconds, if provenance.json lacks cpu_s")
    args = parser.parse_args(argv)
    path = args.run_dir / "provenance.json"
    prov = json.loads(path.read_text()) if path.is_file() else {}
    cpu_s = args.cpu_s if args.cpu_s is not None else prov.get("cpu_s")
    if cpu_s is None:
        parser.error(f"{path} records no cpu_s: give --cpu-s")
    frame, facts = breakdown(args.run_dir, float(cpu_s))
    cores = prov.get("cpu_count") or 2
    print(f"{args.run_dir}: {facts['rows']} rows, {facts['seeds']} seeds; run wall {prov.get('wall_s', float('nan')):.0f} s "
          f"with --jobs {prov.get('jobs', '?')}, {cpu_s:.0f} CPU s ({1e3 * cpu_s / facts['rows']:.1f} ms a row; "
          f"{cpu_s / cores:.0f} s of wall time on {cores} busy cores); load average "
          f"{prov.get('load_average', 'not recorded')}\n")
    print(frame.to_markdown(index=False, floatfmt=".3g"))
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main(sys.argv[1:]))
