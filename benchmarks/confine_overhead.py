"""What confining a method's worker costs per job (docs/robustness.md section 9).

    python benchmarks/confine_overhead.py [JOBS]

Runs JOBS trivial jobs through a two-slot :class:`rippleb.engine.process.pool.Pool` as rippleb's
own jobs run (``confine=None``: PID namespace only), as a method's ran before issue 34
(with the walls of :mod:`rippleb.engine.process.sandbox` switched off: mount namespace, own
/proc, terminals covered, a directory read-only, and since issue 34 a tmpfs as its scratch
directory) and as a method's runs now
(the same, then a second user namespace, Landlock, seccomp, no capabilities), in alternating batches of 20, and prints the median wall time per job of each.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths
from rippleb.engine.process.isolation import Confinement
from rippleb.engine.process.pool import Pool


def _nothing() -> bytes:
    return b"ok"


def batch(confine, n: int = 20) -> float:
    """Seconds per job of ``n`` jobs, two at a time."""
    pool = Pool(2)
    start = time.perf_counter()
    submitted = 0
    while submitted < n or pool.busy:
        while submitted < n and pool.free:
            pool.submit(submitted, _nothing, timeout=30, confine=confine)
            submitted += 1
        for finished in pool.wait():
            assert finished.kind == "done", finished
    return (time.perf_counter() - start) / n


def walled(on: bool, confine, n: int = 20) -> float:
    """:func:`batch` of a method's jobs, with or without the walls of issue 34."""
    from rippleb.engine.process import sandbox

    lock_down, wipe = sandbox.lock_down, sandbox.wipe_command_line
    if not on:
        sandbox.lock_down, sandbox.wipe_command_line = (lambda *args, **kwargs: []), (lambda: None)
    try:
        return batch(confine, n)
    finally:
        sandbox.lock_down, sandbox.wipe_command_line = lock_down, wipe


def main() -> None:
    jobs = int(sys.argv[1]) if len(sys.argv) > 1 else 400
    run_dir = tempfile.mkdtemp(prefix="rippleb-confine-")
    # as a run confines a method's job: its run directory read-only, a scratch directory of the run's
    confine = Confinement.of([run_dir], [], tempfile.mkdtemp(prefix="rippleb-scratch-"))
    plain, mounts, walls = [], [], []
    for _ in range(max(1, jobs // 60)):
        plain.append(batch(None))
        mounts.append(walled(False, confine))
        walls.append(walled(True, confine))
    p, m, w = (statistics.median(times) for times in (plain, mounts, walls))
    print(f"{jobs} jobs of each: rippleb's own {p * 1e3:.2f} ms/job; a method's with the mounts only (section 9, and its scratch tmpfs) "
          f"{m * 1e3:.2f} ms/job (+{(m - p) * 1e3:.2f} ms); with the walls {w * 1e3:.2f} ms/job "
          f"(+{(w - p) * 1e3:.2f} ms; the walls +{(w - m) * 1e3:.2f} ms)")


if __name__ == "__main__":
    main()
