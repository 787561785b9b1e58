"""Options of ``rippleb run`` that combine with others, and the combinations refused.

Kept apart from :mod:`rippleb.cli` (which builds the parser): the sealing options
(:mod:`rippleb.engine.sealing`) and the checks that an option given with ``--resume`` or
``--log`` is not silently ignored.
"""

from __future__ import annotations

from pathlib import Path

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
                        "from standard input)")


def check_run_options(args) -> None:
    """Refuse, in one line, an option that the chosen mode would silently ignore."""
    if args.resume is not None:
        for flag, value in (("--out", args.out), ("--calibration", args.calibration),
                            ("--sealed", getattr(args, "sealed", None))):
            if value is not None:
                hint = "; a sealed run is resumed with --salt-file FILE" if flag == "--sealed" else ""
                raise InputError(f"{flag} does not apply with --resume {args.resume} (the run directory "
                                 f"and its selection are those of {args.resume}/run.json{hint})")
    elif getattr(args, "salt_file", None) is not None:
        raise InputError("--salt-file applies only with --resume DIR of a sealed run (a new sealed run "
                         "draws its own salt: --sealed FILE)")
    if getattr(args, "log", None) is not None and getattr(args, "sealed", None) is not None:
        raise InputError("--sealed does not apply with --log (a recorded log has no seeds to seal)")


def check_sweep_options(args) -> None:
    """``rippleb sweep --resume DIR`` takes its directory from DIR: ``--out`` is refused."""
    if args.resume is not None and args.out is not None:
        raise InputError(f"--out does not apply with --resume {args.resume} (the run directory is "
                         f"{args.resume})")
