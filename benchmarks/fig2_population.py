"""The paper's Fig. 2 over a device population, and the gear's real torque it bounds.

For each device (seed) and each scenario of ``rippleb.simulator.spectrum.SCENARIOS``
(``speed-sweep``, ``paper-quintic``), the strain is re-sampled on the encoder and each
order's amplitude measured per band of wave-generator speed, as ``rippleb report`` draws it
(``figures/fig2_orders_vs_speed.png``); this prints, per scenario and band, on how many
devices order 4 is the largest line, and the gear's order-2 real torque beside the gauges'
order-4 ripple (the bound the paper's Fig. 2 implies, docs/physics.md "Transmission
error"). ``--order2-share`` and ``--gear KNOB=VALUE`` set the ``[gear]`` table, so the same
command measures the simulator before and after a change of the split::

    python benchmarks/fig2_population.py --seeds 0-19                      # today's default
    python benchmarks/fig2_population.py --seeds 2000-2019                 # fresh devices
    python benchmarks/fig2_population.py --seeds 0-19 --order2-share 0.5   # the former split
    python benchmarks/fig2_population.py --seeds 0-19 --condition realistic
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from rippleb.simulator.mismatch import KNOB_BY_NAME
from rippleb.report.order_figure import fraction_sentence
from rippleb.simulator.scenario import load_scenario
from rippleb.simulator import simulate, spectrum


def scenarios(order2_share, gear: dict):
    out = []
    for name in spectrum.SCENARIOS:
        sc = load_scenario(name)
        if order2_share is not None:
            sc = dataclasses.replace(sc, order2_share=order2_share)
        knobs = {KNOB_BY_NAME[f"gear.{k}"].field: v for k, v in gear.items()}
        out.append(dataclasses.replace(sc, unmodelled=dataclasses.replace(sc.unmodelled, **knobs)))
    return out


def gear_over_ripple(sim) -> np.ndarray:
    """Per band: the gear's order-2 real torque over the strain's order-4 line (both in Nm,
    the strain through the device's gain), measured alike on the encoder's windows."""
    strain = spectrum.order_windows(sim.log).bands()
    gear = spectrum.order_windows(dataclasses.replace(sim.log, strain=sim.torque_gear)).bands()
    return gear[:, spectrum.ORDERS.index(2)] / (strain[:, spectrum.ORDERS.index(4)] / sim.device.gain)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-19", help="A-B, inclusive")
    parser.add_argument("--condition", default="same-session")
    parser.add_argument("--order2-share", type=float, default=None)
    parser.add_argument("--gear", action="append", default=[], metavar="KNOB=VALUE",
                        help="a [gear] knob of rippleb.simulator.mismatch, e.g. compliance_variation=0.02")
    args = parser.parse_args(argv)
    lo, hi = (int(x) for x in args.seeds.split("-"))
    gear = {k: float(v) for k, v in (item.split("=") for item in args.gear)}
    cases, ratios = {}, {}
    for sc in scenarios(args.order2_share, gear):
        rows, ratio = [], []
        for seed in range(lo, hi + 1):
            sim = simulate(sc, seed, args.condition)
            rows.append(spectrum.order_windows(sim.log).bands())
            ratio.append(gear_over_ripple(sim))
        cases[sc.name], ratios[sc.name] = np.array(rows), np.array(ratio)
    print(f"seeds {lo}-{hi}, {args.condition}, order2_share {args.order2_share or 'default'}, gear {gear or '-'}:")
    print(fraction_sentence(cases))
    print("the gear's order-2 torque over the strain's order-4 line, per band (median / max over devices), "
          "and on the devices where order 4 is NOT the largest line (min):")
    for name, ratio in ratios.items():
        tops = np.array([spectrum.largest_order(b) for b in cases[name]])
        parts = []
        for i, band in enumerate(spectrum.SPEED_BANDS):
            seen = ~np.isnan(ratio[:, i])
            if seen.any():
                lost = seen & (tops[:, i] != 4)
                parts.append(f"{band[0]:g}-{band[1]:g} rev/s {np.median(ratio[seen, i]):.2f} / {ratio[seen, i].max():.2f}"
                             + (f" (lost from {ratio[lost, i].min():.2f})" if lost.any() else ""))
        print(f"  `{name}`: " + "; ".join(parts))


if __name__ == "__main__":
    main()
