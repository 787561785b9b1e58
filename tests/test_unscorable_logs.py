"""Issue 25 item 6: a recorded log that cannot be scored is refused, never scored ``ok``.

Through the real command (``rippleb.cli.main``, in this process): each bad log is one line
naming the file and the column, exit 2, nothing written. Before, every one of them ended
with ``ok`` rows: two ``ok`` rows on a one-sample log, the first of two ``strain`` columns
read silently, encoder counts of 1e19 cast to garbage, true/false read as 1/0, a
calibration against an all-zero reference; a strain scaled by 1e306 scored
``rms_error_ref_nm = inf`` as ``ok``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from rippleb import JointSpec, make_log
from rippleb.cli import main
from rippleb.errors import InputError

FS = 20_000.0


def _frame(n: int = 4000) -> pd.DataFrame:
    """A plausible recording: a 3 Hz torque, strain at 0.1 V/Nm, an encoder turning."""
    t = np.arange(n) / FS
    torque = 5.0 * np.sin(2 * np.pi * 3 * t) + 2.0
    return pd.DataFrame({"t": t, "strain": 0.1 * torque, "encoder": np.arange(n) // 4,
                         "current": 0.01 * torque, "torque_ref": torque})


def _run(tmp_path, monkeypatch, capsys, *args):
    monkeypatch.chdir(tmp_path)
    code = main(["run", *args, "--methods", "raw,lowpass", "--jobs", "1", "--no-progress", "--out", "out"])
    return code, capsys.readouterr().err


def _refused(tmp_path, monkeypatch, capsys, says: str, *args) -> str:
    before = sorted(p.name for p in tmp_path.iterdir())
    code, err = _run(tmp_path, monkeypatch, capsys, *args)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"rippleb: error: {says}"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # nothing written
    return err


@pytest.mark.parametrize("rows", [1, 2, 30, 3999])
def test_a_log_too_short_to_score_is_refused(rows, tmp_path, monkeypatch, capsys):
    _frame(rows).to_csv(tmp_path / "rec.csv", index=False)
    err = _refused(tmp_path, monkeypatch, capsys, f"rec.csv: {rows} samples (", "--log", "rec.csv")
    assert "needs at least 0.2 s (4000 samples at 20000 Hz), twice the 100 ms of lags delay_ms searches" in err


def test_the_shortest_scorable_log_is_scored(tmp_path, monkeypatch, capsys):
    _frame(4000).to_csv(tmp_path / "rec.csv", index=False)
    code, err = _run(tmp_path, monkeypatch, capsys, "--log", "rec.csv")
    assert code == 0, err
    rows = pd.read_csv(tmp_path / "out" / "results.csv")
    assert (rows.status == "ok").all() and np.isfinite(rows.rms_error_ref_nm).all()


def _duplicated_csv(path):
    frame = _frame()
    frame["strain2"] = 0.0
    text = frame.to_csv(index=False).replace("strain2", "strain", 1)
    path.write_text(text)


def _duplicated_parquet(path):
    frame = _frame()
    columns = [pa.array(frame[c]) for c in frame.columns] + [pa.array(np.zeros(len(frame)))]
    pq.write_table(pa.table(columns, names=list(frame.columns) + ["strain"]), path)


def _changed(column, values):
    def write(path):
        frame = _frame()
        frame[column] = values(frame)
        frame.to_csv(path, index=False)
    return write


#: case -> (file name, writer, what the line says after "rippleb: error: ")
BAD_LOGS = {
    "duplicated column (csv)": ("dup.csv", _duplicated_csv, "dup.csv: column strain appears more than once"),
    "duplicated column (parquet)": ("dup.parquet", _duplicated_parquet,
                                    "dup.parquet: column strain appears more than once"),
    "boolean encoder": ("rec.csv", _changed("encoder", lambda f: f.encoder % 2 == 0),
                        "rec.csv: column encoder holds true/false values, not numbers"),
    "boolean current": ("rec.csv", _changed("current", lambda f: f.current > 0.02),
                        "rec.csv: column current holds true/false values, not numbers"),
    "encoder at 1e19": ("rec.csv", _changed("encoder", lambda f: f.encoder.astype(float) + 1e19),
                        "rec.csv: column encoder reaches 1e+19 counts, beyond +-2^53"),
    "subnormal strain": ("rec.csv", _changed("strain", lambda f: f.strain * 1e-310),
                         "rec.csv: column strain holds subnormal values"),
}


@pytest.mark.parametrize("case", list(BAD_LOGS))
def test_a_log_that_cannot_be_scored_is_refused(case, tmp_path, monkeypatch, capsys):
    name, write, says = BAD_LOGS[case]
    write(tmp_path / name)
    _refused(tmp_path, monkeypatch, capsys, says, "--log", name)


@pytest.mark.parametrize("given", [True, False])
def test_a_calibration_against_a_constant_reference_is_refused(given, tmp_path, monkeypatch, capsys):
    if given:   # a calibration recording whose torque_ref is all zero
        _frame().to_csv(tmp_path / "rec.csv", index=False)
        _frame(int(1.2 * FS)).assign(torque_ref=0.0).to_csv(tmp_path / "cal.csv", index=False)
        args, name = ("--log", "rec.csv", "--calibration", "cal.csv"), "cal.csv"
    else:       # the scored log, calibrated on itself
        _frame().assign(torque_ref=0.0).to_csv(tmp_path / "rec.csv", index=False)
        args, name = ("--log", "rec.csv"), "rec.csv"
    _refused(tmp_path, monkeypatch, capsys, f"{name}: column torque_ref is 0 Nm throughout", *args)


def test_scores_that_overflow_are_invalid_not_ok():
    """A finite estimate of 1e306 Nm whose squared error is not finite: the row is
    ``invalid`` with the overflowing column named, and numpy warns of nothing.

    Through a recorded log this case is now stopped earlier, by the joint's bounded rated
    torque (the scale rule, next test); the overflow rule stands behind it for any path
    that checks no scale (a simulated row has no torque limit)."""
    import warnings

    from rippleb.scoring.metrics import Truth
    from rippleb.scoring.row import score_or_invalid

    n = 4000
    t = np.arange(n) / FS
    truth = Truth(fs=FS, eval_mask=np.ones(n, bool), moving=np.ones(n, bool), wave_angle=40.0 * t,
                  torque_true=np.sin(t), torque_ref=np.sin(t))
    with warnings.catch_warnings():
        warnings.simplefilter("error")      # the overflow is the row's status, not a warning
        fields = score_or_invalid(np.full(n, 1e306), truth)
    assert fields["status"] == "invalid"
    assert fields["message"].startswith("its scores are not finite (rms_error_nm = inf"), fields["message"]


def test_with_the_joints_rated_torque_the_strain_is_refused_before_any_row_runs(tmp_path, monkeypatch, capsys):
    """Calibrated as the calibration log's strain, the scored log's reads 7e306 Nm: its unit
    differs (issue 39: strain in V labelled mV ran 14 rows, 13 invalid, one 'rank 1')."""
    frame = _frame()
    frame.assign(strain=frame.strain * 1e306).to_csv(tmp_path / "rec.csv", index=False)
    _frame(int(1.2 * FS)).to_csv(tmp_path / "cal.csv", index=False)
    says = ("rec.csv: column strain ('strain' in V): calibrated as the calibration log's strain, it reads up to "
            "7e+306 Nm, beyond 510 Nm")
    _refused(tmp_path, monkeypatch, capsys, says, "--log", "rec.csv", "--calibration", "cal.csv")


def test_a_boolean_index_pulse_is_a_pulse(tmp_path):
    """``index`` is a 0/1 flag: a DAQ that logs it as true/false is understood."""
    frame = _frame()
    log = make_log(JointSpec(), {**frame.to_dict("series"), "index": frame.encoder % 100 == 0})
    assert log.index.dtype == np.int8 and log.index.sum() == (frame.encoder % 100 == 0).sum()
    with pytest.raises(InputError, match="api: column t holds true/false values"):
        make_log(JointSpec(), {**frame.to_dict("series"), "t": frame.t > 0}, source="api")
