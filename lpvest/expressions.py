"""Safe arithmetic formulas for model files.

Model files (TOML) write scheduling basis functions (``"theta^2"``), maps to
the simplex (``"(1 - theta)/2"``), time-varying coefficients
(``"t**2 + 1"``), rational gains (``"(1 - shift(p, 1))/shift(p, 1)"``) and
parametrised matrix entries (``"-0.05*rho"``) as text. This module turns such
text into a callable over numpy arrays *without executing code*: the formula is
parsed with :mod:`ast` and only numbers, names, ``+ - * / **`` (``^`` is read as
a power), unary signs and a fixed list of numpy functions are accepted.

Why not sympy: a model file must not be able to run code (sympy's parser calls
``eval``), and the FMUs evaluate these formulas where only numpy is installed.
The derivative, needed by the LTV kernels, is a small symbolic rule set here.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import ExpressionError

__all__ = ["Expression", "FormulaMatrix", "FormulaVector", "FUNCTIONS", "CONSTANTS", "shift_name"]

#: Functions a formula may call (numpy ufuncs, so formulas work on arrays).
FUNCTIONS: dict[str, Any] = {
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "exp": np.exp,
    "log": np.log,
    "sqrt": np.sqrt,
    "sinh": np.sinh,
    "cosh": np.cosh,
    "tanh": np.tanh,
    "arctan": np.arctan,
    "abs": np.abs,
}
#: Named constants a formula may use.
CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e}

_BINOPS = (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow)
# the only globals a formula sees: the whitelisted functions, no builtins
_GLOBALS: dict[str, Any] = {"__builtins__": {}, **FUNCTIONS}
_SHIFT_PREFIX = "__shift__"


def shift_name(name: str, k: int) -> str:
    """The variable name that stands for ``shift(name, k)`` (``name`` at ``t + k``)."""
    return f"{_SHIFT_PREFIX}{name}__{'m' if k < 0 else 'p'}{abs(k)}"


def _unshift(var: str) -> tuple[str, int]:
    body = var[len(_SHIFT_PREFIX) :]
    name, _, k = body.rpartition("__")
    return name, (-1 if k[0] == "m" else 1) * int(k[1:])


class _Validator(ast.NodeTransformer):
    """Check a parsed formula against the whitelist; rewrite
    ``shift(p, k)`` to a plain name and parameters to their values."""

    def __init__(self, text: str, parameters: Mapping[str, float]) -> None:
        self.text = text
        self.parameters = parameters

    def fail(self, what: str) -> ExpressionError:
        return ExpressionError(f"formula {self.text!r}: {what}")

    def visit_Expression(self, node: ast.Expression) -> ast.AST:
        node.body = self.visit(node.body)
        return node

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        if not isinstance(node.op, _BINOPS):
            raise self.fail(f"operator {type(node.op).__name__} is not allowed")
        node.left = self.visit(node.left)
        node.right = self.visit(node.right)
        return node

    def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
        if not isinstance(node.op, ast.USub | ast.UAdd):
            raise self.fail(f"operator {type(node.op).__name__} is not allowed")
        node.operand = self.visit(node.operand)
        return node

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        if isinstance(node.value, bool) or not isinstance(node.value, int | float):
            raise self.fail(f"constant {node.value!r} is not a number")
        return node

    def visit_Name(self, node: ast.Name) -> ast.AST:
        if node.id.startswith("__"):
            raise self.fail(f"name {node.id!r} is not allowed")
        if node.id in self.parameters:
            return ast.copy_location(ast.Constant(float(self.parameters[node.id])), node)
        if node.id in CONSTANTS:
            return ast.copy_location(ast.Constant(CONSTANTS[node.id]), node)
        if node.id in FUNCTIONS:
            raise self.fail(f"function {node.id!r} used without arguments")
        return node

    def visit_Call(self, node: ast.Call) -> ast.AST:
        if not isinstance(node.func, ast.Name) or node.keywords:
            raise self.fail("only calls like sin(x) are allowed")
        fname = node.func.id
        if fname == "shift":
            ok = (
                len(node.args) == 2
                and isinstance(node.args[0], ast.Name)
                and _int_literal(node.args[1]) is not None
            )
            if not ok:
                raise self.fail("shift takes a variable and an integer, e.g. shift(p, 1)")
            k = _int_literal(node.args[1])
            assert k is not None
            return ast.copy_location(ast.Name(shift_name(node.args[0].id, k), ast.Load()), node)
        if fname not in FUNCTIONS:
            raise self.fail(
                f"unknown function {fname!r}; allowed: {', '.join(sorted(FUNCTIONS))}, shift"
            )
        if len(node.args) != 1:
            raise self.fail(f"{fname} takes one argument")
        node.args = [self.visit(node.args[0])]
        return node

    def generic_visit(self, node: ast.AST) -> ast.AST:
        raise self.fail(f"{type(node).__name__} is not allowed in a formula")


def _int_literal(node: ast.AST) -> int | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, int):
        return int(node.value)
    if (
        isinstance(node, ast.UnaryOp)
        and isinstance(node.op, ast.USub | ast.UAdd)
        and isinstance(node.operand, ast.Constant)
        and isinstance(node.operand.value, int)
    ):
        return -int(node.operand.value) if isinstance(node.op, ast.USub) else int(node.operand.value)
    return None


def _free_names(tree: ast.AST) -> frozenset[str]:
    return frozenset(
        n.id
        for n in ast.walk(tree)
        if isinstance(n, ast.Name) and n.id not in FUNCTIONS and isinstance(n.ctx, ast.Load)
    )


@dataclass(frozen=True, eq=False)
class Expression:
    """A validated formula, callable on numpy arrays.

    Examples
    --------
    >>> f = Expression.parse("t**2 + 1")
    >>> float(f(t=2.0))
    5.0
    >>> float(f.derivative("t")(t=2.0))
    4.0
    >>> g = Expression.parse("(1 - shift(p, 1)) / shift(p, 1)")
    >>> sorted(g.shifts["p"])
    [1]
    """

    text: str
    tree: ast.Expression = field(repr=False)
    _code: Any = field(repr=False)
    _names: frozenset[str] = field(repr=False, default=frozenset())

    @classmethod
    def parse(
        cls,
        text: str | float | int,
        *,
        parameters: Mapping[str, float] | None = None,
        allowed: Iterable[str] | None = None,
    ) -> Expression:
        """Parse ``text`` into an :class:`Expression`.

        Parameters
        ----------
        text : str or number
            The formula; a number gives a constant expression.
        parameters : mapping, optional
            Named constants substituted at parse time (model parameters such as
            ``rho``).
        allowed : iterable of str, optional
            Variable names the formula may use; any other name is an error.
        """
        if isinstance(text, bool) or not isinstance(text, str | int | float):
            raise ExpressionError(f"formula {text!r} is neither text nor a number")
        src = repr(float(text)) if not isinstance(text, str) else text
        try:
            # '^' is a power (math notation); replaced before parsing so that it
            # binds like '**' (Python's '^' binds looser than '*')
            tree = ast.parse(src.strip().replace("^", "**"), mode="eval")
        except SyntaxError as exc:
            raise ExpressionError(f"formula {src!r} is not valid: {exc.msg}") from exc
        tree = _Validator(src, dict(parameters or {})).visit(tree)
        ast.fix_missing_locations(tree)
        expr = cls._from_tree(src, tree)
        if allowed is not None:
            allowed = set(allowed)
            unknown = sorted(
                (_unshift(n)[0] if n.startswith(_SHIFT_PREFIX) else n)
                for n in expr.names
                if (_unshift(n)[0] if n.startswith(_SHIFT_PREFIX) else n) not in allowed
            )
            if unknown:
                known = ", ".join(sorted(allowed)) or "none"
                raise ExpressionError(
                    f"formula {src!r} uses unknown name {unknown[0]!r} (known: {known})"
                )
        return expr

    @classmethod
    def _from_tree(cls, text: str, tree: ast.Expression) -> Expression:
        code = compile(tree, "<lpvest formula>", "eval")
        return cls(text, tree, code, _free_names(tree))

    @classmethod
    def constant(cls, value: float) -> Expression:
        """The constant formula ``value``."""
        return cls.parse(float(value))

    # -- inspection -----------------------------------------------------------
    @property
    def names(self) -> frozenset[str]:
        """Free variable names (shifted variables under their internal names)."""
        return self._names

    @property
    def shifts(self) -> dict[str, set[int]]:
        """For each variable, the time shifts it is used with (0 = unshifted)."""
        out: dict[str, set[int]] = {}
        for n in self.names:
            name, k = _unshift(n) if n.startswith(_SHIFT_PREFIX) else (n, 0)
            out.setdefault(name, set()).add(k)
        return out

    @property
    def is_constant(self) -> bool:
        return not self.names

    @property
    def source(self) -> str:
        """The formula as canonical text (``shift`` restored)."""
        text = ast.unparse(self.tree)
        for n in self.names:
            if n.startswith(_SHIFT_PREFIX):
                name, k = _unshift(n)
                text = text.replace(n, f"shift({name}, {k})")
        return text

    def __str__(self) -> str:
        return self.text

    # -- evaluation -----------------------------------------------------------
    def __call__(self, **values: Any) -> Any:
        return self.evaluate(values)

    def evaluate(self, values: Mapping[str, Any]) -> Any:
        """Evaluate with ``values`` for the free names (arrays broadcast)."""
        missing = self._names - values.keys()
        if missing:
            n = sorted(missing)[0]
            shown = f"shift({_unshift(n)[0]}, {_unshift(n)[1]})" if n.startswith(_SHIFT_PREFIX) else n
            raise ExpressionError(f"formula {self.text!r} needs a value for {shown!r}")
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return eval(self._code, _GLOBALS, values)  # noqa: S307 (whitelisted AST)

    def value(self) -> float:
        """The value of a constant formula."""
        if not self.is_constant:
            raise ExpressionError(
                f"formula {self.text!r} must be a constant here but uses {sorted(self.names)}"
            )
        return float(self.evaluate({}))

    # -- calculus -------------------------------------------------------------
    def derivative(self, var: str) -> Expression:
        """The symbolic derivative with respect to ``var``."""
        d = _simplify(_diff(self.tree.body, var))
        tree = ast.fix_missing_locations(ast.Expression(d))
        return Expression._from_tree(f"d/d{var}({self.text})", tree)

    def monomial_exponents(self, names: tuple[str, ...]) -> tuple[int, ...] | None:
        """If the formula is a product of ``names`` to non-negative integer
        powers (coefficient 1), their exponents; otherwise ``None``."""
        exps = [0] * len(names)
        index = {n: i for i, n in enumerate(names)}

        def walk(node: ast.AST) -> bool:
            if isinstance(node, ast.Name) and node.id in index:
                exps[index[node.id]] += 1
                return True
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
                return walk(node.left) and walk(node.right)
            if (
                isinstance(node, ast.BinOp)
                and isinstance(node.op, ast.Pow)
                and isinstance(node.left, ast.Name)
                and node.left.id in index
                and isinstance(node.right, ast.Constant)
                and float(node.right.value).is_integer()
                and node.right.value >= 0
            ):
                exps[index[node.left.id]] += int(node.right.value)
                return True
            return False

        return tuple(exps) if walk(self.tree.body) else None


# -- symbolic differentiation ------------------------------------------------


def _c(v: float) -> ast.Constant:
    return ast.Constant(float(v))


def _is_c(node: ast.AST, v: float | None = None) -> bool:
    return isinstance(node, ast.Constant) and (v is None or node.value == v)


def _bin(left: ast.expr, op: ast.operator, right: ast.expr) -> ast.expr:
    return ast.BinOp(left, op, right)


def _call(fname: str, arg: ast.expr) -> ast.expr:
    return ast.Call(ast.Name(fname, ast.Load()), [arg], [])


def _neg(x: ast.expr) -> ast.expr:
    return ast.UnaryOp(ast.USub(), x)


def _diff(node: ast.expr, var: str) -> ast.expr:
    if isinstance(node, ast.Constant):
        return _c(0.0)
    if isinstance(node, ast.Name):
        return _c(1.0 if node.id == var else 0.0)
    if isinstance(node, ast.UnaryOp):
        d = _diff(node.operand, var)
        return _neg(d) if isinstance(node.op, ast.USub) else d
    if isinstance(node, ast.BinOp):
        u, v = node.left, node.right
        du, dv = _diff(u, var), _diff(v, var)
        if isinstance(node.op, ast.Add):
            return _bin(du, ast.Add(), dv)
        if isinstance(node.op, ast.Sub):
            return _bin(du, ast.Sub(), dv)
        if isinstance(node.op, ast.Mult):
            return _bin(_bin(du, ast.Mult(), v), ast.Add(), _bin(u, ast.Mult(), dv))
        if isinstance(node.op, ast.Div):
            num = _bin(_bin(du, ast.Mult(), v), ast.Sub(), _bin(u, ast.Mult(), dv))
            return _bin(num, ast.Div(), _bin(v, ast.Pow(), _c(2.0)))
        if isinstance(node.op, ast.Pow):
            if _is_c(_simplify(dv), 0.0):  # u**c
                c = v
                return _bin(
                    _bin(c, ast.Mult(), _bin(u, ast.Pow(), _bin(c, ast.Sub(), _c(1.0)))),
                    ast.Mult(),
                    du,
                )
            # u**v = exp(v log u)
            inner = _bin(
                _bin(dv, ast.Mult(), _call("log", u)),
                ast.Add(),
                _bin(v, ast.Mult(), _bin(du, ast.Div(), u)),
            )
            return _bin(node, ast.Mult(), inner)
    if isinstance(node, ast.Call):
        assert isinstance(node.func, ast.Name)
        f, u = node.func.id, node.args[0]
        du = _diff(u, var)
        outer: dict[str, ast.expr] = {
            "sin": _call("cos", u),
            "cos": _neg(_call("sin", u)),
            "tan": _bin(_c(1.0), ast.Add(), _bin(_call("tan", u), ast.Pow(), _c(2.0))),
            "exp": _call("exp", u),
            "log": _bin(_c(1.0), ast.Div(), u),
            "sqrt": _bin(_c(0.5), ast.Div(), _call("sqrt", u)),
            "sinh": _call("cosh", u),
            "cosh": _call("sinh", u),
            "tanh": _bin(_c(1.0), ast.Sub(), _bin(_call("tanh", u), ast.Pow(), _c(2.0))),
            "arctan": _bin(_c(1.0), ast.Div(), _bin(_c(1.0), ast.Add(), _bin(u, ast.Pow(), _c(2.0)))),
        }
        if f == "abs":
            return _bin(_bin(u, ast.Div(), _call("abs", u)), ast.Mult(), du)
        return _bin(outer[f], ast.Mult(), du)
    raise ExpressionError(f"cannot differentiate {ast.unparse(node)!r}")  # pragma: no cover


def _simplify(node: ast.expr) -> ast.expr:
    """Fold the zeros and ones that differentiation leaves behind."""
    if isinstance(node, ast.UnaryOp):
        x = _simplify(node.operand)
        if _is_c(x):
            return _c(-x.value if isinstance(node.op, ast.USub) else x.value)  # type: ignore[attr-defined]
        return ast.UnaryOp(node.op, x)
    if isinstance(node, ast.BinOp):
        a, b = _simplify(node.left), _simplify(node.right)
        op = node.op
        if _is_c(a) and _is_c(b):
            try:
                val = eval(  # noqa: S307 (two numeric constants)
                    compile(ast.fix_missing_locations(ast.Expression(ast.BinOp(a, op, b))), "", "eval")
                )
                return _c(val)
            except (ZeroDivisionError, OverflowError, ValueError):
                return ast.BinOp(a, op, b)
        if isinstance(op, ast.Add):
            if _is_c(a, 0.0):
                return b
            if _is_c(b, 0.0):
                return a
        if isinstance(op, ast.Sub):
            if _is_c(b, 0.0):
                return a
            if _is_c(a, 0.0):
                return _neg(b)
        if isinstance(op, ast.Mult):
            if _is_c(a, 0.0) or _is_c(b, 0.0):
                return _c(0.0)
            if _is_c(a, 1.0):
                return b
            if _is_c(b, 1.0):
                return a
        if isinstance(op, ast.Div):
            if _is_c(a, 0.0):
                return _c(0.0)
            if _is_c(b, 1.0):
                return a
        if isinstance(op, ast.Pow):
            if _is_c(b, 1.0):
                return a
            if _is_c(b, 0.0):
                return _c(1.0)
        return ast.BinOp(a, op, b)
    if isinstance(node, ast.Call):
        return ast.Call(node.func, [_simplify(node.args[0])], [])
    return node


@dataclass(frozen=True, eq=False)
class FormulaMatrix:
    """A matrix whose entries are formulas (numbers are constant formulas).

    Examples
    --------
    >>> K = FormulaMatrix.parse([["(1 - shift(p, 1)) / shift(p, 1)"]], allowed=["p"])
    >>> K.shape, K.shifts
    ((1, 1), {'p': {1}})
    >>> K.evaluate({shift_name("p", 1): 0.5})
    array([[1.]])
    """

    entries: tuple[tuple[Expression, ...], ...]

    @classmethod
    def parse(
        cls,
        rows: Any,
        *,
        name: str = "matrix",
        parameters: Mapping[str, float] | None = None,
        allowed: Iterable[str] | None = None,
    ) -> FormulaMatrix:
        """Parse a list of rows of formulas/numbers (a bare number or formula is 1x1)."""
        if isinstance(rows, str | int | float):
            rows = [[rows]]
        if not isinstance(rows, list | tuple) or not rows or not all(
            isinstance(r, list | tuple) for r in rows
        ):
            raise ExpressionError(f"{name} must be a list of rows, e.g. [[1, 0], [0, 'p']]")
        width = len(rows[0])
        if any(len(r) != width for r in rows) or width == 0:
            shape = [len(r) for r in rows]
            raise ExpressionError(f"{name} has rows of lengths {shape}; expected equal, non-zero lengths")
        allowed = None if allowed is None else list(allowed)
        entries = []
        for i, r in enumerate(rows):
            row = []
            for j, v in enumerate(r):
                try:
                    row.append(Expression.parse(v, parameters=parameters, allowed=allowed))
                except ExpressionError as exc:
                    raise ExpressionError(f"{name}[{i + 1},{j + 1}]: {exc}") from exc
            entries.append(tuple(row))
        return cls(tuple(entries))

    @property
    def shape(self) -> tuple[int, int]:
        return len(self.entries), len(self.entries[0])

    @property
    def shifts(self) -> dict[str, set[int]]:
        out: dict[str, set[int]] = {}
        for row in self.entries:
            for e in row:
                for n, ks in e.shifts.items():
                    out.setdefault(n, set()).update(ks)
        return out

    @property
    def is_constant(self) -> bool:
        return all(e.is_constant for row in self.entries for e in row)

    def evaluate(self, values: Mapping[str, Any]) -> np.ndarray:
        """Evaluate every entry; array values give a stacked ``(..., rows, cols)``."""
        vals = [[e.evaluate(values) for e in row] for row in self.entries]
        shape = np.broadcast_shapes(*(np.shape(v) for row in vals for v in row))
        out = np.empty((*shape, *self.shape))
        for i, row in enumerate(vals):
            for j, v in enumerate(row):
                out[..., i, j] = v
        return out

    def derivative(self, var: str) -> FormulaMatrix:
        return FormulaMatrix(tuple(tuple(e.derivative(var) for e in row) for row in self.entries))

    def to_list(self) -> list[list[float | str]]:
        """Entries as numbers (constants) or formula text, for model files."""
        return [[e.value() if e.is_constant else e.source for e in row] for row in self.entries]


class FormulaVector:
    """Several formulas evaluated together by one compiled expression (the fast
    path for a per-sample evaluation, e.g. a simplex map inside an FMU).

    >>> v = FormulaVector([Expression.parse("(1 - x)/2"), Expression.parse("(1 + x)/2")])
    >>> v.evaluate({"x": 0.5})
    array([0.25, 0.75])
    """

    def __init__(self, formulas: Iterable[Expression]) -> None:
        self.formulas = tuple(formulas)
        body = ast.Tuple([f.tree.body for f in self.formulas], ast.Load())
        tree = ast.fix_missing_locations(ast.Expression(body))
        self._code = compile(tree, "<lpvest formulas>", "eval")
        self._names = frozenset().union(*(f.names for f in self.formulas))

    def evaluate(self, values: Mapping[str, Any]) -> np.ndarray:
        """The formulas' values, shape ``(n,)`` for scalar values or
        ``(*shape, n)`` for arrays of a common ``shape``."""
        missing = self._names - values.keys()
        if missing:
            for f in self.formulas:
                f.evaluate(values)  # raises naming the formula
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            vals = eval(self._code, _GLOBALS, values)  # noqa: S307 (whitelisted AST)
        if all(isinstance(v, float | int) for v in vals):
            return np.array(vals, dtype=float)
        shape = np.broadcast_shapes(*(np.shape(v) for v in vals))
        return np.stack([np.broadcast_to(v, shape) for v in vals], axis=-1).astype(float)
