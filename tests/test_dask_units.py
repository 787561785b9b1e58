"""The pieces of the Dask executor that need no cluster: a row as a self-contained task, the
worker's memo, lost workers as statuses, and the BLAS thread count."""

import os
from types import SimpleNamespace

import pandas as pd
import pytest

from rippleb.engine.dask.executor import _fields
from rippleb.numerics import openblas_threads
from rippleb.engine.executors import RowTask, run_task
from rippleb.registry import Registry
from rippleb.engine.rows import RowKey
from rippleb.engine.runner import run
from rippleb.simulator.scenario import load_scenario

ACCURACY = ["rms_error_nm", "max_error_nm", "rms_error_ref_nm", "delay_ms", "stopped_rms_error_nm"]


def _task(method, seed, run_id="t"):
    return RowTask(RowKey(method, "stop-restart", "same-session", seed), load_scenario("stop-restart"),
                   load_scenario("calibration"), 120.0, 4096.0, run_id)


@pytest.mark.slow
def test_a_task_is_the_local_row_and_reuses_its_cases(tmp_path):
    local = run("raw,lowpass", "stop-restart", [3], jobs=1)
    memo, registry = {}, Registry.discover()
    (tmp_path / "a").mkdir()
    first = run_task(_task("raw", 3), tmp_path / "a", registry, memo)
    (tmp_path / "b").mkdir()
    second = run_task(_task("lowpass", 3), tmp_path / "b", registry, memo)
    for fields, method in ((first, "raw"), (second, "lowpass")):
        row = local[local["method"] == method].iloc[0]
        assert fields["status"] == "ok"
        assert [fields[c] for c in ACCURACY] == [row[c] for c in ACCURACY]
        assert fields["scenario_sha256"] == row["scenario_sha256"]
        for key_column in ("method", "scenario", "condition", "seed", "run_id"):
            assert key_column not in fields  # the client's key is the authority
    # the second row of the same case simulated nothing: its files were the first row's
    assert not any((tmp_path / "b").glob("case-*"))
    assert any((tmp_path / "a").glob("case-*"))


@pytest.mark.slow
def test_a_task_whose_memo_files_vanished_simulates_again(tmp_path):
    memo, registry = {}, Registry.discover()
    (tmp_path / "a").mkdir()
    first = run_task(_task("raw", 1), tmp_path / "a", registry, memo)
    for path in (tmp_path / "a").iterdir():
        path.unlink()
    (tmp_path / "b").mkdir()
    again = run_task(_task("raw", 1), tmp_path / "b", registry, memo)
    assert again["rms_error_nm"] == first["rms_error_nm"]
    assert any((tmp_path / "b").glob("case-*"))


class _Future:
    def __init__(self, status, exc=None, result=None):
        self.status, self._exc, self._result = status, exc, result

    def exception(self):
        return self._exc

    def result(self):
        return self._result


def test_a_task_that_killed_its_workers_is_an_environmental_error_naming_the_worker():
    from distributed import KilledWorker

    # the scheduler sends the last worker's state; its address is what the row must name
    exc = KilledWorker("rippleb-row-1", SimpleNamespace(address="tcp://10.0.0.7:40000"), allowed_failures=3)
    fields = _fields(_Future("error", exc))
    assert fields["status"] == "error"
    assert fields["message"].startswith("environment: dask worker lost")
    assert "tcp://10.0.0.7:40000" in fields["message"]
    cancelled = _fields(_Future("cancelled"))
    assert cancelled["message"].startswith("environment: the cluster cancelled")
    failed = _fields(_Future("error", RuntimeError("boom")))
    assert failed == {"status": "error", "message": "dask task failed: RuntimeError: boom"}


def test_openblas_threads_can_be_set_and_read_back():
    before = openblas_threads()
    if before is None:
        pytest.skip("numpy and scipy do not use OpenBLAS here")
    try:
        assert openblas_threads(1) == 1
    finally:
        assert openblas_threads(before) == before


@pytest.mark.slow
def test_run_sweep_rows_have_a_column_per_parameter_and_distinct_keys():
    from rippleb.engine.sweep import run_sweep

    frame = run_sweep({"joint.counts_per_rev": [500, 2500]}, "raw", "stop-restart", [0], jobs=2)
    assert list(frame["joint.counts_per_rev"]) == [500, 2500]
    assert frame["scenario_sha256"].nunique() == 2
    assert isinstance(frame, pd.DataFrame) and (frame["status"] == "ok").all()


def test_a_worker_restarts_a_dead_fork_server_only_without_truths(monkeypatch):
    """The worker's fork server is started before its first row; one that died is started
    again only when no row runs here, and the memo (with its truths) is dropped first."""
    import signal

    from rippleb.engine.dask import worker as dx

    monkeypatch.setattr(dx, "_server", [])
    monkeypatch.setattr(dx, "_running", [0])
    monkeypatch.setattr(dx, "_memo", dx.collections.OrderedDict())
    first = dx._enter_row()
    dx._leave_row()
    assert dx._enter_row() is first          # alive: the same server
    dx._leave_row()
    dx._memo["case"] = (SimpleNamespace(path="/nonexistent"), "a truth", None, None)
    os.kill(first.pid, signal.SIGKILL)
    os.waitpid(first.pid, 0)
    try:
        second = dx._enter_row()
        assert second is not first and second.alive()
        assert not dx._memo                  # what it could have inherited is gone
    finally:
        dx._leave_row()
        dx._server[0].close()


def test_rows_on_a_dask_worker_reuse_their_heap_like_local_rows():
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_ set, which makes glibc map and
    unmap every log-sized array; a worker undoes it for itself (it unpacks and scores every
    row) before it starts the fork server its rows inherit it from."""
    import subprocess
    import sys

    code = ("import os, resource, numpy as np\n"
            "import rippleb.engine.dask.worker as dx\n"
            "if os.environ.get('UNDO') == 'direct': dx._default_malloc()\n"
            "if os.environ.get('UNDO') == 'worker':\n"
            "    dx._enter_row(); dx._leave_row(); dx._server[0].close()\n"
            "a = np.ones(100_000); del a\n"
            "before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
            "for _ in range(200):\n"
            "    a = np.ones(100_000); del a\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)\n")

    def page_faults(**env):
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env={**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536", **env})
        assert proc.returncode == 0, proc.stderr
        return int(proc.stdout)

    nanny, undone, worker = page_faults(), page_faults(UNDO="direct"), page_faults(UNDO="worker")
    assert nanny > 10_000          # 800 kB mapped and faulted in 200 times
    assert undone < nanny / 20
    assert worker < nanny / 20     # the worker process itself, once it has entered a row


def test_quiet_settings_reach_dask_processes_as_environment(tmp_path):
    """``quiet_environment`` names the variables ``dask worker`` reads: a process started with
    them sees every entry of QUIET_CONFIG."""
    import json
    import subprocess
    import sys

    from rippleb.engine.dask.executor import QUIET_CONFIG, quiet_environment

    code = ("import dask, distributed, json\n"
            f"print(json.dumps({{k: dask.config.get(k) for k in {list(QUIET_CONFIG)!r}}}))\n")
    clean = {k: v for k, v in os.environ.items() if not k.startswith("DASK_")}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env={**clean, **quiet_environment()})
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == QUIET_CONFIG


@pytest.mark.slow
def test_the_local_cluster_runs_with_the_quiet_settings():
    """``--executor dask``: the scheduler (in this process) and the workers (started by
    nannies) run with QUIET_CONFIG, and the settings do not leak past the run."""
    import dask

    from rippleb.engine.dask.executor import QUIET_CONFIG, DaskExecutor

    with DaskExecutor(workers=1)._client() as client:
        workers = client.run(lambda: dask.config.get("distributed.worker.profile.enabled"))
        tick = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler._tick_interval)
        worker_tick = client.run(lambda dask_worker: dask_worker._tick_interval)
    assert list(workers.values()) == [False]
    assert tick == 1.0 and list(worker_tick.values()) == [1.0]
    assert dask.config.get("distributed.admin.tick.interval") != QUIET_CONFIG["distributed.admin.tick.interval"]


def test_the_scale_page_lists_the_quiet_settings():
    """docs/scale.md tells users of hand-started workers what to export: exactly these."""
    from pathlib import Path

    from rippleb.engine.dask.executor import quiet_environment

    page = (Path(__file__).parents[1] / "docs" / "scale.md").read_text()
    exported = dict(line.removeprefix("export ").split("=", 1) for line in page.splitlines()
                    if line.startswith("export DASK_"))
    assert exported == quiet_environment()


def test_the_scale_page_lists_the_portable_numerics_variables():
    """docs/scale.md tells users of hand-started workers how to get the portable paths."""
    import shlex
    from pathlib import Path

    from rippleb.numerics import pinned_environment

    page = (Path(__file__).parents[1] / "docs" / "scale.md").read_text()
    exported = dict(shlex.split(line.removeprefix("export "))[0].split("=", 1) for line in page.splitlines()
                    if line.startswith(("export NPY_", "export OPENBLAS_")))
    assert exported == pinned_environment({})
