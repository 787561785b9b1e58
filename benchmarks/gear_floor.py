"""Why ``raw`` seemed to erase the gear's torque: the floor of the former ``gear_erased_fraction``.

The former column was the share of the gear's real torque ``g`` missing from an estimate,
``-sum_W e g / sum_W g^2`` with ``e`` the error against ``torque_true``. ``raw`` (a gain
and an offset of the strain, nothing removed) scored 0.19 on unseen devices (issue 38).
By linearity the share splits over the terms of ``raw``'s error, i.e. of the strain
(docs/physics.md, "Strain bridge"): ``e = hyst + wave ripple + output-locked ripple +
(gain, offset, drift, noise, ADC)``. This script computes each term's share from the
simulator's truth, for ``raw`` fitted on each device's calibration log, per scored
scenario with at least ``--min-gear`` Nm RMS of gear torque, and prints the mean over the
devices and the per-device standard deviation:

- ``hysteresis``: the strain's play operator (``hyst``), which lags the torque and
  flattens small oscillations on a slow trend: the part of ``g`` the gauges do not carry;
- ``ripple 1-2`` and ``ripple 4-8``: the wave-generator ripple at those orders, locked to
  the angle ``g`` is locked to (orders 1 and 2), so it projects onto ``g`` with the sign
  of the device's ripple phase;
- ``output ripple``: the output-locked ripple (the joint angle is taken as the
  trajectory's, within mrad of the simulated one);
- ``rest``: what is left: gain, offset, drift, noise and the ADC.

It also prints ``raw``'s ``gear_removed_fraction``, the column that replaced it (0 by
construction). ``docs/metrics.md`` ("What a method erased") copies the table made by::

    python benchmarks/gear_floor.py --seeds 2000-2009

(``tests/test_metrics.py`` runs it on one device and one scenario.)
"""

from __future__ import annotations

import argparse
import dataclasses

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

PARTS = ("hysteresis", "ripple 1-2", "ripple 4-8", "output ripple", "rest")
MOVING = ("paper-quintic", "stop-restart", "speed-sweep", "reversal", "load-steps", "torque-chirp")


def shares(sim, estimate) -> dict[str, float] | None:
    """The former column's value for ``estimate`` (``raw``'s) and each term's share of it,
    on the scored window of ``sim``; None when the gear torque is zero."""
    from rippleb.simulator import gauge
    from rippleb.simulator.ripple import OutputRipple, hysteresis
    from rippleb.simulator.sensors import IDEAL

    mask, g = sim.eval_mask, sim.torque_gear
    power = float(np.dot(g[mask], g[mask]))
    if not power > 0:
        return None
    # the bridge as its channel reads it: the ripple terms the gauges' geometry gives it
    # (a one-channel layout, the default; rippleb/simulator/flexspline.py)
    tau, device, sc = sim.log.torque_true, sim.gauges[0], sim.scenario

    def share(x):
        return float(-np.dot(x[mask], g[mask]) / power)

    def wave(orders):
        keep = [o in orders for o in device.ripple_orders]
        only = dataclasses.replace(device, ripple_base=tuple(b * k for b, k in zip(device.ripple_base, keep)),
                                   ripple_load=tuple(b * k for b, k in zip(device.ripple_load, keep)))
        return gauge.wave_ripple(only, IDEAL, sim.wave_angle, tau, sc.spec)

    scale = sc.ripple.temperature_scale(sc.temperature_c)
    out = {"total": share(estimate - tau),
           "hysteresis": share(hysteresis(tau, sc.ripple.hysteresis_nm)),
           "ripple 1-2": share(scale * wave((1, 2))),
           "ripple 4-8": share(scale * wave(tuple(o for o in device.ripple_orders if o > 2))),
           "output ripple": share(scale * sc.ripple.output_scale
                                  * OutputRipple.from_seed(device.seed)(sc.trajectory(sim.log.t)[0], tau))}
    out["rest"] = out["total"] - sum(out[p] for p in PARTS[:-1])
    return out


def measure(seeds, scenarios, min_gear: float = 0.05, condition: str = "same-session") -> dict:
    """``{scenario: {part: [share per device]}}`` and ``raw``'s ``gear_removed_fraction``
    (key ``"removed"``), over ``seeds``."""
    from rippleb.methods.raw import Raw
    from rippleb.scoring.metrics import gear_removed
    from rippleb.simulator import simulate
    from rippleb.harness import run_method

    table: dict = {}
    for seed in seeds:
        calibration = simulate("calibration", seed, condition).log
        for name in scenarios:
            sim = simulate(name, seed, condition)
            mask, g = sim.eval_mask, sim.torque_gear
            if not np.sqrt(np.mean(g[mask] ** 2)) >= min_gear:
                continue
            estimate, _ = run_method(Raw(), calibration, sim.log)
            row = shares(sim, estimate)
            row["removed"] = gear_removed(estimate, sim.log.strain, g, mask)
            for part, value in row.items():
                table.setdefault(name, {}).setdefault(part, []).append(value)
    return table


def markdown(table: dict) -> str:
    """The table: per scenario the mean share of each term over the devices, then the mean
    over the scenarios of each device's mean (with its standard deviation over devices)."""
    columns = ("total",) + PARTS + ("removed",)
    lines = ["| scenario | former `gear_erased_fraction` of `raw` | " + " | ".join(PARTS)
             + " | `gear_removed_fraction` |", "|---" * (len(columns) + 1) + "|"]
    for name, parts in table.items():
        lines.append(f"| {name} | " + " | ".join(f"{np.mean(parts[c]):+.3f}" for c in columns) + " |")
    per_device = {c: np.mean([parts[c] for parts in table.values()], axis=0) for c in columns}
    lines.append("| mean over the scenarios (SD over devices) | "
                 + " | ".join(f"{np.mean(v):+.3f} ({np.std(v, ddof=1) if len(v) > 1 else 0.0:.3f})"
                              for v in per_device.values()) + " |")
    return "\n".join(lines)


def seed_range(text: str) -> range:
    first, _, last = text.partition("-")
    return range(int(first), int(last or first) + 1)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="2000-2009", help="devices, A-B inclusive (default 2000-2009)")
    parser.add_argument("--scenarios", default=",".join(MOVING), help="scored scenarios, comma-separated")
    parser.add_argument("--min-gear", type=float, default=0.05,
                        help="Nm RMS of gear torque a case needs to be counted (default 0.05)")
    args = parser.parse_args(argv)
    table = measure(seed_range(args.seeds), args.scenarios.split(","), args.min_gear)
    print(f"devices {args.seeds}, same-session; share of -g in raw's error, by term of the strain")
    print(markdown(table))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
