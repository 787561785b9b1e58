"""The causal streaming runner: every method x scenario x seed, one killable process each.

A run has two kinds of jobs, both in forked children of :class:`rippleb.pool.Pool`:

* a *simulation* job per (scenario, seed), including ``calibration`` per seed: it calls
  ``simulate(scenario, seed)`` once and stores the log and the truth the metrics need in
  an ``.npz`` file of the run's cache (plain arrays, read with ``allow_pickle=False``);
* a *fit* job per method x calibration log (i.e. per method and seed): it ``fit``s the
  method on the calibration log (with ``torque_ref``) once, as on a real device, and
  pickles the fitted method into the cache;
* a *row* job per method x scenario x seed, started once its simulations and its fit
  exist: it loads the fitted method, ``reset``s it, streams the evaluation log in blocks of
  ``spec.block_size`` samples (:func:`rippleb.streaming.stream`), and scores the estimate
  (:mod:`rippleb.metrics`). Every row of one fit starts from the same fitted state, so the
  rows equal those of fitting in each row. A method that cannot be pickled is fitted in
  each of its rows instead; a fit that fails gives each of its rows the fit's status.

Each row ends as ``ok``, ``error`` (an exception, a memory-limit hit, a crash),
``invalid`` (wrong length or dtype, NaN) or ``timeout`` (killed at ``timeout`` seconds),
and is written to ``DIR/results.csv`` as soon as it ends (:class:`rippleb.results.ResultsFile`).
SIGINT or SIGTERM kills the running children and leaves the finished rows on disk;
``resume=True`` runs only the rows missing from ``DIR/results.csv``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import pickle
import re
import signal
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rippleb.data import JointSpec, SensorLog
from rippleb.errors import InputError
from rippleb.files import atomic_path
from rippleb.metrics import Truth, score, tick_stats
from rippleb.pool import Pool
from rippleb.registry import Registry, one_line
from rippleb.results import ResultsFile, system_info
from rippleb.streaming import InvalidOutput, prepare_blocks, stream

DEFAULT_SEEDS = 3
DEFAULT_TIMEOUT_S = 300.0
DEFAULT_MEMORY_MB = 4096.0
CALIBRATION = "calibration"
_ARRAYS = ("moving", "wave_angle", "eval_mask")


@dataclass(frozen=True)
class _Row:
    method: str
    scenario: str
    seed: int


@dataclass(frozen=True)
class _Case:
    scenario: str
    seed: int


@dataclass(frozen=True)
class _Fit:
    method: str
    calibration: _Case


def run(methods=None, scenarios=None, seeds=DEFAULT_SEEDS, *, seed_start: int = 0, jobs: int = 1,
        out=None, timeout: float | None = DEFAULT_TIMEOUT_S, memory_mb: float | None = DEFAULT_MEMORY_MB,
        resume: bool = False, progress: bool | None = False):
    """Run methods on simulated scenarios and return one row per method x scenario x seed.

    Parameters
    ----------
    methods
        Method names (a list or ``"a,b"``); None for every built-in method, ``"all"`` for
        every built-in and plugin method.
    scenarios
        Scenario names or paths to ``.toml`` files; None for every scored built-in.
    seeds
        The number of seeds (devices) ``seed_start .. seed_start + seeds - 1``, or a list of seeds.
    seed_start
        First seed when ``seeds`` is a number.
    jobs
        Rows run at once, each in its own process.
    out
        Directory for ``results.csv`` (created), or None to keep the rows in memory only.
    timeout
        Seconds one row (fit and run) may take before it is killed; None for no limit.
    memory_mb
        Address space one row may add [MB] before allocations fail; None for no limit.
    resume
        Keep the rows already in ``out/results.csv`` and run only the missing ones.
    progress
        Show a progress bar on stderr (None: only on a terminal).

    Returns
    -------
    pandas.DataFrame
        The rows, standard columns first (see ``rippleb.results.COLUMNS``).
    """
    from rippleb.scenario import load_scenario, scored_scenarios

    registry = Registry.discover()
    names = resolve_methods(registry, methods)
    # Refuse a trajectory outside the joint's limits here, as one line, not as error rows.
    scenario_objs = [load_scenario(s).check_limits() for s in (_split(scenarios) or scored_scenarios())]
    seed_list = _seed_list(seeds, seed_start)
    cases = {s.name: s for s in scenario_objs}
    cases.setdefault(CALIBRATION, load_scenario(CALIBRATION))
    rows = [_Row(m, s.name, k) for k in seed_list for s in scenario_objs for m in names]
    calibration = {r: _Case(CALIBRATION, r.seed) for r in rows}
    jobs_sim = {}
    for k in seed_list:
        jobs_sim[_Case(CALIBRATION, k)] = (cases[CALIBRATION], k)
        for s in scenario_objs:
            jobs_sim[_Case(s.name, k)] = (s, k)
    given = _split(scenarios) or [s.name for s in scenario_objs]
    config = {"methods": names, "seeds": seed_list,
              "scenarios": [str(Path(s).resolve()) if s.endswith(".toml") else s for s in given]}
    return _execute(registry, rows, calibration, jobs_sim, {}, out=out, jobs=jobs, timeout=timeout,
                    memory_mb=memory_mb, resume=resume, progress=progress, config=config,
                    calibration_label=CALIBRATION)


def run_log(log, calibration=None, methods=None, *, jobs: int = 1, out=None,
            timeout: float | None = DEFAULT_TIMEOUT_S, memory_mb: float | None = DEFAULT_MEMORY_MB,
            progress: bool | None = False):
    """Run methods on a recorded log; score against ``torque_ref`` (and ``torque_true`` if present).

    Parameters
    ----------
    log, calibration
        Paths to CSV/Parquet logs, or :class:`SensorLog`. Methods are fit on
        ``calibration``; without one, on ``log`` itself if it has ``torque_ref`` (the
        rows then say ``calibration = self``: fit and scored on the same data).
    methods, jobs, out, timeout, memory_mb, progress
        As in :func:`run`.
    """
    from rippleb.data import read_log

    log_name = Path(log).name if not isinstance(log, SensorLog) else log.meta.get("source", "log")
    log = log if isinstance(log, SensorLog) else read_log(log)
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
    registry = Registry.discover()
    names = resolve_methods(registry, methods)
    scenario = f"log:{log_name}"
    rows = [_Row(m, scenario, 0) for m in names]
    ready = {_Case(scenario, 0): (log, Truth.from_recording(log)),
             _Case(CALIBRATION, 0): (cal, Truth.from_recording(cal))}
    calibration_of = {r: _Case(CALIBRATION, 0) for r in rows}
    return _execute(registry, rows, calibration_of, {}, ready, out=out, jobs=jobs, timeout=timeout,
                    memory_mb=memory_mb, resume=False, progress=progress,
                    config={"methods": names, "log": log_name}, calibration_label=label)


def resolve_methods(registry: Registry, methods) -> list[str]:
    """Method names to run; unknown names raise :class:`InputError` with a suggestion."""
    wanted = _split(methods)
    if not wanted:
        return registry.names("builtin")
    if wanted == ["all"]:
        return registry.names()
    for name in wanted:
        registry.get(name)
    return list(dict.fromkeys(wanted))


def default_out_dir() -> Path:
    """``runs/<timestamp>/`` in the current directory."""
    return Path("runs") / _dt.datetime.now().strftime("%Y%m%d-%H%M%S")


def _execute(registry, rows, calibration_of, sim_jobs, ready, *, out, jobs, timeout, memory_mb,
             resume, progress, config, calibration_label):
    out_dir = _prepare_out(out, resume, config)
    results = ResultsFile(out_dir / "results.csv" if out_dir else None, resume=resume)
    done = results.done_keys()
    rows = [r for r in rows if (r.method, r.scenario, r.seed) not in done]
    needed = {c for r in rows for c in (_Case(r.scenario, r.seed), calibration_of[r])}
    with _cache_dir(out_dir) as cache:
        paths = {c: cache / f"{_safe(c.scenario)}--{c.seed}.npz" for c in needed}
        fits = {_Fit(r.method, calibration_of[r]) for r in rows}
        # Fitted methods live only in this run's own cache; a resumed run fits again.
        paths.update({f: cache / f"fit--{_safe(f.method)}--{_safe(f.calibration.scenario)}--"
                             f"{f.calibration.seed}.pkl" for f in fits})
        for case, (log, truth) in ready.items():
            if case in needed:
                save_case(paths[case], log, truth)
        state = {c: ("done" if c in ready or paths[c].is_file() else "pending") for c in needed}
        state.update({f: "pending" for f in fits})
        context = _Context(registry, results, calibration_of, paths, calibration_label,
                           _log_dir(out_dir), timeout, time.strftime("%Y%m%dT%H%M%S"))
        with _progress(len(rows), progress) as bar, _sigterm_as_interrupt():
            _schedule(Pool(max(1, int(jobs)), memory_mb), rows, sim_jobs, state, context, bar)
    return results.frame()


@dataclass
class _Context:
    registry: Registry
    results: ResultsFile
    calibration_of: dict
    paths: dict
    calibration_label: str
    log_dir: Path | None
    timeout: float | None
    run_id: str


def _schedule(pool, rows, sim_jobs, state, ctx, bar) -> None:
    pending = list(rows)
    try:
        while pending or pool.busy:
            while pool.free and pending:
                if not _start_next(pool, pending, sim_jobs, state, ctx, bar):
                    break
            for fin in pool.wait():
                if isinstance(fin.key, _Case):
                    ok = fin.kind == "done" and ctx.paths[fin.key].is_file()
                    state[fin.key] = "done" if ok else f"failed: {_why(fin)}"
                elif isinstance(fin.key, _Fit):
                    state[fin.key] = _fit_outcome(fin, ctx)
                else:
                    _finish_row(fin, ctx, bar)
    finally:
        pool.kill_all()


def _start_next(pool, pending, sim_jobs, state, ctx, bar) -> bool:
    """Start one job: the first row whose simulations exist, else the next simulation."""
    for row in pending:
        cases = (_Case(row.scenario, row.seed), ctx.calibration_of[row])
        failed = [state[c] for c in cases if state[c].startswith("failed")]
        if failed:
            pending.remove(row)
            ctx.results.add(_row_dict(row, ctx, status="error",
                                      message=f"simulation {failed[0]}"))
            bar.update()
            return True
        if all(state[c] == "done" for c in cases):
            fit = _Fit(row.method, ctx.calibration_of[row])
            if state[fit] == "pending":
                state[fit] = "running"
                output = str(ctx.log_dir / f"fit--{_safe(row.method)}--{row.seed}.txt") if ctx.log_dir else None
                pool.submit(fit, _fit_job(fit, ctx), ctx.timeout, output)
                return True
            if state[fit] == "running":
                continue
            pending.remove(row)
            if state[fit]["status"] != "ok":
                ctx.results.add(_row_dict(row, ctx, **state[fit]))
                bar.update()
                return True
            output = str(ctx.log_dir / f"{_safe(row.method)}--{_safe(row.scenario)}--{row.seed}.txt") \
                if ctx.log_dir else None
            pool.submit(row, _row_job(row, ctx, state[fit]), ctx.timeout, output)
            return True
    for case, st in state.items():
        if isinstance(case, _Case) and st == "pending":
            state[case] = "running"
            scenario, seed = sim_jobs[case]
            pool.submit(case, _sim_job(scenario, seed, ctx.paths[case]), None, None)
            return True
    return False


def _sim_job(scenario, seed, path):
    def job():
        from rippleb.simulator import simulate

        sim = simulate(scenario, seed)
        save_case(path, sim.log, Truth.from_simulation(sim))
    return job


def _fit_job(fit, ctx):
    cal_path, out_path = ctx.paths[fit.calibration], ctx.paths[fit]
    entry = ctx.registry.get(fit.method)

    def job():
        return fit_and_save(entry.load(), load_case(cal_path)[0], out_path)
    return job


def fit_and_save(cls, calibration: SensorLog, path: Path) -> dict:
    """Fit a new ``cls`` on ``calibration`` and pickle it to ``path``; return ``status``,
    ``message``, ``params``, ``fit_s`` and whether it was ``pickled``."""
    result = {"status": "ok", "message": "", "params": ""}
    t0 = time.perf_counter()
    try:
        method = cls()
        result["params"] = _params_json(method)
        method.fit(calibration.for_method(keep_ref=True))
    except Exception as exc:  # the fit's failure becomes the status of each of its rows
        import traceback

        traceback.print_exc()
        return {**result, "status": "error", "message": one_line(exc)}
    result["fit_s"] = time.perf_counter() - t0
    try:
        blob = pickle.dumps(method, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # not picklable (a lambda, a handle): its rows fit it themselves
        return {**result, "pickled": False}
    with atomic_path(path) as tmp:
        tmp.write_bytes(blob)
    return {**result, "pickled": True}


def _fit_outcome(fin, ctx) -> dict:
    if fin.kind == "done":
        return fin.value
    if fin.kind == "timeout":
        return {"status": "timeout", "message": f"fit killed after {ctx.timeout:g} s"}
    return {"status": "error", "message": f"fit: {_why(fin)}"}


def _row_job(row, ctx, fit: dict):
    cal_path, eval_path = ctx.paths[ctx.calibration_of[row]], ctx.paths[_Case(row.scenario, row.seed)]
    fitted_path = ctx.paths[_Fit(row.method, ctx.calibration_of[row])]
    entry = ctx.registry.get(row.method)

    def job():
        if not fit.get("pickled"):
            return evaluate(entry.load(), load_case(cal_path)[0], *load_case(eval_path))
        entry.load()  # import the method's module before unpickling its instance
        method = pickle.loads(fitted_path.read_bytes())
        evaluation, truth = load_case(eval_path)
        fields = {"status": "ok", "message": "", "n_samples": len(evaluation), "params": fit["params"],
                  "fit_s": fit["fit_s"]}
        return run_fitted(method, evaluation, truth, fields)
    return job


def evaluate(cls, calibration: SensorLog, evaluation: SensorLog, truth: Truth, params=None) -> dict:
    """One row's result fields: status, message, metrics, timing, ``params``.

    Runs in the row's child process; exceptions of the method become ``error``, bad
    output ``invalid``.
    """
    result = {"status": "ok", "message": "", "n_samples": len(evaluation), "params": ""}
    t0 = time.perf_counter()
    try:
        method = cls(**(params or {}))
        result["params"] = _params_json(method)
        method.fit(calibration.for_method(keep_ref=True))
        result["fit_s"] = time.perf_counter() - t0
    except Exception as exc:  # any failure of the method is its row's status, never the run's
        import traceback

        traceback.print_exc()
        return {**result, "status": "error", "message": one_line(exc)}
    return run_fitted(method, evaluation, truth, result)


def run_fitted(method, evaluation: SensorLog, truth: Truth, result: dict) -> dict:
    """``reset`` a fitted method, stream ``evaluation`` through it and score it into ``result``."""
    try:
        visible = evaluation.for_method(keep_ref=False)
        method.reset(visible.spec)
        blocks = prepare_blocks(visible)
        estimate, ticks = stream(method.step, blocks, len(visible))
    except InvalidOutput as exc:
        return {**result, "status": "invalid", "message": str(exc)}
    except Exception as exc:  # any failure of the method is its row's status, never the run's
        import traceback

        traceback.print_exc()
        return {**result, "status": "error", "message": one_line(exc)}
    result.update(score(estimate, truth))
    result.update(tick_stats(ticks, len(visible)))
    return result


def _finish_row(fin, ctx, bar) -> None:
    row = fin.key
    if fin.kind == "done":
        fields = fin.value
    elif fin.kind == "timeout":
        fields = {"status": "timeout", "message": f"killed after {ctx.timeout:g} s"}
    else:
        fields = {"status": "error", "message": _why(fin)}
    ctx.results.add(_row_dict(row, ctx, wall_s=fin.wall_s, **fields))
    bar.update()


def _row_dict(row, ctx, **fields) -> dict:
    return {"method": row.method, "scenario": row.scenario, "seed": row.seed, **fields,
            "calibration": ctx.calibration_label, **system_info(), "run_id": ctx.run_id}


def _why(fin) -> str:
    if fin.kind == "raised":
        return fin.value
    if fin.kind == "died":
        code = fin.value
        if code is not None and code < 0:
            return f"process killed by signal {signal.Signals(-code).name} (memory limit or crash?)"
        return f"process exited with code {code} before reporting"
    return fin.kind


def save_case(path: Path, log: SensorLog, truth: Truth) -> None:
    """Store a log and its truth as plain arrays (no pickle), atomically."""
    arrays = {name: values for name, values in log.columns().items()}
    arrays.update({name: getattr(truth, name) for name in _ARRAYS})
    arrays["spec"] = np.array(json.dumps(asdict(log.spec)))
    arrays["meta"] = np.array(json.dumps(log.meta, default=str))
    with atomic_path(path) as tmp:
        np.savez(tmp, **arrays)


def load_case(path: Path) -> tuple[SensorLog, Truth]:
    """The log and truth stored by :func:`save_case`."""
    with np.load(path, allow_pickle=False) as data:
        spec = JointSpec(**json.loads(str(data["spec"])))
        cols = {name: data[name] for name in data.files if name not in _ARRAYS + ("spec", "meta")}
        log = SensorLog(spec=spec, meta=json.loads(str(data["meta"])), **cols)
        truth = Truth(fs=spec.fs, torque_true=log.torque_true, torque_ref=log.torque_ref,
                      **{name: data[name] for name in _ARRAYS})
    return log, truth


def _prepare_out(out, resume: bool, config: dict) -> Path | None:
    if out is None:
        return None
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise InputError(f"{out}: cannot write the output directory: {exc.strerror or exc}") from None
    if resume and not (out / "results.csv").is_file():
        raise InputError(f"{out}: nothing to resume (no results.csv)")
    if not resume:
        (out / "run.json").write_text(json.dumps(config, indent=1) + "\n")
    return out


def read_config(out) -> dict:
    """The selection saved by a run in ``out/run.json`` (for ``--resume``)."""
    path = Path(out) / "run.json"
    try:
        config = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot resume this run: {getattr(exc, 'strerror', None) or exc}") from None
    if not isinstance(config, dict) or "methods" not in config:
        raise InputError(f"{path}: not a rippleb run file")
    return config


@contextlib.contextmanager
def _cache_dir(out_dir: Path | None):
    if out_dir is None:
        with tempfile.TemporaryDirectory(prefix="rippleb-") as tmp:
            yield Path(tmp)
        return
    cache = out_dir / ".cache"
    cache.mkdir(exist_ok=True)
    yield cache
    # Only a completed run drops its cache; an interrupted one keeps it for --resume.
    for path in cache.iterdir():
        path.unlink()
    cache.rmdir()


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


def _split(value) -> list[str]:
    if value is None:
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return [str(i).strip() for i in items if str(i).strip()]


def _seed_list(seeds, seed_start: int) -> list[int]:
    if isinstance(seeds, (int, np.integer)):
        if seeds < 1:
            raise InputError(f"--seeds must be at least 1, got {seeds}")
        if seed_start < 0:
            raise InputError(f"--seed-start must be a non-negative integer, got {seed_start}")
        return list(range(seed_start, seed_start + int(seeds)))
    seeds = [int(s) for s in seeds]
    if any(s < 0 for s in seeds):
        raise InputError(f"seeds must be non-negative integers, got {min(seeds)}")
    return seeds


def _params_json(method) -> str:
    try:
        return json.dumps(method.get_params(), sort_keys=True, default=repr)
    except Exception:  # a broken get_params must not cost the row
        return ""


def _safe(text: str) -> str:
    """A file-name fragment that cannot leave its directory."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).lstrip(".") or "_"
