"""Parameter ranges: the one place that says which values a number may take.

A :class:`Range` checks a value (``ValueError`` naming the parameter) and describes itself
for messages. Dataclasses declare their parameters once with :func:`parameter`, a field that
carries its range; :func:`check_fields` validates an instance and :func:`parameters` lists the
fields with their ranges and defaults (what a scenario file validates against).

::

    @dataclass(frozen=True)
    class Soil:
        phi: float = parameter(0.0, 90.0, "degrees")

    Soil(phi=120)  # ValueError: phi must be in (0, 90) degrees, got 120

Pure Python and numpy: no DOLFINx, no MPI.
"""

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

__all__ = ["Parameter", "Range", "check_fields", "check_range", "parameter", "parameters"]


@dataclass(frozen=True)
class Range:
    """The interval a number must lie in, ``(low, high)`` open unless ``closed`` says otherwise.

    Attributes:
        low, high: bounds (``math.inf`` for none).
        unit: the unit shown in messages (``"Pa"``, ``"degrees"``; ``""`` for none).
        closed: whether ``low`` and ``high`` belong to the interval.

    """

    low: float
    high: float
    unit: str = ""
    closed: tuple[bool, bool] = (False, False)

    def contains(self, value) -> bool:
        """Whether ``value`` lies in the interval (never for NaN nor a non-number)."""
        try:
            lo_ok = value >= self.low if self.closed[0] else value > self.low
            hi_ok = value <= self.high if self.closed[1] else value < self.high
            return bool(lo_ok and hi_ok)
        except TypeError:
            return False

    def interval(self) -> str:
        """The interval in brackets, ``(0, 90)``, ``[0, inf)``."""
        left, right = "[" if self.closed[0] else "(", "]" if self.closed[1] else ")"
        return f"{left}{self.low:g}, {self.high:g}{right}"

    def describe(self) -> str:
        """What a value must be, with the unit: ``must be > 0 Pa``, ``must be in (0, 90) degrees``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.high == math.inf and not self.closed[1]:
            return f"must be {'>=' if self.closed[0] else '>'} {self.low:g}{unit}"
        return f"must be in {self.interval()}{unit}"

    def check(self, name: str, value) -> None:
        """Raise ``ValueError`` naming ``name`` unless ``value`` lies in the interval.

        The message reads ``phi must be in (0, 90) degrees, got 120``.
        """
        if not self.contains(value):
            unit = f" {self.unit}" if self.unit else ""
            raise ValueError(f"{name} must be in {self.interval()}{unit}, got {value!r}")


def check_range(name: str, value: float, low: float, high: float, *, closed=(False, False)) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``value`` lies in the given interval."""
    Range(low, high, closed=tuple(closed)).check(name, value)


class Parameter(NamedTuple):
    """A ranged dataclass field: its range and default (``required`` when it has none)."""

    range: Range
    default: Any = None
    required: bool = True


def parameter(low: float, high: float, unit: str = "", *, closed=(False, False),
              default: Any = dataclasses.MISSING) -> Any:  # fmt: skip
    """A dataclass field whose values must lie in ``Range(low, high, unit, closed)``.

    ``default`` as for :func:`dataclasses.field`; a default of ``None`` means "not given" and
    is not checked.
    """
    return dataclasses.field(default=default, metadata={"range": Range(low, high, unit, tuple(closed))})


def parameters(cls) -> dict[str, Parameter]:
    """The ranged fields of the dataclass ``cls`` (or an instance), in declaration order."""
    out = {}
    for f in dataclasses.fields(cls):
        if "range" in f.metadata:
            required = f.default is dataclasses.MISSING
            out[f.name] = Parameter(f.metadata["range"], None if required else f.default, required)
    return out


def check_fields(obj) -> None:
    """Check every ranged field of the dataclass instance ``obj``, in declaration order.

    Raises ``ValueError`` naming the first field out of its range; an optional field
    (default ``None``) may be ``None``.
    """
    for name, p in parameters(obj).items():
        value = getattr(obj, name)
        if not (value is None and not p.required and p.default is None):
            p.range.check(name, value)
