"""Per-channel strain columns (strain_1 .. strain_K) of a gauge layout: in logs, files, the
cache, the recorded-log path and joint.toml."""

import dataclasses

import numpy as np
import pytest

from rippleb import InputError, JointSpec, read_log, simulate, write_log
from rippleb.data import make_log
from rippleb.engine.cache import log_bytes, log_from_bytes
from rippleb.layouts import GaugeSettings
from rippleb.log_columns import MAX_CHANNELS, channel_columns
from rippleb.simulator.scenario import load_scenario

SPEC = JointSpec()


def columns(n: int = 400, channels: int = 3) -> dict:
    rng = np.random.default_rng(0)
    volts = rng.normal(0.0, 1.0, (n, channels))
    return dict(t=np.arange(n) / SPEC.fs, strain=volts.mean(axis=1), encoder=np.arange(n),
                current=np.zeros(n), torque_ref=np.ones(n), channels=volts)


@pytest.fixture(scope="module")
def ring_log():
    sc = dataclasses.replace(load_scenario("stop-restart"), gauges=GaugeSettings(layout="ring-3"))
    return simulate(sc, 4).log


def test_a_simulated_layout_with_channels_logs_each_and_their_mean(ring_log):
    assert ring_log.channels.shape == (len(ring_log), 3)
    np.testing.assert_allclose(ring_log.strain, ring_log.channels.mean(axis=1), rtol=0, atol=1e-12)
    block = next(ring_log.blocks())
    assert block.channels.shape == (SPEC.block_size, 3)
    assert ring_log.for_method(keep_ref=False).channels is ring_log.channels


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_channels_go_to_files_as_strain_k_and_come_back_bit_for_bit(ring_log, tmp_path, suffix):
    path = write_log(ring_log, tmp_path / f"ring{suffix}")
    if suffix == ".csv":
        header = path.read_text().splitlines()[0].replace('"', "").split(",")
        assert header[-3:] == ["strain_1", "strain_2", "strain_3"]
    back = read_log(path, ring_log.spec)
    assert np.array_equal(back.channels, ring_log.channels)
    assert np.array_equal(back.strain, ring_log.strain)


def test_channels_survive_the_runs_cache(ring_log):
    back = log_from_bytes(log_bytes(ring_log))
    assert np.array_equal(back.channels, ring_log.channels)


def test_a_log_without_channels_has_none():
    log = make_log(SPEC, {k: v for k, v in columns().items() if k != "channels"})
    assert log.channels is None and "channels" not in log.columns()


@pytest.mark.parametrize("names, message", [
    (["strain_1", "strain_3"], "strain_2 is missing"),
    (["strain_2"], "strain_1 is missing"),
    ([f"strain_{k}" for k in range(1, MAX_CHANNELS + 2)], f"at most {MAX_CHANNELS}"),
    (["strain_1", f"strain_{10**30}"], f"at most {MAX_CHANNELS}"),
])
def test_channel_columns_with_a_gap_or_too_many_are_one_line(names, message):
    with pytest.raises(InputError, match=message):
        channel_columns(names, "rec.csv")


def test_channel_names_that_are_not_channels_are_left_alone():
    assert channel_columns(["strain_0", "strain_01", "strain_x", "strain", "strain_1"]) == ("strain_1",)


def test_a_bad_channel_column_is_named():
    bad = columns()
    bad["channels"] = bad["channels"].copy()
    bad["channels"][5, 1] = np.nan
    with pytest.raises(InputError, match="column strain_2 holds NaN"):
        make_log(SPEC, bad)
    flat = columns()
    flat["channels"] = flat["channels"][:, 0]
    with pytest.raises(InputError, match="samples x channels"):
        make_log(SPEC, flat)


def test_joint_toml_maps_a_daqs_channel_columns_with_their_units(tmp_path):
    import pandas as pd

    data = columns()
    frame = pd.DataFrame({"t": data["t"], "bridge_mV": 1e3 * data["strain"], "enc": data["encoder"],
                          "i": data["current"], "ref": data["torque_ref"],
                          **{f"ch{k}_mV": 1e3 * data["channels"][:, k] for k in range(3)}})
    frame.to_csv(tmp_path / "rec.csv", index=False)
    mapping = "\n".join(f'strain_{k + 1} = {{column = "ch{k}_mV", unit = "mV"}}' for k in range(3))
    (tmp_path / "joint.toml").write_text(
        '[joint.columns]\nt = "t"\nstrain = {column = "bridge_mV", unit = "mV"}\nencoder = "enc"\n'
        f'current = "i"\ntorque_ref = "ref"\n{mapping}\n')
    log = read_log(tmp_path / "rec.csv", joint=tmp_path / "joint.toml")
    np.testing.assert_allclose(log.channels, data["channels"], rtol=1e-12)
    assert any("column strain_2 = 'ch1_mV' in mV (given" in line for line in log.meta["joint"])


def test_joint_toml_refuses_a_unit_a_channel_cannot_have(tmp_path):
    (tmp_path / "joint.toml").write_text('[joint.columns]\nstrain_1 = {column = "a", unit = "Nm"}\n')
    with pytest.raises(InputError, match=r"joint\.columns\.strain_1\.unit"):
        from rippleb.joint_file import load_joint

        load_joint(tmp_path / "joint.toml")


def test_a_channel_named_twice_in_a_file_is_refused(tmp_path):
    path = tmp_path / "twice.csv"
    path.write_text("t,strain,encoder,current,strain_1,strain_1\n0,0,0,0,1,2\n5e-05,0,0,0,1,2\n")
    with pytest.raises(InputError, match="strain_1 appears more than once"):
        read_log(path, SPEC)
