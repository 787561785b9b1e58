"""The publishing procedure of docs/report.md at small scale: a sealed run, its report with
the salt published beside it, and the re-run that verifies its rows bit for bit.

The same sequence of commands as the published comparison, on 4 devices, 2 methods and 2
scenarios (``tests/test_published.py`` checks the real publication in ``results/``).
"""

import json

import pandas as pd
import pytest

from rippleb.cli import main
from rippleb.engine.sealing import commitment
from rippleb.report import publication, writer

RUN = ["--methods", "raw,lowpass", "--scenarios", "paper-quintic,stop-restart", "--conditions", "same-session",
       "--seeds", "4", "--jobs", "1", "--no-progress"]


@pytest.fixture(scope="module")
def published(tmp_path_factory):
    """``rippleb run --sealed``, then ``rippleb report --published --salt-file``."""
    base = tmp_path_factory.mktemp("publish")
    run_dir, salt, results = base / "published", base / "published.salt", base / "results"
    assert main(["run", *RUN, "--sealed", str(salt), "--out", str(run_dir)]) == 0
    assert main(["report", str(run_dir), "--out", str(results), "--published", "--no-figures",
                 "--salt-file", str(salt)]) == 0
    return base, run_dir, salt, results


@pytest.mark.slow
def test_the_salt_and_its_commitment_are_published_with_the_rows(published):
    _, run_dir, salt, results = published
    assert (results / "salt.txt").read_text() == salt.read_text()
    recorded = json.loads((results / "provenance.json").read_text())
    assert recorded["run"]["sealed"] == {"commitment": commitment(bytes.fromhex(salt.read_text()))}
    assert recorded["salt"] == "salt.txt"
    readme = (results / "README.md").read_text()
    assert "Sealed: all 16 rows ran on devices drawn from a secret salt" in readme
    assert "The salt is published beside this report (`salt.txt`" in readme
    assert "the salt is published beside this report in `salt.txt`" in readme   # the provenance table
    rows = writer.read_results_exact(results / "results.csv")
    assert rows["sealed"].all() and len(rows) == 16


@pytest.mark.slow
def test_anyone_re_runs_published_rows_bit_for_bit_with_the_salt(published, tmp_path):
    _, _, _, results = published
    keys = [("raw", "paper-quintic", "same-session", 1), ("lowpass", "stop-restart", "same-session", 2)]
    assert publication.verify(results, keys) == []
    # a row edited by one bit is found
    frame = writer.read_results_exact(results / "results.csv")
    edited = tmp_path / "edited"
    edited.mkdir()
    for name in ("provenance.json", "salt.txt"):
        (edited / name).write_bytes((results / name).read_bytes())
    i = frame.index[(frame["method"] == "raw") & (frame["scenario"] == "paper-quintic") & (frame["seed"] == 1)][0]
    frame.loc[i, "rms_error_nm"] = frame.loc[i, "rms_error_nm"] * (1 + 2 ** -50)
    frame.to_csv(edited / "results.csv", index=False)
    problems = publication.verify(edited, keys[:1])
    assert len(problems) == 1 and "rms_error_nm" in problems[0]


@pytest.mark.slow
def test_the_sealed_devices_are_not_the_public_seeds_devices(published, tmp_path):
    """Each publication draws new devices: the same indices on the public seeds give other rows."""
    _, run_dir, _, _ = published
    assert main(["run", *RUN, "--out", str(tmp_path / "public")]) == 0
    sealed = pd.read_csv(run_dir / "results.csv").set_index(["method", "scenario", "seed"])["rms_error_nm"]
    public = pd.read_csv(tmp_path / "public" / "results.csv").set_index(["method", "scenario", "seed"])["rms_error_nm"]
    assert (sealed != public.reindex(sealed.index)).all()


@pytest.mark.slow
def test_a_replay_says_it_is_no_sealed_comparison(published, tmp_path):
    _, _, salt, _ = published
    assert main(["run", "--methods", "raw", "--scenarios", "paper-quintic", "--seeds", "1", "--jobs", "1",
                 "--no-progress", "--salt-file", str(salt), "--out", str(tmp_path / "replay")]) == 0
    config = json.loads((tmp_path / "replay" / "run.json").read_text())
    assert config["sealed"]["salt"] == "given"
    assert main(["report", str(tmp_path / "replay"), "--no-figures"]) == 0
    readme = (tmp_path / "replay" / "report" / "README.md").read_text()
    assert "Replayed: all 1 rows ran on the devices of a salt given to the run" in readme


@pytest.mark.slow
def test_a_salt_that_cannot_be_published_is_one_line_exit_2(published, tmp_path, capsys):
    base, run_dir, salt, _ = published
    wrong = tmp_path / "wrong.salt"
    wrong.write_text("ab" * 32 + "\n")
    cases = [([str(run_dir), "--out", str(tmp_path / "a"), "--salt-file", str(wrong)], "not the salt of this run"),
             ([str(run_dir), "--salt-file", str(salt)], "inside the run directory"),
             ([str(run_dir), "--out", str(tmp_path / "b"), "--salt-file", str(tmp_path / "none")], "cannot read the salt")]
    for args, words in cases:
        assert main(["report", *args, "--no-figures"]) == 2, args
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "a").exists() and not (run_dir / "report").exists()
