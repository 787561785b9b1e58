"""Per-row scheduling overhead of the Dask executor, against the round trip of a no-op.

Starts a LocalCluster of 2 single-thread workers, then streams N tasks through the
executor's own submission loop (:func:`rippleb.engine.dask.executor._stream`, bounded in flight,
one seed per worker) twice: tasks whose function returns at once (the executor's own
overhead: serialising the scenario objects, scheduling, the result's trip back and the
client's bookkeeping), and the same number of bare ``client.submit`` no-ops (dask's floor).
Prints ms per row for each. Usage: python benchmarks/dask_overhead.py [N]
"""

import sys
import time

from distributed import Client, LocalCluster

from rippleb.engine.dask import executor as dask_executor
from rippleb.engine.executors import RowTask
from rippleb.engine.rows import RowKey
from rippleb.simulator.scenario import load_scenario


def _noop(task, blas):
    return {"status": "ok", "message": "noop"}


def main(n: int = 400) -> None:
    scenario, calibration = load_scenario("paper-quintic"), load_scenario("calibration")
    tasks = [RowTask(RowKey("raw", "paper-quintic", "same-session", seed), scenario, calibration, 60.0, None, "b")
             for seed in range(n)]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        client.wait_for_workers(2)
        client.submit(_noop, None, None).result()  # warm the workers
        real = dask_executor.remote_row
        dask_executor.remote_row = _noop  # the executor's loop, minus the row's own work
        try:
            recorded = []
            t0 = time.perf_counter()
            dask_executor._stream(client, tasks, lambda key, fields: recorded.append(key))
            executor_s = time.perf_counter() - t0
        finally:
            dask_executor.remote_row = real
        assert len(recorded) == n
        t0 = time.perf_counter()
        client.gather([client.submit(_noop, i, None, pure=False) for i in range(n)])
        bare_s = time.perf_counter() - t0
    print(f"{n} rows: executor loop {1e3 * executor_s / n:.1f} ms/row, "
          f"bare dask no-op {1e3 * bare_s / n:.1f} ms/task (all submitted at once)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 400)
