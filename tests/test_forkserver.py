"""The fork server: jobs run from it, not from the runner, and it ends with the run."""

import os

import pytest

from rippleb.engine.process.forkserver import ForkServer
from rippleb.engine.process.pool import Pool

SECRET = []  # filled by the test after the server was forked: the job must not see it


def report_what_i_see(context):
    """A job: its context, and whether the runner's later state reached it."""
    return f"{context}|{len(SECRET)}".encode()


def _run_one(pool, job):
    pool.submit("k", job, timeout=60)
    finished = []
    while not finished:
        finished = pool.wait()
    return finished[0]


def test_a_job_runs_from_the_server_with_its_context_and_not_what_the_runner_held_later():
    with ForkServer.start("ctx") as server:
        SECRET.append("truth")  # the runner learns something after the server started
        try:
            fin = _run_one(Pool(1, server=server), report_what_i_see)
        finally:
            SECRET.clear()
    assert fin.kind == "done", fin
    assert fin.value == b"ctx|0"


def test_a_direct_pool_passes_its_context_and_inherits_everything():
    SECRET.append("truth")
    try:
        fin = _run_one(Pool(1, context="direct"), report_what_i_see)
    finally:
        SECRET.clear()
    assert fin.kind == "done" and fin.value == b"direct|1"


def test_the_server_exits_when_the_runner_closes_it():
    server = ForkServer.start(None)
    pid = server.pid
    assert os.waitpid(pid, os.WNOHANG) == (0, 0)   # running
    server.close()
    with pytest.raises(ChildProcessError):         # reaped by close()
        os.waitpid(pid, os.WNOHANG)


def raises(context):
    raise ValueError("bad input in a job")


def test_a_job_that_raises_is_a_status_through_the_server():
    with ForkServer.start(None) as server:
        fin = _run_one(Pool(1, server=server), raises)
    assert fin.kind == "raised" and "bad input in a job" in fin.value
