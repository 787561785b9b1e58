"""A method's process cannot reach the runner's plumbing (issue 25, item 2).

``Prober`` (``support.hostile.PLUMBING_PROBER``) tries, from its ``reset``, everything the
issue found open: the processes it can see in ``/proc``, every file descriptor of theirs it
can open for writing (the keeper's control pipe, the runner's terminal and results), the
terminals in ``/dev/pts``, files in the run directory and the cache, and forged summary
lines on its own output. It prints what it achieved on its own log (the one place it may
write). Through the real CLI the worker is confined (a /proc of its own, terminals hidden,
run directory and cache read-only); where the kernel refuses a mount namespace, the keeper
and the runner are still not dumpable, so their descriptors stay closed to it.
"""

import json
import os
import subprocess
import sys

import pandas as pd
import pytest

import rippleb
from support import install_dist  # a minimal installed distribution without pip
from support.hostile import PLUMBING_PROBER

pytestmark = pytest.mark.slow


def _reports(run_dir):
    return [json.loads(line[len("FOUND "):]) for p in sorted((run_dir / "logs").glob("prober*"))
            if not p.name.startswith("fit--")
            for line in p.read_text().splitlines() if line.startswith("FOUND ")]


def _assert_nothing_reached(found, run_dir):
    rippleb_fds = [entry for entry in found["opened"] if entry[3]]
    assert rippleb_fds == [], rippleb_fds            # no descriptor of the runner, server or keeper
    assert all(v != "opened" for v in found["run_dir"].values()), found["run_dir"]
    assert all(v != "opened" for v in found["cache"].values()), found["cache"]
    assert not (run_dir / "forged.txt").exists()


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    site = tmp_path_factory.mktemp("prober-site")
    install_dist(site, "rippleb-prober", "rippleb_prober", PLUMBING_PROBER, {"prober": "Prober"})
    return site


def test_a_confined_worker_sees_nothing_of_the_run(site, tmp_path):
    """Through the CLI: the worker's /proc holds itself only, no terminal, the run directory
    and the cache read-only; its forged summary lines end in its own log."""
    run_dir = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
           "TMPDIR": str(tmp_path), "RIPPLEB_KEY_FILE": str(tmp_path / "key")}
    prober = f'prober[run_dir="{run_dir}"]'
    proc = subprocess.Popen([sys.executable, "-m", "rippleb", "run", "--methods", f"{prober},raw", "--scenarios",
                             "static-contact", "--seeds", "1", "--jobs", "2", "--no-progress", "--out", str(run_dir)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    (found,) = _reports(run_dir)
    assert found["visible"] == [1], found["visible"]   # PID 1 of its namespace, alone
    assert found["opened"] == []
    assert found["terminals"] == {}
    assert (tmp_path / "key").stat().st_size == 32 and found["key_bytes"] == 0   # covered by /dev/null
    _assert_nothing_reached(found, run_dir)
    assert "12 rows (12 ok)" not in out + err
    assert "2 rows (2 ok)" in out + err
    rows = pd.read_csv(run_dir / "results.csv")
    assert sorted(rows.method) == [prober, "raw"] and (rows.status == "ok").all()
    assert any("12 rows (12 ok)" in p.read_text() for p in (run_dir / "logs").glob("prober*"))


def test_without_a_mount_namespace_the_plumbing_stays_closed(tmp_path, monkeypatch, register_methods):
    """A kernel that refuses the mount namespace (and Landlock, which would hide the host's
    /proc but the worker's own entry): the worker sees the host's processes, but every
    rippleb process (runner, fork server, keepers) is not dumpable, so none of their
    descriptors opens; the run directory is still only rippleb's to write, by its rows."""
    from rippleb.engine.process import isolation, landlock

    namespace = {}
    exec(PLUMBING_PROBER, namespace)
    monkeypatch.setattr(isolation, "NAMESPACE_CHOICES",   # no mount namespace
                        tuple(c for c in isolation.NAMESPACE_CHOICES if not c[1].mount))
    monkeypatch.setattr(landlock, "restrict", lambda *args, **kwargs: ["Landlock"])
    run_dir = tmp_path / "run"
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    register_methods(namespace["Prober"])
    frame = rippleb.run(methods=f'prober[run_dir="{run_dir}",runner={os.getpid()}],raw', scenarios="static-contact",
                        seeds=1, jobs=2, out=run_dir, progress=False)
    assert (frame.status == "ok").all(), frame.message.tolist()
    (found,) = _reports(run_dir)
    assert len(found["visible"]) > 1                   # the host's /proc: this is the weaker case
    rippleb_fds = [entry for entry in found["opened"] if entry[3]]
    assert rippleb_fds == [], rippleb_fds


# ----------------------------------------------------------------------------- the control pipe


def _write_into_keeper(garbage: bytes) -> bytes:
    """A job that writes ``garbage`` into every pipe its keeper holds (the control pipe among
    them), which only a worker with CAP_SYS_PTRACE over its keeper can: root without a user
    namespace. Returns whether it could."""
    keeper = os.getppid()
    wrote = 0
    try:
        fds = os.listdir(f"/proc/{keeper}/fd")
    except OSError:   # not dumpable, and this worker may not look (unprivileged)
        fds = []
    for fd in fds:
        try:
            if os.readlink(f"/proc/{keeper}/fd/{fd}").startswith("pipe:"):
                with open(f"/proc/{keeper}/fd/{fd}", "wb", buffering=0) as fh:
                    fh.write(garbage)
                wrote += 1
        except OSError:
            pass
    return b"wrote %d" % wrote


@pytest.mark.parametrize("garbage", [b"not a pid\n", b"4242 1\n0\n", b"1 1\n" * 3])
@pytest.mark.parametrize("sandbox", [True, False])
def test_garbage_in_the_control_pipe_ends_that_job_only(monkeypatch, garbage, sandbox):
    """Where the worker can reach its keeper's pipes (no namespaces, running as root, and no
    sandbox to drop its capabilities: the issue's attack, which crashed the run or defeated
    --timeout), what it writes ends its own job as ``garbled``, never the pool; a plain job
    beside it is done. With the sandbox (issue 34) a root worker holds no capability and
    opens nothing, as an unprivileged one."""
    import functools

    from rippleb.engine.process import isolation
    from rippleb.engine.process import sandbox as walls
    from rippleb.engine.process.pool import Pool

    monkeypatch.setattr(isolation, "NAMESPACE_CHOICES", ())   # the kernel refuses namespaces
    if not sandbox:
        monkeypatch.setattr(walls, "lock_down", lambda *args, **kwargs: ["a sandbox (switched off)"])
    pool = Pool(2)
    pool.submit("attacker", functools.partial(_write_into_keeper, garbage), timeout=30, confine=())
    pool.submit("plain", lambda: b"fine", timeout=30)
    finished = {}
    while pool.busy:
        finished.update({f.key: f for f in pool.wait()})
    assert finished["plain"].kind == "done" and finished["plain"].value == b"fine"
    if os.geteuid() == 0 and not sandbox:
        assert finished["attacker"].kind == "garbled", finished["attacker"]
    else:   # the keeper is not dumpable: an unprivileged worker cannot open its pipes
        attacker = finished["attacker"]
        assert attacker == attacker.__class__("attacker", "done", b"wrote 0", attacker.wall_s, attacker.method_s)


def test_the_control_parser_never_raises_and_reads_only_what_a_keeper_writes():
    from hypothesis import given
    from hypothesis import strategies as st

    from rippleb.engine.process.pool import control

    @given(st.binary(max_size=40))
    def anything(data):
        parsed = control(data)
        assert parsed is None or all(v is None or isinstance(v, int) for v in parsed)

    anything()
    assert control(b"") == (None, None, None)
    assert control(b"123 1") == (None, None, None)            # cut short by a read
    assert control(b"123 1\n") == (123, None, None)
    assert control(b"123 0\n-9 -1\n") == (123, -9, -1)     # the method never started
    assert control(b"123 0\n0 1500000\n") == (123, 0, 1500000)
    for forged in (b"x", b"123 1\n0\n0\n", b"123 1\nexit 0\n", b"123 2\n", b"123 1\n12345\n"):
        assert control(forged) is None, forged
