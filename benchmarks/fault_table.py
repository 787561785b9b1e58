"""How every built-in method degrades under each faulty sensor (issue 7, item 2).

Writes one scenario file per fault (a short move between holds with a contact at rest,
the base below plus one ``[faults]`` entry), runs every built-in method on them through
``rippleb.run`` and prints a Markdown table of the RMS error against ``torque_true`` (or
the row's status when it is not ``ok``). ``docs/robustness.md`` shows its output; run

    python benchmarks/fault_table.py [--seeds N] [--jobs N]

``tests/test_faults.py`` imports :data:`FAULTS` and :func:`write_scenarios` from here, so
the test and the published table use the same faults.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

#: A short scenario: rest, one move, rest with an unknown +10 Nm push. 0.9 s.
BASE = """\
description = "robustness: {label}"
temperature_c = 40.0

[robot]
posture = {{ elbow_joint = 1.5 }}

[trajectory]
start = -1.8

[[trajectory.segment]]
kind = "hold"
duration = 0.1

[[trajectory.segment]]
kind = "move"
by = 0.3
duration = 0.4

[[trajectory.segment]]
kind = "hold"
duration = 0.4

[[load]]
torque = 10.0
start = 0.6
stop = 0.8
rise = 0.02
"""

#: name -> (faults table entries, what it models). Strong enough to show in the errors.
FAULTS = {
    "no-fault": ({}, "healthy sensors (the reference row)"),
    "encoder-missed": ({"encoder_missed": 0.01}, "1 % of encoder counts lost"),
    "encoder-spurious": ({"encoder_spurious_rate": 50.0}, "50 spurious +-1 counts per second"),
    "strain-clipping": ({"strain_full_scale": 1.0}, "strain ADC full scale +-1 V instead of +-10 V"),
    "dropouts": ({"dropout_rate": 20.0, "dropout_length": 0.005},
                 "20 DAQ dropouts per second, 5 ms each, held at the last sample"),
    "bridge-drift": ({"bridge_drift": 0.05}, "extra bridge drift 0.05 V/s (about 0.5 Nm/s)"),
    "current-offset": ({"current_offset": 0.2}, "current-sensor offset +0.2 A"),
}


def write_scenarios(directory: Path, names=None) -> list[Path]:
    """One TOML file per fault in ``directory``; returns their paths."""
    paths = []
    for name in names or FAULTS:
        values, label = FAULTS[name]
        text = BASE.format(label=label)
        if values:
            text += "\n[faults]\n" + "".join(f"{k} = {v!r}\n" for k, v in values.items())
        path = Path(directory) / f"{name}.toml"
        path.write_text(text)
        paths.append(path)
    return paths


def table(frame) -> str:
    """Markdown: method x fault, RMS error vs torque_true [Nm] (mean over seeds) or status."""
    import pandas as pd

    cells = {}
    for (method, scenario), rows in frame.groupby(["method", "scenario"]):
        bad = rows[rows.status != "ok"]
        cells[(method, scenario)] = (", ".join(sorted(set(bad.status))) if len(bad)
                                     else f"{rows.rms_error_nm.mean():.2f}")
    methods = sorted({m for m, _ in cells})
    out = pd.DataFrame({s: [cells.get((m, s), "") for m in methods] for s in FAULTS}, index=methods)
    out.index.name = "method \\ fault"
    return out.to_markdown()


def main(argv=None) -> int:
    import rippleb

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_scenarios(Path(tmp))
        frame = rippleb.run(scenarios=[str(p) for p in paths], seeds=args.seeds, jobs=args.jobs)
    print(f"RMS error against torque_true [Nm], {args.seeds} seed(s), mean over seeds; "
          "a status where a row is not ok.\n")
    print(table(frame))
    print()
    for name, (values, label) in FAULTS.items():
        print(f"- `{name}`: {label} (`{values}`)" if values else f"- `{name}`: {label}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
