"""The project's own hostile suite for issue 41: a method tries, on every path that runs it,
each attack of the issue's table that concerns the walls, and each test asserts that the
attack failed and that the honest rows beside it are untouched.

The attacks live in one plugin (``tests/support/walls.py``, which the outcome table
``docs/tables/walls_table.py`` shares), installed as a distribution on the CLI's ``PYTHONPATH``:
``prober`` tries them all from its ``reset`` and raises what it achieved as JSON (its row's
message is the one way out that works on every path), the others each forge one column.
What a prober must know (the run directory, the recording, the salt, a port) it is given
as parameters, as a hostile method could guess them; it gets nothing through the
environment, which its process no longer inherits.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
import pytest

from support import install_dist, stopped_tune  # a minimal installed distribution without pip; tune stopped by a signal
from support.walls import (WALLS_METHODS, WALLS_PROBER, WALLS_SECRET, Listener, probe_of, rows_by_method,
                           walls_cli, walls_label)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    where = tmp_path_factory.mktemp("walls-site")
    install_dist(where, "rippleb-walls", "rippleb_walls", WALLS_PROBER, WALLS_METHODS)
    return where


@pytest.fixture
def registry(site, monkeypatch):
    """The registry with the hostile plugin on the path of this process and of the jobs it forks."""
    from rippleb.registry import Registry

    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", str(site))
    return Registry.discover()



def _assert_walls_held(found: dict, listener=None, readable_package=True) -> None:
    import errno

    denied = {k: v for k, v in found["read"].items() if k not in ("own_package", "numpy") and v is not None}
    assert all(v <= 0 for v in denied.values()), found       # -EACCES (Landlock), -ENOENT, or 0 bytes (a cover)
    assert found["read"]["numpy"] > 0                         # the libraries stay readable ...
    assert found["read"]["own_package"] > 0 or not readable_package   # ... and its own package
    assert all(v is None or v < 0 for v in found["list"].values()), found["list"]
    assert not found["environ_secret"] and not found["proc_environ_secret"] and not found["memory_secret"]
    if found["tcp"] is not None:
        assert found["tcp"] != 0 and (listener is None or not listener.received), found["tcp"]
    assert found["dask"] is None or found["dask"].startswith("refused"), found["dask"]
    from rippleb.engine.process.sandbox import MAX_TASKS

    assert found["forks"] < MAX_TASKS, found["forks"]
    assert found["write_package"] in (errno.EACCES, errno.EROFS, errno.EPERM)


def _clean_raw():
    import rippleb

    return rippleb.run(["raw"], ["static-contact"], [0], progress=False).iloc[0]


def _skip_without_walls():
    from rippleb.engine.process.sandbox import missing_protections

    if missing_protections():
        pytest.skip(f"this kernel does not grant {missing_protections()}")


# ----------------------------------------------------------------------------- local and Dask runs


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local", pytest.param("dask", marks=pytest.mark.heavy)])
def test_a_method_reads_only_what_it_is_handed_and_reaches_no_network(site, tmp_path, executor):
    """The issue's last row and its Dask row: the run directory, the key, ``$HOME``, ``/etc``,
    the exported secret (in the environment and anywhere in memory), a port on 127.0.0.1, a
    fork bomb and rippleb's own code; raw's row beside it equals a clean run's."""
    _skip_without_walls()
    home = tmp_path / "home"
    (home / ".ssh").mkdir(parents=True)
    (home / ".ssh" / "id_rsa").write_text("PRIVATE KEY\n")
    listener = Listener()
    try:
        method = walls_label(run_dir=str(tmp_path / "run"), home_file=str(home / ".ssh" / "id_rsa"), port=listener.port)
        proc = walls_cli(tmp_path, site, "run", "--methods", f"raw,{method}", "--scenarios", "static-contact", "--seeds",
                         "1", "--jobs", "2", "--no-progress", "--executor", executor, "--out", tmp_path / "run",
                         env={"HOME": str(home)})
    finally:
        listener.close()
    assert proc.returncode == 0, proc.stderr
    _assert_walls_held(probe_of(tmp_path / "run"), listener)
    raw = rows_by_method(tmp_path / "run")["raw"]
    assert raw["status"] == "ok" and float(raw["rms_error_nm"]) == _clean_raw()["rms_error_nm"]


@pytest.mark.slow
@pytest.mark.heavy
def test_on_a_scheduler_started_by_hand_a_method_cannot_reach_it(site, tmp_path, monkeypatch):
    """The issue's first row: ``--scheduler`` on a real ``dask scheduler`` and two ``dask
    worker`` processes (the plugin installed where they run); the prober tries
    ``run_on_scheduler`` on that address (before, its code ran in the scheduler and wrote rows
    with valid MACs)."""
    from support import Cluster

    _skip_without_walls()
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    cluster = Cluster(tmp_path, n=2)
    try:
        cluster.wait_for_workers(2)
        method = walls_label(run_dir=str(tmp_path / "run"), scheduler=cluster.address)
        proc = walls_cli(tmp_path, site, "run", "--methods", f"raw,{method}", "--scenarios", "static-contact", "--seeds",
                         "1", "--no-progress", "--scheduler", cluster.address, "--out", tmp_path / "run")
    finally:
        cluster.close()
    assert proc.returncode == 0, proc.stderr
    found = probe_of(tmp_path / "run")
    assert found["dask"] is not None
    _assert_walls_held(found)
    raw = rows_by_method(tmp_path / "run")["raw"]
    assert raw["status"] == "ok" and float(raw["rms_error_nm"]) == _clean_raw()["rms_error_nm"]
    report = walls_cli(tmp_path, site, "report", tmp_path / "run", "--out", tmp_path / "rep")
    assert report.returncode == 0 and "ignored" not in report.stderr, report.stderr   # every MAC rippleb's


@pytest.mark.slow
def test_the_walls_hold_for_an_unprivileged_user(site):
    """The same attacks by a run of uid 65534 (``nobody``), whose home is not writable."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to run as uid 65534")
    _skip_without_walls()
    where = Path(tempfile.mkdtemp(prefix="rippleb-walls-nobody-"))
    try:
        shutil.copytree(site, where / "site")
        for path in [where, *where.rglob("*")]:
            os.chown(path, 65534, 65534)
        listener = Listener()
        try:
            method = walls_label(run_dir=str(where / "run"), port=listener.port)
            proc = walls_cli(where, where / "site", "run", "--methods", f"raw,{method}", "--scenarios", "static-contact",
                             "--seeds", "1", "--jobs", "2", "--no-progress", "--out", "run", user=65534,
                             env={"HOME": "/nonexistent", "TMPDIR": str(where)})
        finally:
            listener.close()
        if proc.returncode != 0 and "Permission denied" in proc.stderr:
            pytest.skip(f"uid 65534 cannot run this Python: {proc.stderr.strip()[-200:]}")
        assert proc.returncode == 0, proc.stderr
        assert "warning" not in proc.stderr, proc.stderr      # every protection granted to nobody too
        _assert_walls_held(probe_of(where / "run"), listener)
        assert rows_by_method(where / "run")["raw"]["status"] == "ok"
    finally:
        shutil.rmtree(where, ignore_errors=True)


@pytest.mark.slow
def test_a_method_cannot_read_the_recording_it_is_scored_on(site, tmp_path):
    """The issue's second row: ``run --log`` (its reference in the file beside the method)."""
    from rippleb.log_files import write_log
    from rippleb.simulator import simulate

    _skip_without_walls()
    write_log(simulate("static-contact", 0).log, tmp_path / "rec.csv")
    write_log(simulate("calibration", 0).log, tmp_path / "cal.csv")
    method = walls_label(log=str(tmp_path / "rec.csv"), run_dir=str(tmp_path / "run"))
    proc = walls_cli(tmp_path, site, "run", "--log", tmp_path / "rec.csv", "--calibration", tmp_path / "cal.csv",
                     "--methods", f"raw,{method}", "--no-progress", "--out", tmp_path / "run")
    assert proc.returncode == 0, proc.stderr
    found = probe_of(tmp_path / "run")
    assert found["read"]["log"] < 0
    _assert_walls_held(found)
    assert rows_by_method(tmp_path / "run")["raw"]["status"] == "ok"


@pytest.mark.slow
@pytest.mark.parametrize("given", ["file", pytest.param("stdin", marks=pytest.mark.heavy)])
def test_a_resumed_sealed_run_hides_the_salt_its_file_and_every_copy(site, tmp_path, given):
    """The issue's third row: ``--resume --salt-file FILE``, the salt on stdin, and a copy of it
    in the working directory and in ``$HOME``."""
    _skip_without_walls()
    run, salt = tmp_path / "run", tmp_path / "salt"
    first = walls_cli(tmp_path, site, "run", "--methods", "raw", "--scenarios", "static-contact", "--seeds", "1",
                      "--no-progress", "--sealed", salt, "--out", run)
    assert first.returncode == 0, first.stderr
    before = rows_by_method(run)["raw"]
    shutil.copy(salt, tmp_path / "salt-copy")
    method = walls_label(run_dir=str(run), salt=str(salt), salt_copy=str(tmp_path / "salt-copy"))
    resumed = walls_cli(tmp_path, site, "run", "--resume", run, "--methods", f"raw,{method}", "--salt-file",
                        salt if given == "file" else "-", "--no-progress",
                        stdin=salt.read_text() if given == "stdin" else None)
    assert resumed.returncode == 0, resumed.stderr
    found = probe_of(run)
    assert found["read"]["salt"] <= 0 and found["read"]["salt_copy"] < 0   # 0: /dev/null over the named file
    _assert_walls_held(found)
    after = rows_by_method(run)["raw"]
    assert after["status"] == before["status"] == "ok"
    assert float(after["rms_error_nm"]) == float(before["rms_error_nm"])    # untouched by the resume


# ----------------------------------------------------------------------------- check and tune


@pytest.mark.slow
@pytest.mark.heavy
def test_check_ends_a_hanging_check_at_its_limit_names_it_and_runs_the_rest(site, tmp_path):
    proc = walls_cli(tmp_path, site, "check", "hanger", "--timeout", "20")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    failed = [line for line in lines if line.startswith("  FAIL")]
    assert failed == ["  FAIL  blocks of 7 samples give the estimate of one-tick blocks: no answer within 20 s "
                      "(--timeout): the check was ended"], lines
    assert lines[-1] == "hanger: 8 of 9 checks passed"


@pytest.mark.slow
def test_check_names_the_check_a_method_ends_its_process_in(site, tmp_path):
    proc = walls_cli(tmp_path, site, "check", "exiter", "--timeout", "60")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[2] == ("  FAIL  output: one finite estimate [Nm] per sample, in blocks of one control tick: its "
                        "process ended with exit code 7 before it reported"), lines
    assert all(line.startswith("  skip") for line in lines[3:-1])


@pytest.mark.slow
def test_a_tuning_point_cannot_reach_the_simulations_it_is_tuned_on(registry, monkeypatch):
    """The issue's tune row: its workers held the full simulations, ``torque_true`` included.
    A point now runs as a sandboxed row: it cannot list the directory the runner keeps its
    cache in, so it reads none of it, and its findings reach the record as its error."""
    from rippleb.engine.tuner import plan, tune

    monkeypatch.setattr(tempfile, "tempdir", "/tmp")       # the runner's cache where the peeker looks
    record = tune(plan(["peeker"], registry, 2), [100], jobs=2, timeout=120, registry=registry)["peeker"]
    peeks = [e for e in record["errors"] if "PEEK" in e]
    assert peeks, record["errors"]
    for peek in peeks:
        assert "listed=-13 caches=0 files_read=0" in peek, peek      # EACCES: Landlock


@pytest.mark.slow
@pytest.mark.heavy
def test_a_tuning_point_that_hangs_or_exits_costs_its_own_point(registry):
    """The issue's tune row: each point a sandboxed row under the limits; the record is kept."""
    from rippleb.engine.tuner import plan, tune

    planned = plan(["wobbly"], registry, 4)
    xs = [p["x"] for p in planned["wobbly"][1]]
    assert any(x > 0.8 for x in xs) and any(x < 0.2 for x in xs), xs   # the seed's points hit both
    record = tune(planned, [100], jobs=2, timeout=20, registry=registry)["wobbly"]
    for point in record["points"]:
        x, (score,) = point["params"]["x"], point["scores"]
        assert (score == float("inf")) == (x > 0.8 or x < 0.2), point
    assert any("timeout" in e for e in record["errors"]) and any("exited with code 3" in e for e in record["errors"])
    assert record["default_score"] < float("inf")


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, pytest.param(signal.SIGKILL, marks=pytest.mark.heavy)])
def test_tune_ends_at_once_on_a_signal_and_leaves_no_process(tmp_path, signum):
    """The issue's ``tune`` rows: Ctrl-C ends it (130) within seconds, and neither Ctrl-C nor
    ``kill -9`` leaves a worker of it running."""
    code, ended, family, left = stopped_tune(tmp_path, signum)
    assert code == (130 if signum == signal.SIGINT else -signal.SIGKILL)
    assert ended < 30, ended           # 0.7 s measured; a loaded machine keeps a wide margin
    assert family > 1 and left == 0, (family, left)


# ----------------------------------------------------------------------------- columns a method cannot forge


@pytest.mark.slow
def test_a_method_cannot_forge_its_timing_nor_pass_integers_as_torque(site, tmp_path):
    """The issue's clock, stack-frame and uint64 rows; raw beside them is untouched."""
    proc = walls_cli(tmp_path, site, "run", "--methods", "raw,clockstopper,framer,huge", "--scenarios", "static-contact",
                     "--seeds", "1", "--jobs", "2", "--no-progress", "--out", tmp_path / "run")
    assert proc.returncode == 0, proc.stderr
    rows = rows_by_method(tmp_path / "run")
    assert rows["clockstopper"]["status"] == "invalid" and "took no time" in rows["clockstopper"]["message"]
    assert rows["framer"]["status"] == "invalid" and "does not measure its work" in rows["framer"]["message"]
    assert rows["huge"]["status"] == "invalid" and "float64" in rows["huge"]["message"]
    assert float(rows["clockstopper"]["fit_s"]) >= 2.0      # it slept 2 s and turned its clock back
    assert float(rows["raw"]["rms_error_nm"]) == _clean_raw()["rms_error_nm"]


@pytest.mark.slow
@pytest.mark.heavy
def test_a_fitted_state_is_counted_against_the_memory_limit_not_held_by_the_runner(site, tmp_path):
    """The issue's 900 MB fitted state that cost the runner 3 GB: the runner now receives it
    into a file; beyond --memory-limit the fit fails, and the rows beside it run."""
    script = textwrap.dedent(f"""
        import resource, sys
        sys.path.insert(0, {str(site)!r})
        import rippleb
        frame = rippleb.run(["raw", "fat[mb=600]"], ["static-contact"], [0], jobs=1, memory_mb=float(sys.argv[1]))
        print(dict(zip(frame.method, frame.status)), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    roomy = subprocess.run([sys.executable, "-c", script, "4096"], capture_output=True, text=True, env=env,
                           cwd=tmp_path, timeout=1200)
    assert roomy.returncode == 0, roomy.stderr
    statuses, peak_mb = roomy.stdout.strip().rsplit(" ", 1)
    assert statuses == "{'fat[mb=600]': 'ok', 'raw': 'ok'}"
    assert int(peak_mb) < 600, peak_mb        # the runner never held the 600 MB state
    tight = subprocess.run([sys.executable, "-c", script, "400"], capture_output=True, text=True, env=env,
                           cwd=tmp_path, timeout=1200)
    assert tight.returncode == 0, tight.stderr
    assert tight.stdout.startswith("{'fat[mb=600]': 'error', 'raw': 'ok'}"), tight.stdout


def test_a_method_process_keeps_only_the_variables_that_set_the_libraries(monkeypatch):
    """The environment a method's process keeps (rippleb.engine.process.scrub), in a fork."""
    from rippleb.engine.process import scrub

    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", WALLS_SECRET)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        scrub.scrub_environment()
        text = json.dumps([sorted(os.environ), WALLS_SECRET.encode() in open("/proc/self/environ", "rb").read()])
        os.write(write, text.encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as fh:
        names, in_block = json.loads(fh.read())
    os.waitpid(pid, 0)
    assert "AWS_SECRET_ACCESS_KEY" not in names and "OPENBLAS_NUM_THREADS" in names and "PATH" in names
    assert not in_block
    assert all(n in scrub.KEPT or n.startswith(scrub.KEPT_PREFIXES) for n in names)


def test_an_integer_estimate_is_invalid_however_large():
    from rippleb.harness import InvalidOutput, stream

    class Block:
        t = np.zeros(4)

    with pytest.raises(InvalidOutput, match="float64"):
        stream(lambda block: np.full(4, np.iinfo(np.uint64).max, dtype=np.uint64), [Block()], 4)


@pytest.mark.parametrize("ticks, method_s, why", [
    ([1, 2000], 1.0, "less than any call of a Python method"),
    ([0, 2000], 1e-5, "took no time"),
    ([10**9, 10**9], 1.5, "more than the 1.5 s"),
    ([10**6] * 10, 0.05, ""),
    ([100, 200], None, ""),
])
def test_tick_times_must_agree_with_the_time_measured_outside(ticks, method_s, why):
    from rippleb.scoring.row import check_ticks

    found = check_ticks(np.array(ticks, dtype=np.int64), method_s)
    assert (why in found) if why else found == "", found
