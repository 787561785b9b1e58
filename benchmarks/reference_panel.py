"""The panel of joints that says how far a recorded log's ranking agrees with the truth.

For every joint of the panel (gear ratios 50, 100, 160 x encoders of 2500, 4096, 16384
counts per revolution), every deployment condition and every device (seed), the scenario
and its calibration are simulated on that joint (``rippleb simulate --param`` builds the
same scenarios), and each is written as a lab with each kind of reference records it
(``rippleb.simulator.transducer.lab_log``, what ``rippleb simulate --format lab`` writes):
a torque flange's reading of the true torque, or eq. (7)'s model torque. Every built-in
method is fitted on the calibration log of that kind and streamed over the scored log
(``rippleb.harness.run_method``), and scored as ``rippleb run --log`` scores a recording
(``Truth.from_recording``, ``score_or_invalid``: the whole log, the reference of that kind)
with ``torque_true`` kept for the true error. Per device and kind, each score's ranking of
the ok methods is compared with their ranking by ``rms_error_nm`` (Spearman's rho,
``scipy.stats``; ``strain_delay_ms`` by its absolute value); the summary per joint,
condition, kind and score (mean, lowest, devices) goes to ``rippleb/agreement.json``, which
the report reads, and to docs/metrics.md's tables.

    python benchmarks/reference_panel.py --seeds 10 --seed-start 3000 --jobs 2 --out runs/panel
    python benchmarks/reference_panel.py --out runs/panel --write      # summary, json and docs

The first command appends a row per method, kind and device to ``DIR/panel.csv`` as each
device finishes and skips the devices already there, so an interrupted panel goes on where
it stopped. ``--ratios``, ``--counts``, ``--conditions`` and ``--methods`` make a smaller
panel (the tests run one).
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import argparse
import concurrent.futures
import csv
import json
import multiprocessing
import time
from pathlib import Path

import numpy as np

RATIOS = (50, 100, 160)
COUNTS = (2500, 4096, 16384)
KINDS = ("transducer", "model")
SCENARIO = "paper-quintic"
#: What each row keeps: the true error and every score a recorded log can be ranked by.
SCORED = ("rms_error_nm", "rms_error_ref_nm", "rms_error_rebuilt_nm", "ripple_wg_nm", "rest_std_nm",
          "strain_delay_ms")
FIELDS = ("gear_ratio", "counts_per_rev", "condition", "seed", "reference_kind", "method", "status") + SCORED
#: Fewer ranked methods than this make a rank correlation meaningless.
MIN_METHODS = 3
#: The record's place, and the docs page whose tables it writes.
RECORD = Path(__file__).resolve().parents[1] / "rippleb" / "agreement.json"
DOCS = Path(__file__).resolve().parents[1] / "docs" / "metrics.md"


def device_rows(ratio, counts, condition, seed, methods, scenario=SCENARIO) -> list[dict]:
    """The rows of one device of one joint under one condition: a row per kind and method."""
    from rippleb.scoring.row import score_or_invalid
    from rippleb.engine.sweep import swept_scenario
    from rippleb.scoring.metrics import Truth
    from rippleb.registry import Registry
    from rippleb.simulator import simulate
    from rippleb.simulator.transducer import lab_log
    from rippleb.harness import run_method

    point = {"joint.gear_ratio": float(ratio), "joint.counts_per_rev": int(counts)}
    sim = simulate(swept_scenario(scenario, point), seed, condition)
    cal = simulate(swept_scenario("calibration", point), seed, condition)
    registry = Registry.discover()
    rows = []
    for kind in KINDS:
        log, calibration = lab_log(sim, kind), lab_log(cal, kind)
        truth = Truth.from_recording(log)
        for name in methods:
            row = {"gear_ratio": ratio, "counts_per_rev": counts, "condition": condition, "seed": seed,
                   "reference_kind": kind, "method": name}
            try:
                estimate, _ = run_method(registry.get(name).load()(), calibration, log)
                scores = score_or_invalid(estimate, truth)
            except Exception as exc:  # noqa: BLE001 - a method's failure is its row's status
                scores = {"status": "error", "message": f"{type(exc).__name__}: {exc}"}
            rows.append(row | {"status": scores.get("status", "ok")} | {c: scores.get(c, np.nan) for c in SCORED})
    return rows


def agreement(rows, score: str) -> float:
    """Spearman's rho between ``score`` and ``rms_error_nm`` over the ok rows of one device
    and kind; NaN with fewer than :data:`MIN_METHODS` values or a constant one."""
    from scipy import stats

    ok = [r for r in rows if r["status"] == "ok"]
    x = np.array([abs(r[score]) if score == "strain_delay_ms" else r[score] for r in ok], float)
    y = np.array([r["rms_error_nm"] for r in ok], float)
    keep = np.isfinite(x) & np.isfinite(y)
    if keep.sum() < MIN_METHODS or np.ptp(x[keep]) == 0 or np.ptp(y[keep]) == 0:
        return float("nan")
    return float(stats.spearmanr(x[keep], y[keep]).statistic)


def summary(rows: list[dict], protocol: dict) -> dict:
    """The record: per joint, condition, kind and score, the mean and lowest rho and the devices."""
    from rippleb.report.agreement import SCORES

    groups: dict = {}
    for r in rows:
        groups.setdefault((r["gear_ratio"], r["counts_per_rev"], r["condition"], r["reference_kind"], r["seed"]),
                          []).append(r)
    cells: dict = {}
    for (ratio, counts, condition, kind, _seed), device in groups.items():
        for score in SCORES[kind]:
            rho = agreement(device, score)
            cells.setdefault((ratio, counts, condition, kind, score), [])
            if np.isfinite(rho):
                cells[(ratio, counts, condition, kind, score)].append(rho)
    out = [{"gear_ratio": ratio, "counts_per_rev": counts, "condition": condition, "reference_kind": kind,
            "score": score, "devices": len(rhos), "mean_rho": round(float(np.mean(rhos)), 4) if rhos else None,
            "min_rho": round(float(np.min(rhos)), 4) if rhos else None}
           for (ratio, counts, condition, kind, score), rhos in sorted(cells.items())]
    return {"protocol": protocol, "cells": out}


def _read(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r["gear_ratio"], r["counts_per_rev"], r["seed"] = float(r["gear_ratio"]), int(r["counts_per_rev"]), int(r["seed"])
        for c in SCORED:
            r[c] = float(r[c]) if r[c] not in ("", "nan") else float("nan")
    return rows


def _run(args, path: Path) -> None:
    from rippleb.registry import Registry

    methods = args.methods.split(",") if args.methods else Registry.discover().names("builtin")
    done = {(r["gear_ratio"], r["counts_per_rev"], r["condition"], r["seed"]) for r in _read(path)}
    # seed by seed: a panel cut short has as many devices in every cell
    tasks = [(float(ratio), int(counts), condition, seed) for seed in range(args.seed_start, args.seed_start + args.seeds)
             for ratio in args.ratios for counts in args.counts for condition in args.conditions
             if (float(ratio), int(counts), condition, seed) not in done]
    print(f"{len(tasks)} devices to run ({len(done)} done), {len(methods)} methods, {args.jobs} job(s)", flush=True)
    new = not path.is_file()
    start = time.perf_counter()
    with path.open("a", newline="") as f, concurrent.futures.ProcessPoolExecutor(
            max_workers=args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        writer = csv.DictWriter(f, FIELDS)
        if new:
            writer.writeheader()
        futures = [pool.submit(device_rows, *task, methods, args.scenario) for task in tasks]
        for i, future in enumerate(concurrent.futures.as_completed(futures), start=1):
            writer.writerows(future.result())
            f.flush()
            print(f"{i}/{len(tasks)} devices, {time.perf_counter() - start:.0f} s", flush=True)
    wall = path.with_name("wall_s")   # summed over the resumed parts of one panel
    before = float(wall.read_text()) if wall.is_file() else 0.0
    wall.write_text(f"{before + time.perf_counter() - start:.0f}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="devices per joint and condition (default 10)")
    parser.add_argument("--seed-start", type=int, default=3000, help="first seed (default 3000: fresh devices)")
    parser.add_argument("--jobs", type=int, default=1, help="devices at once (default 1)")
    parser.add_argument("--out", type=Path, required=True, help="directory of panel.csv")
    parser.add_argument("--ratios", type=float, nargs="+", default=RATIOS)
    parser.add_argument("--counts", type=int, nargs="+", default=COUNTS)
    parser.add_argument("--conditions", nargs="+", default=None, help="default: every condition")
    parser.add_argument("--methods", help="comma-separated (default: every built-in)")
    parser.add_argument("--scenario", default=SCENARIO)
    parser.add_argument("--write", action="store_true",
                        help="summarise DIR/panel.csv into rippleb/agreement.json and docs/metrics.md")
    args = parser.parse_args()
    from rippleb.simulator.conditions import CONDITIONS

    args.conditions = args.conditions or list(CONDITIONS)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "panel.csv"
    if not args.write:
        _run(args, path)
        return
    wall = args.out / "wall_s"
    write(_read(path), args, float(wall.read_text()) if wall.is_file() else None)


def write(rows: list[dict], args, wall_s: float | None, record_path: Path = RECORD, docs: Path = DOCS) -> dict:
    """Summarise ``rows`` into the record and the docs page's block."""
    from rippleb.report.agreement import DOCS_BEGIN, DOCS_END, docs_block

    seeds = sorted({r["seed"] for r in rows})
    joints = sorted({(float(r["gear_ratio"]), int(r["counts_per_rev"])) for r in rows})
    # the joints the rows hold, named in the command when they are not the whole panel
    subset = "" if joints == [(float(a), b) for a in RATIOS for b in COUNTS] else (
        f"--ratios {' '.join(sorted({f'{a:g}' for a, _ in joints}))} "
        f"--counts {' '.join(sorted({str(b) for _, b in joints}))} ")
    protocol = {"command": f"python benchmarks/reference_panel.py --seeds {len(seeds)} --seed-start {seeds[0]} "
                           f"{subset}--out {args.out}",
                "scenario": args.scenario, "seeds": f"{seeds[0]}-{seeds[-1]}", "rows": len(rows),
                "methods": len({r["method"] for r in rows}), "min_methods": MIN_METHODS,
                "wall": "wall time not recorded" if wall_s is None else
                        f"{wall_s / 3600:.1f} h of wall time on a shared 2-core machine"}
    record = summary(rows, protocol)
    record_path.write_text(json.dumps(record, indent=1) + "\n")
    text = docs.read_text()
    head, rest = text.split(DOCS_BEGIN, 1)
    docs.write_text(head + docs_block(record) + rest.split(DOCS_END, 1)[1])
    print(f"wrote {record_path} and the tables of {docs}")
    return record


if __name__ == "__main__":
    main()
