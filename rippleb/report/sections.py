"""The report's explanatory sections, written once as Markdown for ``README.md`` and ``index.html``.

:mod:`rippleb.report.writer` puts them in ``README.md``; :mod:`rippleb.report.html_report`
shows the same text through :func:`rippleb.report.markdown_html.markdown_html`. No number
is typed here: each comes from the rows.
"""

from __future__ import annotations

from rippleb.printable import markdown_code
from rippleb.report.gear_section import gear_markdown
from rippleb.report.layouts_section import layouts_markdown
from rippleb.report.markdown import plural
from rippleb.report.stats import condition_order, with_condition
from rippleb.report.tables import condition_headline, condition_summary_markdown, headline_lines, is_recorded
from rippleb.report.verdicts import method_verdicts

# What the tables can and cannot say; no numbers here, so nothing in it can go stale.
READING_SIMULATED = """## Reading these tables

- Every number comes from the simulator (`docs/physics.md`), not from a real joint. Its
  ripple has the wave-generator orders 1, 2, 4, 6 and 8 with amplitudes affine in the load
  and a small load-dependent phase, plus components locked to the output angle and strain
  hysteresis. Under `same-session` the wave-generator part is exactly what the
  calibration-map methods (`kalman-ripple`, `angle-adaptive-frozen`) identify on the
  calibration log of the same device, so their result there is the best case for
  model-based cancellation. The other conditions show what happens when the device has
  changed since calibration: a power cycle loses the absolute angle until the first index
  pulse, ageing drifts the map, re-assembly redraws it (`docs/physics.md`, "Deployment
  conditions").
- Under every condition, calibration included, the gear has its transmission error: a
  position error of the wave-generator angle (twice per turn dominant) that puts **real**
  torque at orders 1 and 2, the ripple's own, through the joint's dynamics
  (`docs/physics.md`, "Transmission error"). `torque_ref` does not know it. A method that
  removes everything at those orders removes it too and is charged for it in
  `rms_error_nm`; `gear_removed_fraction` and `rms_error_without_gear_nm` say what each
  method did with it.
- `realistic` is the same joint as `same-session` with the physics no method models turned on
  at their documented sizes, in the calibration session too: gauge dynamics that change the
  ripple with speed, a ripple that saturates with load, changes with the loaded tooth flank
  and follows the load's history, ripple at orders no method models (3 and the wave
  generator bearing's 9.24), gauge warm-up within the session, an anti-alias filter and PWM
  pickup before the ADC, encoder edge errors, eccentricity and missed counts
  (`docs/physics.md`, "Beyond the methods' models"); its position loop is today's. It is where a method that wins only because the simulator's ripple has
  the form it assumes would be found out; `results/sweeps/` varies each effect alone.
- `torque_ref` (Table I's reference) is the paper's eq. (7) on the desired trajectory with
  a nominal arm model whose masses and inertias differ from the simulated arm's by a few
  per cent, as an identification leaves them.
- `order-tracking` switches to the dead zone when no encoder position is crossed within
  its trigger timeout, chosen on the calibration scenario (`docs/methods/order-tracking.md`).
- `delay_ms` is the lag that best correlates estimate and truth, `n/a` where the
  correlation peak is not distinct (slowly varying torque); `step_latency_ms` and
  `bandwidth_hz` measure latency and bandwidth where the scenario defines them
  (`docs/metrics.md`).
- Timing columns depend on the machine and its load; compare methods within one run."""

READING_RECORDED = """## Reading these tables

- Every number comes from the recorded log named in the scenario column (`log:NAME`),
  scored against its `torque_ref` column where it has one (and `torque_true` where the log
  has one); one log is one device, so there are no intervals over devices.
- What `torque_ref` is decides the ranking (`[joint.reference] kind` in the joint file): a
  transducer in series reads the real torque, and the error against it ranks; a model
  (eq. (7)) lacks the gear's own torque, which a method that erases it would be rewarded for,
  so the rows are ranked by `rms_error_rebuilt_nm`, the error against the torque rebuilt from
  the strain (`docs/metrics.md`, "Scores against a reference").
- Every row also has the truth-free scores (`ripple_wg_nm`, `rest_std_nm`,
  `strain_delay_ms`), computed from the estimate, the strain and the encoder alone; a log
  without any reference is ranked by them. Each measures one symptom, not the error
  (below, and `docs/metrics.md`, "Scores without ground truth").
- The `calibration` column of `results.csv` says what each method was fitted on; `self`
  means the scored log itself, which is not a fair test of any method.
- Timing columns depend on the machine and its load; compare methods within one run."""


def summary_sections(frame) -> list[str]:
    """The lines of a simulated run's summary, as ``README.md`` and ``index.html`` both show it:
    the headlines (claims made on one half of the devices and checked on the other,
    :mod:`rippleb.report.claims`), the method x condition table and its sentences, what each method did with the gear's torque
    (:mod:`rippleb.report.gear_section`), the gauge layouts of a layout sweep
    (:mod:`rippleb.report.layouts_section`) and each method in plain words."""
    from rippleb.report.claims import split_sentence

    parts = ["## Headlines", "", split_sentence(frame["seed"].unique()), ""]
    parts += [f"- {s}" for s in headline_lines(frame)] + [""]
    parts += ["## Method x condition (mean `rms_error_nm` over the scenarios, 95 % interval)", "",
              "Per seed (device), the mean RMS error over the scenarios every method finished under "
              "that condition; then mean ± 95 % t-interval over seeds.", "",
              condition_summary_markdown(frame), "", "### Who leads under each condition", ""]
    parts += [f"- {s}" for s in condition_headline(frame)] + [""]
    return parts + gear_markdown(frame) + layouts_markdown(frame) + verdicts_section(frame)


def verdicts_section(frame) -> list[str]:
    """Each method in plain words (:func:`rippleb.report.verdicts.method_verdicts`), or nothing."""
    verdicts = method_verdicts(frame)
    if not verdicts:
        return []
    return (["### Each method in plain words", "",
             "Where it wins and where it breaks, from the table above; why, from what the "
             "method assumes of the ripple (its page under docs/methods/).", ""]
            + [f"- {v}" for v in verdicts] + [""])


def conditions_note(frame) -> str:
    """A sentence when the simulated rows hold one deployment condition only: the others, and
    the option that runs them; '' otherwise."""
    from rippleb.simulator.conditions import CONDITIONS

    if not len(frame) or is_recorded(frame):
        return ""
    conditions = condition_order(with_condition(frame)["condition"].unique())
    if len(conditions) != 1:
        return ""
    others = [c for c in CONDITIONS if c != conditions[0]]
    return (f"Only the condition {markdown_code(conditions[0])} ran: every number below is of joints in that state. "
            f"`rippleb run --conditions all` runs the {plural(len(others), 'other')} too "
            f"({', '.join(f'`{c}`' for c in others)}: what happened to the joint between its calibration and "
            f"the scored session; `rippleb list` says what each changes), and the report then says under "
            f"which condition each method leads.")
