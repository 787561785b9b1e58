"""`rippleb check NAME`: the conformance kit from the command line, one line per check."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from rippleb.cli.check import run_checks
from rippleb.engine.checking import in_process
from rippleb.engine.conformance import checks, subject
from rippleb.method import Method
from rippleb.methods.raw import Raw


class BlockMean(Method):
    """The mean of each block: right for one-tick blocks only."""

    name = "block-mean"

    def step(self, block):
        return np.full(len(block), float(np.mean(block.strain)))


class Raises(Method):
    name = "raises"

    def step(self, block):
        raise ValueError("plugin bug")


def test_every_check_passes_on_raw(capsys):
    listed = checks()
    assert run_checks(in_process(subject(Raw), listed), listed) == len(listed)
    out = capsys.readouterr().out.splitlines()
    assert len(out) == len(listed) and all(line.startswith("  ok  ") for line in out)


def test_a_method_that_depends_on_the_block_size_fails_those_checks_only(capsys):
    listed = checks()
    passed = run_checks(in_process(subject(BlockMean), listed), listed)
    out = capsys.readouterr().out.splitlines()
    failed = [line for line in out if line.startswith("  FAIL")]
    assert passed == len(listed) - len(failed) and failed
    assert all("blocks of" in line and "max difference" in line for line in failed)
    assert not any("blocks of 20 samples" in line for line in failed)  # one tick is the reference


def test_a_method_that_raises_fails_the_output_check_and_skips_the_others(capsys):
    listed = checks()
    assert run_checks(in_process(subject(Raises), listed), listed) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("  FAIL  output") and out[0].endswith("ValueError: plugin bug")
    assert len(out) == len(listed) and all(line.startswith("  skip") for line in out[1:])


def rippleb(*args, path=None):
    env = dict(os.environ)
    if path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(path), env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "rippleb", *args], capture_output=True, text=True,
                          env=env, timeout=900)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["raw", "order-tracking", "order-tracking[q=20]"])
def test_rippleb_check_passes_on_builtins_and_their_variants(name):
    proc = rippleb("check", name)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith(f"rippleb check {name} (builtin")
    assert sum(line.startswith("  ok  ") for line in lines) == len(checks()) + 1
    assert lines[-1] == f"{name}: {len(checks()) + 1} of {len(checks()) + 1} checks passed"


@pytest.fixture
def installed_plugin(tmp_path):
    """A plugin found through its entry point (a dist-info directory on PYTHONPATH)."""
    (tmp_path / "peeky.py").write_text(textwrap.dedent('''
        import numpy as np
        from rippleb import Method

        class Peeky(Method):
            name = "peeky"
            def step(self, block):
                return np.full(len(block), float(np.mean(block.strain)))
        '''))
    info = tmp_path / "peeky-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: peeky\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[rippleb.methods]\npeeky = peeky:Peeky\n")
    return tmp_path


@pytest.mark.slow
def test_a_failing_plugin_gets_one_line_per_check_and_exit_1(installed_plugin):
    proc = rippleb("check", "peeky", path=installed_plugin)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == "rippleb check peeky (plugin, peeky: peeky:Peeky)"
    assert any(line.startswith("  FAIL  blocks of 1 sample") for line in lines)
    assert lines[-1].startswith("peeky: ") and "of 9 checks passed" in lines[-1]


@pytest.mark.slow
@pytest.mark.parametrize("name, words", [("nope", ["unknown method 'nope'"]),
                                         ("raw[window=3]", ["method 'raw'", "unknown parameter 'window'"]),
                                         ("order-tracking[q=1,2]", ["names 2 variants"])])
def test_bad_input_is_one_line_and_exit_2(name, words):
    proc = rippleb("check", name)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and all(word in lines[0] for word in words), proc.stderr


@pytest.mark.slow
def test_a_plugin_that_fails_to_import_fails_the_import_check(tmp_path):
    info = tmp_path / "gone-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: gone\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[rippleb.methods]\ngone = no_such_module:Gone\n")
    proc = rippleb("check", "gone", path=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[1].startswith("  FAIL  import") and "No module named 'no_such_module'" in lines[1]
    assert len(lines) == 2
