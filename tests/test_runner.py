import signal
import threading
import time
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from conftest import HANG_TIMEOUT_S

import rippleb
from rippleb import InputError, JointSpec, Method, make_log
from rippleb.engine import runner as runner_mod
from rippleb.engine.results import COLUMNS
from support import FAKE_N, Perfect, fake_simulate

class Raises(Method):
    name = "raises"

    def step(self, block):
        raise RuntimeError("boom\nsecond line")


class NaNs(Method):
    name = "nans"

    def step(self, block):
        out = np.zeros(len(block))
        if block.t[0] > 0.1:
            out[3] = np.nan
        return out


class Short(Method):
    name = "short"

    def step(self, block):
        return np.zeros(len(block) - 1)


class Strings(Method):
    name = "strings"

    def step(self, block):
        return np.array(["x"] * len(block))


class Sleeps(Method):
    name = "sleeps"

    def fit(self, calibration):
        time.sleep(3600)


class Hog(Method):
    name = "hog"

    def step(self, block):
        self.keep = getattr(self, "keep", [])
        # 400 MB per tick, without bound; reserved, not written: the limit is on address
        # space (RLIMIT_AS), and writing 800 MB before the MemoryError made the row outlast
        # the 6 s timeout on a loaded machine (2 full-suite runs of 2 at load 10-12)
        self.keep.append(np.empty(50_000_000))
        return np.zeros(len(block))


class Chatty(Method):
    name = "chatty"

    def step(self, block):
        print("debug output of a plugin")
        return np.zeros(len(block))


class Peeks(Method):
    """Records what it was given, to check the runner hides the truth."""
    name = "peeks"

    def fit(self, calibration):
        assert calibration.torque_true is None and calibration.torque_ref is not None

    def reset(self, spec):
        self.sizes = []

    def step(self, block):
        assert not hasattr(block, "torque_true") and not hasattr(block, "torque_ref")
        if len(block) != 20 or (hasattr(self, "last") and block.t[0] <= self.last):
            raise AssertionError("blocks are not ticks in time order")
        self.last = block.t[-1]
        return np.zeros(len(block))


ALL = [Perfect, Raises, NaNs, Short, Strings, Sleeps, Hog, Chatty, Peeks]


@pytest.fixture
def fake(monkeypatch, register_methods):
    """Fake simulation and a registry of the test methods plus the built-ins."""
    import rippleb.simulator

    monkeypatch.setattr(rippleb.simulator, "simulate", fake_simulate)
    register_methods(*ALL)


@pytest.mark.slow
@pytest.mark.heavy
def test_misbehaving_methods_get_their_status_and_the_others_complete(fake, tmp_path):
    names = [c.name for c in ALL] + ["raw"]
    # the sleeper's rows cost the timeout; every other row takes about a second at most
    frame = rippleb.run(methods=names, scenarios=["paper-quintic"], seeds=2, jobs=3, out=tmp_path,
                        timeout=HANG_TIMEOUT_S, memory_mb=1000)
    status = {(r.method, r.seed): r.status for r in frame.itertuples()}
    expected = {"perfect": "ok", "raises": "error", "nans": "invalid", "short": "invalid",
                "strings": "invalid", "sleeps": "timeout", "hog": "error", "chatty": "ok",
                "peeks": "ok", "raw": "ok"}
    assert status == {(m, s): st for m, st in expected.items() for s in (0, 1)}
    msg = frame.set_index(["method", "seed"])["message"]
    assert msg["raises", 0] == "RuntimeError: boom"
    assert "NaN" in msg["nans", 0] and "sample 2023" in msg["nans", 0]
    assert "shape (19,)" in msg["short", 0]
    assert "MemoryError" in msg["hog", 0]
    # every row on disk too, with the standard columns first
    disk = pd.read_csv(tmp_path / "results.csv")
    assert list(disk.columns[: len(COLUMNS)]) == list(COLUMNS) and len(disk) == len(frame)
    assert "debug output" in (tmp_path / "logs" / "chatty--paper-quintic--same-session--0.txt").read_text()


def test_metrics_and_provenance_of_an_ok_row(fake, tmp_path):
    frame = rippleb.run(methods="perfect,raw", scenarios="paper-quintic", seeds=[3], out=None)
    row = frame.set_index("method").loc["perfect"]
    assert row.rms_error_nm < 1e-3 and row.delay_ms == 0 and row.seed == 3
    assert row.rms_error_ref_nm == pytest.approx(0.1, abs=1e-3)
    assert row.us_per_tick_p50 > 0 and row.n_samples == FAKE_N
    assert row.rippleb_version == rippleb.__version__ and row.python and row.cpu
    assert frame.set_index("method").loc["raw"].rms_error_nm > 10 * row.rms_error_nm


@pytest.mark.slow
def test_each_simulation_runs_once_per_run(fake, tmp_path, monkeypatch):
    calls = tmp_path / "calls"

    def counting(scenario, seed, condition="same-session"):
        with open(calls, "a") as fh:   # children are processes: count through a file
            fh.write(f"{getattr(scenario, 'name', scenario)}/{seed}\n")
        return fake_simulate(scenario, seed, condition)
    import rippleb.simulator
    monkeypatch.setattr(rippleb.simulator, "simulate", counting)
    rippleb.run(methods="raw,perfect,chatty", scenarios="paper-quintic,creep", seeds=2, jobs=2)
    lines = calls.read_text().split()
    assert sorted(lines) == sorted(set(lines)) and len(lines) == 6   # 2 seeds x (2 + calibration)


def test_a_failed_simulation_costs_its_rows_only(fake, monkeypatch):
    import rippleb.simulator

    def flaky(scenario, seed, condition="same-session"):
        if getattr(scenario, "name", scenario) == "creep":
            raise ValueError("bad trajectory")
        return fake_simulate(scenario, seed)
    monkeypatch.setattr(rippleb.simulator, "simulate", flaky)
    frame = rippleb.run(methods="raw", scenarios="creep,paper-quintic", seeds=1)
    status = dict(zip(frame.scenario, frame.status))
    assert status == {"creep": "error", "paper-quintic": "ok"}
    assert "bad trajectory" in frame.set_index("scenario").loc["creep", "message"]


def test_resume_runs_only_the_missing_rows(fake, tmp_path):
    first = rippleb.run(methods="raw,perfect", scenarios="paper-quintic", seeds=1, out=tmp_path)
    disk = pd.read_csv(tmp_path / "results.csv")
    disk[disk.method == "raw"].to_csv(tmp_path / "results.csv", index=False)  # as if interrupted
    both = rippleb.run(methods="raw,perfect", scenarios="paper-quintic", seeds=1, out=tmp_path, resume=True)
    assert list(both.method) == ["perfect", "raw"]
    assert both.set_index("method").loc["raw", "run_id"] == first.set_index("method").loc["raw", "run_id"]


def test_resume_refuses_another_selection(fake, tmp_path):
    rippleb.run(methods="raw", scenarios="paper-quintic", seeds=1, out=tmp_path)
    with pytest.raises(InputError, match="run.json: --resume finishes the run it describes"):
        rippleb.run(methods="raw", scenarios="paper-quintic", seeds=1, seed_start=5, out=tmp_path, resume=True)


@pytest.fixture
def sigint_raises():
    """Ctrl-C as in a terminal: SIGINT raises KeyboardInterrupt. A process started in the
    background (a pytest-xdist worker) inherits SIGINT ignored, and an interrupted run
    would then wait for a blocked method forever."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_keeps_the_finished_rows(fake, tmp_path, signum, sigint_raises):
    # The signal arrives while 'sleeps' blocks the run, once the rows before it are on disk
    # (waiting for them, not a fixed delay: on a loaded machine they may take longer).
    def interrupt_after_two_rows():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            path = tmp_path / "results.csv"
            if path.is_file() and len(pd.read_csv(path)) >= 2:
                break
            time.sleep(0.05)
        signal.raise_signal(signum)

    threading.Thread(target=interrupt_after_two_rows, daemon=True).start()
    with pytest.raises(KeyboardInterrupt):
        # a bounded timeout: a signal that never arrives fails the test instead of hanging it
        rippleb.run(methods="raw,perfect,sleeps", scenarios="paper-quintic", seeds=1, jobs=1,
                    out=tmp_path, timeout=150)
    disk = pd.read_csv(tmp_path / "results.csv")
    assert sorted(disk.method) == ["perfect", "raw"] and (disk.status == "ok").all()


def test_recorded_log_scores_against_torque_ref(fake, tmp_path):
    sim = fake_simulate("rec", 0)
    columns = sim.log.columns()
    columns.pop("torque_true")
    path = rippleb.write_log(make_log(JointSpec(), columns), tmp_path / "rec.csv")
    frame = rippleb.run_log(path, methods="perfect,raw")
    row = frame.set_index("method").loc["perfect"]
    assert row.status == "ok" and row.scenario == "log:rec.csv" and row.calibration == "self"
    assert np.isnan(row.rms_error_nm) and row.rms_error_ref_nm == pytest.approx(0.1, abs=1e-3)


def test_recorded_log_without_reference_needs_a_calibration(tmp_path):
    sim = fake_simulate("rec", 0)
    columns = {k: v for k, v in sim.log.columns().items() if not k.startswith("torque")}
    path = rippleb.write_log(make_log(JointSpec(), columns), tmp_path / "rec.parquet")
    with pytest.raises(InputError, match="--calibration"):
        rippleb.run_log(path)


def test_unwritable_output_directory_is_an_input_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(InputError, match="cannot write the output directory"):
        rippleb.run(methods="raw", scenarios="paper-quintic", seeds=1, out=blocker / "sub")


def test_unknown_names_are_input_errors():
    with pytest.raises(InputError, match="did you mean 'raw'"):
        rippleb.run(methods="rwa")
    with pytest.raises(InputError, match="did you mean"):
        rippleb.run(methods="raw", scenarios="paper-quintc")


def test_the_real_simulator_runs_the_baselines():
    frame = rippleb.run(methods="raw,lowpass", scenarios="static-contact", seeds=1)
    assert (frame.status == "ok").all(), frame.message.tolist()
    assert np.isfinite(frame.rms_error_nm).all()
