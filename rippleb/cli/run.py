"""``rippleb run``: methods on scenarios (or a recorded log), rows to ``DIR/results.csv``.

Also what every command that runs rows shares (``run`` and ``sweep``): :func:`recorded`
writes the run's provenance however it ends, and :func:`report_broken_plugins` says which
requested plugins could not be imported.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from rippleb.cli.options import add_executor_options, add_seal_options, check_run_options, executor, limit
from rippleb.errors import InputError
from rippleb.printable import escaped


def add_run(sub) -> None:
    from rippleb.engine.runner import DEFAULT_MEMORY_MB, DEFAULT_SEEDS, DEFAULT_TIMEOUT_S

    p = sub.add_parser(
        "run", help="run methods on scenarios (or a recorded log) and write results.csv",
        description="Run every method on every scenario and seed, causally, one control tick at a "
                    "time, and write one row per method x scenario x seed to DIR/results.csv as it "
                    "finishes. Defaults: every built-in method, every scored built-in scenario, "
                    f"{DEFAULT_SEEDS} seeds, out runs/<timestamp>/.")
    p.add_argument("--methods", help="comma-separated method names, or 'all' to add plugins "
                                     "(default: every built-in method); 'NAME[p=1,2]' runs one variant "
                                     "per value of a constructor parameter (docs/plugins.md)")
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
    p.add_argument("--joint", type=Path, metavar="FILE",
                   help="with --log: the joint.toml describing the joint (counts per revolution, gear "
                        "ratio, rated torque, ...) and the logs' column names and units; a log's sidecar "
                        "(rec.toml beside rec.csv) overrides it; what neither gives is assumed and "
                        "printed before the run (docs/your-joint.md)")
    p.add_argument("--resample", action="store_true",
                   help="with --log: put logs whose time stamps jitter on a uniform grid at their mean "
                        "rate (linear interpolation; encoder counts held) instead of refusing them")
    p.add_argument("--tuning", type=Path, metavar="FILE",
                   help="a record written by 'rippleb tune --out FILE': each method of the run whose best "
                        "point the rule adopted runs as that variant ('NAME[p=v]'); a variant given in "
                        "--methods keeps its own values")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_executor_options(p)
    add_seal_options(p)
    p.set_defaults(func=cmd_run)


def cmd_run(args) -> int:
    """``rippleb run``."""
    return recorded(args, _run)


def recorded(args, body) -> int:
    """Run ``body(args, start)`` (a run or a sweep) and record its provenance, with whether
    it completed, in the run directory however it ends."""
    from rippleb import interrupts

    # Held from here, as the runner holds them: its heavy imports, the provenance and the
    # checks before the run raise a signal at their next check, never where it lands. Raised
    # there, in a finalizer or a callback run during an import, Python printed it as
    # "Exception ignored", dropped it, and the run went on to claim its directory (once in
    # CI's random-moment trials). The runner checks before it claims anything, and its waits
    # poll; a run cut short by a signal here says so in one line, exit 130.
    with interrupts.held():
        from rippleb.report.provenance import collect_provenance
        from rippleb.engine.sealing import redact

        start, cpu_start, load_start = time.perf_counter(), cpu_seconds(), os.getloadavg()
        provenance = collect_provenance(redact(args.argv))  # no pointer to a salt file in the run directory
        interrupts.check_interrupted()
        completed = False
        try:
            status = body(args, start)
            completed = True
            return status
        finally:
            provenance["completed"] = completed
            provenance["load_average"] = {"start": load_start, "end": os.getloadavg()}
            _record_run(args, provenance, time.perf_counter() - start, cpu_seconds() - cpu_start)


def cpu_seconds() -> float:
    """User and system CPU seconds of this process and of every process it started and
    waited for (the fork server waits for the jobs' processes, the runner for the server)."""
    import resource

    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                  resource.getrusage(resource.RUSAGE_CHILDREN)))


def _record_run(args, provenance: dict, wall_s: float, cpu_s: float) -> None:
    """Write DIR/provenance.json (command, code version, software, wall and CPU time) for
    ``rippleb report``; a resumed run keeps the first command and adds its own."""
    import json

    from rippleb.report.provenance import environment_changes

    out_dir = getattr(args, "out_dir", None)
    if out_dir is None or not getattr(args, "started", False):
        return  # the run never started (bad arguments, a refused directory): nothing to describe
    path = out_dir / "provenance.json"
    provenance.update(jobs=args.jobs, wall_s=wall_s, cpu_s=cpu_s, finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    if args.resume is not None and path.is_file():
        from rippleb.reading import RUN_FILE_BYTES, parse_json, read_text

        try:
            first = parse_json(read_text(path, RUN_FILE_BYTES, "run file", in_run_dir=True), path)
        except (OSError, InputError):
            first = {}
        first = first if isinstance(first, dict) else {}
        first["resumes"] = [*(first.get("resumes") if isinstance(first.get("resumes"), list) else []),
                            provenance["command"]]
        changes = environment_changes(first, provenance)
        if changes:
            portable = all((p.get("machine") or {}).get("numerics") == "portable" for p in (first, provenance))
            earlier = first.get("environment_changes")
            first["environment_changes"] = [*(earlier if isinstance(earlier, list) else []),
                                             {"command": provenance["command"], "changes": changes,
                                              "portable": portable}]
        first["wall_s"] = (first["wall_s"] if isinstance(first.get("wall_s"), (int, float)) else 0.0) + wall_s
        first["cpu_s"] = (first["cpu_s"] if isinstance(first.get("cpu_s"), (int, float)) else 0.0) + cpu_s
        first["completed"] = provenance["completed"]
        provenance = first
    from rippleb.files import atomic_path

    try:   # replaced, never written through: a link put there meanwhile is replaced, not followed
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(provenance, indent=1) + "\n")
    except InputError as exc:
        print(f"rippleb: warning: cannot record {path}: {exc}", file=sys.stderr)


def _run(args, start: float) -> int:
    from rippleb.engine import runner

    check_run_options(args)
    timeout = limit("--timeout", args.timeout)
    memory = limit("--memory-limit", args.memory_limit)
    for flag, value in (("--methods", args.methods), ("--scenarios", args.scenarios),
                        ("--conditions", args.conditions)):
        if value is not None and not value.replace(",", "").strip():
            raise InputError(f"{flag} is empty; leave it out for the default")
    progress = False if args.no_progress else None
    if args.tuning is not None:
        if args.resume is not None:
            raise InputError("--tuning does not apply with --resume: the run's methods are in its run.json")
        args.methods = tuned_methods(args.methods, args.tuning)

    def started():
        args.started = True
    if args.log is not None:
        _refuse_with_log(args)
        executor(args)  # refuses dask with --log
        args.out_dir = args.out or runner.default_out_dir()
        log, cal = read_logs(args)

        def started_on_logs():  # the logs passed every check: say how they were read, then run
            print(joint_block(args, log, cal), file=sys.stderr)
            started()
        frame = runner.run_log(log, cal, args.methods, jobs=args.jobs,
                               out=args.out_dir, timeout=timeout, memory_mb=memory, progress=progress,
                               on_start=started_on_logs)
        if args.calibration is None:
            print("rippleb: warning: no --calibration: each method was fitted on the scored log "
                  "itself, not on a calibration recording; a log without motion both ways, a range "
                  "of speeds and known loads fits some methods worse than a calibration recording "
                  "would, or not at all, so these rows are no fair comparison; pass --calibration "
                  "FILE, e.g. one written by 'rippleb simulate calibration'", file=sys.stderr)
    elif args.resume is not None:
        _refuse_without_log(args)
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
        _refuse_without_log(args)
        args.out_dir = args.out or runner.default_out_dir()
        frame = runner.run(args.methods, args.scenarios,
                           runner.DEFAULT_SEEDS if args.seeds is None else args.seeds,
                           conditions=args.conditions, seed_start=args.seed_start or 0, jobs=args.jobs,
                           out=args.out_dir, timeout=timeout, memory_mb=memory, progress=progress,
                           on_start=started, executor=executor(args), sealed=args.sealed,
                           salt_file=args.salt_file)
    from rippleb.report.provenance import read_run_provenance
    from rippleb.report.recorded import run_summary

    joint = read_run_provenance(args.out_dir).get("joint") if args.log is not None and len(frame) else None
    print(run_summary(frame, joint))
    counts = frame["status"].value_counts().to_dict() if len(frame) else {}
    print(f"\n{len(frame)} rows ({', '.join(f'{v} {k}' for k, v in counts.items()) or 'none'}) "
          f"in {args.out_dir / 'results.csv'}; total wall time {time.perf_counter() - start:.1f} s")
    print(f"Next: rippleb report {args.out_dir} (tables with intervals, figures; --html for the "
          f"interactive page)")
    return max(report_broken_plugins(frame), report_nothing_measured(frame))


def report_nothing_measured(frame) -> int:
    """One stderr line and exit 1 when rows ran but none was measured (every one ``error``,
    ``invalid`` or ``timeout``): the run holds no result to compare; else 0."""
    from rippleb.scoring.scorable import MEASURED

    if not len(frame) or frame["status"].isin(MEASURED).any():
        return 0
    counts = ", ".join(f"{v} {k}" for k, v in frame["status"].value_counts().items())
    print(f"rippleb: error: no row was measured ({counts}): nothing to rank; each row's message says why",
          file=sys.stderr)
    return 1


def tuned_methods(methods: str | None, path: Path) -> str:
    """``--methods`` with each plain method name that the tuning record ``path`` adopted a point
    for replaced by that variant (``NAME[p=v]``); said on stderr, one line per method."""
    import json

    from rippleb.registry import Registry
    from rippleb.tuning import adopted_points
    from rippleb.variants import label, split_top_level

    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"--tuning {path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"--tuning {path}: cannot read a tuning record: {exc}") from None
    adopted = adopted_points(record, f"--tuning {path}")
    registry = Registry.discover()
    items = (split_top_level(methods) if methods else registry.names("builtin"))
    items = registry.names() if [i.strip() for i in items] == ["all"] else [i.strip() for i in items if i.strip()]
    out = []
    for item in items:
        if item in adopted:
            out.append(label(item, adopted[item]))
            print(f"rippleb: --tuning {path.name}: {item} runs as {out[-1]!r} (the point 'rippleb tune' adopted)",
                  file=sys.stderr)
        else:
            out.append(item)
    if not any(i in adopted for i in items):
        print(f"rippleb: --tuning {path.name}: no method of this run has an adopted point in it "
              f"({', '.join(adopted) or 'none adopted'}); every method runs at its defaults", file=sys.stderr)
    return ",".join(out)


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


def report_broken_plugins(frame) -> int:
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
            print(f"rippleb: error: {escaped(failed.iloc[0][len('PluginError: '):])}", file=sys.stderr)
            broken += 1
    return 1 if broken else 0


def _refuse_with_log(args) -> None:
    for flag, value in (("--scenarios", args.scenarios), ("--conditions", args.conditions),
                        ("--seeds", args.seeds),
                        ("--seed-start", args.seed_start), ("--resume", args.resume)):
        if value is not None:
            raise InputError(f"{flag} does not apply with --log")


def _refuse_without_log(args) -> None:
    for flag, value in (("--calibration", args.calibration), ("--joint", args.joint),
                        ("--resample", args.resample or None)):
        if value is not None:
            raise InputError(f"{flag} only applies with --log")


def read_logs(args):
    """The scored and the calibration log of ``--log``, read with ``--joint`` and ``--resample``."""
    from rippleb.log_files import read_log
    from rippleb.joint_file import load_joint

    joint = load_joint(args.joint) if args.joint is not None else None
    log = read_log(args.log, joint=joint, resample=args.resample)
    cal = None if args.calibration is None else read_log(args.calibration, spec=log.spec, joint=joint,
                                                         resample=args.resample)
    return log, cal


def joint_block(args, log, cal) -> str:
    """One block for stderr: every value the logs were read with, given or assumed."""
    lines = [f"rippleb: {args.log.name}: read with these values (give the ASSUMED ones in --joint FILE, "
             f"docs/your-joint.md):", *log.meta["joint"]]
    if cal is not None:
        lines += [f"rippleb: {args.calibration.name}: the joint values above; its columns:",
                  *[line for line in cal.meta["joint"] if line.startswith("  column ")]]
    if log.torque_ref is None and log.torque_true is None:
        lines.append(f"rippleb: warning: {args.log.name} has no reference torque (torque_ref): its rows "
                     f"get status no-reference; accuracy cannot be scored, cost can")
    return "\n".join(lines)
