"""Simulator speed: every built-in scenario, the robot model load, and linear scaling.

Run with ``python -m pytest benchmarks/bench_simulator.py --benchmark-enable -s``.

Each scenario's simulation (seed 0, the robot model already loaded) is reported with its
samples per second of simulated log and, as a yardstick measured in the same run, next to
one ``scipy.signal.lfilter`` pass (2nd order) over a log of the same length: on a loaded
machine the ratio holds where the absolute time does not.
"""

import time

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np
import pytest
from scipy import signal

from rippleb import builtin_scenarios, load_scenario, simulate
from rippleb.simulator import robot
from rippleb.simulator.scenario import scenario_from_dict


def _lfilter_seconds(n: int, fs: float) -> float:
    """Best of three ``lfilter`` passes over ``n`` samples [s]."""
    b, a = signal.butter(2, 130.0, fs=fs)
    x = np.random.default_rng(0).normal(size=n)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        signal.lfilter(b, a, x)
        best = min(best, time.perf_counter() - t0)
    return best


@pytest.mark.parametrize("name", builtin_scenarios())
def test_every_scenario(benchmark, name):
    scenario = load_scenario(name)
    simulate(scenario, 0)                       # the robot model, loaded once per process
    t0 = time.perf_counter()
    sim = benchmark.pedantic(simulate, args=(scenario, 0), rounds=3, iterations=1)
    elapsed = time.perf_counter() - t0              # one round when benchmarks are disabled
    n = len(sim.log)
    seconds = benchmark.stats.stats.median if benchmark.stats else elapsed
    yardstick = _lfilter_seconds(n, scenario.spec.fs)
    benchmark.extra_info.update(samples=n, msamples_per_s=round(n / seconds / 1e6, 3),
                                over_one_lfilter_pass=round(seconds / yardstick, 1))
    print(f"\n{name}: {n} samples in {seconds * 1e3:.0f} ms, {n / seconds / 1e6:.2f} M samples/s, "
          f"{seconds / yardstick:.0f}x one lfilter pass over the same length")
    assert n == int(round(scenario.duration * scenario.spec.fs))


def _cold_paper_quintic():
    # A fresh process-level cache: the URDF is parsed and the model built every round.
    robot.load_model.cache_clear()
    return simulate(load_scenario("paper-quintic"), 0)


def test_paper_quintic_cold(benchmark):
    sim = benchmark(_cold_paper_quintic)
    assert len(sim.log) == 80_000


def _cruise(seconds: float):
    """A constant-speed run of ``seconds`` plus fixed ramps, scaled 1x/4x/16x."""
    return scenario_from_dict({"trajectory": {"start": -2.0, "segment": [
        {"kind": "ramp", "velocity": 0.05, "duration": 0.1},
        {"kind": "cruise", "duration": seconds - 0.1}]}}, name="scaling")


@pytest.mark.parametrize("factor", [1, 4, 16])
def test_scaling_with_duration(benchmark, factor):
    scenario = _cruise(2.0 * factor)
    benchmark.extra_info["samples"] = int(2.0 * factor * scenario.spec.fs)
    sim = benchmark(simulate, scenario, 0)
    assert len(sim.log) == int(round(2.0 * factor * scenario.spec.fs))


def _kernel_inputs(seconds: float):
    """The closed-loop joint's integrator inputs for the first ``seconds`` of paper-quintic."""
    from rippleb.simulator import Device, controller, joint

    sc = load_scenario("paper-quintic")
    spec, device = sc.spec, Device.from_seed(0)
    t = np.arange(int(round(seconds * spec.fs))) / spec.fs
    traj = sc.trajectory(t)
    table = joint.load_table(sc, sc.trajectory(np.arange(int(sc.duration * spec.fs)) / spec.fs)[0])
    gains = controller.design_gains(spec, float(np.mean(table.inertia)))
    tau_ref = table.model_torque(traj[0], traj[2])
    ref = controller.reference(spec, t, *traj, tau_ref, device.encoder_zero)
    params = joint.pack_params(**controller.motor_params(device, sc.temperature_c, spec),
                               **controller.loop_params(spec, gains, table))
    inputs = np.ascontiguousarray(np.vstack([np.zeros_like(t), ref]))
    state0 = controller.initial_state(spec, gains, table, traj[0][0], 0.0, 0.0, ref[:, 0], device.encoder_zero)
    return params, controller.table_rows(table), inputs, state0, np.empty((6, len(t)))


def test_compiled_kernel_pays():
    """The joint's per-sample loop compiled (numba, cached on disk) against the same loop
    body run by the interpreter (its helpers stay compiled: a lower bound of the gain), and the cost of loading the compiled kernels in a fresh
    process (what every ``rippleb simulate`` pays on top of the simulation)."""
    import subprocess
    import sys

    from rippleb.simulator import joint

    args = _kernel_inputs(0.2)
    t0 = time.perf_counter()
    joint.integrate.py_func(*args)
    python = time.perf_counter() - t0
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        joint.integrate(*args)
        best = min(best, time.perf_counter() - t0)
    # -X importtime: the joint module's own import time is loading its cached kernels
    report = subprocess.run([sys.executable, "-X", "importtime", "-c", "import rippleb"], capture_output=True,
                            text=True, check=True).stderr.splitlines()
    own = [int(line.split("|")[0].split(":")[1]) for line in report if line.rstrip().endswith(" rippleb.simulator.joint")]
    load = own[0] * 1e-6
    n = args[2].shape[1]
    print(f"\njoint kernel over {n} samples: interpreted {python * 1e3:.0f} ms, compiled {best * 1e3:.2f} ms "
          f"({python / best:.0f}x); loading the joint's compiled kernels in a fresh process {load * 1e3:.0f} ms; "
          f"the compiled loop over 4 s of paper-quintic would cost "
          f"{best * 20 * 1e3:.0f} ms, the interpreted one {python * 20:.1f} s")
    assert python > best
