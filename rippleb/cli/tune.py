"""``rippleb tune``: the one tuning protocol (:mod:`rippleb.tuning`) on installed methods.

Every method gets the same budget of calibration evaluations, on the ``calibration``
scenario of the tuning devices only, scored against ``torque_ref``; the record (JSON, one
entry per method, written as each finishes) says every point tried, its score on each
device, the best point and whether the rule lets it replace the default. The built-ins'
record is ``methods/tuning.json`` (docs/tuning.md). Each point runs as a run's rows do, in
the method's sandboxed worker under the run's default limits (:mod:`rippleb.engine.tuner`).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from rippleb.errors import InputError
from rippleb.files import atomic_path
from rippleb.tuning import (BUDGET, CRITERION, EVERY_DEVICE, PAIRED_SEEDS, PROTOCOL_RULE, RULE_ID, RULES, SEED,
                             SEEDS)

#: The largest ``--budget``: 1024 points a method (64 times the protocol's 16), each fitted
#: and run on every tuning device, is hours of CPU a method; ``--budget 1000000`` was
#: accepted and drew its Sobol points before anything else (2.4 GB).
MAX_BUDGET = 1024


def _help_text(text: str) -> str:
    """``text`` as an argparse help string: argparse %-formats help, so a bare ``%`` (the
    rule's "5 %") printed the option's whole dictionary in ``--help``."""
    return text.replace("%", "%%")


def add_tune(sub) -> None:
    p = sub.add_parser(
        "tune", help="tune methods by the one protocol: same budget, calibration scenario only",
        description="Tune methods' declared parameters (their 'tunable' ranges) by one protocol: the "
                    f"default and budget-1 Sobol points (seed {SEED}), each fitted and run on the "
                    "calibration log of each tuning device and scored against torque_ref (never a "
                    f"scored scenario, never torque_true). Rule (--rule): {RULES[PROTOCOL_RULE]}. Prints one line per method "
                    "and writes the record as JSON (docs/tuning.md); 'rippleb run --tuning FILE' runs "
                    "each method at the point the rule adopted.")
    p.add_argument("--methods", help="comma-separated method names (default: every built-in)")
    p.add_argument("--budget", type=int, default=BUDGET,
                   help=f"calibration evaluations per method (default {BUDGET}, the built-ins' budget)")
    p.add_argument("--seeds", default=f"{SEEDS[0]}-{SEEDS[-1]}",
                   help=f"tuning devices: 'A-B' or 'A,B,C' (default {SEEDS[0]}-{SEEDS[-1]}, devices no "
                        "published row uses)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help=f"points evaluated in parallel processes (default: the number of CPUs, {os.cpu_count()} here)")
    p.add_argument("--out", type=Path, help="JSON file for the record (written after each method; a record of "
                                            "the same protocol is continued: its methods are kept, the rest "
                                            "tuned); 'rippleb run --tuning FILE' runs the adopted points")
    p.add_argument("--rule", choices=sorted(RULES), default=PROTOCOL_RULE,
                   help=f"the adoption rule (default {PROTOCOL_RULE}, the built-ins' record's): {RULE_ID}: "
                        f"{_help_text(RULES[RULE_ID])} (needs 20 devices, e.g. --seeds {PAIRED_SEEDS[0]}-{PAIRED_SEEDS[-1]}); "
                        f"{EVERY_DEVICE}: {_help_text(RULES[EVERY_DEVICE])}")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--compare", nargs=2, type=Path, metavar=("A.json", "B.json"),
                   help="tune nothing: print the stability table of two records made on disjoint sets of "
                        "tuning devices (the point each adopts, and what each choice costs on the other "
                        "set's devices; docs/tuning.md)")
    p.set_defaults(func=cmd_tune)


def cmd_tune(args) -> int:
    """``rippleb tune``."""
    from tqdm import tqdm

    from rippleb.engine.tuner import plan, tune
    from rippleb.registry import Registry
    from rippleb.version import __version__

    if args.compare is not None:
        return compare(args)
    seeds = parse_seeds(args.seeds)
    if not 1 <= args.budget <= MAX_BUDGET:
        raise InputError(f"--budget must be a whole number in 1-{MAX_BUDGET} (the protocol's is {BUDGET}), "
                         f"got {args.budget}")
    if args.jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {args.jobs}")
    registry = Registry.discover()
    names = ([n.strip() for n in args.methods.split(",") if n.strip()] if args.methods
             else registry.names("builtin"))
    if args.out is not None and args.out.is_dir():
        raise InputError(f"--out {args.out}: is a directory; give a file name (e.g. {args.out / 'tuning.json'})")
    record = {"protocol": {"budget": args.budget, "seeds": seeds, "criterion": CRITERION, "rule": RULES[args.rule],
                           "rule_id": args.rule,
                           "sampler": f"the default, then budget-1 points of a scrambled Sobol sequence "
                                      f"(scipy.stats.qmc, seed {SEED}), 3 significant digits"},
              "rippleb_version": __version__, "methods": {}}
    done = _finished_methods(args.out, record["protocol"]) if args.out is not None else {}
    record["methods"].update(done)
    planned = plan([n for n in names if n not in done], registry, args.budget)
    total = sum(len(points) for _, points, _ in planned.values())
    kept = f"; {len(done)} already in {args.out}, kept" if done else ""
    print(f"rippleb tune: {len(planned)} method(s), budget {args.budget}, {total} evaluations on the "
          f"calibration logs of seeds {args.seeds}, {args.jobs} job(s){kept}", file=sys.stderr, flush=True)
    with tqdm(total=total, disable=True if args.no_progress else None, file=sys.stderr, unit="point") as bar:
        def finished(name, entry):
            record["methods"][name] = entry
            if args.out is not None:
                _write(args.out, record)
            bar.write(line(name, entry, args.out, args.rule))

        tune(planned, seeds, args.jobs, on_method=finished, on_point=bar.update, rule=args.rule)
    if args.out is not None:
        print(f"record written to {args.out}", file=sys.stderr)
    return 0


def compare(args) -> int:
    """``rippleb tune --compare A.json B.json``: the stability table, on standard output."""
    from rippleb.report.tuning_stability import read, stability_markdown

    given = [flag for flag, value in (("--methods", args.methods), ("--out", args.out)) if value is not None]
    if given:
        raise InputError(f"{given[0]} does not apply with --compare (it reads two records and tunes nothing)")
    print(stability_markdown(*(read(path) for path in args.compare)))
    return 0


def line(name: str, entry: dict, out: Path | None = None, rule: str = PROTOCOL_RULE) -> str:
    """One method's result as one line, in the words of ``rule``, ending with how to run what
    it adopted: the variant's exact ``--methods`` item, or ``--tuning`` with the record ``out``."""
    from rippleb.variants import label

    if entry["evaluations"] == 1:
        return f"{name}: {entry['default_score']:.3f} Nm at its defaults; {entry['note']}"
    every = rule == EVERY_DEVICE
    if not entry["replaced"]:
        verdict = "default kept" + ("" if entry["best"] == entry["default"] else
                                    " (the best point is not better on every device)" if every else
                                    " (no point is lower by the paired test)")
    else:
        how = f" or --tuning {out}" if out is not None else " (or write the record with --out FILE and pass --tuning FILE)"
        which = ("better on every tuning device, adopted" if every else
                 "lower by the paired test, adopted" if entry["adopted"] == entry["best"] else
                 f"{', '.join(f'{k}={v:g}' for k, v in entry['adopted'].items())} adopted (the best point "
                 f"is not lower by the paired test)")
        verdict = (f"{which}; its constructor's default is unchanged: run it with "
                   f"--methods '{label(name, entry['adopted'])}'{how}")
    best = ", ".join(f"{k}={v:g}" for k, v in entry["best"].items())
    text = (f"{name}: default {entry['default_score']:.3f} Nm, best {entry['best_score']:.3f} Nm at "
            f"{best} ({entry['evaluations']} evaluations): {verdict}")
    return text + (f"; {len(entry['errors'])} error(s): {entry['errors'][0]}" if entry["errors"] else "")


def parse_seeds(text: str) -> list[int]:
    """``A-B`` or ``A,B,C`` as a list of seeds, checked as a run's seeds are
    (:func:`~rippleb.engine.rows.select_seeds`); anything else is one line naming ``--seeds``."""
    from rippleb.engine.rows import MAX_SEEDS, select_seeds

    try:
        span = [int(v) for v in text.split("-")] if "-" in text else None
        seeds = [int(v) for v in text.split(",")] if span is None else []
        lo, hi = span if span is not None else (0, -1)
    except ValueError:
        raise InputError(f"--seeds {text[:60]!r}: expected 'A-B' or 'A,B,C' (non-negative integers)") from None
    if hi - lo >= MAX_SEEDS:   # checked before the list is made
        raise InputError(f"--seeds {text[:60]!r}: {hi - lo + 1} devices, more than the {MAX_SEEDS} a run may have")
    seeds = seeds or list(range(lo, hi + 1))
    if not seeds:
        raise InputError(f"--seeds {text!r}: expected at least one seed")
    return select_seeds(seeds, 0)


def _finished_methods(path: Path, protocol: dict) -> dict:
    """The methods a record at ``path`` already holds, tuned by ``protocol``: a tuning run cut
    short (each method's entry is written as it finishes) goes on where it stopped. A record
    of another protocol is refused, never mixed into this one."""
    from rippleb.report.tuning_stability import read

    if not path.exists():
        return {}
    saved = read(path)
    if saved.get("protocol") != protocol:
        raise InputError(f"--out {path}: a record of another protocol (budget, seeds, rule or sampler); rippleb "
                         f"tune adds to a record of the same protocol only: choose another --out")
    return saved["methods"]


def _write(path: Path, record: dict) -> None:
    """The record, replaced whole (a tune cut short leaves the last method's record, never half)."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(record, indent=1, sort_keys=False) + "\n")
