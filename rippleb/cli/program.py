"""The ``rippleb`` command: ``list``, ``run``, ``sweep``, ``simulate``, ``report``.

Built on argparse (standard library, no extra dependency; subcommands and ``--help``
are all this CLI needs). Every :class:`~rippleb.errors.RipplebError` becomes one line
``rippleb: error: ...`` on stderr and exit status 2, with no traceback unless
``--debug``. An interrupted run (Ctrl-C, SIGTERM) exits 130 after saying where its
finished rows are.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import sys
import time
import warnings
from pathlib import Path

from rippleb.cli.options import add_seal_options, check_run_options
from rippleb.cli.list import add_list
from rippleb.cli.sweep import add_executor_options, add_sweep, executor
from rippleb.errors import InputError, RipplebError

EPILOG = "Run 'rippleb COMMAND --help' for the options of one command."


def entry() -> None:
    """The ``rippleb`` program (its console script and ``python -m rippleb``): :func:`main`,
    with SIGINT and SIGTERM handled from its first line until the process exits."""
    from rippleb import interrupts

    status = 130
    try:
        interrupts.install()
        status = main()
    except KeyboardInterrupt:  # only in the few instructions around main's own handling
        print("rippleb: interrupted", file=sys.stderr)
    finally:
        # The command is over and its status decided: a late signal changes nothing (while
        # Python shuts down it would kill the process or print a traceback), and neither do
        # the libraries' logs as they shut down (Dask's, closing a cluster at exit).
        interrupts.ignore_from_now()
        logging.disable(logging.CRITICAL)
    sys.exit(status)


def main(argv: list[str] | None = None) -> int:
    """Run one ``rippleb`` command line; returns the exit status.

    SIGINT and SIGTERM at any moment (the imports of start-up included) end the command
    with one line on stderr and status 130; an interrupted run says where its finished
    rows are and how to finish it (docs/design.md, "Interrupts").
    """
    from rippleb import interrupts

    args = None
    with interrupts.handling():
        try:
            interrupts.check_interrupted()  # one that came while the program started
            args = build_parser().parse_args(argv)
            # The exact command line, recorded by `run` in DIR/provenance.json and by `report`.
            args.argv = list(sys.argv[1:] if argv is None else argv)
            with _warnings_as_lines():
                return args.func(args) or 0
        except RipplebError as exc:
            if args is not None and args.debug:
                raise
            kept = _interrupted(args) if getattr(exc, "resumable", False) else ""  # a lost scheduler
            print(f"rippleb: error: {exc}{kept}", file=sys.stderr)
            return 2
        except BrokenPipeError:
            # the reader went away (`rippleb list | head`): stop quietly, like any Unix filter
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141
        except KeyboardInterrupt:
            print(f"rippleb: interrupted{_interrupted(args)}", file=sys.stderr)
            return 130


def _interrupted(args) -> str:
    """What an interrupted command left behind: for a run that had claimed its directory,
    its finished rows and how to finish it."""
    if args is None or not getattr(args, "started", False):
        return ""
    return _what_was_kept(getattr(args, "out_dir", None), getattr(args, "command", "run"))


def _what_was_kept(out_dir: Path | None, command: str = "run") -> str:
    """Name what an interrupted run left on disk, and how to finish it."""
    if out_dir is None or not (out_dir / "run.json").is_file():
        return ""
    results = out_dir / "results.csv"
    try:
        done = max(0, len(results.read_text().splitlines()) - 1) if results.is_file() else 0
    except OSError:
        done = 0
    kept = (f"{done} finished row(s) are in {results}" if done
            else f"no row had finished; the selection is in {out_dir / 'run.json'}")
    try:  # a sealed run is resumed with its salt
        salt = " --salt-file FILE" if '"sealed"' in (out_dir / "run.json").read_text(errors="replace") else ""
    except OSError:
        salt = ""
    return f"; {kept}; finish the run with: rippleb {command} --resume {out_dir}{salt}"


@contextlib.contextmanager
def _warnings_as_lines():
    """Show rippleb's warnings as one ``rippleb: warning: ...`` line each."""
    from rippleb.engine.results import RunWarning

    def show(message, category, *args, **kwargs):
        print(f"rippleb: warning: {message}", file=sys.stderr)
    with warnings.catch_warnings():
        warnings.simplefilter("always", RunWarning)
        warnings.showwarning = show
        yield


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with its four subcommands."""
    parser = argparse.ArgumentParser(
        prog="rippleb", epilog=EPILOG,
        description="Benchmark of torque-ripple cancellation methods for strain-gauge joint "
                    "torque sensors in harmonic drives.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    parser.set_defaults(func=lambda args: parser.print_help(), debug=False)
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    add_list(sub)
    _add_run(sub)
    add_sweep(sub)
    _add_simulate(sub)
    _add_report(sub)
    return parser


def _add_run(sub) -> None:
    from rippleb.engine.runner import DEFAULT_MEMORY_MB, DEFAULT_SEEDS, DEFAULT_TIMEOUT_S

    p = sub.add_parser(
        "run", help="run methods on scenarios (or a recorded log) and write results.csv",
        description="Run every method on every scenario and seed, causally, one control tick at a "
                    "time, and write one row per method x scenario x seed to DIR/results.csv as it "
                    "finishes. Defaults: every built-in method, every scored built-in scenario, "
                    f"{DEFAULT_SEEDS} seeds, out runs/<timestamp>/.")
    p.add_argument("--methods", help="comma-separated method names, or 'all' to add plugins "
                                     "(default: every built-in method)")
    p.add_argument("--scenarios", help="comma-separated scenario names or paths to .toml files "
                                       "(default: every scored built-in scenario)")
    p.add_argument("--conditions", metavar="A,B|all",
                   help="comma-separated deployment conditions, or 'all' (default: same-session, the "
                        "most favourable; see 'rippleb list')")
    p.add_argument("--seeds", type=int, help=f"number of seeds, i.e. simulated devices (default {DEFAULT_SEEDS})")
    p.add_argument("--seed-start", type=int, help="first seed (default 0)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="rows run in parallel processes (default: the number of CPUs, "
                        f"{os.cpu_count()} here; use 1 for the least noisy timings)")
    p.add_argument("--out", type=Path, help="output directory, new or empty (default runs/<timestamp>/)")
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT_S,
                   help=f"seconds one row may take before it is killed (default {DEFAULT_TIMEOUT_S:g}; 0: none)")
    p.add_argument("--memory-limit", type=float, default=DEFAULT_MEMORY_MB, metavar="MB",
                   help=f"memory one row may allocate, in MB (default {DEFAULT_MEMORY_MB:g}; 0: none)")
    p.add_argument("--resume", type=Path, metavar="DIR",
                   help="finish an interrupted run with the selection in DIR/run.json: run the rows "
                        "missing from DIR/results.csv and those that failed for an environmental "
                        "reason (disk full, killed)")
    p.add_argument("--log", type=Path, help="run on a recorded log (.csv or .parquet) instead of scenarios")
    p.add_argument("--calibration", type=Path,
                   help="with --log: the calibration log (needs torque_ref); default: the log itself, "
                        "with a warning: a scored log is not a calibration recording, and fits some "
                        "methods worse or not at all")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_executor_options(p)
    add_seal_options(p)
    p.set_defaults(func=cmd_run)


def _add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="simulate one scenario and write its log",
                       description="Simulate SCENARIO (a built-in name or a .toml path) on the device "
                                   "of --seed and write the columns t, strain, encoder, current, "
                                   "torque_true, torque_ref to FILE (.csv or .parquet).")
    p.add_argument("scenario", metavar="SCENARIO")
    p.add_argument("--seed", type=int, default=0, help="device seed (default 0)")
    p.add_argument("--condition", default="same-session", metavar="NAME",
                   help="deployment condition of the simulated session (default same-session; "
                        "see 'rippleb list')")
    p.add_argument("--out", type=Path, required=True, metavar="FILE", help="output .csv or .parquet")
    p.set_defaults(func=cmd_simulate)


def _add_report(sub) -> None:
    p = sub.add_parser("report", help="write the report of a run (tables, figures, provenance; --html)",
                       description="From DIR/results.csv write OUT/README.md (method x condition summary "
                                   "and headline; per condition the method x scenario matrices with 95 % "
                                   "confidence intervals over seeds, timing, ranking, the paper's "
                                   "Table I replica; failed rows; provenance), OUT/results.csv, "
                                   "OUT/provenance.json, OUT/figures/ and, with --html, OUT/index.html. "
                                   "See docs/report.md.")
    p.add_argument("dir", type=Path, metavar="DIR")
    p.add_argument("--out", type=Path, help="output directory (default DIR/report/; the published one is results/)")
    p.add_argument("--no-figures", action="store_true", help="tables and provenance only")
    p.add_argument("--figure-seed", type=int, default=0,
                   help="device seed re-simulated for the signal figures (default 0)")
    p.add_argument("--speed-seeds", type=int, metavar="N",
                   help="error-against-speed figure: mean over the first N seeds of the run "
                        "(default: every seed; each one is re-simulated)")
    p.add_argument("--format", choices=("png", "svg", "pdf"), default="png", help="figure format (default png)")
    p.add_argument("--html", action="store_true",
                   help="also write OUT/index.html: one self-contained interactive page (sortable "
                        "tables, zoomable figures, provenance), opened without network")
    p.add_argument("--published", action="store_true",
                   help="title and caveats of the project's published comparison (results/, see "
                        "docs/report.md); without it the report says it is the report of one run")
    p.set_defaults(func=cmd_report)


def cmd_run(args) -> int:
    """``rippleb run``."""
    return recorded(args, _run)


def recorded(args, body) -> int:
    """Run ``body(args, start)`` (a run or a sweep) and record its provenance, with whether
    it completed, in the run directory however it ends."""
    from rippleb.report.provenance import collect_provenance
    from rippleb.engine.sealing import redact

    start = time.perf_counter()
    provenance = collect_provenance(redact(args.argv))  # no pointer to a salt file in the run directory
    completed = False
    try:
        status = body(args, start)
        completed = True
        return status
    finally:
        provenance["completed"] = completed
        _record_run(args, provenance, time.perf_counter() - start)


def _record_run(args, provenance: dict, wall_s: float) -> None:
    """Write DIR/provenance.json (command, code version, software, wall time) for
    ``rippleb report``; a resumed run keeps the first command and adds its own."""
    import json

    from rippleb.report.provenance import environment_changes

    out_dir = getattr(args, "out_dir", None)
    if out_dir is None or not getattr(args, "started", False):
        return  # the run never started (bad arguments, a refused directory): nothing to describe
    path = out_dir / "provenance.json"
    provenance.update(jobs=args.jobs, wall_s=wall_s, finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    if args.resume is not None and path.is_file():
        try:
            first = json.loads(path.read_text())
        except (OSError, ValueError):
            first = {}
        first.setdefault("resumes", []).append(provenance["command"])
        changes = environment_changes(first, provenance)
        if changes:
            portable = all((p.get("machine") or {}).get("numerics") == "portable" for p in (first, provenance))
            first.setdefault("environment_changes", []).append(
                {"command": provenance["command"], "changes": changes, "portable": portable})
        first["wall_s"] = first.get("wall_s", 0.0) + wall_s
        first["completed"] = provenance["completed"]
        provenance = first
    try:
        path.write_text(json.dumps(provenance, indent=1) + "\n")
    except OSError as exc:
        print(f"rippleb: warning: cannot record {path}: {exc.strerror or exc}", file=sys.stderr)


def _run(args, start: float) -> int:
    from rippleb.engine import runner

    check_run_options(args)
    timeout = _limit("--timeout", args.timeout)
    memory = _limit("--memory-limit", args.memory_limit)
    for flag, value in (("--methods", args.methods), ("--scenarios", args.scenarios),
                        ("--conditions", args.conditions)):
        if value is not None and not value.replace(",", "").strip():
            raise InputError(f"{flag} is empty; leave it out for the default")
    progress = False if args.no_progress else None

    def started():
        args.started = True
    if args.log is not None:
        _refuse_with_log(args)
        executor(args)  # refuses dask with --log
        args.out_dir = args.out or runner.default_out_dir()
        frame = runner.run_log(args.log, args.calibration, args.methods, jobs=args.jobs,
                               out=args.out_dir, timeout=timeout, memory_mb=memory, progress=progress,
                               on_start=started)
        if args.calibration is None:
            print("rippleb: warning: no --calibration: each method was fitted on the scored log "
                  "itself, not on a calibration recording; a log without motion both ways, a range "
                  "of speeds and known loads fits some methods worse than a calibration recording "
                  "would, or not at all, so these rows are no fair comparison; pass --calibration "
                  "FILE, e.g. one written by 'rippleb simulate calibration'", file=sys.stderr)
    elif args.resume is not None:
        config = runner.read_config(args.resume)
        args.out_dir = args.resume
        _warn_other_environment(args.resume)
        seeds = config["seeds"] if args.seeds is None and args.seed_start is None \
            else (runner.DEFAULT_SEEDS if args.seeds is None else args.seeds)
        frame = runner.run(args.methods or config["methods"], args.scenarios or config["scenarios"],
                           seeds, conditions=args.conditions or config.get("conditions"),
                           seed_start=args.seed_start or 0, jobs=args.jobs, out=args.resume,
                           timeout=timeout, memory_mb=memory, resume=True, progress=progress,
                           on_start=started, executor=executor(args), salt_file=args.salt_file)
    else:
        if args.calibration is not None:
            raise InputError("--calibration only applies with --log")
        args.out_dir = args.out or runner.default_out_dir()
        frame = runner.run(args.methods, args.scenarios,
                           runner.DEFAULT_SEEDS if args.seeds is None else args.seeds,
                           conditions=args.conditions, seed_start=args.seed_start or 0, jobs=args.jobs,
                           out=args.out_dir, timeout=timeout, memory_mb=memory, progress=progress,
                           on_start=started, executor=executor(args), sealed=args.sealed)
    from rippleb.report.tables import summary_text

    print(summary_text(frame))
    counts = frame["status"].value_counts().to_dict() if len(frame) else {}
    print(f"\n{len(frame)} rows ({', '.join(f'{v} {k}' for k, v in counts.items()) or 'none'}) "
          f"in {args.out_dir / 'results.csv'}; total wall time {time.perf_counter() - start:.1f} s")
    print(f"Next: rippleb report {args.out_dir} (tables with intervals, figures; --html for the "
          f"interactive page)")
    return _report_broken_plugins(frame)


def _warn_other_environment(run_dir: Path) -> None:
    """One line when ``run_dir``'s rows were made with other versions or numeric paths."""
    from rippleb.report.provenance import environment, environment_changes, read_run_provenance

    try:
        first = read_run_provenance(run_dir)
    except InputError:
        return  # --resume reports an unreadable run directory itself
    if "versions" not in first:
        return  # recorded before versions were: nothing to compare
    changes = environment_changes(first, environment())
    if changes:
        print(f"rippleb: warning: {run_dir} was started with other versions or numeric paths "
              f"({'; '.join(changes)}); the new rows may differ from the old in their last bits",
              file=sys.stderr)


def _report_broken_plugins(frame) -> int:
    """One stderr line per requested plugin that failed to import; exit 1 if any.

    Its rows are kept with status ``error`` and the other methods ran (docs/design.md), but a
    run asked to include a method it could not load is not a clean run. Judged from the rows
    (every row of the method failed to import it): the CLI never imports plugin code itself.
    """
    broken = 0
    if not len(frame):
        return 0
    for name, rows in frame.groupby("method"):
        messages = rows["message"].astype(str)
        failed = messages[messages.str.startswith("PluginError: ")]
        if len(failed) == len(rows):
            print(f"rippleb: error: {failed.iloc[0][len('PluginError: '):]}", file=sys.stderr)
            broken += 1
    return 1 if broken else 0


def _limit(flag: str, value: float) -> float | None:
    """A ``--timeout``/``--memory-limit`` value: 0 means none; negative or NaN is refused."""
    if not math.isfinite(value) or value < 0:
        raise InputError(f"{flag} must be a positive number (0 for no limit), got {value:g}")
    return value or None


def _refuse_with_log(args) -> None:
    for flag, value in (("--scenarios", args.scenarios), ("--conditions", args.conditions),
                        ("--seeds", args.seeds),
                        ("--seed-start", args.seed_start), ("--resume", args.resume)):
        if value is not None:
            raise InputError(f"{flag} does not apply with --log")


def cmd_simulate(args) -> int:
    """``rippleb simulate``."""
    from rippleb.simulator.conditions import check_condition
    from rippleb.data import write_log
    from rippleb.engine.runner import check_scenario
    from rippleb.scenario import load_scenario
    from rippleb.simulator import simulate
    from rippleb.simulator.validity import check_simulation

    if args.seed < 0:
        raise InputError(f"--seed must be a non-negative integer, got {args.seed}")
    scenario = load_scenario(args.scenario)
    check_scenario(scenario)
    try:
        sim = simulate(scenario, args.seed, condition=check_condition(args.condition))
    except NotImplementedError as exc:  # a condition this simulator does not model yet
        raise InputError(f"--condition {args.condition}: {exc}") from None
    path = write_log(sim.log, args.out)
    print(f"wrote {path}")
    unphysical = check_simulation(sim)
    if unphysical:  # written all the same: it is what was asked for, and shows what went wrong
        print(f"rippleb: warning: {path}: not a joint that exists: {unphysical}", file=sys.stderr)
    return 0


def cmd_report(args) -> int:
    """``rippleb report``."""
    from rippleb.report.writer import report

    seeds = None
    if args.speed_seeds is not None:
        if args.speed_seeds < 1:
            raise InputError(f"--speed-seeds {args.speed_seeds}: must be at least 1")
        seeds = args.speed_seeds
    written = report(args.dir, args.out, figures=not args.no_figures, figure_seed=args.figure_seed,
                     argv=args.argv, published=args.published, html=args.html,
                     figure_format=args.format, speed_seeds=seeds)
    for warning in written["warnings"]:
        print(f"rippleb: warning: {warning}", file=sys.stderr)
    print(f"wrote {written['readme']}, {written['csv']}, {written['provenance']}"
          + (f" and {len(written['figures'])} figures in {written['readme'].parent / 'figures'}"
             if written["figures"] else ""))
    if written["html"] is not None:
        print(f"open {written['html']} in a browser (self-contained: no network needed)")
    return 0
