"""The causal streaming runner: every method x scenario x condition x seed, one isolated process each.

A run has three kinds of jobs (:mod:`rippleb.engine.jobs`), each in its own isolated child of
:class:`rippleb.engine.process.pool.Pool`:

* a *simulation* per (scenario content, condition, seed), plus the ``calibration``
  scenario per seed, simulated under ``same-session`` (it is the device's first
  session), or under ``realistic`` for that condition's rows (it changes the joint itself:
  ``conditions.calibration_condition``). It writes what methods may see to hashed cache files and sends the truth
  back through its pipe; the runner keeps the truth in memory only, and only while rows
  of that case are pending;
* a *fit* per method and calibration log: ``fit`` once, as on a real device, and pickle
  the fitted method into the cache (a method that cannot be pickled is fitted in each row);
* a *row* per :class:`~rippleb.engine.rows.RowKey`: it verifies its inputs, loads the fitted
  method, ``reset``s it, streams the scored log in ticks and sends back the estimate and
  tick times. The runner scores the estimate against the truth it holds.

Each row ends as ``ok``, ``error``, ``invalid`` or ``timeout`` and is written to
``DIR/results.csv`` as soon as it ends (:class:`rippleb.engine.results.ResultsFile`). A run
directory is locked while a run writes it, never overwritten without ``resume=True``,
and always resumable from ``DIR/run.json``: ``resume=True`` validates what it reads,
and runs the rows missing from ``results.csv`` plus those that failed for an
environmental reason. See ``docs/robustness.md``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import tempfile
import time
from pathlib import Path

from rippleb import interrupts
from rippleb.engine.process import isolation
from rippleb.engine import jobs as job_fns
from rippleb.engine.process import sandbox
from rippleb.engine import sealing
from rippleb.engine.cache import digest, log_bytes
from rippleb.engine.checks import (check_calibration, check_options, check_recording, check_reference, check_scenario,
                                   check_scored_length, check_strain_scale)
from rippleb.simulator.conditions import DEFAULT_CONDITION, calibration_condition
from rippleb.data import SensorLog
from rippleb.errors import InputError
from rippleb.engine.process.forkserver import ForkServer
from rippleb.scoring.metrics import Truth
from rippleb.scoring.row import score_row
from rippleb.engine.process.pool import Pool
from rippleb.registry import Registry
from rippleb.engine.executors import row_tasks
from rippleb.engine.methods import base_name, resolve_methods
from rippleb.engine.results import (MEASURED, ResultsFile, RunWarning, row_key, say_other_versions,
                                    warn_native_numerics, warn_native_rows)
from rippleb.engine.rows import (CALIBRATION, FITTING, MAX_SEEDS, SCORED, Case, RowKey, check_rows, scenario_hash,
                                 select_conditions, select_scenarios, select_seeds, split_names)
from rippleb.engine.rundir import log_dir, read_config, run_dir
from rippleb.engine.plan import Plan, State, prepare_cases
from rippleb.engine.scheduler import progress_bar, record, say_retried, schedule

__all__ = ["run", "run_log", "resolve_methods", "read_config", "check_scenario", "evaluate",
           "default_out_dir", "DEFAULT_SEEDS", "MAX_SEEDS", "DEFAULT_TIMEOUT_S", "DEFAULT_MEMORY_MB"]

DEFAULT_SEEDS = 3
DEFAULT_TIMEOUT_S = 300.0
DEFAULT_MEMORY_MB = 4096.0


def run(methods=None, scenarios=None, seeds=DEFAULT_SEEDS, *, conditions=None, seed_start: int = 0,
        jobs: int = 1, out=None, timeout: float | None = DEFAULT_TIMEOUT_S,
        memory_mb: float | None = DEFAULT_MEMORY_MB, resume: bool = False, progress: bool | None = False,
        on_start=None, executor=None, sealed=None, salt_file=None):
    """Run methods on simulated scenarios; one row per method x scenario x condition x seed.

    Parameters
    ----------
    methods
        Method names (a list or ``"a,b"``), or variants (``"order-tracking[q=20,30]"``,
        :mod:`rippleb.variants`); None for every built-in method, ``"all"`` for every
        built-in and plugin method.
    scenarios
        Scenario names or paths to ``.toml`` files; None for every scored built-in.
    seeds
        The number of seeds (devices) ``seed_start .. seed_start + seeds - 1``, or a list of seeds.
    conditions
        Deployment conditions (``rippleb.simulator.conditions.CONDITIONS``, a list or ``"a,b"``, or
        ``"all"``); None for ``same-session`` only.
    seed_start
        First seed when ``seeds`` is a number.
    jobs
        Rows run at once, each in its own process.
    out
        Directory for ``results.csv`` (created; refused if not empty unless ``resume``),
        or None to keep the rows in memory only.
    timeout
        Seconds one job (fit or row) may take before it is killed; None for no limit.
    memory_mb
        Address space one job may add [MB] before allocations fail; None for no limit.
    resume
        Finish the run in ``out`` (same selection as ``out/run.json``): keep its finished
        rows, run the missing ones and those that failed for an environmental reason.
    progress
        Show a progress bar on stderr (None: only on a terminal).
    on_start
        Called once the run directory is checked and locked, before any job starts.
    executor
        None for the local forked pool, or an object with ``run(tasks, record)`` that runs
        whole rows elsewhere (:class:`rippleb.engine.dask.executor.DaskExecutor`).
    sealed
        A new sealed run (:mod:`rippleb.engine.sealing`): the path of a new file, outside ``out``,
        that the secret salt is written to when the run ends; the devices and the noise are
        drawn from it, ``run.json`` records its commitment and each row gets
        ``sealed = True``. Needs ``out``; not with an ``executor``.
    salt_file
        With ``resume`` of a sealed run: the file ``sealed`` wrote (``"-"``: standard input).
        Without ``resume``: run on the devices of that salt, e.g. to re-run rows of a
        published sealed comparison (``run.json`` marks the run a replay).

    Returns
    -------
    pandas.DataFrame
        The rows sorted by (method, scenario, condition, seed), standard columns first
        (see ``rippleb.engine.results.COLUMNS``).
    """
    from rippleb.simulator.scenario import load_scenario, scored_scenarios

    check_options(jobs=jobs, timeout=timeout, memory_mb=memory_mb)
    registry = Registry.discover()
    names = resolve_methods(registry, methods)
    if scenarios is not None and not split_names(scenarios):
        raise InputError("--scenarios is empty; give scenario names or .toml paths")
    given = split_names(scenarios) or scored_scenarios()
    scenario_objs = select_scenarios(given, load_scenario)
    for scenario in scenario_objs:
        check_scenario(scenario)
    condition_list = select_conditions(conditions)
    seed_list = select_seeds(seeds, seed_start)
    check_rows(len(names) * len(scenario_objs) * len(condition_list) * len(seed_list),
               f"{len(names)} methods x {len(scenario_objs)} scenarios x {len(condition_list)} conditions x "
               f"{len(seed_list)} seeds")
    calibration = load_scenario(CALIBRATION)
    config = {"methods": names, "conditions": condition_list, "seeds": seed_list,
              "scenarios": [str(Path(s).resolve()) if s.endswith(".toml") else s for s in
                            dict.fromkeys(given)]}
    return run_resolved(registry, names, [(s, calibration, {}) for s in scenario_objs], condition_list,
                        seed_list, config=config, jobs=jobs, out=out, timeout=timeout,
                        memory_mb=memory_mb, resume=resume, progress=progress, on_start=on_start,
                        executor=executor, sealed=sealed, salt_file=salt_file)


def run_resolved(registry: Registry, names: list[str], entries: list[tuple], conditions: list[str],
                 seeds: list[int], *, config: dict, jobs: int = 1, out=None,
                 timeout: float | None = DEFAULT_TIMEOUT_S, memory_mb: float | None = DEFAULT_MEMORY_MB,
                 resume: bool = False, progress: bool | None = False, on_start=None, executor=None,
                 sealed=None, salt_file=None):
    """Run checked selections: ``entries`` holds ``(scenario, calibration scenario, extra key
    columns)`` triples of resolved :class:`~rippleb.simulator.scenario.Scenario` objects.

    The extra columns (``{name: value}``, e.g. the swept values of :mod:`rippleb.engine.sweep`)
    become part of each row's key and columns, so two entries that share a scenario name
    never share a row; their scenario content (hashed into every cache file name)
    differs. The options are those of :func:`run`; ``config`` is saved in ``run.json``.
    """
    warn_native_numerics()
    plan = Plan(calibration_label=CALIBRATION)
    # each content hash once, not per seed: hashing a scenario takes milliseconds, and a plan
    # at MAX_SEEDS hashed 160 000 of them (over 10 minutes) before it started
    hashed: dict[int, str] = {}
    entries = [(scenario, calibration, extra, *(hashed.setdefault(id(s), scenario_hash(s))
                                                for s in (scenario, calibration)))
               for scenario, calibration, extra in entries]
    for seed in seeds:
        interrupts.check_interrupted()   # a plan of many rows takes seconds: Ctrl-C stops it
        for scenario, calibration, extra, content, cal_content in entries:
            for condition in conditions:
                # the device's first session; under a condition of the joint itself
                # (`realistic`) that session has the joint's physics too
                cal_case = Case(CALIBRATION, cal_content, calibration_condition(condition), seed, FITTING)
                plan.add_sim(calibration, cal_case)
                case = Case(scenario.name, content, condition, seed, SCORED)
                plan.add_sim(scenario, case)
                for method in names:
                    key = RowKey(method, scenario.name, condition, seed, tuple(extra.items()))
                    plan.add_row(key, case, cal_case)
    if sealed is not None:
        sealing.check_new_salt_path(sealed, out)
    if executor is not None and (sealed is not None or salt_file is not None):
        raise InputError("--sealed/--salt-file run on the local pool only (the salt would have to "
                         "reach the Dask workers); drop --executor dask/--scheduler")
    return _execute(registry, plan, out=out, jobs=jobs, timeout=timeout, memory_mb=memory_mb,
                    resume=resume, progress=progress, config=config, on_start=on_start, executor=executor,
                    sealed=sealed, salt_file=salt_file)


def run_log(log, calibration=None, methods=None, *, jobs: int = 1, out=None,
            timeout: float | None = DEFAULT_TIMEOUT_S, memory_mb: float | None = DEFAULT_MEMORY_MB,
            progress: bool | None = False, on_start=None, joint=None, resample: bool = False):
    """Run methods on a recorded log; score against ``torque_ref`` (and ``torque_true`` if present).

    Parameters
    ----------
    log, calibration
        Paths to CSV/Parquet logs, or :class:`SensorLog`. Methods are fit on
        ``calibration``; without one, on ``log`` itself if it has ``torque_ref`` (the
        rows then say ``calibration = self``: fit and scored on the same data).
    methods, jobs, out, timeout, memory_mb, progress, on_start
        As in :func:`run`.
    joint, resample
        As in :func:`rippleb.log_files.read_log`, for the logs given as paths; the calibration
        log is read with the scored log's joint values.
    """
    from rippleb.log_files import read_log

    check_options(jobs=jobs, timeout=timeout, memory_mb=memory_mb)
    registry = Registry.discover()
    names = resolve_methods(registry, methods)
    # The fork server before the logs are read: every job is forked from it, and the
    # recording's reference torque, which the rows are scored against, must be in none.
    with isolation.undumpable(), fork_server(registry) as server:
        log_name = _log_label(log, "log")
        log = log if isinstance(log, SensorLog) else read_log(log, joint=joint, resample=resample)
        check_recording(log, log_name)
        if calibration is None:
            if log.torque_ref is None:
                raise InputError(f"{log_name}: no torque_ref column, so methods cannot be calibrated on it; "
                                 "pass --calibration FILE")
            cal, label = log, "self"
        else:
            label = _log_label(calibration, "calibration")
            cal = calibration if isinstance(calibration, SensorLog) else read_log(
                calibration, spec=log.spec, joint=joint, resample=resample)
            if cal.torque_ref is None:
                raise InputError(f"{label}: a calibration log needs a torque_ref column")
            check_recording(cal, label)
            check_calibration(cal, label, log)
        check_scored_length(log, log_name)
        check_reference(cal, log_name if calibration is None else label)
        check_strain_scale(log, cal, log_name)
        truth = Truth.from_recording(log)
        scenario = f"log:{log_name}"
        case = Case(scenario, digest(log_bytes(log)), DEFAULT_CONDITION, 0, SCORED)
        cal_case = Case(CALIBRATION, digest(log_bytes(cal)), DEFAULT_CONDITION, 0, FITTING)
        plan = Plan(calibration_label=label)
        plan.ready = {case: (log, truth), cal_case: (cal, None)}
        for method in names:
            plan.add_row(RowKey(method, scenario, DEFAULT_CONDITION, 0), case, cal_case)
        return _execute(registry, plan, out=out, jobs=jobs, timeout=timeout, memory_mb=memory_mb,
                        resume=False, progress=progress, on_start=on_start, server=server,
                        config={"methods": names, "log": log_name, "conditions": [DEFAULT_CONDITION],
                                "joint": {"gear_ratio": log.spec.gear_ratio,
                                          "counts_per_rev": log.spec.counts_per_rev,
                                          "reference_kind": truth.reference_kind}})


def _log_label(log, default: str) -> str:
    """The file name of a log given as a path or read from one (its ``meta["source"]``)."""
    source = log.meta.get("source") if isinstance(log, SensorLog) else log
    return Path(source).name if source else default


def run_plan(registry, plan: Plan, *, jobs: int = 1, timeout: float | None = DEFAULT_TIMEOUT_S,
             memory_mb: float | None = DEFAULT_MEMORY_MB, progress: bool | None = False, on_record=None,
             server=None, estimates: dict | None = None):
    """Run a plan made elsewhere (the tuner's points, the report's figures) exactly as a run's
    rows run, in memory (no run directory); ``on_record(row)`` is called as each row is
    recorded, and ``estimates``, if given, receives each ``ok`` row's estimate by its key.
    ``server``: a fork server started before the plan's given logs were read
    (:func:`fork_server`), else one is started now. Returns the rows as :func:`run` does."""
    return _execute(registry, plan, out=None, jobs=jobs, timeout=timeout, memory_mb=memory_mb, resume=False,
                    progress=progress, config={}, on_record=on_record, server=server, estimates=estimates)


def fork_server(registry, plan: Plan | None = None) -> ForkServer:
    """The process every job of a run is forked from (:mod:`rippleb.engine.process.forkserver`),
    started now: before anything this process holds a truth of (a simulation, a recorded
    log's reference), so that no job's memory holds one. It loads the simulator and the
    built-in methods (those of ``plan``, else all), never a plugin."""
    return ForkServer.start(registry, preload=functools.partial(_warm, registry, plan))


def _execute(registry, plan: Plan, *, out, jobs, timeout, memory_mb, resume, progress, config,
             on_start=None, executor=None, sealed=None, salt_file=None, on_record=None, server=None,
             estimates=None):
    # Signals are held from here on and raised only where stopping leaves nothing half
    # done (rippleb.interrupts): the loops between jobs and the waits, which poll. So an
    # interrupt never orphans a job, a half-claimed run directory or a temporary file.
    with interrupts.handling(), interrupts.held(), isolation.undumpable():
        interrupts.check_interrupted()   # one that came while the run was prepared: nothing claimed yet
        if executor is not None and hasattr(executor, "check"):
            with interrupts.raising():  # a bad address is bad input: refused before the directory is claimed
                executor.check()
        if executor is None:   # a Dask worker's log says what its own kernel grants
            sandbox.say_missing(sealed=sealed is not None or salt_file is not None)
        # The local jobs are forked by a server forked now, before the first simulation, so
        # no job's memory ever holds a truth (rippleb.engine.process.forkserver). Another executor runs its
        # rows elsewhere.
        if executor is not None:
            server = contextlib.nullcontext()
        elif server is None:
            server = fork_server(registry, plan)
        seal, started = None, False
        try:
            with server:
                # After the fork: the server, and every row it forks, never holds the salt.
                seal = sealing.open_seal(out, resume, config, sealed=sealed, salt_file=salt_file)
                with run_dir(out, resume, config, on_start) as out_dir:
                    started = out_dir is not None
                    interrupts.check_interrupted()
                    if seal is not None:
                        _warm_simulator(plan)  # sealed simulations are forked from here (rippleb.engine.sealing)
                    results = ResultsFile(out_dir / "results.csv" if out_dir else None, resume=resume)
                    try:
                        _run_rows(registry, plan, results, out_dir, resume=resume, jobs=jobs, timeout=timeout,
                                  memory_mb=memory_mb, progress=progress, server=server, executor=executor,
                                  seal=seal, on_record=on_record, estimates=estimates)
                    finally:  # finished or interrupted: the file in key order, from the rows in memory
                        if results.rows:
                            results.flush()
        finally:  # every job has ended (the server reaped them): only now may a salt file exist
            sealing.release(seal, started)
    return results.frame()


def _run_rows(registry, plan: Plan, results: ResultsFile, out_dir, *, resume, jobs, timeout, memory_mb,
              progress, server, executor, seal, on_record=None, estimates=None) -> None:
    """Run the rows of ``plan`` not yet in ``results`` and record each as it ends."""
    if resume:
        say_retried(results.drop_environmental(), out_dir)
    done = results.done_keys()
    # Case-major: a log's rows run together, so memory holds the truths of the cases in flight.
    rows = sorted((k for k in plan.rows if row_key(k.fields()) not in done),
                  key=lambda k: (k.seed, k.scenario, k.extra, k.condition, k.method))
    if resume and rows:
        say_other_versions(results.rows, out_dir)
    # The methods' scratch directories live in one of the run's own, removed with it even
    # where a keeper was killed before it could remove its job's.
    with tempfile.TemporaryDirectory(prefix="rippleb-cache-") as cache, \
            tempfile.TemporaryDirectory(prefix="rippleb-scratch-") as scratch:
        state = State(plan, registry, results, Path(cache), log_dir(out_dir), timeout,
                      time.strftime("%Y%m%dT%H%M%S"), rows, seal=seal, scratch=Path(scratch), on_record=on_record,
                      estimates=estimates)
        with progress_bar(len(rows), progress) as bar:
            prepare_cases(state)
            interrupts.check_interrupted()
            if executor is None:
                schedule(Pool(int(jobs), memory_mb, server=server), state, bar)
            else:  # whole rows run elsewhere; this process only records them
                executor.run(row_tasks(state, memory_mb), lambda key, fields: record(state, key, bar, **fields))
                warn_native_rows(results.rows)


def _warm_simulator(plan: Plan) -> None:
    """Load the simulator and its arm models in this process, which forks a sealed run's
    simulations (rippleb's code only: no method is imported here)."""
    from rippleb.simulator import robot, simulation  # noqa: F401 - the joint's kernels with it

    for scenario, _ in plan.sims.values():
        robot.load_model(scenario.robot)


def _warm(registry, plan: Plan | None) -> None:
    """Load in the fork server what the jobs of ``plan`` would each load again: the
    simulator with the arm models of its scenarios, and its built-in methods (every one
    without a plan) with their compiled kernels. Plugins are not imported here: only
    workers run plugin code."""
    from rippleb.simulator import robot, simulation  # noqa: F401 - the joint's kernels with it

    if plan is None:
        registry.load_builtins()
        return
    for scenario, _ in plan.sims.values():
        robot.load_model(scenario.robot)
    registry.load_builtins({base_name(key.method) for key in plan.rows})


def default_out_dir() -> Path:
    """``runs/<timestamp>/`` in the current directory."""
    return Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")


# ----------------------------------------------------------------------------- in-process helpers


def evaluate(cls, calibration: SensorLog, evaluation: SensorLog, truth: Truth, params=None) -> dict:
    """One row's result fields in this process (tests and tools; the runner isolates rows).

    Fits ``cls(**params)`` on ``calibration``, streams ``evaluation`` and scores it
    against ``truth``; failures of the method become ``error``, bad output ``invalid``.
    """
    from rippleb.registry import Entry

    class _One:
        def get(self, name):
            return Entry(name, "builtin", "evaluate", cls=cls)

    result = job_fns.run_row(getattr(cls, "name", "method"), params, calibration, evaluation, _One())
    fields = result["info"]
    if fields["status"] == "ok":
        fields.update(score_row(result, truth, len(evaluation), len(result["ticks"])))
    return fields
