"""What the walls around a method's worker cost per job (docs/robustness.md, sections 10 and 11).

    python benchmarks/confine_overhead.py [JOBS]
    python benchmarks/confine_overhead.py --steps [FORKS]

Runs trivial jobs through a two-slot :class:`rippleb.engine.process.pool.Pool`, in alternating
batches of 20, four ways: as rippleb's own jobs run (``confine=None``: user and PID
namespaces only); as a method's with the mounts alone (section 9: its own /proc, terminals
covered, a directory read-only, a tmpfs as its scratch directory); with issue 34's walls
too (a second user namespace, Landlock on writes, seccomp, no capabilities: reads and the
network open); and with issue 41's (reads confined to the libraries and its package, its own
network namespace, Landlock's network rules and scopes, the runner's environment wiped, a
control group capping its processes), and issue 34's with each of issue 41's alone. Prints
the median wall time per job of each, and the differences.

``--steps`` times each of issue 41's steps as a keeper or worker first runs it, in a fresh
fork of this process (its pages shared with the parent, as a job's are), FORKS times each,
alternating, and prints the medians: a batch's differences above are within the load's
noise on a shared machine, these are not.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import statistics
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


#: What each of issue 41's walls adds, switched on alone over issue 34's.
STEPS = ("network", "reads", "environment", "process cap")


@contextlib.contextmanager
def walls(level: str, extra: tuple = ()):
    """``mounts`` (no walls), ``issue34`` (writes only, the network open; with ``extra``, those
    of :data:`STEPS` on as well) or ``issue41`` (all of them)."""
    saved = (sandbox.lock_down, scrub.wipe_command_line, scrub.scrub_environment, landlock.restrict,
             isolation.NAMESPACE_CHOICES, tasks.enter)
    if level == "mounts":
        sandbox.lock_down, scrub.wipe_command_line = (lambda *args, **kwargs: []), (lambda: None)
    if level in ("mounts", "issue34"):
        if "environment" not in extra:
            scrub.scrub_environment = lambda: None
        if "process cap" not in extra:
            tasks.enter = lambda limit: None
        if "reads" not in extra:
            landlock.restrict = functools.partial(saved[3], reads=False)
        if "network" not in extra:
            isolation.NAMESPACE_CHOICES = tuple(c for c in isolation.NAMESPACE_CHOICES if not c[1].net)
    try:
        yield
    finally:
        (sandbox.lock_down, scrub.wipe_command_line, scrub.scrub_environment, landlock.restrict,
         isolation.NAMESPACE_CHOICES, tasks.enter) = saved


def _in_fork(step) -> float:
    """Milliseconds ``step()`` takes as the first thing a fresh fork of this process does."""
    import gc
    import os

    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            gc.freeze()   # as a keeper and a worker do first
            start = time.perf_counter_ns()
            step()
            os.write(write, str(time.perf_counter_ns() - start).encode())
        finally:
            os._exit(0)
    os.close(write)
    with os.fdopen(read) as fh:
        spent = int(fh.read() or -1)
    os.waitpid(pid, 0)
    tasks.remove(pid)   # as the keeper's parent does once it has reaped it
    return spent / 1e6


def steps(forks: int) -> None:
    """The medians of :func:`_in_fork` for each step (module docstring)."""
    scratch = tempfile.mkdtemp(prefix="rippleb-scratch-")
    flags = isolation.CLONE_NEWUSER | isolation.CLONE_NEWPID | isolation.CLONE_NEWNS
    timed = {
        "namespaces (user, PID, mount), as issue 34": lambda: isolation.libc().unshare(flags),
        "namespaces with a network one, as now": lambda: isolation.libc().unshare(flags | isolation.CLONE_NEWNET),
        "Landlock on writes, as issue 34": lambda: landlock.restrict(scratch, (), True, reads=False),
        "Landlock on reads, writes, TCP and scopes, as now": lambda: landlock.restrict(scratch, (scratch,), True),
        "the environment wiped": scrub.scrub_environment,
        "the job's control group joined (root only)": lambda: tasks.enter(sandbox.MAX_TASKS + 1),
    }
    spent = {name: [] for name in timed}
    for _ in range(forks):
        for name, step in timed.items():
            spent[name].append(_in_fork(step))
    for name, values in spent.items():
        print(f"{name}: {statistics.median(values):.3f} ms (median of {forks})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("count", nargs="?", type=int, help="trivial jobs (default 400), or with --steps "
                        "forks per step (default 40)")
    parser.add_argument("--steps", action="store_true", help="time each of issue 41's steps in a fresh fork")
    args = parser.parse_args()
    if args.steps:
        steps(args.count or 40)
        return
    jobs = args.count or 400
    run_dir = tempfile.mkdtemp(prefix="rippleb-confine-")
    # as a run confines a method's job: its run directory read-only, a scratch directory of the run's
    confine = Confinement.of([run_dir], [], tempfile.mkdtemp(prefix="rippleb-scratch-"))
    levels = [("own", None, ()), ("mounts", "mounts", ()), ("issue34", "issue34", ()),
              *((f"+{step}", "issue34", (step,)) for step in STEPS), ("issue41", "issue41", ())]
    times = {name: [] for name, _, _ in levels}
    for _ in range(max(1, jobs // (20 * len(levels)))):
        for name, level, extra in levels:
            if level is None:
                times[name].append(batch(None))
                continue
            with walls(level, extra):
                times[name].append(batch(confine))
    ms = {k: statistics.median(v) * 1e3 for k, v in times.items()}
    print(f"{len(times['own']) * 20} jobs of each (median of batches of 20): rippleb's own {ms['own']:.2f} ms/job; "
          f"a method's with the mounts only {ms['mounts']:.2f} ms; with issue 34's walls {ms['issue34']:.2f} ms; "
          f"with issue 41's {ms['issue41']:.2f} ms (+{ms['issue41'] - ms['issue34']:.2f} ms); each of issue 41's "
          f"alone over issue 34's: " + ", ".join(f"{s} {ms['+' + s] - ms['issue34']:+.2f} ms" for s in STEPS))


if __name__ == "__main__":
    main()
