"""The least a row's processes can cost: forks and exits of a process loaded like the fork
server, without anything a row does (docs/report.md, "Where the time of the run goes").

    python benchmarks/fork_floor.py [--jobs N]

Loads what the fork server loads (the simulator and every built-in method, ``runner._warm``),
freezes its objects out of the garbage collector and maps it by 2 MiB pages as the server
does (``hugepages.collapse_private_memory``), then forks ``--jobs`` times in four shapes and
prints the CPU time per job (user and system, this process and its children, from
``getrusage``):

* ``fork, exit``: one child that exits at once;
* ``fork, fork, exit, exit``: a child that forks a grandchild, both exiting at once, which is
  a row's shape (the server forks a keeper, the keeper a worker);
* ``... + stream raw``: the same, the grandchild streaming ``raw`` over a 4-second log
  through :func:`rippleb.harness.run` (the pages a row's method writes after the fork);
* ``stream raw, in process``: that streaming alone, in this process, for comparison;

and the first two shapes again in a bare interpreter (this script run again with ``--bare``:
only the standard library loaded).
CPU seconds, so a busy machine inflates every line alike; what the lines say is their
differences.
"""

from __future__ import annotations

import argparse
import gc
import os
import resource
import subprocess
import sys


def _cpu_seconds() -> float:
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                  resource.getrusage(resource.RUSAGE_CHILDREN)))


def per_job_ms(jobs: int, nested: bool, work=None) -> float:
    """CPU milliseconds per job of forking (twice if ``nested``), ``work()`` in the last
    child if given, and exiting."""
    start = _cpu_seconds()
    for _ in range(jobs):
        pid = os.fork()
        if pid == 0:
            if nested:
                inner = os.fork()
                if inner == 0:
                    gc.freeze()   # as a worker does (keeper._keep_inherited_pages_shared)
                    if work is not None:
                        work()
                    os._exit(0)
                os.waitpid(inner, 0)
            os._exit(0)
        os.waitpid(pid, 0)
    return (_cpu_seconds() - start) / jobs * 1e3


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=60, help="forks timed per line (default 60)")
    parser.add_argument("--bare", action="store_true",
                        help="time the two fork shapes in this interpreter with only the standard library loaded")
    args = parser.parse_args(argv)
    if args.bare:   # how the script times a bare interpreter: itself, run again with nothing loaded
        print(per_job_ms(args.jobs, False), per_job_ms(args.jobs, True))
        return 0

    import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)
    from rippleb import harness
    from rippleb.engine.process import hugepages
    from rippleb.engine.runner import _warm
    from rippleb.registry import Registry
    from rippleb.simulator import simulate
    from rippleb.simulator.scenario import load_scenario

    registry = Registry.discover()
    _warm(registry, None)
    calibration = simulate(load_scenario("calibration"), 0).log
    log = simulate(load_scenario("paper-quintic"), 0).log.for_method(keep_ref=False)
    raw = registry.get("raw").load()
    fitted, _, _ = harness.fitted(raw, None, calibration)
    gc.collect()
    gc.freeze()
    hugepages.collapse_private_memory()

    def stream():
        harness.run(fitted, log)

    stream()   # warm
    start = _cpu_seconds()
    for _ in range(10):
        stream()
    in_process = (_cpu_seconds() - start) / 10 * 1e3
    lines = [("fork, exit", per_job_ms(args.jobs, False)),
             ("fork, fork, exit, exit", per_job_ms(args.jobs, True)),
             ("fork, fork, exit, exit + stream raw", per_job_ms(max(5, args.jobs // 4), True, stream)),
             ("stream raw, in process", in_process)]
    bare = subprocess.run([sys.executable, __file__, "--bare", "--jobs", str(args.jobs)], capture_output=True,
                          text=True, check=True).stdout.split()
    lines += [("bare interpreter: fork, exit", float(bare[0])),
              ("bare interpreter: fork, fork, exit, exit", float(bare[1]))]
    with open("/proc/self/status") as fh:
        anon = next(line.split()[1] for line in fh if line.startswith("RssAnon"))
    print(f"loaded like the fork server: {int(anon) / 1024:.0f} MiB of anonymous memory; "
          f"{len(log)} samples streamed")
    for name, ms in lines:
        print(f"{name:<45} {ms:7.1f} CPU ms a job")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
