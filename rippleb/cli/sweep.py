"""``rippleb sweep``: the benchmark over a grid of scenario parameters (docs/sweeps.md).

A sweep is a run with more rows: it is recorded like ``run`` (:func:`rippleb.cli.run.recorded`)
and takes the same executor options (:mod:`rippleb.cli.options`).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from rippleb.cli.options import add_executor_options, check_sweep_options, executor, limit
from rippleb.cli.run import recorded, report_broken_plugins


def add_sweep(sub) -> None:
    from rippleb.engine.runner import DEFAULT_MEMORY_MB, DEFAULT_SEEDS, DEFAULT_TIMEOUT_S
    from rippleb.engine.sweep import PARAMS

    listing = "\n".join(f"  {p.name:<22} {p.kind(p.low)} .. {p.kind(p.high)}  {p.doc}" for p in PARAMS.values())
    p = sub.add_parser(
        "sweep", help="run the benchmark over a grid of scenario parameters (sensitivity sweep)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run every method on every scenario, condition and seed at each point of the grid "
                    "of the --param values, one row per grid point x method x scenario x condition x "
                    "seed in DIR/results.csv, with one column per swept parameter. A swept value is set "
                    "in every scenario as if written in its file; the joint's hardware (joint.*) also "
                    "in the calibration session. See docs/sweeps.md.\n\nsweepable parameters (valid "
                    f"range, inclusive):\n{listing}")
    p.add_argument("--param", action="append", metavar="NAME=v1,v2,...",
                   help="a parameter and its values; repeat for a grid (required unless --resume)")
    p.add_argument("--methods", help="comma-separated method names, or 'all' (default: every built-in); "
                                     "'NAME[p=1,2]' for variants (docs/plugins.md)")
    p.add_argument("--scenarios", help="comma-separated scenario names or .toml paths "
                                       "(default: every scored built-in scenario)")
    p.add_argument("--conditions", metavar="A,B|all", help="deployment conditions (default: same-session)")
    p.add_argument("--seeds", type=int, help=f"number of seeds (default {DEFAULT_SEEDS})")
    p.add_argument("--seed-start", type=int, help="first seed (default 0)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help=f"rows run at once (default: the number of CPUs, {os.cpu_count()} here); with "
                        f"--executor dask, the local cluster's worker processes")
    p.add_argument("--out", type=Path, help="output directory, new or empty (default runs/<timestamp>/)")
    p.add_argument("--resume", type=Path, metavar="DIR",
                   help="finish an interrupted sweep with the grid and selection in DIR/run.json")
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT_S,
                   help=f"seconds one row may take before it is killed (default {DEFAULT_TIMEOUT_S:g}; 0: none)")
    p.add_argument("--memory-limit", type=float, default=DEFAULT_MEMORY_MB, metavar="MB",
                   help=f"memory one row may allocate, in MB (default {DEFAULT_MEMORY_MB:g}; 0: none)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_executor_options(p)
    p.set_defaults(func=cmd_sweep, command="sweep")


def cmd_sweep(args) -> int:
    """``rippleb sweep``."""
    return recorded(args, _sweep)


def _sweep(args, start: float) -> int:
    from rippleb.engine import runner
    from rippleb.engine.sweep import run_sweep, specs_from_config

    check_sweep_options(args)
    options = dict(jobs=args.jobs, timeout=limit("--timeout", args.timeout),
                   memory_mb=limit("--memory-limit", args.memory_limit),
                   progress=False if args.no_progress else None, executor=executor(args),
                   on_start=lambda: setattr(args, "started", True))
    if args.resume is not None:
        config = runner.read_config(args.resume)
        args.out_dir = args.resume
        seeds = config["seeds"] if args.seeds is None and args.seed_start is None \
            else (runner.DEFAULT_SEEDS if args.seeds is None else args.seeds)
        frame = run_sweep(args.param or specs_from_config(config), args.methods or config["methods"],
                          args.scenarios or config["scenarios"], seeds,
                          conditions=args.conditions or config.get("conditions"),
                          seed_start=args.seed_start or 0, out=args.resume, resume=True, **options)
    else:
        args.out_dir = args.out or runner.default_out_dir()
        frame = run_sweep(args.param or [], args.methods, args.scenarios, args.seeds,
                          conditions=args.conditions, seed_start=args.seed_start or 0, out=args.out_dir,
                          **options)
    counts = frame["status"].value_counts().to_dict() if len(frame) else {}
    print(f"{len(frame)} rows ({', '.join(f'{v} {k}' for k, v in counts.items()) or 'none'}) "
          f"in {args.out_dir / 'results.csv'}; total wall time {time.perf_counter() - start:.1f} s; "
          f"figures: rippleb report {args.out_dir}")
    return report_broken_plugins(frame)
