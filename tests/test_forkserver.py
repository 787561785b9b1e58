"""The fork server: jobs run from it, not from the runner, and it ends with the run."""

import hashlib
import os

import numpy as np
import pytest

from rippleb.engine.process import hugepages
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


def my_name(context):
    """A job: the name its process goes by."""
    with open("/proc/self/comm", "rb") as fh:
        return fh.read().strip()


def test_the_server_and_its_workers_go_by_their_names():
    """``ps`` and ``perf`` tell the kinds of process apart (isolation.name_process)."""
    with ForkServer.start(None) as server:
        fin = _run_one(Pool(1, server=server), my_name)   # the server has named itself by now
        with open(f"/proc/{server.pid}/comm", "rb") as fh:
            server_name = fh.read().strip()
    assert server_name == b"rippleb-server"
    assert fin.kind == "done" and fin.value == b"rippleb-worker", fin


def raises(context):
    raise ValueError("bad input in a job")


def test_a_job_that_raises_is_a_status_through_the_server():
    with ForkServer.start(None) as server:
        fin = _run_one(Pool(1, server=server), raises)
    assert fin.kind == "raised" and "bad input in a job" in fin.value


# The server's memory is re-mapped by 2 MiB pages before its first job
# (rippleb/engine/process/hugepages.py): the bytes a job inherits, and the privacy of
# what it writes, must be those of plain 4 KiB pages. 16 MiB spans whole 2 MiB pages.
INHERITED = np.random.default_rng(7).integers(0, 2**63, size=2 << 20, dtype=np.uint64)


def _digest(array) -> bytes:
    return hashlib.sha256(array.tobytes()).hexdigest().encode()


INHERITED_DIGEST = _digest(INHERITED)


def digest_then_scribble(context):
    """A job: the digest of what it inherited, then it overwrites every byte of it."""
    seen = _digest(INHERITED)
    INHERITED[:] = 0
    return seen


def test_jobs_inherit_the_servers_bytes_and_what_one_writes_stays_its_own():
    with ForkServer.start(None) as server:
        pool = Pool(1, server=server)
        first, second = _run_one(pool, digest_then_scribble), _run_one(pool, digest_then_scribble)
    assert first.kind == second.kind == "done", (first, second)
    assert first.value == second.value == INHERITED_DIGEST


def test_collapsing_changes_no_byte_and_a_childs_write_stays_the_childs():
    data = np.random.default_rng(8).integers(0, 2**63, size=2 << 20, dtype=np.uint64)
    before = _digest(data)
    assert hugepages.collapse_private_memory() >= 0   # 0 where the kernel offers no 2 MiB pages
    assert _digest(data) == before
    pid = os.fork()
    if pid == 0:
        data[:] = 0
        os._exit(0 if not data.any() else 1)
    assert os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 0
    assert _digest(data) == before


def test_only_whole_2mib_pages_of_anonymous_private_memory_are_collapsed():
    ranges = hugepages._aligned_private_ranges()
    assert ranges, "an interpreter has a heap and anonymous mappings"
    for start, end in ranges:
        assert start % hugepages.HUGE_PAGE == 0 and end % hugepages.HUGE_PAGE == 0 and end > start

