"""Scheduling a planned run: simulations, fits and rows as isolated jobs, scored here.

The state (:class:`State`) holds the only copy of the truth, per scored case and only while rows of
it are open. Jobs are :mod:`rippleb.engine.jobs` functions, given a row's method label as name and params
(:func:`rippleb.variants.split_label`); what they send back is read as plain arrays and typed fields."""

from __future__ import annotations

import contextlib
import functools
import sys
import warnings
from pathlib import Path

from rippleb.engine.process import isolation
from rippleb.engine.process.landlock import own_package
from rippleb.engine import jobs as job_fns
from rippleb.interrupts import check_interrupted
from rippleb.engine.cache import Artefact, TamperedError, digest, load_log, unpack
from rippleb.data import SensorLog
from rippleb.scoring.row import score_row
from rippleb.engine.process.pool import Pool
from rippleb.registry import one_line
from rippleb.variants import split_label
from rippleb.engine.results import ENVIRONMENT, RunWarning, system_info
from rippleb.engine.rows import SCORED, Case, RowKey
from rippleb.engine.outcomes import environment_first, row_fields, why
from rippleb.engine.sealing import SEALED_COLUMN
from rippleb.engine.plan import (Fit, Plan, State, prepare_cases, release_fit, release_rows,  # noqa: F401 - re-exported
                                 sim_key)


def say_retried(dropped: list[dict], out_dir) -> None:
    if dropped:
        reasons = sorted({str(r.get("message", ""))[len(ENVIRONMENT):][:60] for r in dropped})
        warnings.warn(f"{out_dir}/results.csv: running {len(dropped)} row(s) again that failed for an "
                      f"environmental reason ({'; '.join(reasons)})", RunWarning, stacklevel=3)


# ----------------------------------------------------------------------------- scheduling


def schedule(pool: Pool, state: State, bar) -> None:
    """Run the pending jobs of ``state`` on ``pool`` and record every row.

    Raises ``KeyboardInterrupt`` between jobs once SIGINT or SIGTERM has arrived
    (:mod:`rippleb.interrupts`; the pool's waits poll for them); the rows that had ended
    are recorded first, and the running jobs ended, so ``--resume`` runs just those.
    """
    finished_rows = []   # rows ended but not yet scored
    try:
        while state.pending or pool.busy or finished_rows:
            while pool.free and state.pending:
                check_interrupted()
                if not _start_next(pool, state, bar):
                    break
            # Score the rows that ended after their slots have new jobs: the slots do not
            # sit idle while this process scores.
            while finished_rows:
                _finish_row(finished_rows.pop(0), state, bar)
            if not (state.pending or pool.busy):
                break
            check_interrupted()
            for fin in pool.wait():
                if isinstance(fin.key, tuple):
                    _finish_sim(fin, state)
                elif isinstance(fin.key, Fit):
                    state.fits[fin.key] = _fit_outcome(fin, state)
                    release_fit(state, fin.key)
                else:
                    finished_rows.append(fin)
    finally:
        pool.kill_all()
        while finished_rows:  # interrupted: what finished is still recorded
            _finish_row(finished_rows.pop(0), state, bar)


def _start_next(pool: Pool, state: State, bar) -> bool:
    """Start one job: the first startable row, else its fit, else the next simulation."""
    while state.startable:
        key = next(iter(state.startable))
        case, cal_case = state.plan.rows[key]
        failed = [state.sims.get(sim_key(c), "") for c in (case, cal_case)]
        failed = [f for f in failed if f.startswith("failed")]
        if failed:
            _record(state, key, bar, status="error", message=environment_first(f"simulation {failed[0]}"))
            return True
        unphysical = _unphysical(state, case, cal_case)
        if unphysical:  # no method is fit or scored on a joint that does not exist
            _record(state, key, bar, status="invalid", message=unphysical)
            return True
        fit = Fit(key.method, cal_case)
        if state.fits[fit] == "pending":
            state.fits[fit] = "running"
            pool.submit(fit, _fit_job(fit, state), state.timeout, _output(state, f"fit--{key.method}--{key.seed}"),
                        confine=_confined(state, key.method), max_bytes=_state_bytes(pool),
                        sink=str(state.cache / f"fit-{digest(repr(fit).encode())[:32]}.pkl"))
            return True
        del state.startable[key]
        if state.fits[fit] == "running":   # back in startable when the fit ends
            state.after_fit.setdefault(fit, []).append(key)
            continue
        state.pending.pop(key)
        if state.fits[fit]["status"] != "ok":
            _record(state, key, bar, **row_fields(state.fits[fit]))
            return True
        try:
            evaluation = _evaluation_log(state, case)
        except TamperedError as exc:
            _record(state, key, bar, status="error", message=one_line(exc))
            return True
        n_samples, _ = state.lengths[case]
        pool.submit(key, _row_job(key, state, state.fits[fit], evaluation), state.timeout,
                    _output(state, f"{key.method}--{key.scenario}--{key.condition}--{key.seed}"),
                    max_bytes=24 * n_samples + 2**20, confine=_confined(state, key.method))
        return True
    while state.sim_order:
        sim = state.sim_order.popleft()
        if state.sims[sim] == "pending":
            state.sims[sim] = "running"
            scenario, roles = state.plan.sims[sim]
            paths = {role: str(state.cache / Case(*sim, role).file_name()) for role in roles}
            _submit_sim(pool, state, sim, _sim_job(scenario, sim, paths, state.seal))
            return True
    return False


def _state_bytes(pool: Pool) -> int | None:
    """The most a fitted state may hold: the memory a job may use (it is counted against the
    limit where it is made, and where each row loads it)."""
    return int(pool.memory_mb * 2**20) + 2**20 if pool.memory_mb else None


def _confined(state: State, method: str) -> isolation.Confinement:
    """A method's worker: the run directory and the cache read-only, a sealed run's salt files
    hidden, its own package readable beside the libraries (the rest of the disk is not)."""
    return isolation.Confinement.of([state.results.path and state.results.path.parent, state.cache],
                                    state.seal.files() if state.seal else (), state.scratch,
                                    own_package(state.registry, method))


def _output(state: State, stem: str) -> str | None:
    from rippleb.engine.rows import safe_name

    return str(state.log_dir / f"{safe_name(stem)}.txt") if state.log_dir else None


def _sim_job(scenario, sim: tuple, paths: dict, seal=None) -> job_fns.Job:
    if seal is None:
        return job_fns.Job("simulate", (scenario, sim[3], sim[2], paths))
    return job_fns.Job("simulate", (scenario, sim[3], sim[2], paths, seal.device_seed(sim[3])))


def _submit_sim(pool: Pool, state: State, sim: tuple, job: job_fns.Job) -> None:
    """Start a simulation. A sealed one is forked from this process, never sent to the
    fork server: the server's memory, freed parts included, is inherited by every row it
    forks later, and the job's arguments hold the secret device seed (rippleb.engine.sealing)."""
    if state.seal is None or pool.server is None:
        pool.submit(sim, job, None, None)
        return
    server, pool.server = pool.server, None   # this one job only: the rows stay with the server
    try:
        pool.submit(sim, functools.partial(job, None), None, None)  # a simulation needs no registry
    finally:
        pool.server = server


def _finish_sim(fin, state: State) -> None:
    if fin.kind != "done":
        state.sims[fin.key] = f"failed: {why(fin, state.timeout)}"
        release_rows(state, fin.key)   # their rows are recorded as errors when they are reached
        return
    arrays, info = unpack(fin.value)
    for role, ref in info["artefacts"].items():
        case = Case(*fin.key, role)
        state.artefacts[case] = Artefact(ref["path"], ref["sha256"])
        if info.get("invalid"):
            state.invalid[case] = str(info["invalid"])
        if role == SCORED:
            truth = job_fns.truth_from_message(arrays, info)
            state.truths[case] = truth
            n_samples = len(truth.eval_mask)
            state.lengths[case] = (n_samples, -(-n_samples // int(info["block_size"])))
    state.sims[fin.key] = "done"
    release_rows(state, fin.key)


def _unphysical(state: State, case: Case, cal_case: Case) -> str | None:
    """Why a row's scored or calibration log is not a joint that exists (checked once per
    simulation, :func:`rippleb.simulator.validity.check_simulation`), or None."""
    for c, what in ((case, "scored"), (cal_case, "calibration")):
        if c in state.invalid:
            return f"the simulated {what} log is not physical: {state.invalid[c]}"
    return None


def _fit_job(fit: Fit, state: State) -> job_fns.Job:
    return job_fns.Job("fit", (*split_label(fit.method), state.artefacts[fit.calibration]))


def _fit_outcome(fin, state: State) -> dict:
    """What a fit left: its info, with ``fit_s`` as its keeper measured it outside the
    method's process, and the artefact of its fitted state (received into the cache by the
    pool: the fit's worker cannot write there, and the runner never holds the state)."""
    if fin.kind == "done":
        try:
            info, size = job_fns.read_fit(fin.value)
        except Exception as exc:  # noqa: BLE001 - whatever a fit sends, it is one status line
            return {"status": "error", "message": f"fit sent an unreadable result ({type(exc).__name__})"}
        info.pop("fit_s", None)   # its own clock's: the time measured outside replaces it
        if fin.method_s is not None:
            info["fit_s"] = fin.method_s
        if size:
            artefact = Artefact.of_file(fin.value)
            info["fitted"] = {"path": artefact.path, "sha256": artefact.sha256}
        else:
            Path(fin.value).unlink(missing_ok=True)
        return info
    if fin.kind == "timeout":
        return {"status": "timeout", "message": f"fit killed after {state.timeout:g} s"}
    if fin.kind == "oversized":
        return {"status": "error", "message": f"fit: its fitted state ({fin.value} bytes) is larger than the "
                                              f"memory a job may use (--memory-limit)"}
    return {"status": "error", "message": environment_first(f"fit: {why(fin, state.timeout)}")}


def _evaluation_log(state: State, case: Case) -> SensorLog:
    """The visible log of a scored case, read and verified here once for all its rows.

    Each row's job carries it (to the fork server, which forks the row), so no row reads
    and hashes the file again (the hash of a one-second log cost each row more than its
    own process start). A file rewritten before this read fails the rows that would
    use it, as a row's own check did; one rewritten after it changes nothing.
    """
    if case not in state.logs:
        state.logs[case] = job_fns.visible_log(load_log(state.artefacts[case]), SCORED)
    return state.logs[case]


def _row_job(key: RowKey, state: State, fit: dict, evaluation: SensorLog) -> job_fns.Job:
    case, cal_case = state.plan.rows[key]
    calibration = state.artefacts[cal_case]
    fitted = Artefact(**fit["fitted"]) if isinstance(fit.get("fitted"), dict) else None
    fit_info = {k: fit[k] for k in ("params", "fit_s") if k in fit} if fitted else None
    return job_fns.Job("row", (*split_label(key.method), calibration, evaluation, fitted, fit_info))


def _finish_row(fin, state: State, bar) -> None:
    key = fin.key
    case, cal_case = state.plan.rows[key]
    if fin.kind == "done":
        fields = _score_row(fin.value, state, case, fin.method_s, key)
    elif fin.kind == "timeout":
        fields = {"status": "timeout", "message": f"killed after {state.timeout:g} s"}
    else:
        fields = {"status": "error", "message": why(fin, state.timeout)}
    # Its fit's time as the fit's keeper measured it; a row that fitted itself (a method
    # that cannot be pickled) has none apart from its own, which its clock could fake.
    fields.pop("fit_s", None)
    fit = state.fits.get(Fit(key.method, cal_case))
    if isinstance(fit, dict) and isinstance(fit.get("fitted"), dict) and "fit_s" in fit:
        fields["fit_s"] = fit["fit_s"]
    _record(state, key, bar, wall_s=fin.wall_s, **fields)


def _score_row(value: bytes, state: State, case: Case, method_s: float | None = None, key=None) -> dict:
    """Score what a row sent against the truth held here; trust only its estimate, and its
    tick times only as far as the time measured outside its process allows."""
    try:
        arrays, info = unpack(value)
    except Exception as exc:  # noqa: BLE001 - a row's bytes are untrusted
        return {"status": "error", "message": f"the row sent an unreadable result ({type(exc).__name__})"}
    fields = row_fields(info)
    if fields["status"] != "ok":
        return fields
    fields.update(score_row(arrays, state.truths[case], *state.lengths[case], method_s=method_s))
    if state.estimates is not None and fields["status"] == "ok":
        state.estimates[key] = arrays["estimate"]
    return fields


def _record(state: State, key: RowKey, bar, **fields) -> None:
    state.pending.pop(key, None)
    state.startable.pop(key, None)
    case, cal_case = state.plan.rows[key]
    # An executor's fields may carry the system information of the machine that ran the row.
    row = {**system_info(), **key.fields(), **fields, "calibration": state.plan.calibration_label,
           "scenario_sha256": case.content, "run_id": state.run_id}
    if state.seal is not None:  # the column exists only in sealed runs: unsealed rows stay as they were
        row[SEALED_COLUMN] = True
    state.results.add(row)
    if state.on_record is not None:
        state.on_record(row)
    bar.update()
    # The truth of a case is kept only while rows of it are open.
    state.open_rows[case] -= 1
    if not state.open_rows[case]:
        state.truths.pop(case, None)
        state.logs.pop(case, None)


record = _record  # for executors that run whole rows elsewhere (rippleb.engine.executors)


@contextlib.contextmanager
def progress_bar(total: int, enabled):
    from tqdm import tqdm

    with tqdm(total=total, disable=(None if enabled is None else not enabled), file=sys.stderr,
              unit="row", dynamic_ncols=True) as bar:
        yield bar
