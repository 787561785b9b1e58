"""What sets Table I's maximum errors on ``paper-quintic`` (issue 38, item 6).

The paper scores current-based and order-tracking against the model torque of its eq. (7)
"during the motion" (0.16-3.79 s): max 8.2 and 4.8 Nm, a ratio of 58 %. This re-simulates
the devices, streams both methods as the runner does (``rippleb.report.plotting``) and
splits each method's largest error against ``torque_ref`` during the motion into what the
reference itself misses of the true torque (``torque_ref - torque_true``: the nominal model,
bearing friction, the joint's dynamics, the gear's torque) and the method's own error
against the true torque, with where in the move each maximum falls::

    python benchmarks/table_one_max.py --seeds 0-9
"""

from __future__ import annotations

import argparse

import numpy as np

from rippleb.report.plotting import fit_methods, stream_methods

METHODS = ("current-based", "order-tracking")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-9", help="A-B, inclusive")
    args = parser.parse_args(argv)
    lo, hi = (int(x) for x in args.seeds.split("-"))
    rows = []
    for seed in range(lo, hi + 1):
        fitted, errors = fit_methods(list(METHODS), seed)
        if errors:
            raise SystemExit(f"seed {seed}: fit failed: {errors}")
        sig = stream_methods(fitted, "paper-quintic", seed)
        log, sim = sig.sim.log, sig.sim
        motion = np.asarray(sim.eval_mask & sim.moving, bool)
        t = log.t[motion]
        floor = log.torque_ref[motion] - log.torque_true[motion]
        row = {"seed": seed, "ref_floor_max": float(np.abs(floor).max()),
               "ref_floor_at": float(t[np.argmax(np.abs(floor))])}
        for name in METHODS:
            est = sig.estimates[name][motion]
            err_ref = est - log.torque_ref[motion]
            err_true = est - log.torque_true[motion]
            i = int(np.argmax(np.abs(err_ref)))
            row[name] = (float(np.abs(err_ref).max()), float(t[i]), float(np.abs(err_true).max()),
                         float(err_true[i]), float(-floor[i]))
        rows.append(row)
        cur, order = row["current-based"], row["order-tracking"]
        print(f"seed {seed}: torque_ref - torque_true max {row['ref_floor_max']:.2f} Nm at {row['ref_floor_at']:.2f} s | "
              f"current-based max {cur[0]:.2f} at {cur[1]:.2f} s (own error there {cur[3]:+.2f}, reference's "
              f"{cur[4]:+.2f}; own max {cur[2]:.2f}) | order-tracking max {order[0]:.2f} at {order[1]:.2f} s "
              f"(own {order[3]:+.2f}, reference's {order[4]:+.2f}; own max {order[2]:.2f}) | ratio "
              f"{100 * order[0] / cur[0]:.0f} %", flush=True)
    mean = lambda key, k: float(np.mean([r[key][k] for r in rows]))  # noqa: E731
    print(f"mean over {len(rows)} devices: torque_ref - torque_true max {np.mean([r['ref_floor_max'] for r in rows]):.2f} Nm; "
          f"current-based max {mean('current-based', 0):.2f} Nm (own max vs torque_true {mean('current-based', 2):.2f}); "
          f"order-tracking max {mean('order-tracking', 0):.2f} Nm (own max vs torque_true {mean('order-tracking', 2):.2f}); "
          f"ratio of the means {100 * mean('order-tracking', 0) / mean('current-based', 0):.0f} % (paper 4.8 / 8.2 = 58 %)")


if __name__ == "__main__":
    main()
