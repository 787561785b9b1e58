"""The physics the benchmark rests on: the paper's Fig. 2, rest, restart, load, friction."""

import numpy as np
import pytest

from rippleb import load_scenario, simulate
from rippleb.simulator.scenario import scenario_from_dict
from rippleb.simulator import Device

SPEEDS_WG = (1.0, 3.0, 6.0)  # wave-generator revolutions per second
RIPPLE_ORDERS = (2, 4, 8)


def constant_speed(wg_rev_per_s: float, cruise: float, load: float = 20.0):
    """Shoulder pan (no gravity) at constant speed under a known constant load."""
    joint_speed = wg_rev_per_s * 2 * np.pi / 100.0
    return scenario_from_dict({
        "robot": {"joint": "shoulder_pan_joint"},
        "trajectory": {"segment": [
            {"kind": "ramp", "velocity": joint_speed, "duration": 0.2},
            {"kind": "cruise", "duration": cruise}]},
        "load": [{"torque": load, "start": 0.0, "rise": 0.05, "known": True}],
    }, name=f"const-{wg_rev_per_s}")


def _floor(x, amps, base):
    """Median amplitude away from every multiple of ``base`` (between the ripple lines)."""
    phase = x / base
    between = (np.abs(phase - np.round(phase)) > 0.3) & (x > 0.5 * base) & (x < 12 * base)
    return np.median(amps[between])


def _peak(freqs, amps, target, tol):
    near = np.abs(freqs - target) <= tol
    return amps[near].max()


def _amplitude_spectrum(x):
    x = (x - x.mean()) * np.hanning(len(x))
    return 2 * np.abs(np.fft.rfft(x)) / np.hanning(len(x)).sum()


def _time_spectrum(sim, start):
    log = sim.log
    sel = log.t >= start
    return np.fft.rfftfreq(sel.sum(), 1 / log.spec.fs), _amplitude_spectrum(log.strain[sel])


def _angle_spectrum(sim, start, revs):
    """Strain re-sampled where the encoder count changes, on whole revolutions."""
    log = sim.log
    sel = np.flatnonzero(log.t >= start)
    enc, strain = log.encoder[sel], log.strain[sel]
    edge = np.flatnonzero(np.diff(enc)) + 1
    cpr = log.spec.counts_per_rev
    angle, value = enc[edge] / cpr, strain[edge]          # in revolutions
    grid = angle[0] + np.arange(int(revs * cpr)) / cpr
    resampled = np.interp(grid, angle, value)
    orders = np.fft.rfftfreq(len(grid), 1 / cpr)
    return orders, _amplitude_spectrum(resampled)


@pytest.mark.parametrize("seed", [0, 1])
def test_fig2_time_peaks_move_with_speed_angle_peaks_do_not(seed):
    for wg in SPEEDS_WG:
        sim = simulate(constant_speed(wg, cruise=max(1.5, 6.0 / wg)), seed)
        freqs, amps = _time_spectrum(sim, start=0.3)
        floor = _floor(freqs, amps, wg)
        time_peaks = {k: _peak(freqs, amps, k * wg, 0.1 * wg) for k in RIPPLE_ORDERS}
        for k, peak in time_peaks.items():
            assert peak > 10 * floor, (wg, k, peak, floor)
        band = (freqs > 1.5 * wg) & (freqs < 12 * wg)
        assert abs(freqs[band][np.argmax(amps[band])] - 4 * wg) <= 0.1 * wg

        orders, oamps = _angle_spectrum(sim, start=0.3, revs=5)
        ofloor = _floor(orders, oamps, 1.0)
        for k in RIPPLE_ORDERS:
            assert _peak(orders, oamps, k, 0.05) > 10 * ofloor, (wg, k)
        oband = (orders > 1.5) & (orders < 12)
        assert orders[oband][np.argmax(oamps[oband])] == pytest.approx(4.0, abs=0.05)


def test_ripple_is_a_constant_offset_at_rest_and_continues_after_restart():
    sc = scenario_from_dict({
        "robot": {"joint": "shoulder_pan_joint"},
        "trajectory": {"segment": [
            {"kind": "move", "by": 0.2, "duration": 0.5},
            {"kind": "hold", "duration": 0.5},
            {"kind": "move", "by": 0.2, "duration": 0.5}]},
        "load": [{"torque": 15.0, "start": 0.0, "rise": 0.05, "known": True}],
    }, name="rest")
    sim = simulate(sc, 3)
    dev, log = sim.gauges[0], sim.log          # the device as its one bridge reads it
    ripple = dev.ripple(sim.wave_angle, log.torque_true)
    # The closed loop settles in about 4 / (zeta w_c) after the stop (docs/physics.md,
    # "Joint dynamics and position controller"); then the motor creeps by a count or two
    # against its friction while the PD trims the last position error.
    rest = (log.t > 0.8) & (log.t < 0.99)
    assert np.ptp(log.encoder[rest]) <= 3
    assert np.ptp(ripple[rest]) < 0.05
    assert abs(ripple[rest].mean()) > 1e-3          # a real offset, not zero
    # The strain at rest is the torque plus that frozen ripple, up to noise and drift.
    gap = log.strain[rest] / dev.gain - log.torque_true[rest] - ripple[rest]
    assert np.std(gap) < 0.03
    # After the restart the ripple starts from the stop's value: same angle, same load.
    moving_again = np.flatnonzero(log.t >= 1.0)[0]
    assert ripple[moving_again] == pytest.approx(ripple[rest][-1], abs=0.02)
    assert np.ptp(ripple[moving_again:]) > 0.3


def test_paper_quintic_matches_the_paper_timing_and_stays_within_rated_torque():
    sim = simulate("paper-quintic", 0)
    log = sim.log
    moving_t = log.t[sim.moving]
    assert moving_t[0] == pytest.approx(0.16, abs=1e-3)
    assert moving_t[-1] == pytest.approx(3.79, abs=1e-3)
    assert np.abs(log.torque_true).max() < log.spec.rated_torque
    assert np.abs(log.torque_ref).max() < log.spec.rated_torque
    # The model torque misses only the unmodelled bearing friction and the nominal
    # model's error here.
    assert np.sqrt(np.mean((log.torque_true - log.torque_ref) ** 2)) < 1.0


def test_friction_differs_between_calibration_and_evaluation_temperature():
    cal, ev = load_scenario("calibration"), load_scenario("paper-quintic")
    assert cal.temperature_c != ev.temperature_c
    dev = Device.from_seed(0)
    w = np.linspace(-100, 100, 201)
    tau = np.full_like(w, 20.0)
    f_cal = dev.motor_friction(w, tau, np.zeros_like(w), cal.temperature_c, 100.0)
    f_ev = dev.motor_friction(w, tau, np.zeros_like(w), ev.temperature_c, 100.0)
    # Warm lubricant: less friction, by a few percent (Coulomb) to tens of percent (viscous).
    assert np.all(np.abs(f_ev[w != 0]) < np.abs(f_cal[w != 0]))
    assert np.abs(f_cal - f_ev).max() > 0.005


def test_current_carries_the_load_through_the_gear():
    sim = simulate("paper-quintic", 0)
    log, spec = sim.log, sim.log.spec
    rest = ~sim.moving & (log.t > 3.85)
    # At rest the friction sign is undetermined only within tanh smoothing; the current
    # must still follow tau / N / K_t up to friction, cogging and offset.
    expected = log.torque_true[rest] / spec.gear_ratio / spec.torque_constant
    assert np.abs(np.median(log.current[rest] - expected)) < 1.0


def test_load_table_matches_rnea():
    import pinocchio as pin

    from rippleb.simulator import robot

    table = robot.load_table("ur5", "shoulder_lift_joint", {"elbow_joint": 1.5}, (-2.2, -0.9))
    model = robot.load_model("ur5")
    data = model.createData()
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(50):
        q = pin.neutral(model)
        q[2] = 1.5
        q[1] = rng.uniform(-2.2, -0.9)
        v, a = np.zeros(6), np.zeros(6)
        v[1], a[1] = rng.uniform(-1, 1), rng.uniform(-3, 3)
        exact = pin.rnea(model, data, q, v, a)[1]
        approx = table.torque(np.array([q[1]]), np.array([v[1]]), np.array([a[1]]))[0]
        worst = max(worst, abs(exact - approx))
    assert worst < 1e-3


def test_fig2_replica_is_written_as_png(tmp_path):
    from rippleb.report.figures import plot_order_spectra, speed_spectra

    out = plot_order_spectra(tmp_path / "fig2.png", seed=0, speeds=(1.0, 4.0), revolutions=4)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    sp = speed_spectra(4.0, seed=0, revolutions=4)
    top = sp.order[(sp.order > 1.5)][np.argmax(sp.angle_amp[sp.order > 1.5])]
    assert top == pytest.approx(4.0)
