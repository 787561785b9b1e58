"""Scenario files: the built-ins load, bad files are refused with one clear line."""

import numpy as np
import pytest

from rippleb import InputError, builtin_scenarios, load_scenario, scored_scenarios
from rippleb.simulator.scenario import scenario_from_dict

EXPECTED = {"paper-quintic", "stop-restart", "reversal", "creep", "speed-sweep",
            "load-steps", "static-contact", "torque-chirp", "calibration"}


def test_builtins_are_the_design_names_and_calibration_is_not_scored():
    assert set(builtin_scenarios()) == EXPECTED
    assert builtin_scenarios() == sorted(builtin_scenarios())
    assert set(scored_scenarios()) == EXPECTED - {"calibration"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_builtin_is_short_described_and_in_range(name):
    sc = load_scenario(name)
    assert sc.name == name and sc.description
    # scored scenarios stay short so a full benchmark is quick; calibration is simulated
    # once per device and sweeps several speeds down to creep, so it may be longer
    assert 0 < sc.duration <= (8.0 if sc.scored else 16.5)
    start, stop = sc.evaluation
    assert 0 <= start < stop <= sc.duration


def test_a_path_loads_like_a_name(tmp_path):
    src = load_scenario("paper-quintic").path
    copy = tmp_path / "mine.toml"
    copy.write_text(open(src).read())
    sc = load_scenario(copy)
    assert sc.name == "mine" and sc.duration == load_scenario("paper-quintic").duration


def test_paper_quintic_trajectory_is_a_rest_to_rest_quintic():
    sc = load_scenario("paper-quintic")
    t = np.linspace(0, sc.duration, 4001)
    q, qd, qdd = sc.trajectory(t)
    assert q[0] == pytest.approx(-2.2) and q[-1] == pytest.approx(-0.9)
    assert np.all(qd[t < 0.16] == 0) and np.all(qd[t > 3.79] == 0)
    # The analytic velocity is the derivative of the position.
    assert np.allclose(np.gradient(q, t), qd, atol=2e-3)
    assert np.allclose(np.gradient(qd, t), qdd, atol=2e-2)


def test_reversal_crosses_zero_velocity_without_a_hold():
    sc = load_scenario("reversal")
    t = np.arange(0, sc.duration, 1e-4)
    _, qd, _ = sc.trajectory(t)
    inner = (t > 0.6) & (t < 3.0)
    crossings = np.flatnonzero(np.diff(np.sign(qd[inner])) != 0)
    assert len(crossings) >= 3
    assert np.count_nonzero(qd[inner] == 0) == 0


BASE = {"trajectory": {"segment": [{"kind": "move", "by": 0.1, "duration": 0.5}]}}


def _bad(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_scenario(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message
    return message


GOOD = '[[trajectory.segment]]\nkind = "move"\nby = 0.1\nduration = 0.5\n'
CHIRP = '[[load]]\nkind = "chirp"\namplitude = 8.0\nf0 = 0.5\nf1 = 80.0\nstart = 0.1\nstop = 0.4\n'


@pytest.mark.parametrize("text, key, words", [
    ("this is = not toml [", "", "not valid TOML"),
    ("duraton = 2.0\n" + GOOD, "duraton", "duration"),
    ("[joint]\nfs = -1.0\n" + GOOD, "joint.fs", "positive"),
    ("[joint]\ngear_ratio = 0\n" + GOOD, "joint.gear_ratio", "positive"),
    ("[joint]\ncounts_per_rev = 0\n" + GOOD, "joint.counts_per_rev", "positive"),
    ("[joint]\ncounts_per_rev = 2.5\n" + GOOD, "joint.counts_per_rev", "integer"),
    ("duration = \"long\"\n" + GOOD, "duration", "number"),
    ("scored = 1\n" + GOOD, "scored", "true or false"),
    ("[robot]\nname = \"ur55\"\n" + GOOD, "robot.name", "ur5"),
    ("[robot]\njoint = \"elbow\"\n" + GOOD, "robot.joint", "elbow_joint"),
    ("[robot]\nposture = { knee = 1.0 }\n" + GOOD, "robot.posture.knee", "held joint"),
    (GOOD + '[[trajectory.segment]]\nkind = "hold"\nduration = -0.1\n',
     "trajectory.segment[1].duration", ">= 0"),
    (GOOD + '[[trajectory.segment]]\nkind = "jump"\nduration = 0.1\n',
     "trajectory.segment[1].kind", "hold, move"),
    (GOOD + '[[trajectory.segment]]\nkind = "move"\nduration = 0.1\n',
     "trajectory.segment[1]", "exactly one of to, by"),
    ('[[trajectory.segment]]\nkind = "ramp"\nvelocity = 0.1\nduration = 0.2\n'
     '[[trajectory.segment]]\nkind = "hold"\nduration = 0.1\n',
     "trajectory.segment[1].kind", "ramp to velocity = 0"),
    (GOOD + "[[load]]\ntorque = 1.0\n", "load[0].start", "missing"),
    (GOOD + "[evaluation]\nstart = 2.0\nstop = 1.0\n", "evaluation", "start < stop"),
    (GOOD + CHIRP.replace("f1 = 80.0\n", ""), "load[0].f1", "missing"),
    (GOOD + CHIRP.replace("f1 = 80.0", "f1 = 0.4"), "load[0].f1", "above f0"),
    (GOOD + CHIRP.replace("f0 = 0.5", "f0 = 0.0"), "load[0].f0", "positive"),
    (GOOD + CHIRP.replace("f1 = 80.0", "f1 = 2000.0"), "load[0].f1", "at most"),
    (GOOD + CHIRP.replace("amplitude", "torque"), "load[0].torque", "not used by a chirp"),
    (GOOD + CHIRP.replace("amplitude = 8.0", "amplitude = 900.0"), "load[0].amplitude", "break"),
    (GOOD + CHIRP.replace('"chirp"', '"sine"'), "load[0].kind", "step, chirp"),
    (GOOD + "[[load]]\ntorque = 1.0\nstart = 0.1\nf0 = 2.0\n", "load[0].f0", "not used by a step"),
    ("[ripple]\nhysteresis = 1.0\n" + GOOD, "ripple.hysteresis", "hysteresis_nm"),
    ("[ripple]\nhysteresis_nm = -1.0\n" + GOOD, "ripple.hysteresis_nm", "in [0"),
    ("[ripple]\noutput_scale = 11\n" + GOOD, "ripple.output_scale", "in [0, 10]"),
    ("temperature_c = 150.0\n[ripple]\ntemperature_coeff = -0.01\n" + GOOD, "ripple.temperature_coeff",
     "negative"),
])
def test_bad_files_are_refused_with_file_and_key(tmp_path, text, key, words):
    message = _bad(tmp_path, text)
    if key:
        assert f": {key}:" in message, message
    assert words in message, message


def test_unknown_key_names_the_close_valid_ones(tmp_path):
    message = _bad(tmp_path, "[robot]\njiont = \"elbow_joint\"\n" + GOOD)
    assert "robot.jiont" in message and "joint" in message


def test_unknown_builtin_name_suggests_close_names():
    with pytest.raises(InputError, match="paper-quintic"):
        load_scenario("paper-quintik")


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no such"):
        load_scenario(tmp_path / "nope.toml")


def test_scenario_from_dict_is_checked_too():
    with pytest.raises(InputError, match="<x>: trajectory.segment: needs"):
        scenario_from_dict({"trajectory": {"segment": []}}, name="x")
    assert scenario_from_dict(BASE).duration == pytest.approx(0.5)


def test_chirp_sweeps_log_frequency_from_f0_to_f1_and_fades_out():
    sc = load_scenario("torque-chirp")
    chirp = sc.loads[0]
    assert chirp.kind == "chirp" and chirp.known and (chirp.f0, chirp.f1) == (0.5, 80.0)
    span = chirp.stop - chirp.start
    for s in (0.1, 0.5, 0.9):
        t = chirp.start + s * span
        dt = 1e-6
        freq = (chirp.chirp_phase(t + dt) - chirp.chirp_phase(t - dt)) / (2 * dt) / (2 * np.pi)
        assert freq == pytest.approx(chirp.f0 * (chirp.f1 / chirp.f0) ** s, rel=1e-6)
    t = np.linspace(chirp.start + chirp.rise, chirp.stop, 200_001)
    assert np.max(np.abs(chirp.evaluate(t))) == pytest.approx(chirp.torque, rel=1e-3)
    assert chirp.evaluate(np.array([chirp.start - 0.01, chirp.stop + chirp.rise + 0.01])).tolist() == [0, 0]


def test_torque_chirp_excites_at_rest_and_in_motion_and_is_known():
    sc = load_scenario("torque-chirp")
    windows = sc.chirp_windows()
    assert len(windows) == 2 and sc.scored
    _, qd, _ = sc.trajectory(np.linspace(*windows[0], 1000))
    assert not qd.any()                        # the first sweep runs at rest
    _, qd, _ = sc.trajectory(np.linspace(*windows[1], 1000))
    assert np.all(qd == pytest.approx(0.3))    # the second while cruising
    t = np.linspace(0, sc.duration, 10_000)
    assert np.array_equal(sc.external_torque(t), sc.external_torque(t, known_only=True))
    assert sc.chirp_bands().tolist() == [[0.5, 80.0], [0.5, 80.0]]


def test_step_edges_are_the_on_and_off_edges_of_step_loads():
    edges = load_scenario("load-steps").step_edges()
    assert edges[:, 0].tolist() == [0.8, 1.5, 1.7, 2.2, 2.8, 3.5]
    assert edges[:, 2].tolist() == [15.0, -15.0, -10.0, 10.0, 12.0, -12.0]
    assert load_scenario("torque-chirp").step_edges().shape == (0, 3)


def test_ripple_table_sets_the_drive_ripple_and_defaults_are_documented():
    from rippleb.simulator.scenario import HYSTERESIS_NM, RippleSettings

    assert load_scenario("paper-quintic").ripple == RippleSettings()
    assert RippleSettings().hysteresis_nm == HYSTERESIS_NM and RippleSettings().output_scale == 1.0
    sc = scenario_from_dict({**BASE, "ripple": {"output_scale": 0, "hysteresis_nm": 1.5,
                                                "temperature_coeff": 0.002}})
    assert sc.ripple == RippleSettings(output_scale=0.0, hysteresis_nm=1.5, temperature_coeff=0.002)
