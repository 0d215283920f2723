"""Regions of space and fields given as data: unions of boxes, or numpy expressions of x, y, z.

Scenario files describe where bodies are seeded, which grid nodes a wall holds and where a
sink absorbs particles with these, instead of Python predicates.
"""

from types import CodeType

import numpy as np

__all__ = ["FUNCTIONS", "Expression", "Region"]

#: Names an expression may use besides the coordinates ``x, y, z`` [m].
FUNCTIONS = {
    "pi": np.pi, "e": np.e, "inf": np.inf,
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "arctan2": np.arctan2, "hypot": np.hypot,
    "minimum": np.minimum, "maximum": np.maximum, "where": np.where,
}  # fmt: skip
_COORDINATES = ("x", "y", "z")


class Expression:
    """A numpy expression of the coordinates, e.g. ``"0.01 * sin(pi * x / 2)"`` or ``"y < 0.2"``.

    Only the coordinates and :data:`FUNCTIONS` are visible: no builtins, no attributes, no
    lambdas. Combine conditions with ``&``, ``|`` and ``~`` (they act on arrays).

    Raises:
        ValueError: a syntax error or a name that is not allowed, at construction.

    """

    def __init__(self, text: str):
        self.text = text
        try:
            self._code = compile(text, "<expression>", "eval")
        except SyntaxError as e:
            raise ValueError(f"invalid expression {text!r}: {e.msg}") from None
        unknown = sorted(set(self._code.co_names) - set(FUNCTIONS) - set(_COORDINATES))
        if unknown or any(isinstance(c, CodeType) for c in self._code.co_consts):
            allowed = ", ".join([*_COORDINATES, *FUNCTIONS])
            raise ValueError(
                f"expression {text!r} may only use {allowed}; got {', '.join(unknown) or 'a lambda'}"
            )

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The value at the points ``x`` (``shape=(3, n)``), ``shape=(n,)``."""
        names = {**FUNCTIONS, **dict(zip(_COORDINATES, x))}
        value = eval(self._code, {"__builtins__": {}}, names)  # names checked in __init__
        return np.broadcast_to(np.asarray(value), (x.shape[1],))


class Region:
    """Points in a union of closed axis-aligned boxes, or where an expression holds.

    Args:
        boxes: ``(lower, upper)`` corners [m], each ``shape=(gdim,)``; ``-inf``/``inf`` for
            unbounded sides. A point inside any box (within ``tol``) is in the region.
        expression: a boolean :class:`Expression` instead of boxes.
        tol: how far outside a box a point may lie [m] (nodes on a wall's line).

    """

    def __init__(self, boxes=(), expression: Expression | None = None, tol: float = 0.0):
        self.boxes = [(np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes]
        self.expression, self.tol = expression, tol

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Mask of the points ``x`` (``shape=(3, n)``) in the region, ``shape=(n,)``."""
        if self.expression is not None:
            return np.asarray(self.expression(x), dtype=bool)
        inside = np.zeros(x.shape[1], dtype=bool)
        for lo, hi in self.boxes:
            xd = x[: len(lo)].T
            inside |= np.all((xd >= lo - self.tol) & (xd <= hi + self.tol), axis=1)
        return inside
