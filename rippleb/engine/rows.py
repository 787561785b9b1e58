"""Row identity: what a row ran, so that two different inputs never share a key or a cache file.

A row is keyed by ``(method, scenario, condition, seed)`` (:class:`RowKey`); its input
is further identified by the scenario's content hash (``scenario_sha256``, a column of
the results) and the method's parameters (``params``). Simulations are keyed by
:class:`Case`, which holds the content hash, so cache files are named by what they
hold, not by a name two files could share.

Scenario selections are checked here: a user file is named by its stem, and a name
given twice for different content, or a file named like a built-in scenario, is refused
with one line (it would otherwise shadow the built-in silently), and so are the seeds.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rippleb.simulator.conditions import CONDITIONS, DEFAULT_CONDITION, check_condition
from rippleb.errors import InputError

CALIBRATION = "calibration"
SCORED, FITTING = "scored", "calibration"
#: The most seeds (devices) one run may have. 20 devices give the published intervals;
#: 10 000 narrow a 95 % interval to about 2 % of the device-to-device spread, beyond
#: anything a comparison needs, and already take weeks of CPU for the default selection
#: (10 000 x 8 scenarios x 10 methods rows). A larger number is a typo (--seeds 100000
#: for --seeds 10), which would otherwise plan millions of rows and list every seed in run.json.
MAX_SEEDS = 10_000
#: The most rows one run or sweep may plan, checked before anything is planned: the default
#: selection at :data:`MAX_SEEDS` is 1.12 million rows (14 built-ins x 8 scenarios, months of
#: CPU); the published comparison is 11 200. Its plan holds about 1 GB and takes under a
#: minute; more was a typo (a grid of 1e9 variants, a sweep of 40 000 points) expanded until
#: memory ran out.
MAX_ROWS = 2_000_000


def check_rows(count: int, what: str) -> None:
    """Refuse, before planning, a selection of more than :data:`MAX_ROWS` rows; ``what``
    says how the count was made (``2 methods x 8 scenarios x ...``)."""
    if count > MAX_ROWS:
        raise InputError(f"{what} is {count:.4g} rows, more than the {MAX_ROWS} one run may have "
                         f"(docs/robustness.md, section 11); split it into runs")


@dataclass(frozen=True, order=True)
class RowKey:
    """The key of one result row."""

    method: str
    scenario: str
    condition: str
    seed: int
    extra: tuple = ()  # ((column, value), ...): swept values, part of the identity

    def fields(self) -> dict:
        """The key as result columns."""
        return {"method": self.method, "scenario": self.scenario, "condition": self.condition,
                "seed": self.seed, **dict(self.extra)}


@dataclass(frozen=True)
class Case:
    """One simulated (or recorded) log: which scenario content, condition and seed, and
    whether methods see it as their calibration (with ``torque_ref``) or as a scored log."""

    scenario: str
    content: str
    condition: str
    seed: int
    role: str

    def file_name(self) -> str:
        """A cache file name derived from everything that identifies the case."""
        key = json.dumps(dataclasses.asdict(self), sort_keys=True)
        return f"case-{hashlib.sha256(key.encode()).hexdigest()[:32]}.npz"


def scenario_hash(scenario) -> str:
    """SHA-256 of a scenario's content (every parsed field but its file path)."""
    fields = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(scenario)
              if f.name != "path" and not _default_added_field(scenario, f)}
    text = json.dumps(_plain(fields), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


#: Scenario fields added after results were published: left out of the hash while they hold
#: their default, so every scenario that does not use them keeps its published hash.
_ADDED_FIELDS = ("unmodelled",)


def _default_added_field(scenario, f) -> bool:
    return f.name in _ADDED_FIELDS and getattr(scenario, f.name) == f.default


def _plain(value):
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return repr(value)


def select_scenarios(given: list[str], load) -> list:
    """Load the scenarios ``given`` (names or paths) and refuse ambiguous selections.

    The same built-in name or the same file given twice is kept once. Two different
    scenarios that would share a name (``d1/x.toml`` and ``d2/x.toml``), or a file named
    like a built-in (``./creep.toml``, ``calibration.toml``), raise :class:`InputError`.
    """
    from rippleb.simulator.scenario import builtin_scenarios

    builtins = set(builtin_scenarios())
    chosen: dict[str, tuple[str, object, str]] = {}
    for item in given:
        scenario = load(item)
        content = scenario_hash(scenario)
        is_file = item not in builtins
        if is_file and scenario.name in builtins:
            raise InputError(f"{item}: a scenario file may not be named like the built-in scenario "
                             f"{scenario.name!r} (its rows and its cache would be confused with the "
                             f"built-in's); rename the file")
        if scenario.name in chosen:
            first, _, first_content = chosen[scenario.name]
            if first_content == content and _same_source(first, item):
                continue
            raise InputError(f"two scenarios are named {scenario.name!r}: {first} and {item}; "
                             f"rename one of the files")
        chosen[scenario.name] = (item, scenario, content)
    return [scenario for _, scenario, _ in chosen.values()]


def _same_source(a: str, b: str) -> bool:
    if a == b:
        return True
    return Path(a).suffix == ".toml" and Path(b).suffix == ".toml" and Path(a).resolve() == Path(b).resolve()


def select_conditions(conditions) -> list[str]:
    """Condition names from a list or ``"a,b"``; ``"all"`` for every one; None for the default."""
    wanted = split_names(conditions)
    if conditions is not None and not wanted:
        raise InputError("--conditions is empty; give condition names or 'all'")
    if not wanted:
        return [DEFAULT_CONDITION]
    if wanted == ["all"]:
        return list(CONDITIONS)
    return list(dict.fromkeys(check_condition(name) for name in wanted))


def select_seeds(seeds, seed_start: int) -> list[int]:
    """The seeds of a run: ``seeds`` devices from ``seed_start`` on, or the given list without
    repeats; at most :data:`MAX_SEEDS`."""
    if isinstance(seeds, (int, np.integer)):
        if seeds < 1:
            raise InputError(f"--seeds must be at least 1, got {seeds}")
        if seeds > MAX_SEEDS:
            raise InputError(f"--seeds {seeds}: at most {MAX_SEEDS} devices per run (docs/design.md); "
                             f"split a larger study into runs with --seed-start")
        if seed_start < 0:
            raise InputError(f"--seed-start must be a non-negative integer, got {seed_start}")
        return list(range(seed_start, seed_start + int(seeds)))
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise InputError("no seeds given")
    if any(s < 0 for s in seeds):
        raise InputError(f"seeds must be non-negative integers, got {min(seeds)}")
    seeds = list(dict.fromkeys(seeds))
    if len(seeds) > MAX_SEEDS:
        raise InputError(f"{len(seeds)} seeds: at most {MAX_SEEDS} devices per run (docs/design.md)")
    return seeds


def check_trajectory(scenario, max_speed: float | None = None) -> None:
    """Refuse a scenario whose posture or trajectory is not finite, that leaves the
    joint's position limits, or whose joint speed exceeds ``max_speed`` [rad/s] (the
    joint's URDF velocity limit), with one line."""
    for joint, value in scenario.posture:
        if not math.isfinite(value):
            raise InputError(f"{scenario.path}: posture: {joint} = {value} is not a finite angle")
    # Sampled densely per segment, so a short, fast move is not stepped over.
    t = np.concatenate([np.linspace(seg.t0, min(seg.t1, scenario.duration), 65)
                        for seg in scenario.segments if seg.t0 <= scenario.duration])
    q, qd, qdd = scenario.trajectory(t)
    for name, values in (("position", q), ("velocity", qd), ("acceleration", qdd)):
        if not np.isfinite(values).all():
            raise InputError(f"{scenario.path}: trajectory: the joint {name} is not finite")
    scenario.check_limits()
    peak = float(np.abs(qd).max())
    if max_speed is not None and peak > max_speed:
        raise InputError(f"{scenario.path}: trajectory: asks {peak:.4g} rad/s at the joint, beyond its "
                         f"velocity limit of {max_speed:.4g} rad/s")


def split_names(value) -> list[str]:
    """``"a, b"`` or ``["a", "b"]`` as a list of stripped, non-empty names."""
    if value is None:
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return [str(i).strip() for i in items if str(i).strip()]


def safe_name(text: str) -> str:
    """A file-name fragment that cannot leave its directory; names that had to be changed
    get a hash suffix, so two different names never share a file."""
    cleaned = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).lstrip(".") or "_"
    if cleaned != text:
        cleaned = f"{cleaned}-{hashlib.sha256(text.encode()).hexdigest()[:8]}"
    return cleaned
