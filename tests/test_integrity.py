"""Integrity against a hostile plugin package, through the real CLI.

The package is installed as a distribution (a ``.dist-info`` directory with entry points)
in a site directory put on ``PYTHONPATH`` of the ``rippleb`` subprocess only, so the test
environment itself is unchanged. Each plugin (``support.hostile.INTEGRITY_HOSTILE``) attacks
one promise: rows forged through the cache, truth read from the cache, processes left
behind, the runner signalled, imports that hang or exit.
"""

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest
from conftest import HANG_TIMEOUT_S

from support import NAPPER, install_dist, nap, napping
from support.hostile import INTEGRITY_HOSTILE, SLOW_IMPORT

pytestmark = pytest.mark.slow

EXITS = "raise SystemExit(3)\n"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    site = tmp_path_factory.mktemp("hostile-site")
    install_dist(site, "rippleb-hostile", "rippleb_hostile", INTEGRITY_HOSTILE,
          {"forger": "Forger", "peeker": "Peeker", "spawner": "Spawner", "killer": "Killer",
           "rummager": "Rummager"})
    install_dist(site, "rippleb-slow", "rippleb_slow", SLOW_IMPORT, {"slow-import": "Anything"})
    install_dist(site, "rippleb-exits", "rippleb_exits", EXITS, {"exits": "Anything"})
    install_dist(site, "rippleb-napper", "rippleb_napper", NAPPER, {"napper": "Napper"})
    return site


def _env(site, tmp):
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
            "TMPDIR": str(tmp), "HOSTILE_PIDS": str(tmp / "pids")}


def rippleb(site, *args, tmp, timeout=600):
    return subprocess.run([sys.executable, "-m", "rippleb", *map(str, args)], capture_output=True,
                          text=True, env=_env(site, tmp), timeout=timeout)


def _spawned(seconds=("987", "988")) -> list[int]:
    """Live ``sleep`` processes of the given arguments, seen from here: the hostile spawner
    starts ``sleep 987`` and ``sleep 988``; ``Spawns`` (which may run at the same time on the
    other test worker) other numbers, so neither test sees the other's."""
    wanted = {b"sleep\0" + s.encode() + b"\0" for s in seconds}
    found = []
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as fh:
                cmdline = fh.read()
            with open(f"/proc/{entry}/stat") as fh:
                state = fh.read().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if cmdline in wanted and state != "Z":
            found.append(int(entry))
    return found


def _run(site, tmp, out, methods, jobs="2"):
    return rippleb(site, "run", "--methods", methods, "--scenarios", "static-contact", "--seeds", "1",
                   "--jobs", jobs, "--no-progress", "--timeout", "120", "--out", out, tmp=tmp)


def test_hostile_plugins_cannot_peek_escape_or_kill(site, tmp_path):
    clean = _run(site, tmp_path, tmp_path / "clean", "raw,lowpass", jobs="1")
    assert clean.returncode == 0, clean.stderr
    reference = pd.read_csv(tmp_path / "clean" / "results.csv").set_index("method")
    proc = _run(site, tmp_path, tmp_path / "hostile", "peeker,spawner,killer,rummager,raw,lowpass")
    assert proc.returncode == 0, proc.stderr      # the killer did not end the run
    rows = pd.read_csv(tmp_path / "hostile" / "results.csv").set_index("method")
    assert sorted(rows.index) == ["killer", "lowpass", "peeker", "raw", "rummager", "spawner"]
    assert (rows.status == "ok").all(), rows.message.to_dict()
    for method in ("raw", "lowpass"):
        assert rows.loc[method, "rms_error_nm"] == reference.loc[method, "rms_error_nm"]
    # the truth never reached a method: the peeker found none and scores like zeros (= the torque)
    assert rows.loc["peeker", "rms_error_nm"] > 0.1
    time.sleep(0.5)
    assert "spawned" in (tmp_path / "hostile" / "logs" / "fit--spawner--0.txt").read_text()   # it did start them
    assert _spawned() == []
    assert not list(tmp_path.glob("rippleb-cache-*"))        # the cache went with the run


def test_a_plugin_cannot_rewrite_the_cache(site, tmp_path):
    """One job at a time, rows in key order: the forger's fit tries to rewrite every cached
    log before the other rows read theirs; its worker sees the cache read-only."""
    clean = _run(site, tmp_path, tmp_path / "clean", "lowpass,raw", jobs="1")
    assert clean.returncode == 0, clean.stderr
    proc = _run(site, tmp_path, tmp_path / "forged", "forger,lowpass,raw", jobs="1")
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_csv(tmp_path / "forged" / "results.csv").set_index("method")
    reference = pd.read_csv(tmp_path / "clean" / "results.csv").set_index("method")
    for method in ("lowpass", "raw"):
        assert rows.loc[method, "status"] == "ok", rows.loc[method, "message"]
        assert rows.loc[method, "rms_error_nm"] == reference.loc[method, "rms_error_nm"]


def test_where_the_cache_is_writable_a_rewrite_fails_the_rows_it_tampered(tmp_path, monkeypatch,
                                                                            register_methods):
    """Without a mount namespace and without Landlock (a kernel that refuses both) the worker
    can write the cache; the SHA-256 of every cached file, taken before any method ran, still
    catches it. (With Landlock alone the rewrite is refused: tests/test_hostile.py.)"""
    from rippleb.engine.process import isolation, landlock

    namespace = {}
    exec(INTEGRITY_HOSTILE, namespace)
    monkeypatch.setattr(isolation, "NAMESPACE_CHOICES",   # no mount namespace
                        tuple(c for c in isolation.NAMESPACE_CHOICES if not c[1].mount))
    monkeypatch.setattr(landlock, "restrict", lambda *args, **kwargs: ["Landlock"])          # nor Landlock
    (tmp_path / "tmp").mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))   # the forger rewrites this run's cache only
    monkeypatch.setattr("tempfile.tempdir", None)
    monkeypatch.chdir(tmp_path)
    register_methods(namespace["Forger"])
    import rippleb

    frame = rippleb.run(methods="forger,lowpass,raw", scenarios="static-contact", seeds=1, jobs=1,
                        out=tmp_path / "forged", progress=False).set_index("method")
    for method in ("lowpass", "raw"):
        assert frame.loc[method, "status"] == "error"
        assert "SHA-256 mismatch" in frame.loc[method, "message"]


@pytest.mark.heavy
def test_a_plugin_that_hangs_or_exits_at_import_delays_only_itself(site, tmp_path):
    # A healthy plugin imports in milliseconds in its forked child: 10 s is out of reach of
    # a loaded host, and the hanging import (an hour) is bounded by it; the subprocess's own
    # limit fails the test if the hang reached the parent instead.
    proc = rippleb(site, "list", "--import-timeout", "10", tmp=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = {line.split()[0]: line for line in proc.stdout.splitlines() if line.startswith("  ")}
    assert "broken" in lines["slow-import"] and "longer than 10 s" in lines["slow-import"]
    assert "broken" in lines["exits"] and "SystemExit" in lines["exits"]
    assert "plugin" in lines["forger"]

    # the hanging import costs its row the timeout; raw's jobs take well under a second
    proc = rippleb(site, "run", "--methods", "slow-import,exits,raw", "--scenarios", "static-contact",
                   "--seeds", "1", "--jobs", "2", "--timeout", HANG_TIMEOUT_S, "--no-progress", "--out",
                   tmp_path / "run", tmp=tmp_path)
    assert proc.returncode == 1 and "exits" in proc.stderr      # a requested plugin is broken
    rows = pd.read_csv(tmp_path / "run" / "results.csv").set_index("method")
    assert rows.loc["raw", "status"] == "ok" and rows.loc["slow-import", "status"] == "timeout"
    assert rows.loc["exits", "status"] == "error" and "SystemExit" in rows.loc["exits", "message"]


def test_a_running_directory_is_locked_and_an_interrupted_one_resumable(site, tmp_path):
    out = tmp_path / "run"
    args = [sys.executable, "-m", "rippleb", "run", "--methods", "napper,raw", "--scenarios", "static-contact",
            "--seeds", "1", "--jobs", "1", "--no-progress", "--out", str(out)]
    env = _env(site, tmp_path)
    with nap(site):
        runner = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        while not napping(out):    # the napper's fit is running: no row finished
            assert runner.poll() is None
            time.sleep(0.02)
        second = subprocess.run(args[:-2] + ["--resume", str(out)], capture_output=True, text=True,
                                timeout=120, env=env)
        assert second.returncode == 2 and "another rippleb run is writing this directory" in second.stderr
        runner.send_signal(signal.SIGTERM)
        _, err = runner.communicate(timeout=60)
    assert runner.returncode == 130, err
    assert "no row had finished" in err and f"rippleb run --resume {out}" in err
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    refused = subprocess.run(args, capture_output=True, text=True, timeout=120, env=env)
    assert refused.returncode == 2 and f"{out}: not empty" in refused.stderr
    assert f"--resume {out}" in refused.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before   # nothing replaced
    resumed = subprocess.run(args[:4] + ["--resume", str(out), "--no-progress"], capture_output=True,
                             text=True, timeout=300, env=env)
    assert resumed.returncode == 0, resumed.stderr
    rows = pd.read_csv(out / "results.csv")
    assert list(rows.method) == ["napper", "raw"] and list(rows.status) == ["ok", "ok"]


SPAWNS = textwrap.dedent('''
    import os, subprocess, time
    import numpy as np
    from rippleb import Method

    class Spawns(Method):
        name = "spawns"
        def fit(self, calibration):
            subprocess.Popen(["sleep", "977"], start_new_session=True)
            if os.fork() == 0:
                os.setsid()
                os.execvp("sleep", ["sleep", "978"])
            time.sleep(0.2)
        def step(self, block):
            return np.zeros(len(block))
''')


@pytest.mark.parametrize("namespaces", [True, False], ids=["pid-namespace", "subreaper-only"])
def test_no_process_outlives_its_row(tmp_path, monkeypatch, namespaces, register_methods):
    """With and without PID namespaces (where the kernel refuses them, the keeper is a
    child subreaper that kills every descendant)."""
    import importlib

    import rippleb
    from rippleb.engine.process import isolation

    (tmp_path / "spawns_mod.py").write_text(SPAWNS)
    monkeypatch.syspath_prepend(str(tmp_path))
    cls = importlib.import_module("spawns_mod").Spawns
    if not namespaces:
        monkeypatch.setattr(isolation, "new_namespaces", lambda: isolation.NONE)
    register_methods(cls)
    frame = rippleb.run(methods="spawns", scenarios="static-contact", seeds=1)
    assert list(frame.status) == ["ok"], frame.message.tolist()
    time.sleep(0.3)
    assert _spawned(("977", "978")) == []


def _signals_its_group_and_parent():
    for action in (lambda: os.killpg(0, signal.SIGTERM), lambda: os.kill(os.getppid(), signal.SIGKILL)):
        try:
            action()
        except OSError:
            pass
    time.sleep(0.3)  # the keeper, had it been hit, is gone by now
    return b"reported"


def _signals_its_group():
    os.killpg(0, signal.SIGTERM)
    time.sleep(0.3)
    return b"reported"


@pytest.mark.parametrize("namespaces", [True, False], ids=["pid-namespace", "subreaper-only"])
def test_a_job_that_signals_its_group_cannot_kill_its_keeper(monkeypatch, namespaces):
    """The worker has its own process group: killpg(0) reaches only the worker and its
    children, never the keeper that reports how the job ended. In a PID namespace the
    worker is its init and survives its own signals (kill(getppid()) is kill(0) there), so
    the job reports; without one the worker ends itself, and the keeper lives to report the
    signal (before, it died with it, and the row's cause was lost or, when the worker was
    still fast enough, the row was saved by luck)."""
    from rippleb.engine.process import isolation
    from rippleb.engine.process.pool import Pool

    if not namespaces:
        monkeypatch.setattr(isolation, "new_namespaces", lambda: isolation.NONE)
    job = _signals_its_group_and_parent if namespaces else _signals_its_group
    expected = ("done", b"reported") if namespaces else ("died", -signal.SIGTERM)
    outcomes = []
    for key in range(5):
        pool = Pool(1)
        pool.submit(key, job, timeout=60)
        finished = []
        while not finished:
            finished = pool.wait()
        outcomes.append((finished[0].kind, finished[0].value))
    assert outcomes == [expected] * 5


def test_dask_rows_cannot_find_the_truth_either(site, tmp_path):
    """``--executor dask`` starts a local cluster and closes it; on its workers the rows'
    processes are forked by each worker's fork server, started before its first row, so the
    worker's memo of simulations (truths included) is not theirs, and the rows equal a local run's."""
    common = ["--scenarios", "stop-restart", "--seeds", "1", "--no-progress"]
    proc = rippleb(site, "run", "--methods", "rummager,raw,angle-adaptive", *common, "--executor", "dask",
                   "--jobs", "2", "--out", tmp_path / "dask", tmp=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    rows = pd.read_csv(tmp_path / "dask" / "results.csv").set_index("method")
    assert (rows.status == "ok").all(), rows.message.to_dict()   # the rummager found no truth
    local = rippleb(site, "run", "--methods", "raw,angle-adaptive", *common, "--jobs", "1",
                    "--out", tmp_path / "local", tmp=tmp_path)
    assert local.returncode == 0, local.stderr
    reference = pd.read_csv(tmp_path / "local" / "results.csv").set_index("method")
    columns = ["rms_error_nm", "max_error_nm", "restart_max_error_nm", "stopped_rms_error_nm"]
    pd.testing.assert_frame_equal(rows.loc[["raw", "angle-adaptive"], columns],
                                  reference.loc[["raw", "angle-adaptive"], columns], check_exact=True)
