"""Issue 25 item 3: ``--memory-limit`` is a hard limit of the row's worker, and of it only.

A method could raise its soft ``RLIMIT_AS`` to the (unlimited) hard one and then allocate
as much as it liked: 1.5 GiB under ``--memory-limit 200`` ended ``ok``, locally and on Dask.
"""

from __future__ import annotations

import functools
import json
import os
import resource
import subprocess
import sys
import textwrap
import time

import pandas as pd
import pytest

from rippleb.engine.process.pool import Pool
from support import install_dist  # a minimal installed distribution without pip

GIB = 2**30

LIFTER = textwrap.dedent('''
    import resource
    import numpy as np
    from rippleb import Method

    class Lifter(Method):
        """Raises its soft RLIMIT_AS to the hard limit, then holds 1.5 GiB (touched)."""
        name = "lifter"
        def reset(self, spec):
            soft, hard = resource.getrlimit(resource.RLIMIT_AS)
            try:
                resource.setrlimit(resource.RLIMIT_AS, (hard, hard))
            except (ValueError, OSError):
                pass
            self.hog = np.ones(int(1.5 * 2**30) // 8)
        def step(self, block):
            return block.strain * 0.0
''')


def _lift_and_allocate(go: str) -> bytes:
    """A job: once the file ``go`` exists, try to lift its own limit, then hold 1.5 GiB;
    report what happened."""
    import numpy as np

    deadline = time.monotonic() + 300
    while not os.path.exists(go) and time.monotonic() < deadline:
        time.sleep(0.01)  # the test reads the keeper's limits meanwhile, however loaded the host
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    for wanted in ((hard, hard), (resource.RLIM_INFINITY, resource.RLIM_INFINITY)):
        try:
            resource.setrlimit(resource.RLIMIT_AS, wanted)
        except (ValueError, OSError):
            pass
    lifted = resource.getrlimit(resource.RLIMIT_AS) != (soft, hard)
    try:
        hog = np.ones(int(1.5 * GIB) // 8)
        allocated = bool(hog[-1])
    except MemoryError:
        allocated = False
    return json.dumps({"soft": soft, "hard": hard, "lifted": lifted, "allocated": allocated}).encode()


def _address_space_limit(pid: int) -> str:
    with open(f"/proc/{pid}/limits") as fh:
        line = next(line for line in fh if line.startswith("Max address space"))
    return " ".join(line.split()[3:5])  # soft and hard, as the kernel prints them


def test_the_memory_limit_binds_the_worker_and_nothing_else(tmp_path):
    before = resource.getrlimit(resource.RLIMIT_AS)
    pool = Pool(1, memory_mb=200)
    go = tmp_path / "go"
    pool.submit("lifter", functools.partial(_lift_and_allocate, str(go)), timeout=600)
    run = pool._running[0]
    while run.worker is None:  # the keeper names its worker once it has forked it
        pool._collect()
        time.sleep(0.01)
    keeper_limits = _address_space_limit(run.keeper)   # the worker reports its own below
    go.touch()
    finished = []
    while not finished:
        finished = pool.wait()
    assert finished[0].kind == "done", finished[0]
    report = json.loads(finished[0].value)
    assert report["soft"] == report["hard"] != resource.RLIM_INFINITY   # the hard limit is the cap
    assert not report["lifted"] and not report["allocated"]
    # rippleb's own processes keep their limits: the keeper and this (runner) process
    assert keeper_limits == " ".join("unlimited" if v == resource.RLIM_INFINITY else str(v) for v in before)
    assert resource.getrlimit(resource.RLIMIT_AS) == before


@pytest.fixture(scope="module")
def lifter_site(tmp_path_factory):
    site = tmp_path_factory.mktemp("site")
    install_dist(site, "rippleb-lifter", "lifter_plugin", LIFTER, {"lifter": "Lifter"})
    return site


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local", "dask"])
def test_a_method_cannot_lift_the_memory_limit(lifter_site, tmp_path, executor):
    """Through the real CLI: the lifter's row fails with a MemoryError (before: ``ok``)
    and the other method's row is untouched."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(lifter_site), os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "rippleb", "run", "--methods", "lifter,raw",
                           "--scenarios", "static-contact", "--seeds", "1", "--memory-limit", "200",
                           "--no-progress", "--executor", executor, "--out", str(out)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_csv(out / "results.csv").set_index("method")
    assert rows.loc["lifter", "status"] == "error" and "MemoryError" in rows.loc["lifter", "message"]
    assert rows.loc["raw", "status"] == "ok"
