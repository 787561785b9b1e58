"""Start a Dask cluster of SLURM jobs for rippleb and print the scheduler's address.

Run it on the login node and keep it running while rippleb runs against it::

    python examples/slurm_cluster.py --jobs 10 --cores 8 --queue normal   # prints tcp://HOST:PORT
    rippleb sweep ... --scheduler tcp://HOST:PORT --out runs/big          # in another shell

Each SLURM job runs ``--cores`` single-thread Dask workers: rippleb runs every row in a
process of its own, so one thread per worker keeps one row per CPU. Close the cluster
(and cancel its jobs) with Ctrl-D or Ctrl-C. Needs ``pip install dask-jobqueue``; see
docs/scale.md.
"""

from __future__ import annotations

import argparse
import shlex
import sys


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=10, help="SLURM jobs to submit (default 10)")
    parser.add_argument("--cores", type=int, default=8,
                        help="CPUs per job, one single-thread worker each (default 8)")
    parser.add_argument("--memory", default="32GB", help="memory per job (default 32GB)")
    parser.add_argument("--queue", default="normal", help="SLURM partition (default normal)")
    parser.add_argument("--walltime", default="04:00:00", help="job time limit (default 04:00:00)")
    parser.add_argument("--host", default="0.0.0.0",
                        help="interface the scheduler listens on (default all)")
    return parser.parse_args(argv)


def main(argv=None) -> None:
    import dask
    from dask_jobqueue import SLURMCluster

    from rippleb.engine.dask.executor import QUIET_CONFIG, quiet_environment
    from rippleb.numerics import pinned_environment

    args = parse_args(argv)
    # Dask's idle periodic callbacks, cut for the scheduler (here) and the workers (their jobs'
    # environment): at the defaults they would take a third of a core per 8-worker job.
    # ... and the portable numeric paths: `dask worker` loads numpy before rippleb could set them.
    exports = [f"export {name}={shlex.quote(value)}"
               for name, value in {**quiet_environment(), **pinned_environment({})}.items()]
    with dask.config.set(QUIET_CONFIG), \
            SLURMCluster(queue=args.queue, cores=args.cores, processes=args.cores, memory=args.memory,
                         walltime=args.walltime, scheduler_options={"host": args.host},
                         job_script_prologue=exports) as cluster:
        cluster.scale(jobs=args.jobs)
        print(cluster.scheduler_address, flush=True)
        try:
            sys.stdin.read()   # until Ctrl-D (end of input) ...
        except KeyboardInterrupt:
            pass               # ... or Ctrl-C; leaving the block cancels the jobs


if __name__ == "__main__":
    main()
