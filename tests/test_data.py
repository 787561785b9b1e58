import numpy as np
import pytest

from rippleb import InputError, JointSpec, SensorLog, make_log, read_log, write_log


def _columns(n=100, fs=20_000.0):
    t = np.arange(n) / fs
    return {"t": t, "strain": np.sin(t), "encoder": np.arange(n), "current": np.cos(t),
            "torque_true": 2 * t, "torque_ref": 3 * t}


def test_block_size_follows_rates():
    assert JointSpec().block_size == 20
    assert JointSpec(fs=10_000, control_rate=500).block_size == 20


@pytest.mark.parametrize("field", ["fs", "gear_ratio", "counts_per_rev", "control_rate"])
def test_spec_refuses_non_positive_values(field):
    import dataclasses

    with pytest.raises(InputError, match=field):
        dataclasses.replace(JointSpec(), **{field: 0}).validate()


def test_blocks_cover_the_log_in_order():
    log = make_log(JointSpec(), _columns(n=105))
    blocks = list(log.blocks())
    assert [len(b) for b in blocks] == [20] * 5 + [5]
    np.testing.assert_array_equal(np.concatenate([b.t for b in blocks]), log.t)


def test_for_method_hides_truth():
    log = make_log(JointSpec(), _columns())
    assert log.for_method(keep_ref=True).torque_true is None
    assert log.for_method(keep_ref=True).torque_ref is not None
    assert log.for_method(keep_ref=False).torque_ref is None


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip(tmp_path, suffix):
    log = make_log(JointSpec(), _columns())
    back = read_log(write_log(log, tmp_path / f"log{suffix}"))
    assert back.spec.fs == pytest.approx(20_000.0)
    for name, values in log.columns().items():
        np.testing.assert_array_equal(getattr(back, name), values)  # bit for bit, CSV too
    assert back.encoder.dtype == np.int64


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda c: c.pop("current"), "missing column"),
        (lambda c: c["strain"].__setitem__(3, np.nan), "strain holds NaN"),
        (lambda c: c["t"].__setitem__(5, c["t"][4]), "strictly increase"),
        (lambda c: c["t"].__setitem__(slice(50, None), c["t"][50:] + 1.0), "gap"),
        (lambda c: c.__setitem__("encoder", np.arange(100) + 0.5), "integer"),
    ],
)
def test_schema_check_names_the_column(change, message):
    columns = _columns()
    change(columns)
    with pytest.raises(InputError, match=message):
        make_log(JointSpec(), columns, source="x.csv")


def test_empty_log_is_refused():
    with pytest.raises(InputError, match="empty"):
        make_log(JointSpec(), {k: [] for k in ("t", "strain", "encoder", "current")})


def test_read_log_refuses_unknown_suffix(tmp_path):
    with pytest.raises(InputError, match="unsupported"):
        read_log(tmp_path / "log.txt")
