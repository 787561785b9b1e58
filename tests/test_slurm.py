"""The SLURM recipe of docs/scale.md end to end, with stand-ins for SLURM's commands.

``examples/slurm_cluster.py`` starts a ``dask_jobqueue.SLURMCluster``; the ``sbatch`` and
``scancel`` on its PATH here run the job script on this machine in a session of its own and
end that session, which is what SLURM does with a job on a node. So the test covers
everything but SLURM itself: the job script dask-jobqueue writes from the documented
options, its workers joining the scheduler, ``rippleb run --scheduler`` on them (rows equal
to a local run's) and the jobs cancelled when the cluster closes.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from support import read_results, same_accuracy, rippleb_cli

pytestmark = pytest.mark.slow
pytest.importorskip("dask_jobqueue")

ROOT = Path(__file__).resolve().parents[1]
SBATCH = """#!/usr/bin/env bash
# SLURM's sbatch, for a test: run the job script here in a session of its own
# (a copy: dask-jobqueue deletes its script once sbatch returns, as SLURM allows)
cp "${@: -1}" "$FAKE_SLURM/job.sh"
setsid bash "$FAKE_SLURM/job.sh" > "$FAKE_SLURM/job.log" 2>&1 < /dev/null &
echo $! >> "$FAKE_SLURM/jobs"
echo "Submitted batch job $!"
"""
SCANCEL = """#!/usr/bin/env bash
# SLURM's scancel, for a test: end each job's session
for job in "$@"; do kill -KILL -- "-$job" 2>/dev/null; echo "$job" >> "$FAKE_SLURM/cancelled"; done
exit 0
"""


def _fake_slurm(tmp: Path) -> dict:
    bin_dir = tmp / "bin"
    bin_dir.mkdir()
    for name, text in (("sbatch", SBATCH), ("scancel", SCANCEL), ("squeue", "#!/bin/sh\nexit 0\n")):
        (bin_dir / name).write_text(text)
        (bin_dir / name).chmod(0o755)
    return {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "FAKE_SLURM": str(tmp)}


def _alive(pid: int) -> bool:
    try:
        os.killpg(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.heavy
def test_the_documented_slurm_cluster_runs_rows_equal_to_a_local_run(tmp_path):
    env = _fake_slurm(tmp_path)
    cluster = subprocess.Popen(
        [sys.executable, str(ROOT / "examples" / "slurm_cluster.py"), "--jobs", "1", "--cores", "2",
         "--memory", "4GB", "--queue", "debug", "--walltime", "00:20:00", "--host", "127.0.0.1"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=open(tmp_path / "cluster.log", "wb"),
        text=True, env=env, start_new_session=True)
    try:
        address = cluster.stdout.readline().strip()
        assert address.startswith("tcp://127.0.0.1:"), (tmp_path / "cluster.log").read_text()
        from distributed import Client

        with Client(address, timeout=90) as client:
            client.wait_for_workers(2, timeout=90)
        script = (tmp_path / "job.sh").read_text()
        assert "#SBATCH -p debug" in script and "#SBATCH -t 00:20:00" in script
        assert "--nthreads 1" in script and "--nworkers 2" in script
        assert "export DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL=1s" in script

        common = ["--methods", "raw,angle-adaptive", "--scenarios", "stop-restart", "--seeds", "1", "--no-progress"]
        remote = rippleb_cli("run", *common, "--scheduler", address, "--out", tmp_path / "remote")
        assert remote.returncode == 0, remote.stderr
        local = rippleb_cli("run", *common, "--jobs", "2", "--out", tmp_path / "local")
        assert local.returncode == 0, local.stderr
        same_accuracy(read_results(tmp_path / "remote"), read_results(tmp_path / "local"))

        cluster.stdin.close()   # Ctrl-D: the script closes the cluster and cancels its jobs
        assert cluster.wait(timeout=60) == 0
        jobs = [int(j) for j in (tmp_path / "jobs").read_text().split()]
        assert [int(j) for j in (tmp_path / "cancelled").read_text().split()] == jobs
        deadline = time.monotonic() + 30
        while any(_alive(j) for j in jobs) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(_alive(j) for j in jobs)
    finally:
        if cluster.poll() is None:
            os.killpg(cluster.pid, signal.SIGKILL)
            cluster.wait()
        for job in (tmp_path / "jobs").read_text().split() if (tmp_path / "jobs").exists() else []:
            try:
                os.killpg(int(job), signal.SIGKILL)
            except ProcessLookupError:
                pass
