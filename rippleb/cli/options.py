"""Options more than one command takes, and the combinations refused.

The sealing options of ``run`` (:mod:`rippleb.engine.sealing`), the executor options of
``run`` and ``sweep`` (``--executor``, ``--scheduler``), the limits (``--timeout``,
``--memory-limit``, ``--import-timeout``), and the checks that an option given with
``--resume`` or ``--log`` is not silently ignored.
"""

from __future__ import annotations

import math
from pathlib import Path

from rippleb.engine.dask.connect import CONNECT_TIMEOUT_S
from rippleb.errors import InputError


def add_seal_options(p) -> None:
    """``--sealed FILE`` (a new sealed run) and ``--salt-file FILE`` (its ``--resume``)."""
    p.add_argument("--sealed", type=Path, metavar="FILE",
                   help="a sealed run, for comparisons that matter: devices and noise are drawn from "
                        "a secret random salt that no method can know, so no method can re-simulate "
                        "the device it is scored on (the scenarios stay public: docs/robustness.md); "
                        "run.json records the salt's SHA-256 commitment, and the salt is written to "
                        "FILE (new, outside --out) when the run ends. Keep FILE apart, publish it "
                        "to let others verify")
    p.add_argument("--salt-file", type=Path, metavar="FILE",
                   help="with --resume of a sealed run: the salt file --sealed wrote ('-': read it "
                        "from standard input); without --resume: run on the devices of that salt, e.g. "
                        "to re-run rows of a published sealed comparison and compare them (a replay: "
                        "the salt is known, so the rows are no sealed comparison themselves)")


def check_run_options(args) -> None:
    """Refuse, in one line, an option that the chosen mode would silently ignore."""
    if args.resume is not None:
        for flag, value in (("--out", args.out), ("--calibration", args.calibration),
                            ("--sealed", getattr(args, "sealed", None))):
            if value is not None:
                hint = "; a sealed run is resumed with --salt-file FILE" if flag == "--sealed" else ""
                raise InputError(f"{flag} does not apply with --resume {args.resume} (the run directory "
                                 f"and its selection are those of {args.resume}/run.json{hint})")
    elif getattr(args, "salt_file", None) is not None and getattr(args, "sealed", None) is not None:
        raise InputError("--sealed draws a new salt and --salt-file re-runs the devices of a given one; "
                         "give one of them")
    for flag in ("--sealed", "--salt-file"):
        if getattr(args, "log", None) is not None and getattr(args, flag[2:].replace("-", "_"), None) is not None:
            raise InputError(f"{flag} does not apply with --log (a recorded log has no seeds to seal)")


def check_sweep_options(args) -> None:
    """``rippleb sweep --resume DIR`` takes its directory from DIR: ``--out`` is refused."""
    if args.resume is not None and args.out is not None:
        raise InputError(f"--out does not apply with --resume {args.resume} (the run directory is "
                         f"{args.resume})")


def limit(flag: str, value: float) -> float | None:
    """A ``--timeout``/``--memory-limit`` value: 0 means none; negative or NaN is refused."""
    if not math.isfinite(value) or value < 0:
        raise InputError(f"{flag} must be a positive number (0 for no limit), got {value:g}")
    return value or None


def add_executor_options(p) -> None:
    p.add_argument("--executor", choices=("local", "dask"), default="local",
                   help="where rows run: 'local' forked processes (default), or 'dask': a local "
                        "dask cluster of --jobs worker processes (see docs/scale.md)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the rows on the dask.distributed cluster of this scheduler "
                        "(e.g. tcp://10.0.0.5:8786); implies --executor dask")
    p.add_argument("--connect-timeout", type=float, default=CONNECT_TIMEOUT_S, metavar="S",
                   help=f"seconds the --scheduler has to answer, and to come back if it is lost mid-run "
                        f"(default {CONNECT_TIMEOUT_S:g})")


def executor(args):
    """The executor the options ask for: None for the local pool."""
    if args.scheduler is None and args.executor == "local":
        return None
    if getattr(args, "log", None) is not None:
        raise InputError("--executor dask/--scheduler do not apply with --log (a recorded log runs "
                         "on the local pool)")
    from rippleb.engine.dask.executor import DaskExecutor

    timeout = args.connect_timeout
    if not (math.isfinite(timeout) and timeout > 0):
        raise InputError(f"--connect-timeout must be a positive number of seconds, got {timeout:g}")
    return DaskExecutor(scheduler=args.scheduler, workers=args.jobs, connect_timeout=timeout)
