"""Issue 32 items 1-2, unit level: the joint description (joint.toml, a log's sidecar), the
time base (units, epoch, mean rate, jitter, resampling) and the rules that keep a row of a
recorded log that cannot be scored right from being ``ok``."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rippleb import InputError, JointSpec, read_log
from rippleb.joint_file import description_for, load_joint
from rippleb.scoring.metrics import Truth
from rippleb.scoring.scorable import NO_REFERENCE, implausible
from rippleb.timebase import check_steps, resample, sample_periods, to_seconds, uniform_rate
from rippleb.scoring.row import score_or_invalid

FS = 20_000.0


def _frame(n: int = 400) -> pd.DataFrame:
    t = np.arange(n) / FS
    return pd.DataFrame({"t": t, "strain": 0.1 * np.sin(t), "encoder": np.arange(n) // 4,
                         "current": 0.01 * np.cos(t), "torque_ref": np.sin(t)})


def _joint(tmp_path, text: str, name: str = "joint.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


LAB = """[joint]
counts_per_rev = 16384
gear_ratio = 80.0
rated_torque = 30
[joint.columns]
t = {column = "t_ms", unit = "ms"}
strain = {column = "strain_mV", unit = "mV"}
encoder = "enc_counts"
current = {column = "i_mA", scale = 0.001}
"""


def test_a_joint_file_renames_scales_and_sets_the_spec(tmp_path):
    frame = _frame()
    lab = pd.DataFrame({"t_ms": frame.t * 1e3, "strain_mV": frame.strain * 1e3,
                        "enc_counts": frame.encoder, "i_mA": frame.current * 1e3})
    lab.to_csv(tmp_path / "rec.csv", index=False)
    log = read_log(tmp_path / "rec.csv", joint=_joint(tmp_path, LAB))
    assert (log.spec.counts_per_rev, log.spec.gear_ratio, log.spec.rated_torque) == (16384, 80.0, 30.0)
    assert log.spec.fs == pytest.approx(FS)
    np.testing.assert_allclose(log.t, frame.t, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(log.strain, frame.strain, rtol=1e-12)
    np.testing.assert_allclose(log.current, frame.current, rtol=1e-12)
    np.testing.assert_array_equal(log.encoder, frame.encoder)
    said = "\n".join(log.meta["joint"])
    assert "counts_per_rev = 16384 (given in" in said
    assert "torque_constant = 0.07 (ASSUMED" in said
    assert "column strain = 'strain_mV' in mV (given in" in said


def test_without_a_joint_file_every_value_is_said_to_be_assumed(tmp_path):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    said = "\n".join(read_log(tmp_path / "rec.csv").meta["joint"])
    assert "counts_per_rev = 2500 (ASSUMED (rippleb's default); not checked: the log has no index pulse" in said
    assert "column strain = 'strain' in V (ASSUMED" in said
    assert "index_pulse = false (ASSUMED" in said
    given = "\n".join(read_log(tmp_path / "rec.csv", spec=JointSpec(counts_per_rev=16384)).meta["joint"])
    assert "counts_per_rev = 16384 (given as read_log's spec;" in given and "(ASSUMED (rippleb's default)" not in given


def test_a_sidecar_overrides_the_joint_file_key_by_key(tmp_path):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    given = load_joint(_joint(tmp_path, "[joint]\ncounts_per_rev = 4096\ngear_ratio = 50.0\n"))
    _joint(tmp_path, "[bench]\nnote = 'ours'\n[joint]\ncounts_per_rev = 8192\n", "rec.toml")
    joint = description_for(tmp_path / "rec.csv", given)
    assert joint.values == {"counts_per_rev": 8192, "gear_ratio": 50.0}
    assert joint.sources["counts_per_rev"].endswith("rec.toml")
    assert read_log(tmp_path / "rec.csv", joint=given).spec.counts_per_rev == 8192


#: text of joint.toml -> what the one line says after the file name
BAD_JOINTS = {
    "[joint]\ncount_per_rev = 4096\n": "joint.count_per_rev: unknown key",
    "[joint]\ncounts_per_rev = 4096.5\n": "joint.counts_per_rev: must be a whole number",
    "[joint]\ngear_ratio = -1\n": "joint.gear_ratio: must be positive",
    "[joint]\nindex_pulse = 1\n": "joint.index_pulse: must be true or false",
    "[joint.columns]\nstrain = {column = 'strain_mV', unit = 'millivolt'}\n":
        "joint.columns.strain.unit: 'millivolt' is not a unit of strain",
    "[joint.columns]\nt = {column = 'ts', unit = 'hours'}\n": "joint.columns.t.unit: 'hours' is not a unit of t",
    "[joint.columns]\nstrian = 'strain_mV'\n": "joint.columns.strian: unknown column",
    "[joint.columns]\nstrain = {column = 'x', unit = 'mV', scale = 2}\n": "joint.columns.strain: give unit or scale",
    "[joint.columns]\nstrain = {column = 'x', gain = 2}\n": "joint.columns.strain.gain: unknown key",
    "[joint.columns]\nencoder = {column = 'x', scale = 2}\n": "joint.columns.encoder.scale: encoder takes a unit",
    "[other]\nx = 1\n": "other: unknown key",
    "[joint\n": "not valid TOML",
}


@pytest.mark.parametrize("text", list(BAD_JOINTS))
def test_a_bad_joint_file_is_one_line_naming_the_field(tmp_path, text):
    path = _joint(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_joint(path)
    assert str(caught.value).startswith(f"{path}: {BAD_JOINTS[text]}"), str(caught.value)


def test_a_mapped_column_the_log_lacks_is_named(tmp_path):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    path = _joint(tmp_path, "[joint.columns]\nstrain = {column = 'strain_mV', unit = 'mV'}\n")
    with pytest.raises(InputError, match=r"joint.toml: joint.columns.strain: .*rec.csv has no column 'strain_mV'"):
        read_log(tmp_path / "rec.csv", joint=path)


def test_an_index_pulse_promised_but_absent_is_named(tmp_path):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    path = _joint(tmp_path, "[joint]\nindex_pulse = true\n")
    with pytest.raises(InputError, match="joint.index_pulse: true, but .*rec.csv has no index column"):
        read_log(tmp_path / "rec.csv", joint=path)


def test_an_index_pulse_turned_off_is_not_passed_on(tmp_path):
    _frame().assign(index=0).to_csv(tmp_path / "rec.csv", index=False)
    assert read_log(tmp_path / "rec.csv").index is not None
    assert read_log(tmp_path / "rec.csv", joint=_joint(tmp_path, "[joint]\nindex_pulse = false\n")).index is None


def test_epoch_stamps_give_the_rate_they_were_recorded_at(tmp_path):
    """Unix time at 20 kHz: float64 steps alternate 49.8/50.1 us; the median said 19972.9 Hz."""
    frame = _frame(4000)
    frame.assign(t=1.7e9 + frame.t).to_csv(tmp_path / "rec.csv", index=False)
    assert 1 / np.median(np.diff(pd.read_csv(tmp_path / "rec.csv").t)) != pytest.approx(FS, rel=1e-3)
    log = read_log(tmp_path / "rec.csv")
    assert log.spec.fs == pytest.approx(FS, rel=1e-6)
    assert log.t[0] == 0.0 and log.t[-1] == pytest.approx(3999 / FS, rel=1e-6)
    assert any("epoch (assumed" in line for line in log.meta["joint"])


def test_time_units():
    np.testing.assert_allclose(to_seconds(np.array([5.0, 5.5]), "ms"), [5e-3, 5.5e-3])
    np.testing.assert_allclose(to_seconds(np.array([1.7e12, 1.7e12 + 1]), "epoch_ms"), [0.0, 1e-3])


def _jittered(n: int = 20_000, sd: float = 5e-6, seed: int = 1) -> np.ndarray:
    return np.arange(n) / FS + np.random.default_rng(seed).normal(0.0, sd, n)


def test_jitter_is_refused_with_the_resample_hint():
    with pytest.raises(InputError, match=r"timing jitter or a dropped sample; pass --resample .* \(2000\d\.?\d* Hz\)"):
        check_steps(_jittered(), "rec.csv")
    check_steps(_jittered(), "rec.csv", resampling=True)


def test_a_gap_is_refused_even_when_resampling():
    t = np.arange(1000) / FS
    t[500:] += 10 / FS
    with pytest.raises(InputError, match="gap of .* at row 500"):
        check_steps(t, "rec.csv", resampling=True)


def test_dropped_samples_do_not_move_the_rate_and_get_their_grid_points_back():
    """Issue 39: 2 % of isolated dropped samples at 20 kHz read 19 600 Hz; the clock's rate is 20 kHz."""
    t = np.arange(20_000) / FS
    rng = np.random.default_rng(4)
    kept = np.ones(len(t), bool)
    kept[rng.choice(np.arange(1, len(t) - 1, 3), 400, replace=False)] = False   # isolated: never two in a row
    assert uniform_rate(t[kept]) == pytest.approx(FS, rel=1e-12)
    assert (len(t[kept]) - 1) / (t[-1] - t[0]) == pytest.approx(0.98 * FS, rel=1e-3)   # what the mean rate said
    out = resample({"t": t[kept], "strain": 2.0 * t[kept], "encoder": np.arange(len(t))[kept]})
    np.testing.assert_allclose(out["t"], t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["strain"], 2.0 * t, atol=1e-12)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(n=st.integers(3, 400), sd=st.floats(0.0, 8e-6), seed=st.integers(0, 99))
def test_resampling_keeps_span_count_counts_and_pulses(n, sd, seed):
    t = np.sort(_jittered(n, sd, seed))
    if (np.diff(t) <= 0).any():
        return
    encoder = np.cumsum(np.random.default_rng(seed).integers(0, 3, n))
    index = (np.arange(n) % 50 == 7).astype(np.int8)
    out = resample({"t": t, "strain": 2.0 * t, "encoder": encoder, "index": index})
    periods = sample_periods(t)
    assert len(out["t"]) == periods + 1 and out["t"][0] == t[0] and out["t"][-1] == t[-1]
    assert periods == n - 1   # jitter, no dropped sample: every stamp keeps its period
    np.testing.assert_allclose(np.diff(out["t"]), (t[-1] - t[0]) / periods, rtol=1e-6)
    assert uniform_rate(out["t"]) == pytest.approx(uniform_rate(t))
    np.testing.assert_allclose(out["strain"], 2.0 * out["t"], atol=1e-12)   # linear: exact on a line
    assert set(out["encoder"]) <= set(encoder) and (np.diff(out["encoder"]) >= 0).all()
    assert out["index"].sum() == index.sum()


def test_a_resampled_log_reads_at_its_mean_rate(tmp_path):
    frame = _frame(20_000).assign(t=_jittered())
    frame.to_csv(tmp_path / "rec.csv", index=False)
    with pytest.raises(InputError, match="pass --resample"):
        read_log(tmp_path / "rec.csv")
    log = read_log(tmp_path / "rec.csv", resample=True)
    assert log.spec.fs == pytest.approx(FS, rel=1e-4)
    assert np.ptp(np.diff(log.t)) < 1e-9


def _truth(n=100, **kw):
    return Truth(fs=FS, eval_mask=np.ones(n, bool), moving=np.zeros(n, bool), wave_angle=np.zeros(n), **kw)


def test_an_estimate_beyond_the_joints_range_is_not_scored():
    limit = 10 * JointSpec().rated_torque
    assert implausible(np.full(10, limit), limit) == ""
    assert "reaches 511 Nm, beyond 510 Nm" in implausible(np.full(10, limit + 1), limit)
    assert implausible(np.full(10, 1e9), None) == ""   # simulated rows: no limit
    row = score_or_invalid(np.full(100, 600.0), _truth(torque_ref=np.zeros(100), torque_limit=limit))
    assert row["status"] == "invalid" and "strain in mV against V" in row["message"]


def test_a_log_without_reference_is_its_own_status():
    row = score_or_invalid(np.ones(100), _truth(torque_limit=510.0))
    assert row["status"] == NO_REFERENCE and "cannot be scored" in row["message"]
    assert np.isnan(row["rms_error_ref_nm"]) and np.isnan(row["rms_error_nm"])
    assert "status" not in score_or_invalid(np.ones(100), _truth(torque_ref=np.arange(100.0), torque_limit=510.0))


def test_a_calibration_sidecar_that_names_another_joint_is_refused(tmp_path):
    _frame().to_csv(tmp_path / "cal.csv", index=False)
    _joint(tmp_path, "[joint]\ncounts_per_rev = 4096\n", "cal.toml")
    with pytest.raises(InputError, match=r"cal.toml: joint.counts_per_rev: 4096, but .*cal.csv is read with "
                                         r"counts_per_rev = 16384 \(one joint"):
        read_log(tmp_path / "cal.csv", spec=JointSpec(counts_per_rev=16384))
    _joint(tmp_path, "[joint]\ncounts_per_rev = 16384\n", "cal.toml")
    assert read_log(tmp_path / "cal.csv", spec=JointSpec(counts_per_rev=16384)).spec.counts_per_rev == 16384


def test_lab_columns_and_their_joint_file_read_back_as_the_log(tmp_path):
    """What ``rippleb simulate --format lab`` writes reads back, through its joint.toml, as
    the log it came from, its reference named and declared for what it is; a joint.toml that
    says something else is kept and refused."""
    from rippleb import make_log
    from rippleb.log_files import write_columns
    from rippleb.lab_format import joint_toml, lab_columns, write_joint_toml

    frame = _frame(4000)
    log = make_log(JointSpec(counts_per_rev=97), {**frame.to_dict("series"), "index": frame.encoder % 97 == 0,
                                                 "torque_true": frame.torque_ref})
    for kind, column in (("transducer", "torque_sensor_Nm"), ("model", "model_torque_Nm")):
        columns = lab_columns(log, kind)
        assert list(columns) == ["t", "strain_mV", "enc_counts", "i_motor_A", "idx", column]   # no truth
        write_columns(columns, tmp_path / f"{kind}.csv")
        (tmp_path / kind).mkdir()
        joint = write_joint_toml(joint_toml(log.spec, True, kind), tmp_path / kind / "joint.toml")
        back = read_log(tmp_path / f"{kind}.csv", joint=joint)
        assert back.spec == log.spec and back.torque_true is None and back.meta["reference_kind"] == kind
        for name in ("t", "strain", "current", "torque_ref"):
            np.testing.assert_allclose(getattr(back, name), getattr(log, name), rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(back.encoder, log.encoder)
        np.testing.assert_array_equal(back.index, log.index)
        assert f"reference kind = {kind} (given in" in "\n".join(back.meta["joint"])
    assert write_joint_toml(joint_toml(log.spec, True, "model"), joint) == joint   # the same text: fine
    with pytest.raises(InputError, match="joint.toml: exists and describes another joint"):
        write_joint_toml(joint_toml(log.spec, True, "transducer"), joint)


def test_a_control_rate_above_the_sample_rate_is_named(tmp_path):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    path = _joint(tmp_path, "[joint]\ncontrol_rate = 40000.0\n")
    with pytest.raises(InputError, match=r"joint.toml: joint.control_rate: 40000 Hz exceeds .*rec.csv's sample rate, 20000 Hz"):
        read_log(tmp_path / "rec.csv", joint=path)


def test_a_reference_declares_its_kind_and_a_bad_kind_is_one_line(tmp_path):
    _frame().to_csv(tmp_path / "rec.csv", index=False)
    log = read_log(tmp_path / "rec.csv", joint=_joint(tmp_path, '[joint.reference]\nkind = "transducer"\n'))
    assert log.meta["reference_kind"] == "transducer"
    assert "reference kind = transducer (given in" in "\n".join(log.meta["joint"])
    said = "\n".join(read_log(tmp_path / "rec.csv").meta["joint"])
    assert 'reference kind = model (ASSUMED: declare it in [joint.reference] kind = "transducer" or "model")' in said
    with pytest.raises(InputError, match=r"joint.reference.kind: 'loadcell' is not a kind of reference; use "
                                         r"'transducer' \(a torque sensor in series"):
        load_joint(_joint(tmp_path, '[joint.reference]\nkind = "loadcell"\n'))
    with pytest.raises(InputError, match="joint.reference.bandwidth: unknown key; known: kind"):
        load_joint(_joint(tmp_path, '[joint.reference]\nkind = "model"\nbandwidth = 3\n'))


def test_a_log_without_the_shared_reference_column_is_told_its_sidecar_fixes_it(tmp_path):
    """Issue 39: a scored log without a reference beside a joint.toml that maps one was refused
    with no hint; its sidecar's ``torque_ref = false`` reads it as a log without one."""
    _frame().drop(columns="torque_ref").to_csv(tmp_path / "rec.csv", index=False)
    joint = _joint(tmp_path, '[joint.columns]\ntorque_ref = "load_Nm"\n')
    with pytest.raises(InputError, match=r"joint.toml: joint.columns.torque_ref: .*rec.csv has no column 'load_Nm' "
                                         r"\(its columns: .*\); if .*rec.csv has none, say so in its sidecar "
                                         r"rec.toml: \[joint.columns\] torque_ref = false"):
        read_log(tmp_path / "rec.csv", joint=joint)
    _joint(tmp_path, "[joint.columns]\ntorque_ref = false\n", "rec.toml")
    assert read_log(tmp_path / "rec.csv", joint=joint).torque_ref is None
    with pytest.raises(InputError, match=r"joint.columns.strain: must be a column name or a table"):
        load_joint(_joint(tmp_path, "[joint.columns]\nstrain = false\n"))


def test_counts_per_rev_that_the_index_pulses_contradict_is_refused_naming_the_value(tmp_path):
    """Issue 39: a 4096-count encoder read as 2500 counts was scored, 14 of 14 rows ok."""
    n = 40_000
    encoder = np.arange(n) // 2 + 123                      # 10 kHz of counts: 4.9 revolutions
    frame = _frame(n).assign(encoder=encoder, index=(encoder % 4096 == 7).astype(int))
    frame.to_csv(tmp_path / "rec.csv", index=False)
    with pytest.raises(InputError, match=r"joint.toml: joint.counts_per_rev: 2500, but .*rec.csv's index pulses "
                                         r"are 4096 counts apart \(\d+ revolutions\): the encoder has 4096 counts "
                                         r"per revolution; give counts_per_rev = 4096"):
        read_log(tmp_path / "rec.csv", joint=_joint(tmp_path, "[joint]\ncounts_per_rev = 2500\n"))
    with pytest.raises(InputError, match=r"rec.csv: counts_per_rev = 2500 \(ASSUMED: rippleb's default"):
        read_log(tmp_path / "rec.csv")
    said = "\n".join(read_log(tmp_path / "rec.csv", joint=_joint(tmp_path, "[joint]\ncounts_per_rev = 4096\n",
                                                                  "j2.toml")).meta["joint"])
    assert "counts_per_rev = 4096 (given in" in said and "agrees with the index pulses, 4096 counts apart" in said
    assert "gear_ratio = 100 (ASSUMED (rippleb's default); no log can check it" in said


def test_a_single_turn_encoder_that_wraps_is_named(tmp_path):
    counts = (np.arange(40_000) // 2) % 4096
    _frame(40_000).assign(encoder=counts).to_csv(tmp_path / "rec.csv", index=False)
    with pytest.raises(InputError, match=r"counts_per_rev = 2500 .*encoder counts wrap at 4096"):
        read_log(tmp_path / "rec.csv")
    with pytest.raises(InputError, match=r"column encoder wraps at 4096 counts .*numpy.unwrap"):
        read_log(tmp_path / "rec.csv", joint=_joint(tmp_path, "[joint]\ncounts_per_rev = 4096\n"))


def test_the_gear_ratio_note_names_every_reader_of_the_gear_ratio():
    """joint_checks.GEAR_RATIO_NOTE says which built-in reads ``gear_ratio`` and that no score
    does: read from the source, so a method or a score that starts to read it fails here."""
    from pathlib import Path

    from rippleb.joint_checks import GEAR_RATIO_NOTE

    root = Path(__file__).resolve().parents[1]
    readers = sorted(p.stem for p in (root / "methods").glob("*.py") if "gear_ratio" in p.read_text())
    assert readers == ["current_based"] and "only current-based reads it" in GEAR_RATIO_NOTE
    scores = [p.name for p in (root / "rippleb" / "scoring").glob("*.py") if "gear_ratio" in p.read_text()]
    assert scores == [] and "no score uses it" in GEAR_RATIO_NOTE
