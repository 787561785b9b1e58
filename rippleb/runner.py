"""The causal streaming runner: every method x scenario x condition x seed, one isolated process each.

A run has three kinds of jobs (:mod:`rippleb.jobs`), each in its own isolated child of
:class:`rippleb.pool.Pool`:

* a *simulation* per (scenario content, condition, seed), plus the ``calibration``
  scenario per seed, always simulated under ``same-session`` (it is the device's first
  session). It writes what methods may see to hashed cache files and sends the truth
  back through its pipe; the runner keeps the truth in memory only, and only while rows
  of that case are pending;
* a *fit* per method and calibration log: ``fit`` once, as on a real device, and pickle
  the fitted method into the cache (a method that cannot be pickled is fitted in each row);
* a *row* per :class:`~rippleb.rows.RowKey`: it verifies its inputs, loads the fitted
  method, ``reset``s it, streams the scored log in ticks and sends back the estimate and
  tick times. The runner scores the estimate against the truth it holds.

Each row ends as ``ok``, ``error``, ``invalid`` or ``timeout`` and is written to
``DIR/results.csv`` as soon as it ends (:class:`rippleb.results.ResultsFile`). A run
directory is locked while a run writes it, never overwritten without ``resume=True``,
and always resumable from ``DIR/run.json``: ``resume=True`` validates what it reads,
and runs the rows missing from ``results.csv`` plus those that failed for an
environmental reason. See ``docs/robustness.md``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import json
import math
import signal
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rippleb import jobs as job_fns
from rippleb.cache import Artefact, digest, log_bytes, store, unpack
from rippleb.conditions import DEFAULT_CONDITION
from rippleb.data import SensorLog
from rippleb.errors import InputError
from rippleb.files import atomic_path
from rippleb.metrics import Truth, score, tick_stats
from rippleb.pool import Pool
from rippleb.registry import Registry
from rippleb.results import ENVIRONMENT, STATUSES, ResultsFile, RunWarning, row_key, system_info
from rippleb.rows import (CALIBRATION, FITTING, SCORED, Case, RowKey, check_trajectory, scenario_hash,
                          select_conditions, select_scenarios, split_names)

# Kept for callers of the former module layout.
from rippleb.jobs import params_json as _params_json  # noqa: F401

DEFAULT_SEEDS = 3
DEFAULT_TIMEOUT_S = 300.0
DEFAULT_MEMORY_MB = 4096.0
MIN_FS, MAX_FS = 100.0, 1e6
MIN_CALIBRATION_S = 1.0


def run(methods=None, scenarios=None, seeds=DEFAULT_SEEDS, *, conditions=None, seed_start: int = 0,
        jobs: int = 1, out=None, timeout: float | None = DEFAULT_TIMEOUT_S,
        memory_mb: float | None = DEFAULT_MEMORY_MB, resume: bool = False, progress: bool | None = False,
        on_start=None, executor=None):
    """Run methods on simulated scenarios; one row per method x scenario x condition x seed.

    Parameters
    ----------
    methods
        Method names (a list or ``"a,b"``); None for every built-in method, ``"all"`` for
        every built-in and plugin method.
    scenarios
        Scenario names or paths to ``.toml`` files; None for every scored built-in.
    seeds
        The number of seeds (devices) ``seed_start .. seed_start + seeds - 1``, or a list of seeds.
    conditions
        Deployment conditions (``rippleb.conditions.CONDITIONS``, a list or ``"a,b"``, or
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
        whole rows elsewhere (:class:`rippleb.dask_executor.DaskExecutor`).

    Returns
    -------
    pandas.DataFrame
        The rows sorted by (method, scenario, condition, seed), standard columns first
        (see ``rippleb.results.COLUMNS``).
    """
    from rippleb.scenario import load_scenario, scored_scenarios

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
    seed_list = _seed_list(seeds, seed_start)
    calibration = load_scenario(CALIBRATION)
    config = {"methods": names, "conditions": condition_list, "seeds": seed_list,
              "scenarios": [str(Path(s).resolve()) if s.endswith(".toml") else s for s in
                            dict.fromkeys(given)]}
    return run_resolved(registry, names, [(s, calibration, {}) for s in scenario_objs], condition_list,
                        seed_list, config=config, jobs=jobs, out=out, timeout=timeout,
                        memory_mb=memory_mb, resume=resume, progress=progress, on_start=on_start,
                        executor=executor)


def run_resolved(registry: Registry, names: list[str], entries: list[tuple], conditions: list[str],
                 seeds: list[int], *, config: dict, jobs: int = 1, out=None,
                 timeout: float | None = DEFAULT_TIMEOUT_S, memory_mb: float | None = DEFAULT_MEMORY_MB,
                 resume: bool = False, progress: bool | None = False, on_start=None, executor=None):
    """Run checked selections: ``entries`` holds ``(scenario, calibration scenario, extra key
    columns)`` triples of resolved :class:`~rippleb.scenario.Scenario` objects.

    The extra columns (``{name: value}``, e.g. the swept values of :mod:`rippleb.sweep`)
    become part of each row's key and columns, so two entries that share a scenario name
    never share a row; their scenario content (hashed into every cache file name)
    differs. The options are those of :func:`run`; ``config`` is saved in ``run.json``.
    """
    plan = _Plan(calibration_label=CALIBRATION)
    for seed in seeds:
        for scenario, calibration, extra in entries:
            cal_case = Case(CALIBRATION, scenario_hash(calibration), DEFAULT_CONDITION, seed, FITTING)
            plan.add_sim(calibration, cal_case)
            content = scenario_hash(scenario)
            for condition in conditions:
                case = Case(scenario.name, content, condition, seed, SCORED)
                plan.add_sim(scenario, case)
                for method in names:
                    key = RowKey(method, scenario.name, condition, seed, tuple(extra.items()))
                    plan.add_row(key, case, cal_case)
    return _execute(registry, plan, out=out, jobs=jobs, timeout=timeout, memory_mb=memory_mb,
                    resume=resume, progress=progress, config=config, on_start=on_start, executor=executor)


def run_log(log, calibration=None, methods=None, *, jobs: int = 1, out=None,
            timeout: float | None = DEFAULT_TIMEOUT_S, memory_mb: float | None = DEFAULT_MEMORY_MB,
            progress: bool | None = False, on_start=None):
    """Run methods on a recorded log; score against ``torque_ref`` (and ``torque_true`` if present).

    Parameters
    ----------
    log, calibration
        Paths to CSV/Parquet logs, or :class:`SensorLog`. Methods are fit on
        ``calibration``; without one, on ``log`` itself if it has ``torque_ref`` (the
        rows then say ``calibration = self``: fit and scored on the same data).
    methods, jobs, out, timeout, memory_mb, progress, on_start
        As in :func:`run`.
    """
    from rippleb.data import read_log

    check_options(jobs=jobs, timeout=timeout, memory_mb=memory_mb)
    log_name = Path(log).name if not isinstance(log, SensorLog) else log.meta.get("source", "log")
    log = log if isinstance(log, SensorLog) else read_log(log)
    check_recording(log, log_name)
    if calibration is None:
        if log.torque_ref is None:
            raise InputError(f"{log_name}: no torque_ref column, so methods cannot be calibrated on it; "
                             "pass --calibration FILE")
        cal, label = log, "self"
    else:
        label = Path(calibration).name if not isinstance(calibration, SensorLog) else "calibration"
        cal = calibration if isinstance(calibration, SensorLog) else read_log(calibration, spec=log.spec)
        if cal.torque_ref is None:
            raise InputError(f"{label}: a calibration log needs a torque_ref column")
        check_recording(cal, label)
        check_calibration(cal, label, log)
    registry = Registry.discover()
    names = resolve_methods(registry, methods)
    scenario = f"log:{log_name}"
    case = Case(scenario, digest(log_bytes(log)), DEFAULT_CONDITION, 0, SCORED)
    cal_case = Case(CALIBRATION, digest(log_bytes(cal)), DEFAULT_CONDITION, 0, FITTING)
    plan = _Plan(calibration_label=label)
    plan.ready = {case: (log, Truth.from_recording(log)), cal_case: (cal, None)}
    for method in names:
        plan.add_row(RowKey(method, scenario, DEFAULT_CONDITION, 0), case, cal_case)
    return _execute(registry, plan, out=out, jobs=jobs, timeout=timeout, memory_mb=memory_mb,
                    resume=False, progress=progress, on_start=on_start,
                    config={"methods": names, "log": log_name, "conditions": [DEFAULT_CONDITION]})


def resolve_methods(registry: Registry, methods) -> list[str]:
    """Method names to run; unknown names raise :class:`InputError` with a suggestion."""
    wanted = split_names(methods)
    if methods is not None and not wanted:
        raise InputError("--methods is empty; give method names or 'all'")
    if not wanted:
        return registry.names("builtin")
    if wanted == ["all"]:
        return registry.names()
    for name in wanted:
        registry.get(name)
    return list(dict.fromkeys(wanted))


def check_options(*, jobs, timeout, memory_mb) -> None:
    """Refuse a job count below 1, and a negative or non-finite timeout or memory limit."""
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise InputError(f"--jobs must be a whole number of at least 1, got {jobs!r}")
    for option, value, unit in (("--timeout", timeout, "seconds"), ("--memory-limit", memory_mb, "MB")):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"{option} must be a positive number of {unit} (0 for no limit), got {value!r}")


def check_scenario(scenario) -> None:
    """Refuse a scenario outside the joint's position or speed limits, or not finite."""
    from rippleb import robot as arm

    model = arm.load_model(scenario.robot)
    joint = model.joints[model.getJointId(scenario.joint)]
    check_trajectory(scenario, float(model.velocityLimit[joint.idx_v]))


def check_recording(log: SensorLog, name: str) -> None:
    """Refuse a recorded log whose sample rate (from ``t``) is implausible."""
    fs = rate_from_t(log)
    if not MIN_FS <= fs <= MAX_FS:
        hint = " (is t in seconds?)" if fs < MIN_FS else ""
        raise InputError(f"{name}: column t gives a sample rate of {fs:.6g} Hz, outside the plausible "
                         f"{MIN_FS:g} Hz - {MAX_FS:g} Hz for a joint torque sensor{hint}")


def check_calibration(cal: SensorLog, name: str, scored: SensorLog) -> None:
    """Refuse a calibration log too short to fit on, or recorded at another rate than the scored log."""
    seconds = (cal.t[-1] - cal.t[0]) if len(cal) > 1 else 0.0
    if seconds < MIN_CALIBRATION_S:
        raise InputError(f"{name}: {len(cal)} samples ({seconds:.3g} s) is too short to calibrate on; "
                         f"record at least {MIN_CALIBRATION_S:g} s with the joint moving")
    fs, scored_fs = rate_from_t(cal), rate_from_t(scored)
    if not math.isclose(fs, scored_fs, rel_tol=1e-3):
        raise InputError(f"{name}: recorded at {fs:.6g} Hz, the scored log at {scored_fs:.6g} Hz; "
                         f"record both at one rate")


def rate_from_t(log: SensorLog) -> float:
    """The sample rate [Hz] given by the log's time stamps (its spec's ``fs`` if it has one sample)."""
    if len(log) < 2:
        return float(log.spec.fs)
    return 1.0 / float(np.median(np.diff(log.t)))


def default_out_dir() -> Path:
    """``runs/<timestamp>/`` in the current directory."""
    return Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")


# ----------------------------------------------------------------------------- the plan


@dataclass
class _Plan:
    """What a run must do: simulations (with the roles they feed), rows, and their cases."""

    calibration_label: str
    sims: dict = field(default_factory=dict)       # (scenario, content, condition, seed) -> (obj, {roles})
    rows: dict = field(default_factory=dict)       # RowKey -> (scored Case, calibration Case)
    ready: dict = field(default_factory=dict)      # Case -> (log, truth) given, not simulated

    def add_sim(self, scenario, case: Case) -> None:
        key = _sim_key(case)
        self.sims.setdefault(key, (scenario, set()))[1].add(case.role)

    def add_row(self, key: RowKey, case: Case, cal_case: Case) -> None:
        self.rows[key] = (case, cal_case)


def _sim_key(case: Case) -> tuple:
    return case.scenario, case.content, case.condition, case.seed


@dataclass(frozen=True)
class _Fit:
    method: str
    calibration: Case


@dataclass
class _State:
    """Everything the scheduler tracks; the truth lives here only."""

    plan: _Plan
    registry: Registry
    results: ResultsFile
    cache: Path
    log_dir: Path | None
    timeout: float | None
    run_id: str
    pending: list
    sims: dict = field(default_factory=dict)        # sim key -> "pending" | "running" | "done" | "failed: ..."
    artefacts: dict = field(default_factory=dict)   # Case -> Artefact
    truths: dict = field(default_factory=dict)      # Case -> Truth (scored cases with pending rows)
    fits: dict = field(default_factory=dict)        # _Fit -> "pending" | "running" | info dict
    lengths: dict = field(default_factory=dict)     # Case -> (n_samples, n_ticks)
    open_rows: dict = field(default_factory=dict)   # scored Case -> rows not yet recorded


def _execute(registry, plan: _Plan, *, out, jobs, timeout, memory_mb, resume, progress, config,
             on_start=None, executor=None):
    with _run_dir(out, resume, config) as out_dir:
        if on_start is not None:
            on_start()
        results = ResultsFile(out_dir / "results.csv" if out_dir else None, resume=resume)
        if resume:
            _say_retried(results.drop_environmental(), out_dir)
        done = results.done_keys()
        rows = sorted(k for k in plan.rows if row_key(k.fields()) not in done)
        with tempfile.TemporaryDirectory(prefix="rippleb-cache-") as cache:
            state = _State(plan, registry, results, Path(cache), _log_dir(out_dir), timeout,
                           time.strftime("%Y%m%dT%H%M%S"), rows)
            with _progress(len(rows), progress) as bar, _sigterm_as_interrupt():
                if executor is None:
                    _prepare_cases(state)
                    _schedule(Pool(int(jobs), memory_mb), state, bar)
                else:  # whole rows run elsewhere; this process only records them
                    _count_open_rows(state)
                    executor.run(_row_tasks(state, memory_mb),
                                 lambda key, fields: _record(state, key, bar, **fields))
        results.flush()
    return results.frame()


def _say_retried(dropped: list[dict], out_dir) -> None:
    if dropped:
        reasons = sorted({str(r.get("message", ""))[len(ENVIRONMENT):][:60] for r in dropped})
        warnings.warn(f"{out_dir}/results.csv: running {len(dropped)} row(s) again that failed for an "
                      f"environmental reason ({'; '.join(reasons)})", RunWarning, stacklevel=3)


def _prepare_cases(state: _State) -> None:
    needed = {c for key in state.pending for c in state.plan.rows[key]}
    for case in needed:
        if case in state.plan.ready:
            log, truth = state.plan.ready[case]
            state.artefacts[case] = store(state.cache / case.file_name(),
                                          log_bytes(job_fns.visible_log(log, case.role)))
            if truth is not None:
                state.truths[case] = truth
            state.lengths[case] = _lengths(log)
    state.sims = {_sim_key(c): "pending" for c in needed if c not in state.plan.ready}
    state.fits = {_Fit(k.method, state.plan.rows[k][1]): "pending" for k in state.pending}
    _count_open_rows(state)


def _count_open_rows(state: _State) -> None:
    for key in state.pending:
        case = state.plan.rows[key][0]
        state.open_rows[case] = state.open_rows.get(case, 0) + 1


def _row_tasks(state: _State, memory_mb) -> list:
    """What an executor needs to run each pending row anywhere: the scenarios themselves
    (nothing read from this machine's files), the key, and the limits."""
    tasks = []
    for key in state.pending:
        case, cal_case = state.plan.rows[key]
        tasks.append(RowTask(key, state.plan.sims[_sim_key(case)][0], state.plan.sims[_sim_key(cal_case)][0],
                             state.timeout, memory_mb, state.run_id))
    return tasks


def run_task(task: "RowTask", cache: Path, registry: Registry, memo: dict | None = None) -> dict:
    """Run one row here, exactly as a local run does (same pool, isolation, limits, scoring).

    For an executor's worker: the row's simulations are recomputed from its seed (or taken
    from ``memo``, which this call also fills: ``Case -> (artefact, truth, lengths)`` and
    ``_Fit -> fit info``, valid while their files in ``cache`` exist). Returns the row's
    fields without its key columns, with the system information of this machine.
    """
    key = task.key
    cal_case = Case(CALIBRATION, scenario_hash(task.calibration), DEFAULT_CONDITION, key.seed, FITTING)
    case = Case(key.scenario, scenario_hash(task.scenario), key.condition, key.seed, SCORED)
    plan = _Plan(calibration_label=CALIBRATION)
    plan.add_sim(task.calibration, cal_case)
    plan.add_sim(task.scenario, case)
    plan.add_row(key, case, cal_case)
    state = _State(plan, registry, ResultsFile(None), Path(cache), None, task.timeout, task.run_id, [key])
    _prepare_cases(state)
    state.open_rows[case] += 1  # keep the truth after the row is recorded, for the memo
    memo = {} if memo is None else memo
    _restore(state, memo, case, cal_case)
    _schedule(Pool(1, task.memory_mb), state, _NoBar())
    for c in (case, cal_case):
        if c in state.artefacts and (c.role == FITTING or c in state.truths):
            memo[c] = (state.artefacts[c], state.truths.get(c), state.lengths.get(c))
    for fit, info in state.fits.items():
        if isinstance(info, dict) and info.get("status") == "ok" and isinstance(info.get("fitted"), dict):
            memo[fit] = info
    row = state.results.rows[0]
    return {k: v for k, v in row.items() if k not in key.fields() and k not in ("calibration", "run_id")}


def _restore(state: _State, memo: dict, *cases: Case) -> None:
    """Take simulations and fits an earlier row of this process left (files checked by hash on use)."""
    for sim, (_, roles) in state.plan.sims.items():
        known = [memo.get(Case(*sim, role)) for role in roles]
        if all(k is not None and Path(k[0].path).is_file() for k in known):
            for role, (artefact, truth, lengths) in zip(roles, known):
                c = Case(*sim, role)
                state.artefacts[c] = artefact
                if truth is not None:
                    state.truths[c] = truth
                if lengths is not None:
                    state.lengths[c] = lengths
            state.sims[sim] = "done"
    for fit in state.fits:
        info = memo.get(fit)
        if info is not None and Path(info["fitted"]["path"]).is_file():
            state.fits[fit] = info


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass


@dataclass(frozen=True)
class RowTask:
    """One row as a self-contained task: an executor recomputes its simulations from the seed."""

    key: RowKey
    scenario: object
    calibration: object
    timeout: float | None
    memory_mb: float | None
    run_id: str


def _lengths(log: SensorLog) -> tuple[int, int]:
    return len(log), -(-len(log) // log.spec.block_size)


# ----------------------------------------------------------------------------- scheduling


def _schedule(pool: Pool, state: _State, bar) -> None:
    try:
        while state.pending or pool.busy:
            while pool.free and state.pending:
                if not _start_next(pool, state, bar):
                    break
            for fin in pool.wait():
                if isinstance(fin.key, tuple):
                    _finish_sim(fin, state)
                elif isinstance(fin.key, _Fit):
                    state.fits[fin.key] = _fit_outcome(fin, state)
                else:
                    _finish_row(fin, state, bar)
    finally:
        pool.kill_all()


def _start_next(pool: Pool, state: _State, bar) -> bool:
    """Start one job: the first row whose inputs exist, else its fit, else the next simulation."""
    for key in list(state.pending):
        case, cal_case = state.plan.rows[key]
        failed = [state.sims.get(_sim_key(c), "") for c in (case, cal_case)]
        failed = [f for f in failed if f.startswith("failed")]
        if failed:
            _record(state, key, bar, status="error", message=f"simulation {failed[0]}")
            return True
        if not all(c in state.artefacts for c in (case, cal_case)):
            continue
        fit = _Fit(key.method, cal_case)
        if state.fits[fit] == "pending":
            state.fits[fit] = "running"
            pool.submit(fit, _fit_job(fit, state), state.timeout, _output(state, f"fit--{key.method}--{key.seed}"))
            return True
        if state.fits[fit] == "running":
            continue
        state.pending.remove(key)
        if state.fits[fit]["status"] != "ok":
            _record(state, key, bar, **_row_fields(state.fits[fit]))
            return True
        n_samples, _ = state.lengths[case]
        pool.submit(key, _row_job(key, state, state.fits[fit]), state.timeout,
                    _output(state, f"{key.method}--{key.scenario}--{key.condition}--{key.seed}"),
                    max_bytes=24 * n_samples + 2**20)
        return True
    for sim, st in state.sims.items():
        if st == "pending":
            state.sims[sim] = "running"
            scenario, roles = state.plan.sims[sim]
            paths = {role: str(state.cache / Case(*sim, role).file_name()) for role in roles}
            pool.submit(sim, _sim_job(scenario, sim, paths), None, None)
            return True
    return False


def _output(state: _State, stem: str) -> str | None:
    from rippleb.rows import safe_name

    return str(state.log_dir / f"{safe_name(stem)}.txt") if state.log_dir else None


def _sim_job(scenario, sim: tuple, paths: dict):
    def job():
        return job_fns.simulate_case(scenario, sim[3], sim[2], paths)
    return job


def _finish_sim(fin, state: _State) -> None:
    if fin.kind != "done":
        state.sims[fin.key] = f"failed: {_why(fin, state)}"
        return
    arrays, info = unpack(fin.value)
    for role, ref in info["artefacts"].items():
        case = Case(*fin.key, role)
        state.artefacts[case] = Artefact(ref["path"], ref["sha256"])
        if role == SCORED:
            truth = job_fns.truth_from_message(arrays, info)
            state.truths[case] = truth
            n_samples = len(truth.eval_mask)
            state.lengths[case] = (n_samples, -(-n_samples // int(info["block_size"])))
    state.sims[fin.key] = "done"


def _fit_job(fit: _Fit, state: _State):
    calibration = state.artefacts[fit.calibration]
    path = state.cache / f"fit-{digest(repr(fit).encode())[:32]}.pkl"
    registry = state.registry

    def job():
        return job_fns.fit_method(fit.method, None, calibration, path, registry)
    return job


def _fit_outcome(fin, state: _State) -> dict:
    if fin.kind == "done":
        try:
            return unpack(fin.value)[1]
        except Exception as exc:  # noqa: BLE001 - whatever a fit sends, it is one status line
            return {"status": "error", "message": f"fit sent an unreadable result ({type(exc).__name__})"}
    if fin.kind == "timeout":
        return {"status": "timeout", "message": f"fit killed after {state.timeout:g} s"}
    return {"status": "error", "message": f"fit: {_why(fin, state)}"}


def _row_job(key: RowKey, state: _State, fit: dict):
    case, cal_case = state.plan.rows[key]
    evaluation, calibration = state.artefacts[case], state.artefacts[cal_case]
    fitted = Artefact(**fit["fitted"]) if isinstance(fit.get("fitted"), dict) else None
    fit_info = {k: fit[k] for k in ("params", "fit_s") if k in fit} if fitted else None
    registry = state.registry

    def job():
        return job_fns.row_message(job_fns.run_row(key.method, None, calibration, evaluation, registry,
                                                   fitted=fitted, fit_info=fit_info))
    return job


def _finish_row(fin, state: _State, bar) -> None:
    key = fin.key
    case = state.plan.rows[key][0]
    if fin.kind == "done":
        fields = _score_row(fin.value, state, case)
    elif fin.kind == "timeout":
        fields = {"status": "timeout", "message": f"killed after {state.timeout:g} s"}
    else:
        fields = {"status": "error", "message": _why(fin, state)}
    _record(state, key, bar, wall_s=fin.wall_s, **fields)


def _score_row(value: bytes, state: _State, case: Case) -> dict:
    """Score what a row sent against the truth held here; trust only its estimate."""
    try:
        arrays, info = unpack(value)
    except Exception as exc:  # noqa: BLE001 - a row's bytes are untrusted
        return {"status": "error", "message": f"the row sent an unreadable result ({type(exc).__name__})"}
    fields = _row_fields(info)
    if fields["status"] != "ok":
        return fields
    truth = state.truths[case]
    n_samples, n_ticks = state.lengths[case]
    checked = job_fns.check_estimate(arrays, n_samples, n_ticks)
    if isinstance(checked, str):
        return {**fields, "status": "invalid", "message": checked}
    estimate, ticks = checked
    fields["n_samples"] = n_samples
    fields.update(score(estimate, truth))
    fields.update(tick_stats(ticks, n_samples))
    return fields


def _row_fields(info: dict) -> dict:
    """The fields a job may set, type-checked: a job cannot write metrics or keys."""
    status = info.get("status") if info.get("status") in STATUSES else "error"
    fields = {"status": status, "message": str(info.get("message", ""))[:500],
              "params": str(info.get("params", ""))[:2000]}
    fit_s = info.get("fit_s")
    if isinstance(fit_s, (int, float)) and math.isfinite(fit_s):
        fields["fit_s"] = float(fit_s)
    if status != info.get("status"):
        fields["message"] = f"the row sent an unknown status {str(info.get('status'))[:40]!r}"
    return fields


def _record(state: _State, key: RowKey, bar, **fields) -> None:
    if key in state.pending:
        state.pending.remove(key)
    case, cal_case = state.plan.rows[key]
    # An executor's fields may carry the system information of the machine that ran the row.
    row = {**system_info(), **key.fields(), **fields, "calibration": state.plan.calibration_label,
           "scenario_sha256": case.content, "run_id": state.run_id}
    state.results.add(row)
    bar.update()
    # The truth of a case is kept only while rows of it are open.
    state.open_rows[case] -= 1
    if not state.open_rows[case]:
        state.truths.pop(case, None)


def _why(fin, state: _State) -> str:
    if fin.kind == "raised":
        text = fin.value
        if any(marker in text for marker in ("No space left", "Disk quota")):
            return f"{ENVIRONMENT}{text}"
        return text
    if fin.kind == "timeout":
        return f"killed after {state.timeout:g} s"
    if fin.kind == "oversized":
        return f"sent {fin.value} bytes, more than a row's result can hold"
    code = fin.value
    if code is not None and code < 0:
        name = signal.Signals(-code).name
        if -code == signal.SIGKILL:  # not our timeout: the OOM killer or a user
            return f"{ENVIRONMENT}process killed by {name} (out of memory, or killed from outside)"
        return f"process killed by signal {name} (a crash?)"
    return f"process exited with code {code} before reporting"


# ----------------------------------------------------------------------------- the run directory


@contextlib.contextmanager
def _run_dir(out, resume: bool, config: dict):
    """Create (or, to resume, check) the run directory and hold its lock while the run writes."""
    if out is None:
        yield None
        return
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise InputError(f"{out}: cannot write the output directory: {exc.strerror or exc}") from None
    with _locked(out):
        if resume:
            _check_resume(out, config)
        else:
            kept = sorted(p.name for p in out.iterdir() if p.name != ".lock")
            if kept:
                raise InputError(f"{out}: not empty (holds {', '.join(kept[:3])}"
                                 f"{', ...' if len(kept) > 3 else ''}); finish that run with "
                                 f"--resume {out}, or choose another --out")
            with atomic_path(out / "run.json") as tmp:
                tmp.write_text(json.dumps(config, indent=1) + "\n")
        yield out


@contextlib.contextmanager
def _locked(out: Path):
    handle = open(out / ".lock", "a")
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{out}: another rippleb run is writing this directory; wait for it to "
                             f"end or choose another --out") from None
        yield
    finally:
        handle.close()


def _check_resume(out: Path, config: dict) -> None:
    saved = read_config(out)
    saved.setdefault("conditions", [DEFAULT_CONDITION])
    differ = [name for name in ("methods", "scenarios", "conditions", "seeds", "log", "sweep")
              if saved.get(name) != config.get(name)]
    if differ:
        name = differ[0]
        raise InputError(f"{out / 'run.json'}: --resume finishes the run it describes ({name} "
                         f"{saved.get(name)}, asked {config.get(name)}); drop the selection options "
                         f"or choose another --out")


def read_config(out) -> dict:
    """The selection saved by a run in ``out/run.json`` (for ``--resume``)."""
    path = Path(out) / "run.json"
    if not path.is_file():
        raise InputError(f"{Path(out)}: nothing to resume (no run.json: no run was started there)")
    try:
        config = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot resume this run: {getattr(exc, 'strerror', None) or exc}") from None
    if not isinstance(config, dict) or not isinstance(config.get("methods"), list):
        raise InputError(f"{path}: not a rippleb run file")
    if "log" in config:
        raise InputError(f"{path}: a run on a recorded log cannot be resumed; run it again")
    return config


def _log_dir(out_dir: Path | None) -> Path | None:
    if out_dir is None:
        return None
    logs = out_dir / "logs"
    logs.mkdir(exist_ok=True)
    return logs


@contextlib.contextmanager
def _progress(total: int, enabled):
    from tqdm import tqdm

    with tqdm(total=total, disable=(None if enabled is None else not enabled), file=sys.stderr,
              unit="row", dynamic_ncols=True) as bar:
        yield bar


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """Treat SIGTERM like Ctrl-C, so that both end with the finished rows on disk."""
    def handler(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")
    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _seed_list(seeds, seed_start: int) -> list[int]:
    if isinstance(seeds, (int, np.integer)):
        if seeds < 1:
            raise InputError(f"--seeds must be at least 1, got {seeds}")
        if seed_start < 0:
            raise InputError(f"--seed-start must be a non-negative integer, got {seed_start}")
        return list(range(seed_start, seed_start + int(seeds)))
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise InputError("no seeds given")
    if any(s < 0 for s in seeds):
        raise InputError(f"seeds must be non-negative integers, got {min(seeds)}")
    return list(dict.fromkeys(seeds))


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
        fields.update(score(result["estimate"], truth))
        fields.update(tick_stats(result["ticks"], len(evaluation)))
    return fields
