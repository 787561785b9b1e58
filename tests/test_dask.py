"""The Dask executor end to end: a real scheduler and two real workers started through their
own CLIs on the loopback interface, driven by the real ``rippleb`` CLI.

Each test compares with a local run of the same selection: the accuracy columns must be
bit for bit equal (the workers recompute the simulations from the seeds). One test kills a
worker mid-run: no row may be lost (each is retried elsewhere, or marked as an error that
names the lost worker).
"""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from support import BIN, Cluster, read_results, rippleb_cli, same_accuracy, stop_process

pytestmark = pytest.mark.slow

@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """One cluster for the module (starting one takes seconds); the test that kills a
    worker comes last."""
    c = Cluster(tmp_path_factory.mktemp("cluster"))
    try:
        c.wait_for_workers(2)
        yield c
    finally:
        c.close()


def test_run_and_sweep_on_a_cluster_equal_a_local_run(cluster, tmp_path):
    common = ["--methods", "lowpass,angle-adaptive", "--scenarios", "paper-quintic", "--seeds", "2",
              "--no-progress"]
    remote = rippleb_cli("run", *common, "--scheduler", cluster.address, "--out", tmp_path / "remote")
    assert remote.returncode == 0, remote.stderr
    local = rippleb_cli("run", *common, "--jobs", "2", "--out", tmp_path / "local")
    assert local.returncode == 0, local.stderr
    a, b = read_results(tmp_path / "remote"), read_results(tmp_path / "local")
    assert len(a) == 4
    same_accuracy(a, b)

    sweep = ["sweep", "--param", "joint.counts_per_rev=500,2500", "--methods", "angle-adaptive",
             "--scenarios", "paper-quintic", "--seeds", "1", "--no-progress"]
    remote = rippleb_cli(*sweep, "--scheduler", cluster.address, "--out", tmp_path / "sweep-remote")
    assert remote.returncode == 0, remote.stderr
    local = rippleb_cli(*sweep, "--jobs", "2", "--out", tmp_path / "sweep-local")
    assert local.returncode == 0, local.stderr
    a, b = read_results(tmp_path / "sweep-remote"), read_results(tmp_path / "sweep-local")
    assert sorted(a["joint.counts_per_rev"]) == [500, 2500]
    same_accuracy(a, b)
    # the two grid points are two devices' worth of rows, not one row twice
    assert a["rms_error_nm"].nunique() == 2


@pytest.mark.heavy
def test_a_worker_killed_mid_run_loses_no_row(cluster, tmp_path):
    out = tmp_path / "run"
    args = [str(BIN / "rippleb"), "run", "--methods", "angle-adaptive,kalman-ripple,lowpass",
            "--scenarios", "paper-quintic,reversal", "--seeds", "2", "--no-progress",
            "--scheduler", cluster.address, "--out", str(out)]
    run = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        # kill one worker (with its nanny: a lost machine) once rows are flowing
        while not (out / "results.csv").is_file() and time.monotonic() < deadline and run.poll() is None:
            time.sleep(0.2)
        assert run.poll() is None, "the run ended before a worker could be killed"
        stop_process(cluster.workers[0])
        _, stderr = run.communicate(timeout=600)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 0, stderr
    frame = read_results(out)
    assert len(frame) == 3 * 2 * 2  # every row is there
    lost = frame[frame["status"] != "ok"]
    assert lost["message"].astype(str).str.contains("worker").all(), lost["message"].tolist()
    assert len(lost) < len(frame)
    # the worker was really lost while the run went on
    assert cluster.workers[0].poll() is not None
    assert "Remove worker" in (cluster.tmp / "scheduler.log").read_text()

@pytest.mark.heavy
def test_a_scheduler_killed_mid_run_is_one_line_and_the_run_resumable(tmp_path):
    """Before: a ``RuntimeError: ConnectionPool is closed`` traceback and exit 1 (issue 25)."""
    own = Cluster(tmp_path, n=2)   # its own: the module's cluster serves the other tests
    out, run = tmp_path / "run", None
    try:
        own.wait_for_workers(2)
        run = subprocess.Popen([str(BIN / "rippleb"), "run", "--methods", "raw,lowpass,kalman-ripple",
                                "--scenarios", "paper-quintic,reversal", "--seeds", "3", "--no-progress",
                                "--scheduler", own.address, "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 300
        while not (out / "results.csv").is_file() and time.monotonic() < deadline and run.poll() is None:
            time.sleep(0.1)
        assert run.poll() is None, "the run ended before the scheduler could be killed"
        stop_process(own.scheduler)
        _, stderr = run.communicate(timeout=120)   # a lost scheduler must not keep it waiting
    finally:
        if run is not None and run.poll() is None:
            run.kill()
            run.wait()
        own.close()
    assert run.returncode == 2 and len(stderr.splitlines()) == 1, stderr
    assert stderr.startswith(f"rippleb: error: --scheduler {own.address}: lost the scheduler mid-run")
    assert stderr.rstrip().endswith(f"finish the run with: rippleb run --resume {out}")
    kept = pd.read_csv(out / "results.csv")
    assert 1 <= len(kept) < 18
    # rows the scheduler cancelled are `environment` rows (--resume runs them again); the
    # kill may also land between rows, when none was cancelled (the column then reads as NaN)
    cancelled = kept.loc[kept.status != "ok", "message"].astype(str)
    assert cancelled.str.startswith("environment: ").all(), cancelled.tolist()

    resumed = rippleb_cli("run", "--resume", out, "--jobs", "2", "--no-progress")   # on the local pool
    assert resumed.returncode == 0, resumed.stderr
    rows = pd.read_csv(out / "results.csv")
    assert len(rows) == 18 and (rows.status == "ok").all()


# ``--executor dask`` (a local cluster the run starts and closes) is tested with a hostile
# plugin in tests/test_integrity.py (test_dask_rows_cannot_find_the_truth_either).
