"""Scenario files: the built-ins load, bad files are refused with one clear line."""

import numpy as np
import pytest

from rippleb import InputError, builtin_scenarios, load_scenario, scored_scenarios
from rippleb.scenario import scenario_from_dict

EXPECTED = {"paper-quintic", "stop-restart", "reversal", "creep", "speed-sweep",
            "load-steps", "static-contact", "calibration"}


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
