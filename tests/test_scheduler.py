"""The scheduler's choice of the next job (rippleb/engine/scheduler.py), with a pool that only
records what it is given: simulations in the order the case-major rows first need them, a row
started once both its logs exist and its fit has ended, and no pass over every pending row."""

from pathlib import Path

from rippleb.engine.cache import Artefact
from rippleb.engine.results import ResultsFile
from rippleb.engine.rows import FITTING, SCORED, Case, RowKey
from rippleb.engine.plan import Fit, Plan, State, prepare_cases, release_rows
from rippleb.engine.scheduler import _start_next
from rippleb.registry import Registry


class RecordingPool:
    """Takes every job and runs none; what was submitted, in order."""

    memory_mb = None
    server = None

    def __init__(self):
        self.submitted = []

    def submit(self, key, *args, **kwargs):
        self.submitted.append(key)


class NoBar:
    def update(self, n: int = 1) -> None:
        pass


def _state(tmp_path: Path, seeds=(0, 1), scenarios=("creep", "reversal"), methods=("raw", "lowpass")) -> State:
    plan = Plan(calibration_label="calibration")
    for seed in seeds:
        cal = Case("calibration", "c", "same-session", seed, FITTING)
        plan.add_sim(None, cal)
        for scenario in scenarios:
            case = Case(scenario, "s", "same-session", seed, SCORED)
            plan.add_sim(None, case)
            for method in methods:
                plan.add_row(RowKey(method, scenario, "same-session", seed), case, cal)
    rows = sorted(plan.rows, key=lambda k: (k.seed, k.scenario, k.condition, k.method))  # as the runner does
    state = State(plan, Registry.discover(), ResultsFile(None), tmp_path, None, None, "test", rows)
    prepare_cases(state)
    return state


def _simulated(state: State, sim: tuple) -> None:
    """What the end of a simulation leaves, without one: its logs exist."""
    for role in state.plan.sims[sim][1]:
        state.artefacts[Case(*sim, role)] = Artefact("unused", "0" * 64)
    state.sims[sim] = "done"
    release_rows(state, sim)


def test_simulations_start_in_the_order_the_rows_need_them_calibration_first(tmp_path):
    state, pool = _state(tmp_path), RecordingPool()
    while _start_next(pool, state, NoBar()):
        pass
    assert pool.submitted == [("calibration", "c", "same-session", 0), ("creep", "s", "same-session", 0),
                              ("reversal", "s", "same-session", 0), ("calibration", "c", "same-session", 1),
                              ("creep", "s", "same-session", 1), ("reversal", "s", "same-session", 1)]
    assert not state.startable and all(len(rows) for rows in state.blocked.values())


def test_a_row_waits_for_both_logs_then_for_its_fit(tmp_path):
    state, pool = _state(tmp_path, seeds=(0,), scenarios=("creep",), methods=("raw",)), RecordingPool()
    cal_sim, creep_sim = ("calibration", "c", "same-session", 0), ("creep", "s", "same-session", 0)
    key = RowKey("raw", "creep", "same-session", 0)
    _simulated(state, cal_sim)
    assert key not in state.startable                # its scored log is not there yet
    _simulated(state, creep_sim)
    assert list(state.startable) == [key]
    assert _start_next(pool, state, NoBar()) and pool.submitted == [Fit("raw", state.plan.rows[key][1])]
    assert not _start_next(pool, state, NoBar())     # the fit runs: nothing else to start
    assert key in state.after_fit[pool.submitted[0]] and key in state.pending


def test_rows_of_a_failed_simulation_are_recorded_as_errors(tmp_path):
    state, pool = _state(tmp_path, seeds=(0,), scenarios=("creep",), methods=("raw", "lowpass")), RecordingPool()
    _simulated(state, ("calibration", "c", "same-session", 0))
    sim = ("creep", "s", "same-session", 0)
    state.sims[sim] = "failed: it raised"
    release_rows(state, sim)
    while _start_next(pool, state, NoBar()):
        pass
    assert not state.pending and pool.submitted == []
    assert {row["status"] for row in state.results.rows} == {"error"}
    assert all("simulation failed: it raised" in row["message"] for row in state.results.rows)
