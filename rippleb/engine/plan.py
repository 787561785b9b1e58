"""What a run must do and which of it can start: the plan (simulations, rows and their
cases), the scheduler's state, and the bookkeeping that makes a row startable once both its
logs have settled (:mod:`rippleb.engine.scheduler` runs the jobs)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from rippleb.data import SensorLog
from rippleb.engine import jobs as job_fns
from rippleb.engine.cache import store, log_bytes
from rippleb.engine.results import ResultsFile
from rippleb.engine.rows import Case, RowKey
from rippleb.registry import Registry


@dataclass
class Plan:
    """What a run must do: simulations (with the roles they feed), rows, and their cases."""

    calibration_label: str
    sims: dict = field(default_factory=dict)       # (scenario, content, condition, seed) -> (obj, {roles})
    rows: dict = field(default_factory=dict)       # RowKey -> (scored Case, calibration Case)
    ready: dict = field(default_factory=dict)      # Case -> (log, truth) given, not simulated

    def add_sim(self, scenario, case: Case) -> None:
        key = sim_key(case)
        self.sims.setdefault(key, (scenario, set()))[1].add(case.role)

    def add_row(self, key: RowKey, case: Case, cal_case: Case) -> None:
        self.rows[key] = (case, cal_case)


def sim_key(case: Case) -> tuple:
    return case.scenario, case.content, case.condition, case.seed


@dataclass(frozen=True)
class Fit:
    method: str
    calibration: Case


@dataclass
class State:
    """Everything the scheduler tracks; the truth lives here only."""

    plan: Plan
    registry: Registry
    results: ResultsFile
    cache: Path
    log_dir: Path | None
    timeout: float | None
    run_id: str
    pending: dict                                    # RowKey -> None: the rows not yet recorded, in run order
    sims: dict = field(default_factory=dict)        # sim key -> "pending" | "running" | "done" | "failed: ..."
    artefacts: dict = field(default_factory=dict)   # Case -> Artefact
    truths: dict = field(default_factory=dict)      # Case -> Truth (scored cases with pending rows)
    fits: dict = field(default_factory=dict)        # _Fit -> "pending" | "running" | info dict
    lengths: dict = field(default_factory=dict)     # Case -> (n_samples, n_ticks)
    open_rows: dict = field(default_factory=dict)   # scored Case -> rows not yet recorded
    logs: dict = field(default_factory=dict)        # scored Case -> its visible log, verified (rows open)
    invalid: dict = field(default_factory=dict)     # Case -> why its simulated log is not physical
    seal: object = None                              # a sealed run's rippleb.engine.sealing.Seal, else None
    scratch: Path | None = None                      # where methods' jobs get their scratch directories
    on_record: object = None                         # called with each row as it is recorded, or None
    estimates: dict | None = None                    # RowKey -> estimate of each ok row, when asked for
    # Which pending rows can start, kept as jobs end rather than found by a pass over every
    # pending row per job started: that pass made a 32 000-row run quadratic (0.1-0.26 s a pass)
    startable: dict = field(default_factory=dict)   # RowKey -> None: both its logs settled, in order
    blocked: dict = field(default_factory=dict)     # Case -> [RowKey]: rows waiting for its simulation
    after_fit: dict = field(default_factory=dict)   # Fit -> [RowKey]: rows waiting for a running fit
    sim_order: deque = field(default_factory=deque)  # sim keys, in the order the rows first need them


def prepare_cases(state: State) -> None:
    needed = {c for key in state.pending for c in state.plan.rows[key]}
    for case in needed:
        if case in state.plan.ready:
            log, truth = state.plan.ready[case]
            state.artefacts[case] = store(state.cache / case.file_name(),
                                          log_bytes(job_fns.visible_log(log, case.role)))
            if truth is not None:
                state.truths[case] = truth
            state.lengths[case] = _lengths(log)
    state.pending = dict.fromkeys(state.pending)
    # Simulations in the order the rows (case-major, rippleb.engine.runner) first need them, the
    # calibration first: a scored log's rows can start as soon as it is simulated, so its truth
    # is released soon and the truths held stay those of the cases in flight
    first_need = dict.fromkeys(sim_key(c) for key in state.pending for c in reversed(state.plan.rows[key])
                               if c not in state.plan.ready)
    state.sims = dict.fromkeys(first_need, "pending")
    state.sim_order = deque(first_need)
    state.fits = {Fit(k.method, state.plan.rows[k][1]): "pending" for k in state.pending}
    for key in state.pending:
        case = state.plan.rows[key][0]
        state.open_rows[case] = state.open_rows.get(case, 0) + 1
        waiting = [c for c in state.plan.rows[key] if c not in state.artefacts]
        for c in waiting:
            state.blocked.setdefault(c, []).append(key)
        if not waiting:
            state.startable[key] = None


def _lengths(log: SensorLog) -> tuple[int, int]:
    return len(log), -(-len(log) // log.spec.block_size)


def release_rows(state: State, sim: tuple) -> None:
    """Make startable the rows that waited for the simulation ``sim`` (done, failed, or taken
    from an earlier row's memo) and now wait for nothing else."""
    for role in state.plan.sims[sim][1]:
        for key in state.blocked.pop(Case(*sim, role), ()):
            if key in state.pending and all(_settled(state, c) for c in state.plan.rows[key]):
                state.startable[key] = None


def release_fit(state: State, fit: Fit) -> None:
    """Make startable again the rows that waited for the fit ``fit``, which has ended."""
    for key in state.after_fit.pop(fit, ()):
        if key in state.pending:
            state.startable[key] = None


def _settled(state: State, case: Case) -> bool:
    """The case's log exists, or its simulation failed."""
    return case in state.artefacts or state.sims.get(sim_key(case), "").startswith("failed")
