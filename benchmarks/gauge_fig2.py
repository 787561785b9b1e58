"""The paper's Fig. 2 from the gauges' geometry: which order is the strain's largest line, per
band of wave-generator speed, over a population of devices (docs/physics.md, "Gauges on the
flexspline").

Each device (seeds 2000-2029, never used by the tests) turns the wave generator at a
constant 1, 3, 6 and 10 rev/s (the shoulder pan joint, no gravity, a known 20 Nm load) for
at least six revolutions. The amplitude of each order 1-10 of the encoder angle in the
strain (not the strain less the torque: what a spectrum of the strain shows, the gear's
real torque at the wave-generator orders included) comes from least squares over whole
revolutions of the cruise; the table gives, per variant and speed, the fraction of devices
whose largest line is order 4, and the median amplitude of orders 2, 4 and 8 [Nm].

Variants: ``drawn`` (the earlier simulator's bridge, with the gear's transmission error as
in every condition), ``paper, ideal gear`` (the geometry alone) and ``paper`` (the default:
geometry and gear). Run: ``python benchmarks/gauge_fig2.py [N_DEVICES]`` (30 devices: some
10 minutes on a loaded 2-core machine). When the spectrum function of issue 38 lands, the
measure here should be that function's.
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import dataclasses
import sys

import numpy as np

from rippleb.dsp import encoder_angle
from rippleb.layouts import GaugeSettings
from rippleb.simulator.scenario import scenario_from_dict
from rippleb.simulator import simulate

SEEDS_FROM = 2000
SPEEDS_REV_S = (1.0, 3.0, 6.0, 10.0)
ORDERS = tuple(range(1, 11))
VARIANTS = {"drawn": ("drawn", None), "paper, ideal gear": ("paper", 0.0), "paper": ("paper", None)}


def cruise(rev_s: float):
    joint_speed = rev_s * 2 * np.pi / 100.0
    return scenario_from_dict({
        "robot": {"joint": "shoulder_pan_joint"},
        "trajectory": {"segment": [{"kind": "ramp", "velocity": joint_speed, "duration": 0.2},
                                   {"kind": "cruise", "duration": max(1.0, 6.5 / rev_s)}]},
        "load": [{"torque": 20.0, "start": 0.0, "rise": 0.05, "known": True}],
    }, name=f"fig2-{rev_s:g}")


def order_amplitudes(sim) -> np.ndarray:
    """Amplitude [Nm] of each of :data:`ORDERS` in the strain over whole revolutions of the cruise."""
    log = sim.log
    angle = encoder_angle(log.encoder, log.spec.counts_per_rev)
    start = np.flatnonzero(log.t >= 0.3)[0]
    turns = (angle - angle[start]) / (2 * np.pi)
    keep = (log.t >= 0.3) & (turns < np.floor(turns[-1]))
    design = np.column_stack([np.ones(keep.sum()), log.t[keep]]
                             + [f(k * angle[keep]) for k in ORDERS for f in (np.cos, np.sin)])
    coef = np.linalg.lstsq(design, log.strain[keep], rcond=None)[0]
    return np.hypot(coef[2::2], coef[3::2]) / np.mean([d.gain for d in sim.gauges])


if __name__ == "__main__":
    devices = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    print(f"devices {SEEDS_FROM}-{SEEDS_FROM + devices - 1}\n")
    print("| variant | WG speed [rev/s] | order 4 largest | else largest | median order 2 | median order 4 | "
          "median order 8 |\n|---|---:|---:|---|---:|---:|---:|")
    for variant, (name, gear) in VARIANTS.items():
        for rev_s in SPEEDS_REV_S:
            base = dataclasses.replace(cruise(rev_s), gauges=GaugeSettings(layout=name))
            if gear is not None:
                base = dataclasses.replace(base, transmission_error=gear)
            amps = np.array([order_amplitudes(simulate(base, seed))
                             for seed in range(SEEDS_FROM, SEEDS_FROM + devices)])
            largest = np.asarray(ORDERS)[np.argmax(amps, axis=1)]
            others = ", ".join(f"{o}: {np.sum(largest == o)}" for o in sorted(set(largest) - {4}))
            print(f"| {variant} | {rev_s:g} | {np.mean(largest == 4):.0%} | {others or '-'} | "
                  + " | ".join(f"{np.median(amps[:, ORDERS.index(o)]):.3f}" for o in (2, 4, 8)) + " |")
