"""Ctrl-C and SIGTERM at any moment (issue 25, item 1).

A signal must end a run within seconds, keep every finished row, print one line (with
``rippleb run --resume DIR`` once the run has claimed its directory) and exit 130, and
leave no process behind. Each way the old code failed has a test of its own here; the
slow test interrupts small runs at random moments (``benchmarks/signal_trials.py`` runs
hundreds of such trials).
"""

from __future__ import annotations

import importlib.util
import os
import random
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pandas as pd
import pytest

from rippleb import interrupts
from rippleb.cli import program as cli
from rippleb.engine.process import forkserver, isolation
from rippleb.engine.process.forkserver import ForkServer
from rippleb.engine.process.pool import Pool

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("signal_trials", ROOT / "benchmarks" / "signal_trials.py")
signal_trials = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(signal_trials)

#: How long a command may take to end after its signal before it counts as a hang [s].
HANG_S = 60


def python(code: str, *args, cwd=None, env=None) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter with SIGINT not ignored (a child of a pytest-xdist
    worker inherits it ignored), in a session of its own; a hang fails, it does not block."""
    return subprocess.run([*signal_trials._default_sigint(), sys.executable, "-c", code, *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, env=env, timeout=HANG_S,
                          start_new_session=True)


#: Ctrl-C at the very moment a job's keeper exists but the runner has not yet recorded it
#: (right after the fork server answered), once the job, a simulation, is writing its truth
#: (megabytes, more than a pipe holds) into its pipe: a job the runner lost track of kept
#: its worker, keeper, the fork server and the runner waiting for ever.
SIGNAL_IN_SUBMIT = """
import os, signal, sys, time
from rippleb.engine.process import forkserver
real = forkserver.ForkServer.spawn
def spawn(self, job, *args, **kwargs):
    pid = real(self, job, *args, **kwargs)
    if job.kind == "simulate" and "scored" in job.args[3] and not getattr(spawn, "sent", False):
        spawn.sent = True
        deadline = time.monotonic() + 60
        while not os.path.exists(job.args[3]["scored"]) and time.monotonic() < deadline:
            time.sleep(0.05)   # its log is stored: next it sends the truth
        time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGINT)
    return pid
forkserver.ForkServer.spawn = spawn
from rippleb.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_signal_while_a_job_starts_ends_the_run_and_leaves_nothing_running(tmp_path):
    marker = f"RIPPLEB_TEST_{os.getpid()}_{time.monotonic_ns()}"
    env = {**os.environ, marker: "1"}
    try:
        proc = python(SIGNAL_IN_SUBMIT, "run", "--methods", "raw", "--scenarios", "static-contact",
                      "--seeds", "1", "--jobs", "1", "--out", tmp_path / "out", "--no-progress", env=env)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the run still waited {HANG_S} s after Ctrl-C")
    finally:
        left = _processes_with(marker)
        for pid in left:
            os.kill(pid, signal.SIGKILL)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"rippleb: interrupted; no row had finished; the selection is in {tmp_path / 'out' / 'run.json'}; "
        f"finish the run with: rippleb run --resume {tmp_path / 'out'}"]
    assert not left, f"{len(left)} process(es) of the run still running"


def _processes_with(marker: str, grace_s: float = 2.0) -> list[int]:
    deadline = time.monotonic() + grace_s
    while True:
        found = []
        for entry in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{entry}/environ", "rb") as fh:
                    if f"{marker}=1".encode() in fh.read().split(b"\0"):
                        found.append(int(entry))
            except OSError:
                continue
        if not found or time.monotonic() > deadline:
            return found
        time.sleep(0.05)


def big_result():
    return b"x" * (8 << 20)  # far more than a pipe holds: the worker blocks until it is read


def test_a_keeper_ends_its_worker_once_the_runner_stops_listening():
    from rippleb.engine.process.keeper import keeper

    result_r, result_w = os.pipe()
    ctrl_r, ctrl_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        keeper(big_result, result_w, ctrl_w, None, None)  # never returns
    os.close(result_w)
    os.close(ctrl_w)
    try:
        line = b""
        while not line.endswith(b"\n"):
            line += os.read(ctrl_r, 100)   # the keeper names its worker
        os.close(ctrl_r)  # the runner stops listening; the result pipe stays open, unread
        ended = isolation.wait_exit(pid, HANG_S)
        if not ended:
            os.killpg(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        assert ended, "the keeper still waited for a worker blocked on a pipe nobody reads"
    finally:
        os.close(result_r)


def test_a_fork_server_that_does_not_exit_when_closed_is_killed(monkeypatch):
    monkeypatch.setattr(forkserver, "EXIT_GRACE_S", 0.5)
    server = ForkServer.start(None, preload=lambda: time.sleep(600))  # deaf to its socket
    closing = threading.Thread(target=server.close, daemon=True)
    closing.start()
    closing.join(HANG_S)
    try:
        assert not closing.is_alive(), "close() still waits for the server"
        with pytest.raises(ChildProcessError):  # killed and reaped
            os.waitpid(server.pid, os.WNOHANG)
    finally:
        if closing.is_alive():
            os.kill(server.pid, signal.SIGKILL)


def test_a_job_waiting_for_a_busy_fork_server_gives_way_to_a_signal():
    server = ForkServer.start(None, preload=lambda: time.sleep(600))  # busy: never answers
    # whatever happens, the server dies in HANG_S, so a wait without a way out fails, not hangs
    killer = threading.Timer(HANG_S, os.kill, (server.pid, signal.SIGKILL))
    killer.start()
    try:
        with interrupts.handling(), interrupts.held():
            threading.Timer(0.3, signal.raise_signal, (signal.SIGTERM,)).start()
            pool = Pool(1, server=server)
            with pytest.raises(KeyboardInterrupt):
                pool.submit("k", big_result, timeout=None)
            assert not pool.busy   # nothing half started is tracked
    finally:
        killer.cancel()
        os.kill(server.pid, signal.SIGKILL)
        server.close()


def test_an_interrupt_while_the_command_starts_is_one_line(monkeypatch, capsys):
    def interrupted():
        raise KeyboardInterrupt  # as a Ctrl-C while the parser imports the runner
    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["list"]) == 130
    assert capsys.readouterr().err == "rippleb: interrupted\n"


SIGTERM_IN_START_UP = """
import os, signal, sys
import rippleb.cli.program as cli
real = cli.build_parser
def build():
    os.kill(os.getpid(), signal.SIGTERM)
    return real()
cli.build_parser = build
sys.exit(cli.main(["list"]))
"""


def test_sigterm_while_the_command_starts_is_one_line_and_status_130():
    proc = python(SIGTERM_IN_START_UP)
    assert (proc.returncode, proc.stderr) == (130, "rippleb: interrupted\n")


#: Pinocchio's import runs Python code through Boost.Python's ``exec`` (``PyRun_String``);
#: a Ctrl-C there leaves Python remembering an "unhandled" KeyboardInterrupt, for which it
#: kills itself with SIGINT at exit, whatever status the program chose (unless a later
#: ``PyRun_String``, e.g. numpy's import, happens to clear it).
INTERRUPTED_EXEC = """
import ctypes, sys
import rippleb.cli.program as cli
real = cli.build_parser
def build():
    parser = real()
    ctypes.pythonapi.PyRun_SimpleString(b"raise KeyboardInterrupt")  # Boost's exec, interrupted,
    raise KeyboardInterrupt                                           # and so the import
cli.build_parser = build
sys.argv = ["rippleb", "list"]
cli.entry()
"""


def test_the_program_exits_130_after_an_interrupted_exec(tmp_path):
    (tmp_path / "interrupted_exec.py").write_text(INTERRUPTED_EXEC)
    proc = subprocess.run([sys.executable, "-m", "interrupted_exec"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=HANG_S)
    assert proc.returncode == 130, (proc.returncode, proc.stderr)
    assert proc.stderr.splitlines()[-1] == "rippleb: interrupted"


#: Reports whether signals are held in this process and in a child that multiprocessing
#: spawns (as a local Dask cluster starts its workers: the child gets this sys.argv).
HELD_PROBE = """
import multiprocessing, signal, sys
import rippleb

def report(queue):
    import rippleb
    queue.put(rippleb.interrupts._HELD[0])

if __name__ == "__main__":
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    child = ctx.Process(target=report, args=(queue,))
    child.start()
    print(rippleb.interrupts._HELD[0], signal.getsignal(signal.SIGTERM) is signal.SIG_DFL, queue.get())
    child.join()
"""


@pytest.mark.parametrize("script, held", [("rippleb", "1 False"), ("my_script.py", "0 True")])
def test_signals_are_held_from_the_first_line_of_the_program_only(tmp_path, script, held):
    (tmp_path / script).write_text(HELD_PROBE)
    proc = subprocess.run([sys.executable, tmp_path / script], capture_output=True, text=True, timeout=HANG_S)
    # the program holds them from its first line; a library user and a spawned child do not
    assert proc.stdout.split() == [*held.split(), "0"], proc.stderr


# ----------------------------------------------------------------------------- random moments

#: A tiny run (2 rows, about 3 s on 2 cores), interrupted over its start-up and its rows.
TINY = ["--methods", "raw", "--scenarios", "static-contact", "--seeds", "2", "--jobs", "2"]
TRIALS = 48
MAX_DELAY_S = 2.5


@pytest.mark.slow
@pytest.mark.heavy
def test_interrupts_at_random_moments_end_every_run_cleanly():
    rng = random.Random(25)
    plan = [(rng.uniform(0.0, MAX_DELAY_S), rng.choice(signal_trials.MODES), i % 8 == 0) for i in range(TRIALS)]

    def one(delay, mode, resume):
        return signal_trials.trial(delay, mode, run_args=TINY, rows=2, timeout=HANG_S, resume=resume)
    with ThreadPoolExecutor(2) as pool:   # two at a time: a trial mostly waits
        results = list(pool.map(lambda args: one(*args), plan))
    failed = [f"{r['mode']} at {r['delay']:.2f} s: {r['problems']}" for r in results if r["problems"]]
    assert not failed, "\n".join(failed)
    outcomes = {r["outcome"] for r in results}
    assert "interrupted" in outcomes, outcomes   # the signals did land in runs


def test_the_trial_checker_sees_a_traceback_and_a_lost_row(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text("{}")
    pd.DataFrame({"method": ["raw"], "status": ["ok"]}).to_csv(out / "results.csv", index=False)
    line = f"rippleb: interrupted; 2 finished row(s) are in {out}/results.csv; finish the run with: x --resume {out}"
    result = {"delay": 1.0, "code": 130, "problems": []}
    signal_trials._check(result, "", "Traceback (most recent call last):\nKeyboardInterrupt\n" + line, out, 2)
    kinds = sorted(p.split(":", 1)[0] for p in result["problems"])
    assert kinds == ["rows", "traceback"], result["problems"]


def test_recording_the_git_state_never_takes_git_s_index_lock(tmp_path):
    """A run records its checkout's git state as it starts. ``git status`` rewrites a stale
    index under ``.git/index.lock``; an interrupt meanwhile killed it and left the lock, and
    the user's next ``git commit`` failed. The index must be left as it was."""
    from rippleb.report.provenance import git_state

    def git(*args):
        subprocess.run(["git", "-C", tmp_path, "-c", "user.email=t@t", "-c", "user.name=t", *args],
                       check=True, capture_output=True)
    git("init", "-q")
    (tmp_path / "rippleb").mkdir()
    (tmp_path / "rippleb" / "x.py").write_text("x = 1\n")
    git("add", ".")
    git("commit", "-qm", "x")
    index = tmp_path / ".git" / "index"
    before = index.stat()
    time.sleep(1.1)   # the file's stat data now differ from the index's: a refresh would rewrite it
    os.utime(tmp_path / "rippleb" / "x.py")
    state = git_state(tmp_path)
    assert state["git_dirty"] is False
    after = index.stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns), "the index was rewritten"
