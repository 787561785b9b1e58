"""A simulated log written as a lab's DAQ writes it, and the ``joint.toml`` that reads it back.

``rippleb simulate --format lab`` uses it for the worked example (docs/your-joint.md): the
columns carry the DAQ's names and units (time in ms, strain in mV), the joint is the
scenario's (its encoder's counts per revolution, its gear ratio), and the log holds no truth
a bench cannot measure (no ``torque_true``). Its reference is one of the two a bench has,
named for what it is and declared in ``joint.toml``'s ``[joint.reference]``
(:data:`~rippleb.joint_file.REFERENCE_KINDS`):

* ``transducer``: a torque flange in series, the real torque through the flange's bandwidth
  and noise (:mod:`rippleb.simulator.transducer`), column ``torque_sensor_Nm``;
* ``model``: eq. (7)'s model torque, the simulator's ``torque_ref``, column ``model_torque_Nm``.
"""

from __future__ import annotations

from pathlib import Path

from rippleb.errors import InputError
from rippleb.files import atomic_path

#: rippleb's column -> (the DAQ's column, its unit, the factor from rippleb's unit to it).
LAB_COLUMNS = {
    "t": ("t", "ms", 1e3),
    "strain": ("strain_mV", "mV", 1e3),
    "encoder": ("enc_counts", "counts", 1),
    "current": ("i_motor_A", "A", 1.0),
    "index": ("idx", "pulse", 1),
}
#: The reference's column per kind: named for what it is.
REFERENCE_COLUMNS = {"transducer": "torque_sensor_Nm", "model": "model_torque_Nm"}


def lab_columns(log, kind: str) -> dict:
    """The columns of ``log`` under the DAQ's names and in its units, its ``torque_ref`` (of
    ``kind``) under the name of that kind, and no ``torque_true``."""
    out = {}
    for name, (column, _unit, factor) in LAB_COLUMNS.items():
        values = getattr(log, name)
        if values is not None:
            out[column] = values * factor if factor != 1 else values
    out[REFERENCE_COLUMNS[kind]] = log.torque_ref
    return out


def joint_toml(spec, has_index: bool, kind: str) -> str:
    """The ``joint.toml`` text that describes ``spec``, the lab columns and the reference's kind."""
    lines = ["# The joint and the DAQ's columns of a log written by 'rippleb simulate --format lab'.",
             "# docs/your-joint.md explains every key.", "[joint]",
             f"counts_per_rev = {spec.counts_per_rev}", f"gear_ratio = {spec.gear_ratio!r}",
             f"index_pulse = {'true' if has_index else 'false'}", f"rated_torque = {spec.rated_torque!r}",
             f"torque_constant = {spec.torque_constant!r}", f"rotor_inertia = {spec.rotor_inertia!r}",
             f"control_rate = {spec.control_rate!r}", "", "[joint.columns]"]
    for name, (column, unit, _factor) in LAB_COLUMNS.items():
        if name != "index" or has_index:
            lines.append(f'{name} = {{column = "{column}", unit = "{unit}"}}')
    lines += [f'torque_ref = {{column = "{REFERENCE_COLUMNS[kind]}", unit = "Nm"}}', "",
              "[joint.reference]", f'kind = "{kind}"']
    return "\n".join(lines) + "\n"


def write_joint_toml(text: str, path: Path) -> Path:
    """Write ``text`` to ``path``; an existing file that says something else is kept and refused."""
    if path.is_file() and path.read_text(encoding="utf-8", errors="replace") != text:
        raise InputError(f"{path}: exists and describes another joint, columns or reference; move it away, or "
                         f"write the log into another directory")
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return path
