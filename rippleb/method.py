"""The method plugin API: one small base class.

A method turns the sensor stream of one joint into a torque estimate, one control tick
at a time. The runner calls, in this order::

    method = MyMethod(**params)      # plain keyword arguments, no logic
    method.fit(calibration_log)      # once per device; may be a no-op
    method.reset(spec)               # before each evaluation run
    for block in log.blocks():       # blocks of fs/control_rate samples, in time order
        estimate = method.step(block)   # one torque value [Nm] per sample

Examples
--------
>>> import numpy as np
>>> from rippleb import Method
>>> class Zero(Method):
...     name = "zero"
...     def step(self, block):
...         return np.zeros(len(block))
"""

from __future__ import annotations

import numpy as np

from rippleb.data import JointSpec, SensorBlock, SensorLog


class Method:
    """Base class of every torque-ripple cancellation method.

    Subclasses set ``name`` (unique, kebab-case) and implement :meth:`step`; they
    override :meth:`fit` to identify parameters from the calibration log and
    :meth:`reset` to clear streaming state. Constructor parameters are plain keyword
    arguments stored as attributes (scikit-learn's rule): derive anything else in
    ``fit`` or ``reset``. A subclass may declare ``tunable = {"param": (low, high,
    "log" | "linear" | "int"), ...}``, the constructor parameters worth tuning on the
    calibration scenario and their ranges (``{}``: none); see docs/design.md.
    """

    name: str = ""
    #: One line for ``rippleb list``: what the method does, with its default parameter
    #: values written out. Empty: the first line of the class docstring, else of its module's.
    description: str = ""

    def fit(self, calibration: SensorLog) -> None:
        """Identify parameters from a calibration log of the same device.

        ``calibration.torque_ref`` holds the known torque; ``calibration.spec`` the joint.
        The default does nothing.
        """

    def reset(self, spec: JointSpec) -> None:
        """Clear the streaming state before a run on a joint described by ``spec``."""
        self.spec_ = spec

    def step(self, block: SensorBlock) -> np.ndarray:
        """Return one torque estimate [Nm] per sample of ``block``, causally."""
        raise NotImplementedError(f"{type(self).__name__}.step")

    def get_params(self) -> dict:
        """The constructor parameters, as given (for result provenance)."""
        import inspect

        names = [p for p in inspect.signature(type(self).__init__).parameters if p != "self"]
        return {n: getattr(self, n) for n in names if hasattr(self, n)}

    @classmethod
    def summary(cls) -> str:
        """What ``rippleb list`` says of the method: :attr:`description`, else the first line
        of the class docstring, else of its module's docstring."""
        import sys

        module = sys.modules.get(cls.__module__)
        return cls.description or first_line(cls.__doc__) or first_line(getattr(module, "__doc__", None))

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({params})"


def first_line(doc: str | None) -> str:
    """The first non-empty line of a docstring, without reST's double back-quotes."""
    lines = [line.strip() for line in (doc or "").strip().splitlines() if line.strip()]
    return lines[0].replace("``", "") if lines else ""
