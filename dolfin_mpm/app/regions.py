"""Regions of space and fields given as data: unions of boxes, or numpy expressions of x, y, z.

Scenario files describe where bodies are seeded, which grid nodes a wall holds and where a
sink absorbs particles with these, instead of Python predicates.

An expression is read as Python syntax but only a small part of it is accepted (checked on the
syntax tree before anything runs): the coordinates, numbers, the names of :data:`FUNCTIONS`,
arithmetic, comparisons, ``&``, ``|``, ``~`` and calls with positional arguments. Its length,
its nesting and its powers are bounded, so that reading and evaluating it cannot hang or
exhaust memory, and it is evaluated on copies of the coordinates.
"""

import ast
import warnings

import numpy as np

__all__ = ["FUNCTIONS", "MAX_EXPONENT", "MAX_LENGTH", "Expression", "Region"]

#: Names an expression may use besides the coordinates ``x, y, z`` [m].
FUNCTIONS = {
    "pi": np.pi, "e": np.e, "inf": np.inf,
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "arctan2": np.arctan2, "hypot": np.hypot,
    "minimum": np.minimum, "maximum": np.maximum, "where": np.where,
}  # fmt: skip
#: How many arguments each function takes (a numpy function given one more writes its result
#: into that argument).
_ARITY = {name: 1 for name in ("abs", "sqrt", "exp", "log", "sin", "cos", "tan")} | {
    "arctan2": 2, "hypot": 2, "minimum": 2, "maximum": 2, "where": 3,
}  # fmt: skip
_COORDINATES = ("x", "y", "z")
#: Longest expression [characters].
MAX_LENGTH = 1000
#: Largest literal exponent of ``**`` (a power of whole numbers is computed exactly: ``10**10**10``
#: would not finish).
MAX_EXPONENT = 100
#: Deepest nesting of operations.
_MAX_DEPTH = 100

_OPERATORS = (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.FloorDiv, ast.Mod, ast.Pow, ast.BitAnd, ast.BitOr)
_COMPARISONS = (ast.Lt, ast.LtE, ast.Gt, ast.GtE, ast.Eq, ast.NotEq)
_LOGIC = "combine conditions with & | ~ and put each comparison in parentheses, e.g. (y < 0.2) & (x > 0.1)"


def _literal(node) -> float | None:
    """The value of a number or a signed number, else ``None``."""
    sign = 1.0
    while isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        sign = -sign if isinstance(node.op, ast.USub) else sign
        node = node.operand
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
        try:
            return sign * float(node.value)
        except OverflowError:
            return sign * np.inf
    return None


def _condition_operand(node) -> bool:
    """Whether ``node`` is an ``&``/``|`` that a comparison took as its operand (no parentheses)."""
    return isinstance(node, ast.BinOp) and isinstance(node.op, (ast.BitAnd, ast.BitOr))


def _check(tree: ast.Expression) -> str | None:
    """Why the syntax tree is not allowed, or ``None``."""
    stack = [(tree.body, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > _MAX_DEPTH:
            return f"is nested more than {_MAX_DEPTH} operations deep"
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool):
                continue
            if not isinstance(node.value, (int, float)):
                return f"may not contain {node.value!r}: only numbers"
            try:
                float(node.value)
            except OverflowError:
                return f"has a number too large: {str(node.value)[:20]}..."
            continue
        if isinstance(node, ast.Name):
            if node.id in _ARITY:
                return f"uses the function {node.id} without calling it"
            if node.id not in FUNCTIONS and node.id not in _COORDINATES:
                allowed = ", ".join([*_COORDINATES, *FUNCTIONS])
                return f"may only use {allowed}; got {node.id}"
            continue
        if isinstance(node, ast.BoolOp) or (isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not)):
            word = "not" if isinstance(node, ast.UnaryOp) else type(node.op).__name__.lower()
            return f"uses {word!r}, which does not act on arrays: {_LOGIC}"
        if isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, (ast.USub, ast.UAdd, ast.Invert)):
                return f"may not use the operator {type(node.op).__name__}"
            children = [node.operand]
        elif isinstance(node, ast.BinOp):
            if isinstance(node.op, ast.BitXor):
                return "uses ^, which is not a power here: write x**2 for a square"
            if not isinstance(node.op, _OPERATORS):
                return f"may not use the operator {type(node.op).__name__}"
            if isinstance(node.op, ast.Pow):
                exponent = _literal(node.right)
                if any(isinstance(n, ast.BinOp) and isinstance(n.op, ast.Pow) for n in ast.walk(node.right)):
                    return "has a power in an exponent: write the exponent out"
                if exponent is not None and not abs(exponent) <= MAX_EXPONENT:
                    return f"has an exponent beyond +-{MAX_EXPONENT}: {exponent:g}"
            children = [node.left, node.right]
        elif isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(map(_condition_operand, operands)):
                return f"compares a result of & or | (they bind before comparisons): {_LOGIC}"
            if len(node.ops) > 1:
                return f"chains comparisons (a < b < c), which does not act on arrays: {_LOGIC}"
            if not all(isinstance(op, _COMPARISONS) for op in node.ops):
                return f"may not use the comparison {type(node.ops[0]).__name__}"
            children = operands
        elif isinstance(node, ast.Call):
            name = node.func.id if isinstance(node.func, ast.Name) else None
            if name not in _ARITY:
                what = name if name in FUNCTIONS or name in _COORDINATES else None
                if what is not None:
                    return f"calls {what}, which is not a function (functions: {', '.join(_ARITY)})"
                return f"may only call {', '.join(_ARITY)}"
            if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
                return f"calls {name} with keyword or starred arguments: only plain ones are allowed"
            if len(node.args) != _ARITY[name]:
                n = _ARITY[name]
                return f"calls {name} with {len(node.args)} arguments, it takes {n}"
            children = node.args
        else:
            kind = {
                ast.Attribute: "attributes (a.b)", ast.Subscript: "subscripts (a[i])",
                ast.Lambda: "a lambda", ast.IfExp: "if/else (use where(condition, a, b))",
                ast.NamedExpr: "assignments", ast.Tuple: "tuples", ast.List: "lists",
            }.get(type(node), type(node).__name__)  # fmt: skip
            return f"may not use {kind}"
        stack.extend((child, depth + 1) for child in children)
    return None


class _Floats(ast.NodeTransformer):
    def visit_Constant(self, node):
        if isinstance(node.value, int) and not isinstance(node.value, bool):
            return ast.copy_location(ast.Constant(float(node.value)), node)
        return node


class Expression:
    """A numpy expression of the coordinates, e.g. ``"0.01 * sin(pi * x / 2)"`` or ``"y < 0.2"``.

    Only the coordinates and :data:`FUNCTIONS` are visible: no builtins, no attributes, no
    subscripts, no lambdas, no keyword arguments. Combine conditions with ``&``, ``|`` and
    ``~`` (they act on arrays), each comparison in parentheses: ``(y < 0.2) & (x > 0.1)``.
    At most :data:`MAX_LENGTH` characters; a literal exponent at most :data:`MAX_EXPONENT`.

    Raises:
        ValueError: a syntax error or anything not allowed, at construction.

    """

    def __init__(self, text: str):
        self.text = text
        if not isinstance(text, str):
            raise ValueError(f"an expression must be a string, got {text!r}")
        if len(text) > MAX_LENGTH:
            raise ValueError(f"expression is {len(text)} characters long, at most {MAX_LENGTH} allowed")
        shown = text if len(text) <= 80 else text[:77] + "..."
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # Python's warnings on the text (~ of a bool) refuse it
                tree = ast.parse(text.strip(), "<expression>", "eval")
                problem = _check(tree)
                if problem is None:
                    # Whole numbers as floats: no exact (unbounded) integer arithmetic at run time.
                    tree = ast.fix_missing_locations(_Floats().visit(tree))
                    self._code = compile(tree, "<expression>", "eval")
        except Warning as e:
            raise ValueError(f"invalid expression {shown!r}: {e}") from None
        except SyntaxError as e:
            raise ValueError(f"invalid expression {shown!r}: {e.msg}") from None
        except (RecursionError, MemoryError):
            raise ValueError(f"invalid expression {shown!r}: nested too deeply") from None
        except ValueError as e:  # a null character
            raise ValueError(f"invalid expression {shown!r}: {e}") from None
        if problem is not None:
            raise ValueError(f"expression {shown!r} {problem}")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The value at the points ``x`` (``shape=(3, n)``), ``shape=(n,)``.

        Raises:
            ValueError: the expression fails on these points (``"1 / 0"``, a power too large).

        """
        x = np.asarray(x, dtype=np.float64)
        names = {**FUNCTIONS, **{c: x[i].copy() for i, c in enumerate(_COORDINATES)}}
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("error")  # numpy's warnings (+ of a condition) are failures
                value = eval(self._code, {"__builtins__": {}}, names)  # the tree checked in __init__
            return np.array(np.broadcast_to(np.asarray(value), (x.shape[1],)))  # own memory: DOLFINx reads it
        except (ArithmeticError, TypeError, ValueError, MemoryError, Warning) as e:
            raise ValueError(f"expression {self.text!r} fails: {e}") from None

    def numbers(self, x: np.ndarray) -> np.ndarray:
        """Finite numbers at the points ``x`` (``shape=(3, n)``), ``shape=(n,)`` (a field).

        Raises:
            ValueError: a condition instead of numbers, or a value that is not finite.

        """
        value = self(x)
        if not (np.issubdtype(value.dtype, np.floating) or np.issubdtype(value.dtype, np.integer)):
            raise ValueError(f"expression {self.text!r} must give real numbers, not {value.dtype}")
        value = value.astype(np.float64)
        bad = np.flatnonzero(~np.isfinite(value))
        if bad.size:
            at = ", ".join(f"{a:g}" for a in x[:, bad[0]])
            raise ValueError(f"expression {self.text!r} is {value[bad[0]]} at ({at}), not a finite number")
        return value

    def condition(self, x: np.ndarray) -> np.ndarray:
        """Where it holds at the points ``x`` (``shape=(3, n)``), ``shape=(n,)`` (a region).

        Raises:
            ValueError: numbers instead of a condition.

        """
        value = self(x)
        if value.dtype != bool:
            raise ValueError(
                f"expression {self.text!r} must be a condition (a comparison, or comparisons "
                "combined with & | ~), not numbers"
            )
        return value


class Region:
    """Points in a union of closed axis-aligned boxes, or where an expression holds.

    Args:
        boxes: ``(lower, upper)`` corners [m], each ``shape=(gdim,)``; ``-inf``/``inf`` for
            unbounded sides. A point inside any box (within ``tol``) is in the region.
        expression: a boolean :class:`Expression` instead of boxes.
        tol: how far outside a box a point may lie [m] (nodes on a wall's line).

    Raises:
        ValueError: a NaN corner, a lower corner at ``inf`` or an upper one at ``-inf``.

    """

    def __init__(self, boxes=(), expression: Expression | None = None, tol: float = 0.0):
        self.boxes = [(np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes]
        for lo, hi in self.boxes:
            if np.isnan(lo).any() or np.isnan(hi).any() or (lo == np.inf).any() or (hi == -np.inf).any():
                raise ValueError(f"box corners must be numbers, min not inf, max not -inf: {lo}, {hi}")
        self.expression, self.tol = expression, tol

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Mask of the points ``x`` (``shape=(3, n)``) in the region, ``shape=(n,)``."""
        if self.expression is not None:
            return self.expression.condition(x)
        inside = np.zeros(x.shape[1], dtype=bool)
        for lo, hi in self.boxes:
            xd = x[: len(lo)].T
            inside |= np.all((xd >= lo - self.tol) & (xd <= hi + self.tol), axis=1)
        return inside
