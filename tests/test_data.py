import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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


@settings(max_examples=60, deadline=None, derandomize=True)
@given(n=st.integers(0, 130), size=st.integers(1, 45), n_channels=st.sampled_from([0, 1, 3]),
       stride=st.sampled_from([1, 2]), with_index=st.booleans())
def test_blocks_are_the_slices_of_the_log_as_views(n, size, n_channels, stride, with_index):
    """Each block holds exactly ``column[start:start + size]`` of every column, as a view of
    the log's own array (strided columns and 2-D channels too), and stays frozen."""
    rng = np.random.default_rng(n * 1000 + size)
    wide = rng.normal(size=(n * stride, 6 + max(n_channels, 1)))[::stride]   # strided columns
    index = (rng.random(n) < 0.1).astype(np.int8) if with_index else None
    channels = wide[:, 6:6 + n_channels] if n_channels else None
    log = SensorLog(spec=JointSpec(), t=wide[:, 0], strain=wide[:, 1],
                    encoder=np.arange(n, dtype=np.int64), current=wide[:, 2], index=index,
                    channels=channels)
    blocks = list(log.blocks(size))
    assert len(blocks) == -(-n // size)
    for k, block in enumerate(blocks):
        part = slice(k * size, (k + 1) * size)
        for name in ("t", "strain", "encoder", "current", "index", "channels"):
            column, got = getattr(log, name), getattr(block, name)
            if column is None:
                assert got is None
                continue
            np.testing.assert_array_equal(got, column[part])
            assert got.dtype == column.dtype
            assert got.flags.c_contiguous == column[part].flags.c_contiguous   # what a compiled signature reads
            assert np.shares_memory(got, column)
        with pytest.raises(dataclasses.FrozenInstanceError):
            block.strain = None


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
