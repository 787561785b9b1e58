"""Sensitivity sweeps: the same benchmark with one (or a grid of) parameters varied.

A swept parameter is a key of the scenario file (``joint.counts_per_rev``,
``temperature_c``, ...) set to each given value in every scenario of the run. The swept
scenarios are built exactly as a file with that value would be (every range check of
:mod:`rippleb.simulator.scenario` applies), so a sweep can ask for nothing a scenario file could
not. Each result row gets one column per swept parameter, named after it.

Examples
--------
>>> from rippleb.engine.sweep import parse_params, grid
>>> params = parse_params(["joint.counts_per_rev=500,2500", "temperature_c=25,40"])
>>> [p.name for p in params]
['joint.counts_per_rev', 'temperature_c']
>>> len(grid(params))
4
"""

from __future__ import annotations

import copy
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

from rippleb.engine.params import PARAMS, UNMODELLED_RANGES, Param  # noqa: F401 - re-exported
from rippleb.errors import InputError
from rippleb.registry import unknown_name


#: Parameters that change only the scored session of one condition: sweeping them
#: without it would give every grid point the same rows.
CONDITION_OF = {"ripple.drift": "aged"}
#: The most points a sweep's grid may have, counted before it is made: the published sweeps
#: have 4-8 values of one parameter, a grid of three parameters at ten values is 1000. A
#: grid of 40 000 points had been expanded, a scenario built per point, until memory ran out.
MAX_POINTS = 1000


@dataclass(frozen=True)
class Sweep:
    """One parameter and the values it takes."""

    param: Param
    values: tuple

    @property
    def name(self) -> str:
        return self.param.name


def parse_params(specs: list[str]) -> list[Sweep]:
    """``["name=v1,v2", ...]`` -> sweeps; unknown names and bad values are one clear line."""
    if not specs:
        raise InputError("--param: give at least one NAME=v1,v2,... "
                         f"(sweepable: {', '.join(PARAMS)})")
    sweeps, seen = [], set()
    for spec in specs:
        name, sep, values = spec.partition("=")
        name = name.strip()
        if not sep or not values.strip():
            raise InputError(f"--param {spec!r}: expected NAME=v1,v2,...")
        if name not in PARAMS:
            raise InputError("--param: " + unknown_name("sweep parameter", name, list(PARAMS)))
        if name in seen:
            raise InputError(f"--param {name}: given twice; list all its values in one --param")
        seen.add(name)
        parsed = [PARAMS[name].parse(v.strip()) for v in values.split(",") if v.strip()]
        if not parsed:  # "joint.fs=,,": a grid of no points would run no row and say nothing
            raise InputError(f"--param {spec!r}: no values; expected NAME=v1,v2,...")
        if len(set(parsed)) != len(parsed):
            raise InputError(f"--param {name}: a value is repeated")
        sweeps.append(Sweep(PARAMS[name], tuple(parsed)))
    points = math.prod(len(s.values) for s in sweeps)
    if points > MAX_POINTS:
        raise InputError(f"--param: a grid of {points} points ({' x '.join(str(len(s.values)) for s in sweeps)} "
                         f"values), more than the {MAX_POINTS} a sweep may have (docs/robustness.md, section 11)")
    return sweeps


def grid(sweeps: list[Sweep]) -> list[dict]:
    """Every combination of the swept values, as ``{name: value}`` dicts, in order."""
    names = [s.name for s in sweeps]
    return [dict(zip(names, combo)) for combo in itertools.product(*(s.values for s in sweeps))]


def apply(raw: dict, point: dict) -> dict:
    """A copy of the parsed scenario file ``raw`` with each ``dotted.key = value`` of ``point`` set."""
    out = copy.deepcopy(raw)
    for name, value in point.items():
        table = out
        *parents, leaf = name.split(".")
        for key in parents:
            table = table.setdefault(key, {})
        table[leaf] = value
    return out


def swept_scenario(name_or_path, point: dict):
    """The scenario ``name_or_path`` with ``point`` applied, checked like a file.

    Its name stays the original one (the result rows say which values were swept); an
    impossible combination (e.g. a control rate above the swept sample rate) is refused
    with the file, key and the swept values named.
    """
    from rippleb.reading import parse_toml
    from rippleb.simulator.scenario import Parser, read_source

    text, path, name = read_source(name_or_path)
    raw = apply(parse_toml(text, path), point)
    where = ", ".join(f"{k}={v}" for k, v in point.items())
    try:
        return Parser(path, name).scenario(raw)
    except InputError as exc:
        raise InputError(f"{exc} (with {where})") from None


def run_sweep(params, methods=None, scenarios=None, seeds=None, *, conditions=None, seed_start: int = 0,
              **options):
    """Run the benchmark at every point of the grid of ``params``; one row per grid point x
    method x scenario x condition x seed.

    Parameters
    ----------
    params
        ``["name=v1,v2", ...]`` (as on the command line) or ``{name: [v1, v2], ...}``.
    methods, scenarios, seeds, conditions, seed_start
        As in :func:`rippleb.engine.runner.run`.
    **options
        ``jobs``, ``out``, ``timeout``, ``memory_mb``, ``resume``, ``progress``,
        ``on_start``, ``executor``: as in :func:`rippleb.engine.runner.run`.

    Returns
    -------
    pandas.DataFrame
        The rows sorted by (method, scenario, condition, seed, swept values), with one
        column per swept parameter, named after it.
    """
    from rippleb.engine import runner
    from rippleb.engine.checks import check_options, check_scenario
    from rippleb.registry import Registry
    from rippleb.engine.results import KEY_COLUMNS
    from rippleb import interrupts
    from rippleb.engine.rows import (CALIBRATION, check_rows, select_conditions, select_scenarios, select_seeds,
                                     split_names)
    from rippleb.simulator.scenario import load_scenario, scored_scenarios

    sweeps = parse_params(_specs(params))
    check_options(jobs=options.get("jobs", 1), timeout=options.get("timeout", runner.DEFAULT_TIMEOUT_S),
                         memory_mb=options.get("memory_mb", runner.DEFAULT_MEMORY_MB))
    registry = Registry.discover()
    names = runner.resolve_methods(registry, methods)
    if scenarios is not None and not split_names(scenarios):
        raise InputError("--scenarios is empty; give scenario names or .toml paths")
    given = split_names(scenarios) or scored_scenarios()
    chosen = select_scenarios(given, load_scenario)
    condition_list = select_conditions(conditions)
    seed_list = select_seeds(runner.DEFAULT_SEEDS if seeds is None else seeds, seed_start)
    for sweep in sweeps:
        needed = CONDITION_OF.get(sweep.name)
        if needed and needed not in condition_list:
            raise InputError(f"--param {sweep.name}: acts only under the {needed!r} condition; "
                             f"add --conditions {needed} (given: {','.join(condition_list)})")
    points = grid(sweeps)
    check_rows(len(points) * len(names) * len(chosen) * len(condition_list) * len(seed_list),
               f"{len(points)} points x {len(names)} methods x {len(chosen)} scenarios x "
               f"{len(condition_list)} conditions x {len(seed_list)} seeds")
    entries = []
    for point in points:
        interrupts.check_interrupted()   # a scenario is built per point: Ctrl-C stops it
        device = {k: v for k, v in point.items() if PARAMS[k].device}
        calibration = swept_scenario(CALIBRATION, device)
        for scenario in chosen:
            swept = swept_scenario(scenario.path, point)
            check_scenario(swept)
            entries.append((swept, calibration, point))
    config = {"methods": names, "conditions": condition_list, "seeds": seed_list,
              "scenarios": [str(Path(s).resolve()) if s.endswith(".toml") else s for s in dict.fromkeys(given)],
              "sweep": {s.name: list(s.values) for s in sweeps}}
    frame = runner.run_resolved(registry, names, entries, condition_list, seed_list, config=config,
                                **options)
    if len(frame):
        keys = list(KEY_COLUMNS) + [s.name for s in sweeps]
        frame = frame.sort_values(keys, kind="stable").reset_index(drop=True)
    return frame


def _specs(params) -> list[str]:
    if isinstance(params, dict):
        return [f"{name}={','.join(str(v) for v in values)}" for name, values in params.items()]
    return [params] if isinstance(params, str) else list(params)


def specs_from_config(config: dict) -> list[str]:
    """The ``--param`` specs of a sweep saved in ``run.json`` (for ``--resume``)."""
    sweep = config.get("sweep")
    if not isinstance(sweep, dict) or not sweep:
        raise InputError("run.json describes a run, not a sweep; finish it with rippleb run --resume")
    return _specs(sweep)
