"""What confining a method's worker costs per job (docs/robustness.md section 9).

    python benchmarks/confine_overhead.py [JOBS]

Runs JOBS trivial jobs through a two-slot :class:`rippleb.engine.pool.Pool` as rippleb's
own jobs run (``confine=None``: PID namespace only) and as a method's run (``confine=(dir,)``:
mount namespace, own /proc, terminals covered, a directory read-only), in alternating
batches of 20, and prints the median wall time per job of each and their ratio.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths
from rippleb.engine.pool import Pool


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


def main() -> None:
    jobs = int(sys.argv[1]) if len(sys.argv) > 1 else 400
    run_dir = tempfile.mkdtemp(prefix="rippleb-confine-")
    plain, confined = [], []
    for _ in range(max(1, jobs // 40)):
        plain.append(batch(None))
        confined.append(batch((run_dir,)))
    p, c = statistics.median(plain), statistics.median(confined)
    print(f"{jobs} jobs: rippleb's own {p * 1e3:.2f} ms/job, a method's (confined) {c * 1e3:.2f} ms/job, "
          f"ratio {c / p:.2f} (+{(c - p) * 1e3:.2f} ms)")


if __name__ == "__main__":
    main()
