"""Scenarios: one TOML file each, read as data, checked key by key.

A scenario says which arm joint moves how (a piecewise trajectory of rest-to-rest
quintic moves, holds, speed ramps and constant-speed cruises), which external torques
act on it, at which temperature, and which time window is scored. The file name is the
scenario's name. ``docs/scenarios.md`` describes the format and every built-in.

This module reads and checks the files (:class:`Parser`); what they are read into,
:class:`Scenario` and its defaults, is :mod:`rippleb.simulator.scenario_types`, re-exported here.

Examples
--------
>>> from rippleb.simulator.scenario import load_scenario
>>> sc = load_scenario("paper-quintic")
>>> sc.name, sc.scored, round(sc.duration, 2)
('paper-quintic', True, 4.0)
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib.resources
from pathlib import Path

import numpy as np

from rippleb.data import MAX_TORQUE_FACTOR, JointSpec
from rippleb.reading import check_joint_value
from rippleb.errors import InputError
from rippleb.layouts import GAUGE_KEYS, parse_gauges
from rippleb.simulator.mismatch import TABLES as _UNMODELLED_TABLES, parse_tables
from rippleb.simulator.profiles import DEFAULT_RISE, Load, Segment, evaluate_segments  # noqa: F401 (re-exported)
from rippleb.simulator.scenario_types import (DEFAULT_JOINT, DEFAULT_ROBOT, DEFAULT_TEMPERATURE_C,  # noqa: F401 (re-exported)
                                    HYSTERESIS_NM, REFERENCE_TEMPERATURE_C, RIPPLE_TEMP_COEFF, Faults,
                                    ORDER2_SHARE, TRANSMISSION_ERROR_PP, RippleSettings, Scenario)

CALIBRATION = "calibration"
SEGMENT_KINDS = ("hold", "move", "ramp", "cruise")

# Allowed keys and their types, per table; the first type is the one named in errors.
_NUMBER = (float, int)
_TOP_KEYS = {"description": (str,), "scored": (bool,), "duration": _NUMBER,
             "temperature_c": _NUMBER, "evaluation": (dict,), "joint": (dict,),
             "robot": (dict,), "trajectory": (dict,), "load": (list,), "faults": (dict,),
             "ripple": (dict,), "gear": (dict,), "gauges": (dict,), **{table: (dict,) for table in _UNMODELLED_TABLES}}
_RIPPLE_KEYS = {"output_scale": _NUMBER, "hysteresis_nm": _NUMBER, "temperature_coeff": _NUMBER,
                "drift": _NUMBER}
#: The [gear] keys that act in every condition; the table's knobs are :mod:`rippleb.simulator.mismatch`'s.
_GEAR_KEYS = {"transmission_error": _NUMBER, "order2_share": _NUMBER}
#: Largest transmission-error class accepted [rad peak to peak]: 3.4 arcmin, above every
#: class of the CSF catalogue (1 arcmin standard).
MAX_TRANSMISSION_ERROR = 1e-3
_EVAL_KEYS = {"start": _NUMBER, "stop": _NUMBER}
_JOINT_KEYS = {f.name: ((int,) if f.type in ("int", int) else _NUMBER)
               for f in dataclasses.fields(JointSpec)}
_ROBOT_KEYS = {"name": (str,), "joint": (str,), "posture": (dict,)}
_TRAJ_KEYS = {"start": _NUMBER, "segment": (list,)}
_SEGMENT_KEYS = {"kind": (str,), "duration": _NUMBER, "to": _NUMBER, "by": _NUMBER,
                 "velocity": _NUMBER, "shape": (str,)}
_LOAD_KEYS = {"kind": (str,), "torque": _NUMBER, "amplitude": _NUMBER, "f0": _NUMBER,
              "f1": _NUMBER, "start": _NUMBER, "stop": _NUMBER, "rise": _NUMBER, "known": (bool,)}
LOAD_KINDS = ("step", "chirp")
#: Keys each load kind needs and may have (``kind`` itself is optional, default ``step``).
_LOAD_NEEDS = {"step": {"torque", "start"}, "chirp": {"amplitude", "f0", "f1", "start", "stop"}}
_LOAD_OPTIONAL = {"step": {"stop", "rise", "known"}, "chirp": {"rise", "known"}}
#: A chirp's top frequency may reach this fraction of ``fs`` (well below Nyquist, so the
#: sampled sweep is a sweep and not its alias).
CHIRP_MAX_F1_FS = 0.05
_FAULT_KEYS = {"encoder_missed": _NUMBER, "encoder_spurious_rate": _NUMBER,
               "strain_full_scale": _NUMBER, "dropout_rate": _NUMBER, "dropout_length": _NUMBER,
               "bridge_drift": _NUMBER, "current_offset": _NUMBER}

#: Longest log a scenario may ask for, in samples (500 s at 20 kHz; the simulator holds
#: a few dozen float arrays of this length). Longer would exhaust memory, not simulate.
MAX_SAMPLES = 10_000_000
#: Lubricant temperatures the friction model is meant for [deg C].
TEMPERATURE_RANGE = (-40.0, 150.0)
#: An external load above this many times the rated torque would break the drive
#: (:data:`rippleb.data.MAX_TORQUE_FACTOR`).
MAX_LOAD_FACTOR = MAX_TORQUE_FACTOR

def _scenario_dir():
    return importlib.resources.files("rippleb.scenarios")


def builtin_scenarios() -> list[str]:
    """Names of the built-in scenarios, sorted (``calibration`` included)."""
    return sorted(entry.name[:-5] for entry in _scenario_dir().iterdir()
                  if entry.name.endswith(".toml"))


def scored_scenarios() -> list[str]:
    """Built-in scenarios scored by default: all but those with ``scored = false``."""
    return [name for name in builtin_scenarios() if load_scenario(name).scored]


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name, or a scenario file by path.

    Raises
    ------
    InputError
        One line ``<file>: <key>: <what is wrong>`` for a file that is not TOML, an
        unknown key, a wrong type or an impossible value; or for an unknown name.
    """
    from rippleb.reading import parse_toml

    text, path, name = read_source(name_or_path)
    return Parser(path, name).scenario(parse_toml(text, path))


def scenario_from_dict(raw: dict, name: str = "custom") -> Scenario:
    """Build a scenario from the parsed form of a TOML file (tests, figures, scripts).

    Checked exactly like a file; errors name ``<name>`` as the file.
    """
    return Parser(Path(f"<{name}>"), name).scenario(raw)


def read_source(name_or_path) -> tuple[str, Path, str]:
    from rippleb.reading import TOML_BYTES, read_text

    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        try:   # a regular file of at most TOML_BYTES: not a FIFO, a device or a giant
            return read_text(candidate, TOML_BYTES, "scenario file"), candidate, candidate.stem
        except FileNotFoundError:
            raise InputError(f"{candidate}: no such scenario file") from None
    name = str(name_or_path)
    if not name or any(c in name for c in "/\\") or name.startswith("."):
        # a name is not a path: it must not reach files outside the built-ins
        raise InputError(f"{name}: not a built-in scenario name; give a path to a .toml file "
                         f"for a scenario of your own")
    resource = _scenario_dir() / f"{name}.toml"
    if not resource.is_file():
        close = difflib.get_close_matches(name, builtin_scenarios(), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise InputError(f"{name}: unknown scenario{hint}; built-ins: "
                         f"{', '.join(builtin_scenarios())}")
    return resource.read_text(encoding="utf-8"), Path(str(resource)), name


class Parser:
    """Checks a parsed TOML document key by key and builds the :class:`Scenario`."""

    def __init__(self, path: Path, name: str):
        self.path, self.name = path, name

    def fail(self, key: str, what: str):
        raise InputError(f"{self.path}: {key}: {what}")

    def table(self, raw, allowed: dict, where: str) -> dict:
        """Check keys and types of one table; return it."""
        if not isinstance(raw, dict):
            self.fail(where, f"must be a table, got {type(raw).__name__}")
        for key, value in raw.items():
            full = f"{where}.{key}" if where else key
            if key not in allowed:
                close = difflib.get_close_matches(key, list(allowed), n=3)
                hint = f"; did you mean {', '.join(close)}?" if close else \
                    f"; valid keys: {', '.join(allowed)}"
                self.fail(full, f"unknown key{hint}")
            types = allowed[key]
            if isinstance(value, bool) and bool not in types or not isinstance(value, types):
                self.fail(full, f"must be {_type_name(types[0])}, got {type(value).__name__}")
            if isinstance(value, float) and not np.isfinite(value):
                self.fail(full, f"must be finite, got {value}")
        return raw

    def scenario(self, raw: dict) -> Scenario:
        top = self.table(raw, _TOP_KEYS, "")
        spec = self.spec(top.get("joint", {}))
        robot, joint, posture = self.robot(top.get("robot", {}))
        segments = self.segments(top.get("trajectory", {}))
        end = segments[-1].t0
        duration = float(top.get("duration", end))
        if duration <= 0:
            self.fail("duration", f"must be positive, got {duration}")
        if duration * spec.fs < 2 * spec.block_size:
            self.fail("duration", f"{duration} s is shorter than two control ticks")
        if duration * spec.fs > MAX_SAMPLES:
            self.fail("duration", f"{duration} s at fs {spec.fs:g} Hz is more than {MAX_SAMPLES} "
                      f"samples ({MAX_SAMPLES / spec.fs:g} s); split it into shorter scenarios")
        temperature = float(top.get("temperature_c", DEFAULT_TEMPERATURE_C))
        if not TEMPERATURE_RANGE[0] <= temperature <= TEMPERATURE_RANGE[1]:
            self.fail("temperature_c", f"must be within {TEMPERATURE_RANGE[0]:g} to "
                      f"{TEMPERATURE_RANGE[1]:g} degC, got {temperature:g}")
        loads = tuple(self.load(item, i, spec) for i, item in enumerate(top.get("load", [])))
        evaluation = self.evaluation(top.get("evaluation", {}), duration)
        faults = self.faults(top.get("faults", {}), spec)
        ripple = self.ripple(top.get("ripple", {}), spec)
        if ripple.temperature_scale(temperature) < 0:
            self.fail("ripple.temperature_coeff", f"{ripple.temperature_coeff:g} per K would turn the "
                      f"ripple negative at {temperature:g} degC")
        for table, keys in _UNMODELLED_TABLES.items():
            self.table(top.get(table, {}), {**keys, **(_GEAR_KEYS if table == "gear" else {})}, table)
        unmodelled = parse_tables(top, self.fail, spec)
        gear = top.get("gear", {})
        transmission_error = float(gear.get("transmission_error", TRANSMISSION_ERROR_PP))
        if not 0.0 <= transmission_error <= MAX_TRANSMISSION_ERROR:
            self.fail("gear.transmission_error", f"must be in [0, {MAX_TRANSMISSION_ERROR:g}] rad peak to "
                      f"peak, got {transmission_error:g}")
        order2_share = float(gear.get("order2_share", ORDER2_SHARE))
        if not 0.0 <= order2_share <= 1.0:
            self.fail("gear.order2_share", f"must be in [0, 1] (of the class), got {order2_share:g}")
        gauges = parse_gauges(self.table(top.get("gauges", {}), GAUGE_KEYS, "gauges"), self.fail)
        return Scenario(name=self.name, path=self.path,
                        description=top.get("description", "").strip(),
                        spec=spec, duration=duration, scored=top.get("scored", True),
                        evaluation=evaluation,
                        temperature_c=temperature,
                        robot=robot, joint=joint, posture=posture,
                        segments=segments, loads=loads, faults=faults, ripple=ripple,
                        unmodelled=unmodelled, transmission_error=transmission_error,
                        order2_share=order2_share, gauges=gauges)

    def spec(self, raw) -> JointSpec:
        values = self.table(raw, _JOINT_KEYS, "joint")
        for key, value in values.items():
            check_joint_value(key, value, f"{self.path}: joint.{key}")
        spec = JointSpec(**{k: (v if k == "counts_per_rev" else float(v)) for k, v in values.items()})
        if spec.control_rate > spec.fs:
            self.fail("joint.control_rate", f"{spec.control_rate} exceeds fs {spec.fs}")
        return spec

    def robot(self, raw):
        from rippleb.simulator import robot as arm

        values = self.table(raw, _ROBOT_KEYS, "robot")
        name = values.get("name", DEFAULT_ROBOT)
        known = arm.robot_names()
        if name not in known:
            close = difflib.get_close_matches(name, known, n=3)
            self.fail("robot.name", f"unknown robot {name!r}"
                      + (f"; did you mean {', '.join(close)}?" if close else ""))
        joints = arm.joint_names(name)
        joint = values.get("joint", DEFAULT_JOINT if name == DEFAULT_ROBOT else joints[0])
        if joint not in joints:
            self.fail("robot.joint", f"{name} has no revolute joint {joint!r}; "
                      f"its joints: {', '.join(joints)}")
        posture = values.get("posture", {})
        for key, value in posture.items():
            if key not in joints or key == joint:
                self.fail(f"robot.posture.{key}", f"not a held joint of {name}; "
                          f"held joints: {', '.join(j for j in joints if j != joint)}")
            if isinstance(value, bool) or not isinstance(value, _NUMBER):
                self.fail(f"robot.posture.{key}", f"must be a number, got {type(value).__name__}")
        return name, joint, tuple(sorted((k, float(v)) for k, v in posture.items()))

    def segments(self, raw) -> tuple[Segment, ...]:
        values = self.table(raw, _TRAJ_KEYS, "trajectory")
        items = values.get("segment", [])
        if not items:
            self.fail("trajectory.segment", "needs at least one segment")
        t, q, v = 0.0, float(values.get("start", 0.0)), 0.0
        out = []
        for i, item in enumerate(items):
            seg = self.segment(item, f"trajectory.segment[{i}]", t, q, v)
            out.append(seg)
            t, q, v = seg.t1, seg.q1, seg.end_velocity
        # Open end: keep the final velocity (a hold at rest) for any time after the plan.
        out.append(Segment("cruise", t, 1.0, q, v))
        return tuple(out)

    def segment(self, raw, where: str, t: float, q: float, v: float) -> Segment:
        values = self.table(raw, _SEGMENT_KEYS, where)
        kind = values.get("kind")
        if kind not in SEGMENT_KINDS:
            self.fail(f"{where}.kind", f"must be one of {', '.join(SEGMENT_KINDS)}, got {kind!r}")
        needed = {"hold": {"duration"}, "move": {"duration"}, "ramp": {"duration", "velocity"},
                  "cruise": {"duration"}}[kind]
        optional = {"move": {"to", "by"}, "ramp": {"shape"}}.get(kind, set())
        for key in values:
            if key != "kind" and key not in needed | optional:
                self.fail(f"{where}.{key}", f"not used by a {kind} segment")
        for key in needed - set(values):
            self.fail(f"{where}.{key}", f"missing (a {kind} segment needs {', '.join(sorted(needed))})")
        duration = float(values["duration"])
        if duration < 0 or (duration == 0 and kind != "hold"):
            self.fail(f"{where}.duration", f"must be {'>= 0' if kind == 'hold' else '> 0'}, "
                      f"got {duration}")
        if kind in ("hold", "move") and abs(v) > 1e-12:
            self.fail(f"{where}.kind", f"a {kind} starts at rest but the joint moves at "
                      f"{v:g} rad/s; ramp to velocity = 0 first")
        if kind == "move":
            if ("to" in values) == ("by" in values):
                self.fail(where, "a move needs exactly one of to, by")
            distance = float(values["to"]) - q if "to" in values else float(values["by"])
            return Segment("move", t, duration, q, 0.0, distance=distance)
        if kind == "ramp":
            shape = values.get("shape", "smooth")
            if shape not in ("smooth", "linear"):
                self.fail(f"{where}.shape", f"must be smooth or linear, got {shape!r}")
            return Segment("ramp", t, duration, q, v, v1=float(values["velocity"]), shape=shape)
        return Segment(kind, t, duration, q, v if kind == "cruise" else 0.0)

    def faults(self, raw, spec: JointSpec) -> Faults:
        values = self.table(raw, _FAULT_KEYS, "faults")
        ranges = {"encoder_missed": (0.0, 1.0, "a probability in [0, 1]"),
                  "encoder_spurious_rate": (0.0, spec.fs, f"in [0, fs = {spec.fs:g}] per second"),
                  "strain_full_scale": (1e-3, 100.0, "in [0.001, 100] V"),
                  "dropout_rate": (0.0, spec.fs, f"in [0, fs = {spec.fs:g}] per second"),
                  "dropout_length": (0.0, 10.0, "in [0, 10] s"),
                  "bridge_drift": (-10.0, 10.0, "in [-10, 10] V/s"),
                  "current_offset": (-100.0, 100.0, "in [-100, 100] A")}
        for key, value in values.items():
            lo, hi, what = ranges[key]
            if not lo <= value <= hi:
                self.fail(f"faults.{key}", f"must be {what}, got {value:g}")
        if values.get("dropout_rate", 0) > 0 and values.get("dropout_length", 0) <= 0:
            self.fail("faults.dropout_length", "must be positive when dropout_rate is set")
        return Faults(**{k: float(v) for k, v in values.items()})

    def ripple(self, raw, spec: JointSpec) -> RippleSettings:
        values = self.table(raw, _RIPPLE_KEYS, "ripple")
        ranges = {"output_scale": (0.0, 10.0, "in [0, 10]"),
                  "hysteresis_nm": (0.0, 0.2 * spec.rated_torque,
                                    f"in [0, 0.2 x rated_torque = {0.2 * spec.rated_torque:g}] Nm"),
                  "temperature_coeff": (-0.01, 0.01, "in [-0.01, 0.01] per K"),
                  "drift": (0.0, 5.0, "in [0, 5] (multiples of the documented drift)")}
        for key, value in values.items():
            lo, hi, what = ranges[key]
            if not lo <= value <= hi:
                self.fail(f"ripple.{key}", f"must be {what}, got {value:g}")
        return RippleSettings(**{k: float(v) for k, v in values.items()})

    def load(self, raw, i: int, spec: JointSpec | None = None) -> Load:
        where = f"load[{i}]"
        spec = spec or JointSpec()
        values = self.table(raw, _LOAD_KEYS, where)
        kind = values.get("kind", "step")
        if kind not in LOAD_KINDS:
            self.fail(f"{where}.kind", f"must be one of {', '.join(LOAD_KINDS)}, got {kind!r}")
        for key in values:
            if key != "kind" and key not in _LOAD_NEEDS[kind] | _LOAD_OPTIONAL[kind]:
                self.fail(f"{where}.{key}", f"not used by a {kind} load")
        for key in sorted(_LOAD_NEEDS[kind] - set(values)):
            self.fail(f"{where}.{key}", f"missing (a {kind} load needs "
                      f"{', '.join(sorted(_LOAD_NEEDS[kind]))})")
        size_key = "torque" if kind == "step" else "amplitude"
        load = Load(torque=float(values[size_key]), start=float(values["start"]),
                    stop=float(values.get("stop", float("inf"))),
                    rise=float(values.get("rise", DEFAULT_RISE)),
                    known=values.get("known", False), kind=kind,
                    f0=float(values.get("f0", 0.0)), f1=float(values.get("f1", 0.0)))
        if load.rise <= 0:
            self.fail(f"{where}.rise", f"must be positive, got {load.rise}")
        peak = MAX_LOAD_FACTOR * spec.rated_torque
        if abs(load.torque) > peak:
            self.fail(f"{where}.{size_key}", f"|{load.torque:g}| Nm exceeds {MAX_LOAD_FACTOR:g} x "
                      f"rated_torque ({peak:g} Nm); the drive would break")
        if load.start < 0:
            self.fail(f"{where}.start", f"must be >= 0, got {load.start}")
        if load.stop < load.start + load.rise:
            self.fail(f"{where}.stop", f"must be at least start + rise ({load.start + load.rise})")
        if kind == "chirp":
            self.chirp_band(load, where, spec)
        return load

    def chirp_band(self, load: Load, where: str, spec: JointSpec) -> None:
        """Refuse a sweep that does not rise or that the DAQ cannot sample."""
        top = CHIRP_MAX_F1_FS * spec.fs
        if load.f0 <= 0:
            self.fail(f"{where}.f0", f"must be positive, got {load.f0:g}")
        if load.f1 <= load.f0:
            self.fail(f"{where}.f1", f"must be above f0 ({load.f0:g} Hz), got {load.f1:g}")
        if load.f1 > top:
            self.fail(f"{where}.f1", f"must be at most {CHIRP_MAX_F1_FS:g} x fs ({top:g} Hz), "
                      f"got {load.f1:g}")

    def evaluation(self, raw, duration: float) -> tuple[float, float]:
        values = self.table(raw, _EVAL_KEYS, "evaluation")
        start = float(values.get("start", 0.0))
        stop = float(values.get("stop", duration))
        if not 0 <= start < stop <= duration + 1e-9:
            self.fail("evaluation", f"need 0 <= start < stop <= duration ({duration}), "
                      f"got start {start}, stop {stop}")
        return start, stop


def _type_name(kind) -> str:
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false",
            dict: "a table", list: "an array of tables"}[kind]
