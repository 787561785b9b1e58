"""Every bad input of the CLI, written into a directory: the cases of ``tests/test_bad_input.py``.

The test asserts that each ends in one line and exit 2, and ``docs/tables/bad_input_table.py``
prints the table of ``docs/robustness.md`` from the same cases: both import them from here.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from support import GOOD, PLUGIN, install_dist, log_frame


class PicklePayload:
    """Unpickling this creates a file: proof that a reader executed code."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def bad_inputs(root: Path) -> dict:
    """Write every bad input under ``root``; return {case: (argv, env site or None, words)}."""
    (root / "not-toml.toml").write_text("this is = not toml [")
    (root / "unknown-key.toml").write_text("duraton = 2.0\n" + GOOD)
    (root / "wrong-type.toml").write_text('duration = "long"\n' + GOOD)
    (root / "impossible.toml").write_text("[joint]\nfs = -1.0\n" + GOOD)
    (root / "huge.toml").write_text("duration = 1e9\n" + GOOD)
    (root / "beyond-limits.toml").write_text(GOOD.replace("by = 0.1", "by = 9.0"))
    (root / "bad-fault.toml").write_text(GOOD + "[faults]\nencoder_missed = 1.5\n")
    (root / "robot.toml").write_text('[robot]\nname = "ur55"\n' + GOOD.split("[trajectory]")[0].replace(
        "[robot]\n", "") + "[trajectory]" + GOOD.split("[trajectory]")[1])
    (root / "joint.toml").write_text(GOOD.replace("[robot]\n", '[robot]\njoint = "knee"\n'))
    (root / "binary.toml").write_bytes(b"\xff\xfe\x00bad")
    frame = log_frame()
    (root / "empty.csv").write_text("")
    frame.iloc[:0].to_csv(root / "header-only.csv", index=False)
    frame.drop(columns="current").to_csv(root / "no-current.csv", index=False)
    nan = frame.copy()
    nan.loc[50, "strain"] = np.nan
    nan.to_csv(root / "nan.csv", index=False)
    repeat = frame.copy()
    repeat.loc[60, "t"] = repeat.loc[59, "t"]
    repeat.to_parquet(root / "repeat.parquet")
    back = frame.copy()
    back.loc[70, "t"] = back.loc[68, "t"]
    back.to_csv(root / "back.csv", index=False)
    gap = frame.copy()
    gap.loc[100:, "t"] += 0.01
    gap.to_csv(root / "gap.csv", index=False)
    code = frame.astype({"strain": object})
    code.loc[3, "strain"] = "__import__('os').system('touch PWNED')"
    code.to_csv(root / "code.csv", index=False)
    (root / "pickle.parquet").write_bytes(pickle.dumps(PicklePayload(root / "PWNED")))
    (root / "pickle.csv").write_bytes(pickle.dumps(PicklePayload(root / "PWNED")))
    (root / "a-file").write_text("I am a regular file")
    frame.to_csv(root / "good.csv", index=False)
    install_dist(root / "site-dup", "rippleb-dup-a", "dup_a", PLUGIN, {"dup": "Plugin"})
    install_dist(root / "site-dup", "rippleb-dup-b", "dup_b", PLUGIN, {"dup": "Plugin"})
    install_dist(root / "site-clash", "rippleb-clash", "clash", PLUGIN, {"raw": "Plugin"})
    install_dist(root / "site-broken", "rippleb-broken", "broken_mod", "import no_such_module_xyz\n",
          {"broken-one": "Plugin"})
    run = ["run", "--seeds", "1", "--jobs", "1", "--no-progress", "--methods", "raw"]
    out = ["--out", "out"]
    return {
        # scenario files
        "scenario not TOML": ([*run, "--scenarios", "not-toml.toml", *out], None, ["not-toml.toml", "not valid TOML"]),
        "scenario unknown key": ([*run, "--scenarios", "unknown-key.toml", *out], None,
                                 ["unknown-key.toml: duraton: unknown key", "duration"]),
        "scenario wrong type": ([*run, "--scenarios", "wrong-type.toml", *out], None,
                                ["wrong-type.toml: duration: must be a number, got str"]),
        "scenario impossible value": ([*run, "--scenarios", "impossible.toml", *out], None,
                                      ["impossible.toml: joint.fs: must be positive"]),
        "scenario too long": ([*run, "--scenarios", "huge.toml", *out], None, ["huge.toml: duration:", "samples"]),
        "scenario beyond joint limits": ([*run, "--scenarios", "beyond-limits.toml", *out], None,
                                         ["beyond-limits.toml: trajectory:", "outside its limits"]),
        "scenario bad fault": ([*run, "--scenarios", "bad-fault.toml", *out], None,
                               ["bad-fault.toml: faults.encoder_missed: must be a probability"]),
        "scenario not UTF-8": (["simulate", "binary.toml", "--out", "x.csv"], None, ["binary.toml: cannot read"]),
        "unknown robot": ([*run, "--scenarios", "robot.toml", *out], None, ["robot.toml: robot.name: unknown robot 'ur55'"]),
        "unknown joint": ([*run, "--scenarios", "joint.toml", *out], None, ["joint.toml: robot.joint:", "'knee'"]),
        "missing scenario file": ([*run, "--scenarios", "nope.toml", *out], None, ["nope.toml: no such scenario file"]),
        "unknown scenario": ([*run, "--scenarios", "paper-quintc", *out], None, ["paper-quintc: unknown scenario"]),
        "scenario name with ../": ([*run, "--scenarios", "../scenarios/creep", *out], None,
                                   ["../scenarios/creep: not a built-in scenario name"]),
        # recorded logs
        "log empty file": (["run", "--log", "empty.csv", *out], None, ["empty.csv: cannot read as csv"]),
        "log without rows": (["run", "--log", "header-only.csv", *out], None, ["header-only.csv: the log is empty"]),
        "log lacks a column": (["run", "--log", "no-current.csv", *out], None, ["no-current.csv: missing column(s) current"]),
        "log holds NaN": (["run", "--log", "nan.csv", *out], None, ["nan.csv: column strain holds NaN", "row 50"]),
        "log t repeats": (["run", "--log", "repeat.parquet", *out], None,
                          ["repeat.parquet: column t must strictly increase (row 60"]),
        "log t goes back": (["run", "--log", "back.csv", *out], None, ["back.csv: column t must strictly increase (row 70"]),
        "log has a gap": (["run", "--log", "gap.csv", *out], None, ["gap.csv: column t has a gap", "row 100"]),
        "log cell holds code": (["run", "--log", "code.csv", *out], None, ["code.csv: column strain is not numeric"]),
        "log is a pickle (.parquet)": (["run", "--log", "pickle.parquet", *out], None,
                                       ["pickle.parquet: cannot read as parquet"]),
        "log is a pickle (.csv)": (["run", "--log", "pickle.csv", *out], None, ["pickle.csv"]),
        "log wrong suffix": (["run", "--log", "a-file", *out], None, ["a-file: unsupported log format"]),
        "calibration log lacks a column": (["run", "--log", "good.csv", "--calibration", "no-current.csv", *out],
                                               None, ["no-current.csv: missing column(s) current"]),
        # names and plugins
        "unknown method": ([*run[:-1], "rwa", "--scenarios", "creep", *out], None, ["unknown method 'rwa'", "'raw'"]),
        "two plugins, one name": ([*run, "--scenarios", "creep", *out], "site-dup",
                                  ["two methods are named 'dup'", "rippleb-dup-a", "rippleb-dup-b"]),
        "plugin named like a built-in": (["list"], "site-clash", ["two methods are named 'raw'", "rippleb-clash"]),
        # outputs and arguments
        "output dir under a regular file": ([*run, "--scenarios", "creep", "--out", "a-file/out"], None,
                                            ["a-file/out: cannot write the output directory"]),
        "simulate into a regular file's child": (["simulate", "creep", "--out", "a-file/x.csv"], None,
                                                 ["a-file/x.csv: cannot write: a-file is not a directory"]),
        "negative seed": ([*run, "--scenarios", "creep", "--seed-start", "-3", *out], None,
                          ["--seed-start must be a non-negative integer"]),
    }
