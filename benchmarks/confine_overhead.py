"""What the walls around a method's worker cost per job (docs/robustness.md, sections 10 and 11).

    python benchmarks/confine_overhead.py [JOBS]

Runs trivial jobs through a two-slot :class:`rippleb.engine.process.pool.Pool`, in alternating
batches of 20, four ways: as rippleb's own jobs run (``confine=None``: user and PID
namespaces only); as a method's with the mounts alone (section 9: its own /proc, terminals
covered, a directory read-only, a tmpfs as its scratch directory); with issue 34's walls
too (a second user namespace, Landlock on writes, seccomp, no capabilities: reads and the
network open); and with issue 41's (reads confined to the libraries and its package, its own
network namespace, Landlock's network rules and scopes, the runner's environment wiped, a
control group capping its processes). Prints the median wall time per job of each, and the
differences.
"""

from __future__ import annotations

import contextlib
import functools
import statistics
import sys
import tempfile
import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths
from rippleb.engine.process import isolation, landlock, sandbox, scrub, tasks
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


@contextlib.contextmanager
def walls(level: str):
    """``mounts`` (no walls), ``issue34`` (writes only, the network open) or ``issue41``."""
    saved = (sandbox.lock_down, scrub.wipe_command_line, scrub.scrub_environment, landlock.restrict,
             isolation.NAMESPACE_CHOICES, tasks.enter)
    if level == "mounts":
        sandbox.lock_down, scrub.wipe_command_line = (lambda *args, **kwargs: []), (lambda: None)
    if level in ("mounts", "issue34"):
        scrub.scrub_environment, tasks.enter = (lambda: None), (lambda limit: None)
        landlock.restrict = functools.partial(saved[3], reads=False)
        isolation.NAMESPACE_CHOICES = tuple(c for c in isolation.NAMESPACE_CHOICES if not c[1].net)
    try:
        yield
    finally:
        (sandbox.lock_down, scrub.wipe_command_line, scrub.scrub_environment, landlock.restrict,
         isolation.NAMESPACE_CHOICES, tasks.enter) = saved


def main() -> None:
    jobs = int(sys.argv[1]) if len(sys.argv) > 1 else 400
    run_dir = tempfile.mkdtemp(prefix="rippleb-confine-")
    # as a run confines a method's job: its run directory read-only, a scratch directory of the run's
    confine = Confinement.of([run_dir], [], tempfile.mkdtemp(prefix="rippleb-scratch-"))
    times = {"own": [], "mounts": [], "issue34": [], "issue41": []}
    for _ in range(max(1, jobs // 80)):
        times["own"].append(batch(None))
        for level in ("mounts", "issue34", "issue41"):
            with walls(level):
                times[level].append(batch(confine))
    ms = {k: statistics.median(v) * 1e3 for k, v in times.items()}
    print(f"{jobs // 4} jobs of each (median of batches of 20): rippleb's own {ms['own']:.2f} ms/job; a method's "
          f"with the mounts only {ms['mounts']:.2f} ms; with issue 34's walls {ms['issue34']:.2f} ms "
          f"(+{ms['issue34'] - ms['mounts']:.2f} ms); with issue 41's {ms['issue41']:.2f} ms "
          f"(+{ms['issue41'] - ms['issue34']:.2f} ms for reads, network, environment and process cap)")


if __name__ == "__main__":
    main()
