"""The runner fits each method once per calibration log (per device), not once per row.

Rows must not change for it: each row starts from the same pickled fitted state that
fitting in the row would give. Methods that cannot be pickled fit in each row, as before.
"""

import numpy as np
import pytest

import rippleb
from rippleb import Method
from rippleb.scoring.metrics import Truth
from rippleb.engine.runner import evaluate
from support import fake_simulate

FIT_MARK = "counts-fits: fitting"
ACCURACY = ["rms_error_nm", "max_error_nm", "rms_error_ref_nm", "max_error_ref_nm", "delay_ms",
            "stopped_rms_error_nm"]


class CountsFits(Method):
    """Learns a gain in fit, and keeps streaming state that reset must clear."""
    name = "counts-fits"

    def fit(self, calibration):
        # rows run in child processes that may write no file (issue 34): count on their logs
        print(FIT_MARK, flush=True)
        self.gain = float(np.polyfit(calibration.strain, calibration.torque_ref, 1)[0])

    def reset(self, spec):
        self.last = 0.0

    def step(self, block):
        out = 0.5 * self.last + 0.5 * self.gain * block.strain
        self.last = float(out[-1])
        return out


class Unpicklable(CountsFits):
    name = "unpicklable"

    def fit(self, calibration):
        super().fit(calibration)
        self.scale = lambda x: x   # a lambda cannot be pickled


class FitRaises(Method):
    name = "fit-raises"

    def fit(self, calibration):
        raise ValueError("no calibration for you")

    def step(self, block):
        return np.zeros(len(block))


@pytest.fixture
def fake(monkeypatch, tmp_path, register_methods):
    import rippleb.simulator

    monkeypatch.setattr(rippleb.simulator, "simulate", fake_simulate)
    register_methods(CountsFits, Unpicklable, FitRaises)
    return tmp_path / "run"


def _fits(run) -> int:
    """How many times a method fitted in the run directory ``run`` (its jobs' logs say)."""
    return sum(log.read_text().count(FIT_MARK) for log in (run / "logs").iterdir())


def test_one_fit_per_method_and_seed_and_the_rows_equal_fitting_in_each_row(fake):
    frame = rippleb.run(methods="counts-fits", scenarios="paper-quintic,creep,reversal", seeds=2, jobs=2, out=fake)
    assert _fits(fake) == 2   # 2 seeds, not 2 x 3 rows
    assert (frame["status"] == "ok").all() and len(frame) == 6
    for row in frame.itertuples():
        cal = fake_simulate("calibration", row.seed)
        sim = fake_simulate(row.scenario, row.seed)
        alone = evaluate(CountsFits, cal.log, sim.log, Truth.from_simulation(sim))
        assert [getattr(row, c) for c in ACCURACY] == [alone[c] for c in ACCURACY]


def test_an_unpicklable_method_fits_in_each_row(fake):
    frame = rippleb.run(methods="unpicklable", scenarios="paper-quintic,creep", seeds=1, out=fake)
    assert (frame["status"] == "ok").all()
    assert _fits(fake) == 1 + 2   # the fit job, then each row again


def test_a_failed_fit_is_the_status_of_each_of_its_rows(fake):
    frame = rippleb.run(methods="fit-raises,raw", scenarios="paper-quintic,creep", seeds=1)
    status = {(r.method, r.scenario): (r.status, r.message) for r in frame.itertuples()}
    for scenario in ("paper-quintic", "creep"):
        assert status["fit-raises", scenario] == ("error", "ValueError: no calibration for you")
        assert status["raw", scenario][0] == "ok"
    assert "pickled" not in frame.columns
