"""``rippleb report``: the report of a run directory (:func:`rippleb.report.writer.report`)."""

from __future__ import annotations

import sys
from pathlib import Path

from rippleb.errors import InputError
from rippleb.printable import escaped


def add_report(sub) -> None:
    p = sub.add_parser("report", help="write the report of a run (tables, figures, provenance; --html)",
                       description="From DIR/results.csv write OUT/README.md (method x condition summary "
                                   "and headline; per condition the method x scenario matrices with 95 % "
                                   "confidence intervals over seeds, timing, ranking, the paper's "
                                   "Table I replica; failed rows; provenance), OUT/results.csv, "
                                   "OUT/provenance.json, OUT/figures/ and, with --html, OUT/index.html. "
                                   "See docs/report.md.")
    p.add_argument("dir", type=Path, metavar="DIR")
    p.add_argument("--out", type=Path, help="output directory (default DIR/report/; the published one is results/)")
    p.add_argument("--no-figures", action="store_true", help="tables and provenance only")
    p.add_argument("--figure-seed", type=int, default=0,
                   help="device seed re-simulated for the signal figures (default 0)")
    p.add_argument("--speed-seeds", type=int, metavar="N",
                   help="error-against-speed figure: mean over the first N seeds of the run "
                        "(default: every seed; each one is re-simulated)")
    p.add_argument("--format", choices=("png", "svg", "pdf"), default="png", help="figure format (default png)")
    p.add_argument("--html", action="store_true",
                   help="also write OUT/index.html: one self-contained interactive page (sortable "
                        "tables, zoomable figures, provenance), opened without network")
    p.add_argument("--published", action="store_true",
                   help="title and caveats of the project's published comparison (results/, see "
                        "docs/report.md); without it the report says it is the report of one run")
    p.add_argument("--salt-file", type=Path, metavar="FILE",
                   help="publish the salt of a sealed run (the file 'rippleb run --sealed' wrote) as "
                        "OUT/salt.txt, checked against the run's commitment, so that anyone can re-run "
                        "its rows on the same devices; OUT must be outside DIR")
    p.add_argument("--sweep", type=Path, action="append", default=[], metavar="SWEEP",
                   help="a sweep's rows (the directory of a 'rippleb sweep' run, or of its report): the "
                        "report's conclusions are re-evaluated at each swept value in the section 'Where "
                        "each conclusion holds' (repeat for several sweeps)")
    p.set_defaults(func=cmd_report)


def cmd_report(args) -> int:
    """``rippleb report``."""
    from rippleb.report.writer import report

    seeds = None
    if args.speed_seeds is not None:
        if args.speed_seeds < 1:
            raise InputError(f"--speed-seeds {args.speed_seeds}: must be at least 1")
        seeds = args.speed_seeds
    written = report(args.dir, args.out, figures=not args.no_figures, figure_seed=args.figure_seed,
                     argv=args.argv, published=args.published, html=args.html,
                     figure_format=args.format, speed_seeds=seeds, salt_file=args.salt_file,
                     sweeps=args.sweep)
    for warning in written["warnings"]:
        print(f"rippleb: warning: {escaped(warning)}", file=sys.stderr)
    print(f"wrote {written['readme']}, {written['csv']}, {written['provenance']}"
          + (f" and {len(written['figures'])} figures in {written['readme'].parent / 'figures'}"
             if written["figures"] else ""))
    if written["html"] is not None:
        print(f"open {written['html']} in a browser (self-contained: no network needed)")
    return 0
