"""``rippleb simulate``: one scenario on one device, its log written to a file."""

from __future__ import annotations

import sys
from pathlib import Path

from rippleb.errors import InputError


def add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="simulate one scenario and write its log",
                       description="Simulate SCENARIO (a built-in name or a .toml path) on the device "
                                   "of --seed and write the columns t, strain, encoder, current, index, "
                                   "torque_true, torque_ref to FILE (.csv or .parquet); with --format "
                                   "lab, as a lab's DAQ would, with a joint.toml to read it.")
    p.add_argument("scenario", metavar="SCENARIO")
    p.add_argument("--seed", type=int, default=0, help="device seed (default 0)")
    p.add_argument("--condition", default="same-session", metavar="NAME",
                   help="deployment condition of the simulated session (default same-session; "
                        "see 'rippleb list')")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="set a sweepable scenario key for this log (repeatable), e.g. "
                        "--param joint.counts_per_rev=4096 --param joint.gear_ratio=160 for your own "
                        "joint (the names: 'rippleb sweep --help'); simulate its calibration with the "
                        "same values")
    p.add_argument("--out", type=Path, required=True, metavar="FILE", help="output .csv or .parquet")
    p.add_argument("--format", choices=("rippleb", "lab"), default="rippleb",
                   help="rippleb (default): rippleb's columns and units, with the truth; lab: as a lab's "
                        "DAQ writes it (t in ms, strain_mV, enc_counts with the scenario's encoder, "
                        "i_motor_A, idx, the reference of --reference; no torque_true), plus joint.toml "
                        "beside FILE to read it with 'rippleb run --log FILE --joint joint.toml' "
                        "(docs/your-joint.md)")
    p.add_argument("--reference", choices=("transducer", "model"), default=None,
                   help="with --format lab: the log's reference torque. transducer (default): a torque "
                        "flange in series, the real torque through its bandwidth and noise "
                        "(torque_sensor_Nm); model: eq. (7)'s model torque, without the gear's own "
                        "torque (model_torque_Nm)")
    p.set_defaults(func=cmd_simulate)


def cmd_simulate(args) -> int:
    """``rippleb simulate``."""
    from rippleb.simulator.conditions import check_condition
    from rippleb.log_files import write_log
    from rippleb.engine.runner import check_scenario
    from rippleb.simulator import simulate
    from rippleb.simulator.validity import check_simulation

    if args.seed < 0:
        raise InputError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.reference is not None and args.format != "lab":
        raise InputError("--reference only applies with --format lab")
    scenario = _scenario(args.scenario, args.param)
    check_scenario(scenario)
    try:
        sim = simulate(scenario, args.seed, condition=check_condition(args.condition))
    except NotImplementedError as exc:  # a condition this simulator does not model yet
        raise InputError(f"--condition {args.condition}: {exc}") from None
    if args.format == "lab":
        path = _write_lab(sim, args.out, args.reference or "transducer")
    else:
        path = write_log(sim.log, args.out)
        print(f"wrote {path}")
    unphysical = check_simulation(sim)
    if unphysical:  # written all the same: it is what was asked for, and shows what went wrong
        print(f"rippleb: warning: {path}: not a joint that exists: {unphysical}", file=sys.stderr)
    return 0


def _scenario(name: str, params: list[str]):
    """The scenario ``name`` with each ``--param NAME=VALUE`` set, checked as a sweep's point is."""
    from rippleb.engine.sweep import parse_params, swept_scenario
    from rippleb.simulator.scenario import load_scenario

    if not params:
        return load_scenario(name)
    point = {}
    for sweep in parse_params(params):
        if len(sweep.values) != 1:
            raise InputError(f"--param {sweep.name}: one value per log (rippleb sweep runs several)")
        point[sweep.name] = sweep.values[0]
    return swept_scenario(name, point)


def _write_lab(sim, out: Path, kind: str) -> Path:
    """The log in the lab's columns with the reference of ``kind``, and ``joint.toml`` beside it."""
    from rippleb.log_files import write_columns
    from rippleb.lab_format import joint_toml, lab_columns, write_joint_toml
    from rippleb.simulator.transducer import lab_log

    log = lab_log(sim, kind)
    joint = write_joint_toml(joint_toml(log.spec, log.index is not None, kind), out.parent / "joint.toml")
    path = write_columns(lab_columns(log, kind), out)
    print(f"wrote {path} and {joint}")
    return path

