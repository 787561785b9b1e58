"""The ``rippleb`` command: ``list``, ``run``, ``sweep``, ``simulate``, ``report``, ``check``, ``tune``.

Built on argparse (standard library, no extra dependency; subcommands and ``--help``
are all this CLI needs). Every :class:`~rippleb.errors.RipplebError` becomes one line
``rippleb: error: ...`` on stderr and exit status 2, with no traceback unless
``--debug``. An interrupted run (Ctrl-C, SIGTERM) exits 130 after saying where its
finished rows are.

This module is the program (:func:`entry`, :func:`main`, the parser); each subcommand is
a module of :mod:`rippleb.cli` (``run``, ``sweep``, ``simulate``, ``report``, ``list``, ``check``, ``tune``),
and the options they share are in :mod:`rippleb.cli.options`.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
import warnings
from pathlib import Path

from rippleb.cli.check import add_check
from rippleb.cli.list import add_list
from rippleb.cli.report import add_report
from rippleb.cli.run import add_run
from rippleb.cli.simulate import add_simulate
from rippleb.cli.sweep import add_sweep
from rippleb.cli.tune import add_tune
from rippleb.errors import RipplebError
from rippleb.printable import escaped

EPILOG = "Run 'rippleb COMMAND --help' for the options of one command."


def entry() -> None:
    """The ``rippleb`` program (its console script and ``python -m rippleb``): :func:`main`,
    with SIGINT and SIGTERM handled from its first line until the process exits."""
    from rippleb import interrupts

    status = 130
    try:
        interrupts.install()
        status = main()
    except KeyboardInterrupt:  # only in the few instructions around main's own handling
        print("rippleb: interrupted", file=sys.stderr)
    finally:
        # The command is over and its status decided: a late signal changes nothing (while
        # Python shuts down it would kill the process or print a traceback), and neither do
        # the libraries' logs as they shut down (Dask's, closing a cluster at exit).
        interrupts.ignore_from_now()
        logging.disable(logging.CRITICAL)
    sys.exit(status)


def main(argv: list[str] | None = None) -> int:
    """Run one ``rippleb`` command line; returns the exit status.

    SIGINT and SIGTERM at any moment (the imports of start-up included) end the command
    with one line on stderr and status 130; an interrupted run says where its finished
    rows are and how to finish it (docs/design.md, "Interrupts").
    """
    from rippleb import interrupts

    args = None
    with interrupts.handling():
        try:
            interrupts.check_interrupted()  # one that came while the program started
            args = build_parser().parse_args(argv)
            # The exact command line, recorded by `run` in DIR/provenance.json and by `report`.
            args.argv = list(sys.argv[1:] if argv is None else argv)
            with _warnings_as_lines():
                return args.func(args) or 0
        except RipplebError as exc:
            if args is not None and args.debug:
                raise
            kept = _interrupted(args) if getattr(exc, "resumable", False) else ""  # a lost scheduler
            print(f"rippleb: error: {escaped(exc)}{kept}", file=sys.stderr)
            return 2
        except BrokenPipeError:
            # the reader went away (`rippleb list | head`): stop quietly, like any Unix filter
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141
        except KeyboardInterrupt:
            print(f"rippleb: interrupted{_interrupted(args)}", file=sys.stderr)
            return 130
        except Exception:
            # A signal raised inside a C extension's import can reach us as another
            # exception (an ImportError wrapping the KeyboardInterrupt): still an interrupt.
            if not interrupts.received():
                raise
            print(f"rippleb: interrupted{_interrupted(args)}", file=sys.stderr)
            return 130


def _interrupted(args) -> str:
    """What an interrupted command left behind: for a run that had claimed its directory,
    its finished rows and how to finish it."""
    if args is None or not getattr(args, "started", False):
        return ""
    return _what_was_kept(getattr(args, "out_dir", None), getattr(args, "command", "run"))


def _what_was_kept(out_dir: Path | None, command: str = "run") -> str:
    """Name what an interrupted run left on disk, and how to finish it."""
    from rippleb.errors import InputError
    from rippleb.reading import RESULTS_BYTES, RUN_FILE_BYTES, read_bytes

    if out_dir is None or not (out_dir / "run.json").is_file():
        return ""
    results = out_dir / "results.csv"
    try:
        done = max(0, read_bytes(results, RESULTS_BYTES, "results file", in_run_dir=True).count(b"\n") - 1)
    except (OSError, InputError):
        done = 0
    kept = (f"{done} finished row(s) are in {results}" if done
            else f"no row had finished; the selection is in {out_dir / 'run.json'}")
    try:  # a sealed run is resumed with its salt
        run = read_bytes(out_dir / "run.json", RUN_FILE_BYTES, "run file", in_run_dir=True)
        salt = " --salt-file FILE" if b'"sealed"' in run else ""
    except (OSError, InputError):
        salt = ""
    return f"; {kept}; finish the run with: rippleb {command} --resume {out_dir}{salt}"


@contextlib.contextmanager
def _warnings_as_lines():
    """Show rippleb's warnings as one ``rippleb: warning: ...`` line each."""
    from rippleb.engine.results import RunWarning

    def show(message, category, *args, **kwargs):
        print(f"rippleb: warning: {escaped(message)}", file=sys.stderr)
    with warnings.catch_warnings():
        warnings.simplefilter("always", RunWarning)
        warnings.showwarning = show
        yield


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with its subcommands."""
    parser = argparse.ArgumentParser(
        prog="rippleb", epilog=EPILOG,
        description="Benchmark of torque-ripple cancellation methods for strain-gauge joint "
                    "torque sensors in harmonic drives.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    parser.set_defaults(func=lambda args: parser.print_help(), debug=False)
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    add_list(sub)
    add_run(sub)
    add_sweep(sub)
    add_simulate(sub)
    add_report(sub)
    add_check(sub)
    add_tune(sub)
    return parser
