"""The speed scripts of benchmarks/ whose figures docs/report.md quotes ("Where the time of the
run goes") run and print what the page reads. No time is asserted: the times are the machine's."""

import gc

import pytest

from support import load_script

pytestmark = pytest.mark.slow


def test_the_fork_floor_script_prints_a_cost_for_every_shape(capsys):
    """benchmarks/fork_floor.py ("Where the floor is"): a positive CPU time for each of its six shapes."""
    try:
        assert load_script("benchmarks/fork_floor.py").main(["--jobs", "2"]) == 0
    finally:
        gc.unfreeze()   # the script freezes this process's objects as the fork server does
    lines = [line for line in capsys.readouterr().out.splitlines() if line.endswith("CPU ms a job")]
    assert len(lines) == 6
    assert all(float(line.split()[-5]) > 0 for line in lines)


def test_the_yardsticks_script_times_both_yardsticks_on_every_tick():
    """benchmarks/yardsticks.py ("The machine's pace against the yardsticks")."""
    lfilter_us, raw_us, ticks = load_script("benchmarks/yardsticks.py").yardsticks(passes=1)
    assert ticks == 4000   # paper-quintic: 4 s at 20 kHz in 20-sample ticks
    assert lfilter_us > 0 and raw_us > 0
