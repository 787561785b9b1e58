"""``rippleb simulate``: one scenario on one device, its log written to a file."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from rippleb.errors import InputError


def add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="simulate one scenario and write its log",
                       description="Simulate SCENARIO (a built-in name or a .toml path) on the device "
                                   "of --seed and write the columns t, strain, encoder, current, "
                                   "torque_true, torque_ref to FILE (.csv or .parquet); with --format "
                                   "lab, as a lab's DAQ would, with a joint.toml to read it.")
    p.add_argument("scenario", metavar="SCENARIO")
    p.add_argument("--seed", type=int, default=0, help="device seed (default 0)")
    p.add_argument("--condition", default="same-session", metavar="NAME",
                   help="deployment condition of the simulated session (default same-session; "
                        "see 'rippleb list')")
    p.add_argument("--out", type=Path, required=True, metavar="FILE", help="output .csv or .parquet")
    p.add_argument("--format", choices=("rippleb", "lab"), default="rippleb",
                   help="rippleb (default): rippleb's columns and units, with the truth; lab: as a lab's "
                        "DAQ writes it (t in ms, strain_mV, a 16384-count encoder enc_counts, i_motor_A, "
                        "idx, load_cell_Nm; no torque_true), plus joint.toml beside FILE to read it with "
                        "'rippleb run --log FILE --joint joint.toml' (docs/your-joint.md)")
    p.set_defaults(func=cmd_simulate)


def cmd_simulate(args) -> int:
    """``rippleb simulate``."""
    from rippleb.simulator.conditions import check_condition
    from rippleb.data import write_log
    from rippleb.engine.runner import check_scenario
    from rippleb.scenario import load_scenario
    from rippleb.simulator import simulate
    from rippleb.simulator.validity import check_simulation
    from rippleb.lab_format import LAB_COUNTS_PER_REV

    if args.seed < 0:
        raise InputError(f"--seed must be a non-negative integer, got {args.seed}")
    scenario = load_scenario(args.scenario)
    if args.format == "lab":
        scenario = dataclasses.replace(scenario, spec=dataclasses.replace(scenario.spec,
                                                                          counts_per_rev=LAB_COUNTS_PER_REV))
    check_scenario(scenario)
    try:
        sim = simulate(scenario, args.seed, condition=check_condition(args.condition))
    except NotImplementedError as exc:  # a condition this simulator does not model yet
        raise InputError(f"--condition {args.condition}: {exc}") from None
    if args.format == "lab":
        path = _write_lab(sim.log, args.out)
    else:
        path = write_log(sim.log, args.out)
        print(f"wrote {path}")
    unphysical = check_simulation(sim)
    if unphysical:  # written all the same: it is what was asked for, and shows what went wrong
        print(f"rippleb: warning: {path}: not a joint that exists: {unphysical}", file=sys.stderr)
    return 0


def _write_lab(log, out: Path) -> Path:
    """The log in the lab's columns, and ``joint.toml`` beside it."""
    from rippleb.data import write_columns
    from rippleb.lab_format import joint_toml, lab_columns, write_joint_toml

    joint = write_joint_toml(joint_toml(log.spec, log.index is not None), out.parent / "joint.toml")
    path = write_columns(lab_columns(log), out)
    print(f"wrote {path} and {joint}")
    return path
