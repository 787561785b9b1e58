"""``rippleb sweep`` and the executor options of ``run`` and ``sweep`` (``--executor``, ``--scheduler``).

Kept apart from :mod:`rippleb.cli`, which builds the parser and calls :func:`add_sweep`
and :func:`add_executor_options`; the helpers shared with ``run`` (provenance, limits)
are imported from it when a command runs.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

from rippleb.cli.options import check_sweep_options
from rippleb.engine.dask_connect import CONNECT_TIMEOUT_S
from rippleb.errors import InputError


def add_executor_options(p) -> None:
    p.add_argument("--executor", choices=("local", "dask"), default="local",
                   help="where rows run: 'local' forked processes (default), or 'dask': a local "
                        "dask cluster of --jobs worker processes (see docs/scale.md)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the rows on the dask.distributed cluster of this scheduler "
                        "(e.g. tcp://10.0.0.5:8786); implies --executor dask")
    p.add_argument("--connect-timeout", type=float, default=CONNECT_TIMEOUT_S, metavar="S",
                   help=f"seconds the --scheduler has to answer, and to come back if it is lost mid-run "
                        f"(default {CONNECT_TIMEOUT_S:g})")


def executor(args):
    """The executor the options ask for: None for the local pool."""
    if args.scheduler is None and args.executor == "local":
        return None
    if getattr(args, "log", None) is not None:
        raise InputError("--executor dask/--scheduler do not apply with --log (a recorded log runs "
                         "on the local pool)")
    from rippleb.engine.dask_executor import DaskExecutor

    timeout = args.connect_timeout
    if not (math.isfinite(timeout) and timeout > 0):
        raise InputError(f"--connect-timeout must be a positive number of seconds, got {timeout:g}")
    return DaskExecutor(scheduler=args.scheduler, workers=args.jobs, connect_timeout=timeout)


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
    p.add_argument("--methods", help="comma-separated method names, or 'all' (default: every built-in)")
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
    from rippleb.cli.program import recorded

    return recorded(args, _sweep)


def _sweep(args, start: float) -> int:
    from rippleb.engine import runner
    from rippleb.cli.program import _limit, _report_broken_plugins
    from rippleb.engine.sweep import run_sweep, specs_from_config

    check_sweep_options(args)
    options = dict(jobs=args.jobs, timeout=_limit("--timeout", args.timeout),
                   memory_mb=_limit("--memory-limit", args.memory_limit),
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
    return _report_broken_plugins(frame)
