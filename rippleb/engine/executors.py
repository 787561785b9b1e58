"""Rows as self-contained tasks, for executors that run them away from the runner (Dask).

The local runner schedules simulations, fits and rows as separate jobs sharing a cache
directory. A remote worker shares no file system with the runner, so an executor sends it
a whole row instead (:class:`RowTask`: the scenario objects, the key and the limits) and
the worker runs it with :func:`run_task`: the very scheduler of a local run, on a
one-row plan, in a pool of one. Its simulations are recomputed from the seed (the
simulator is deterministic), so the row's accuracy columns are those of a local run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rippleb.simulator.conditions import calibration_condition
from rippleb.engine.process.pool import Pool
from rippleb.engine.results import ResultsFile
from rippleb.engine.rows import CALIBRATION, FITTING, SCORED, Case, RowKey, scenario_hash


@dataclass(frozen=True)
class RowTask:
    """One row as a self-contained task."""

    key: RowKey
    scenario: object
    calibration: object
    timeout: float | None
    memory_mb: float | None
    run_id: str
    #: :func:`rippleb.engine.rows.scenario_hash` of ``scenario`` and ``calibration``, computed by the
    #: client once per case (about 9 ms each); None to compute them where the task runs
    scenario_hash: str | None = None
    calibration_hash: str | None = None


def row_tasks(state, memory_mb) -> list[RowTask]:
    """A task for each pending row of a runner's ``state`` (nothing read from this machine's files)."""
    tasks = []
    for key in state.pending:
        case, cal_case = state.plan.rows[key]
        tasks.append(RowTask(key, state.plan.sims[_sim_key(case)][0], state.plan.sims[_sim_key(cal_case)][0],
                             state.timeout, memory_mb, state.run_id, case.content, cal_case.content))
    return tasks


def _sim_key(case: Case) -> tuple:
    return case.scenario, case.content, case.condition, case.seed


def run_task(task: RowTask, cache: Path, registry, memo: dict | None = None, server=None) -> dict:
    """Run one row here, exactly as a local run does (same scheduler, pool, isolation,
    limits and scoring); the truth stays in this process.

    Parameters
    ----------
    task
        The row.
    cache
        A directory of this machine for the row's files (simulated logs, the fitted method).
    registry
        The methods this machine can load.
    memo
        Simulations and fits of earlier rows in this process, read and filled:
        ``Case -> (artefact, truth, lengths, verified visible log, why it is unphysical or None)``
        and ``Fit -> fit info``; an entry is used
        only while its file exists (and files are checked by hash when read).
    server
        The :class:`rippleb.engine.process.forkserver.ForkServer` that forks the row's jobs (one started
        before this process held any truth); None forks them from this process.

    Returns
    -------
    dict
        The row's fields without its key columns, with the system information of this machine.
    """
    from rippleb.engine.plan import Plan, State, prepare_cases
    from rippleb.engine.scheduler import schedule

    key = task.key
    cal_hash = task.calibration_hash or scenario_hash(task.calibration)
    cal_case = Case(CALIBRATION, cal_hash, calibration_condition(key.condition), key.seed, FITTING)
    case = Case(key.scenario, task.scenario_hash or scenario_hash(task.scenario), key.condition, key.seed, SCORED)
    plan = Plan(calibration_label=CALIBRATION)
    plan.add_sim(task.calibration, cal_case)
    plan.add_sim(task.scenario, case)
    plan.add_row(key, case, cal_case)
    state = State(plan, registry, ResultsFile(None), Path(cache), None, task.timeout, task.run_id, [key])
    prepare_cases(state)
    state.open_rows[case] += 1  # keep the truth after the row is recorded, for the memo
    memo = {} if memo is None else memo
    _restore(state, memo)
    schedule(Pool(1, task.memory_mb, context=registry, server=server), state, _NoBar())
    for c in (case, cal_case):
        if c in state.artefacts and (c.role == FITTING or c in state.truths):
            memo[c] = (state.artefacts[c], state.truths.get(c), state.lengths.get(c), state.logs.get(c),
                       state.invalid.get(c))
    for fit, info in state.fits.items():
        if isinstance(info, dict) and info.get("status") == "ok" and isinstance(info.get("fitted"), dict):
            memo[fit] = info
    row = state.results.rows[0]
    return {k: v for k, v in row.items() if k not in key.fields() and k not in ("calibration", "run_id")}


def _restore(state, memo: dict) -> None:
    """Take the simulations and fits an earlier row of this process left."""
    from rippleb.engine.plan import release_rows

    for sim, (_, roles) in state.plan.sims.items():
        known = [memo.get(Case(*sim, role)) for role in roles]
        if not all(k is not None and Path(k[0].path).is_file() for k in known):
            continue
        for role, (artefact, truth, lengths, log, invalid) in zip(roles, known):
            c = Case(*sim, role)
            state.artefacts[c] = artefact
            if invalid is not None:
                state.invalid[c] = invalid
            if truth is not None:
                state.truths[c] = truth
            if log is not None:  # read and verified by an earlier row here
                state.logs[c] = log
            if lengths is not None:
                state.lengths[c] = lengths
        state.sims[sim] = "done"
        release_rows(state, sim)
    for fit in state.fits:
        info = memo.get(fit)
        if info is not None and Path(info["fitted"]["path"]).is_file():
            state.fits[fit] = info


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass
