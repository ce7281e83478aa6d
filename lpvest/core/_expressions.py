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
import copy
import math
import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ._errors import ExpressionError, abbreviate, shorten

if TYPE_CHECKING:
    from types import CodeType

    from numpy.typing import ArrayLike

__all__ = [
    "Expression",
    "FormulaMatrix",
    "FormulaVector",
    "FUNCTIONS",
    "CONSTANTS",
    "shift_name",
    "MAX_FORMULA_LENGTH",
    "MAX_FORMULA_DEPTH",
    "MAX_DERIVATIVE_SIZE",
]

#: Functions a formula may call (numpy ufuncs, so formulas work on arrays).
FUNCTIONS: dict[str, object] = {
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

#: The longest formula accepted (characters). Model formulas are a line; the
#: bound keeps parsing, differentiating and compiling a formula far below a
#: second, whatever the text.
MAX_FORMULA_LENGTH = 2000
#: The deepest nesting of operations accepted (``1+1+...+1`` with 100 terms, or
#: 100 nested calls). Python's parser and compiler recurse on the syntax tree;
#: the derivative roughly doubles the depth and must still compile.
MAX_FORMULA_DEPTH = 100

_BINOPS = (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow)
# ``a ** b`` is compiled as a call of numpy's power (see _compile)
_POWER = "__power__"
# the only globals a formula sees: the whitelisted functions, no builtins
_GLOBALS: dict[str, object] = {"__builtins__": {}, **FUNCTIONS, _POWER: np.power}
_SHIFT_PREFIX = "__shift__"


def shift_name(name: str, k: int) -> str:
    """The variable name that stands for ``shift(name, k)`` (``name`` at ``t + k``).

    Parameters
    ----------
    name : str
        The variable, e.g. ``"p"``.
    k : int
        The shift in samples (negative: the past).

    Returns
    -------
    var : str
        The internal name, e.g. ``"__shift__p__p1"`` for ``k = 1``, the key under
        which :meth:`Expression.evaluate` expects the shifted value.
    """
    return f"{_SHIFT_PREFIX}{name}__{'m' if k < 0 else 'p'}{abs(k)}"


def _unshift(var: str) -> tuple[str, int]:
    body = var[len(_SHIFT_PREFIX) :]
    name, _, k = body.rpartition("__")
    return name, (-1 if k[0] == "m" else 1) * int(k[1:])


def _shown(var: str) -> str:
    """A variable as the user wrote it: ``shift(p, 1)`` for the internal name of a shifted ``p``."""
    if var.startswith(_SHIFT_PREFIX):
        name, k = _unshift(var)
        return f"shift({name}, {k})"
    return var


def _depth(tree: ast.AST) -> int:
    """The nesting depth of a syntax tree, without recursion."""
    deepest = 0
    stack = [(tree, 1)]
    while stack:
        node, d = stack.pop()
        deepest = max(deepest, d)
        if d > MAX_FORMULA_DEPTH + 1:
            break
        stack.extend((child, d + 1) for child in ast.iter_child_nodes(node))
    return deepest


def _arithmetic_failure(exc: BaseException) -> str:
    """What went wrong in a floating-point evaluation, in words."""
    text = str(exc)
    if "divide by zero encountered in log" in text:
        return "takes the log of zero"
    if isinstance(exc, ZeroDivisionError) or "divide by zero" in text:
        return "divides by zero"
    if "invalid value encountered in power" in text:
        return "is not a real number (a negative number to a fractional power)"
    if isinstance(exc, OverflowError) or "overflow" in text:
        return "overflows (its value exceeds the floating-point range, about 1.8e308)"
    return "is undefined (e.g. the log or square root of a negative number)"


class _PowerAsCall(ast.NodeTransformer):
    def visit_BinOp(self, node: ast.BinOp) -> ast.expr:
        self.generic_visit(node)
        if isinstance(node.op, ast.Pow):
            call = ast.Call(ast.Name(_POWER, ast.Load()), [node.left, node.right], [])
            return ast.copy_location(call, node)
        return node


@dataclass(frozen=True)
class _Compiled:
    code: CodeType
    #: the formula calls numpy (a power or a function), which warns where IEEE
    #: arithmetic gives nan or inf unless evaluated under np.errstate
    calls_numpy: bool


def _compile(node: ast.expr, filename: str = "<lpvest formula>") -> _Compiled:
    """The compiled form of a formula's syntax tree (the tree is not changed).

    ``a ** b`` becomes ``numpy.power(a, b)``: one power function for every
    evaluation path. Python's ``float.__pow__`` calls the C library's ``pow``,
    numpy's array loops may run their own SIMD implementation (on AVX-512 a
    result can differ in the last bit: ``10 ** 0.7071067811865476`` is
    5.094561170451297 in Python, 5.094561170451296 in numpy), so a formula
    evaluated one sample at a time (FMUs, streaming) would otherwise differ
    from the same formula evaluated on arrays (simulations). The other
    operations are IEEE-exact and the functions numpy's already.
    """
    tree = _PowerAsCall().visit(ast.Expression(copy.deepcopy(node)))
    calls = any(isinstance(n, ast.Call) for n in ast.walk(tree))
    return _Compiled(compile(ast.fix_missing_locations(tree), filename, "eval"), calls)


def _fold(text: str, node: ast.expr) -> ast.Constant:
    """The value of an operation on constants, in floating point, as a constant
    node; a division by zero, an overflow or a non-real result is an error."""
    code = _compile(node).code
    try:
        with np.errstate(all="raise"):
            value = eval(code, _GLOBALS, {})  # noqa: S307 (whitelisted AST of constants)
    except (ArithmeticError, ValueError) as exc:
        raise ExpressionError(f"formula {abbreviate(text)} {_arithmetic_failure(exc)}") from None
    if isinstance(value, complex) or np.iscomplexobj(value):
        raise ExpressionError(f"formula {abbreviate(text)} is not a real number (a negative number to a "
                              "fractional power)")
    value = float(value)
    if math.isinf(value):
        raise ExpressionError(f"formula {abbreviate(text)} {_arithmetic_failure(OverflowError())}")
    if math.isnan(value):
        raise ExpressionError(f"formula {abbreviate(text)} {_arithmetic_failure(ValueError())}")
    return ast.copy_location(ast.Constant(value), node)


class _Validator(ast.NodeTransformer):
    """Check a parsed formula against the whitelist; rewrite ``shift(p, k)``
    to a plain name, parameters to their values, and every number to a float;
    fold operations on constants (so that ``9**9**9`` is an error at once,
    never a long computation with Python integers)."""

    def __init__(self, text: str, parameters: Mapping[str, float]) -> None:
        self.text = text
        self.parameters = parameters

    def fail(self, what: str) -> ExpressionError:
        return ExpressionError(f"formula {abbreviate(self.text)}: {what}")

    def visit_Expression(self, node: ast.Expression) -> ast.AST:
        node.body = self.visit(node.body)
        return node

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        if not isinstance(node.op, _BINOPS):
            raise self.fail(f"operator {type(node.op).__name__} is not allowed")
        node.left = self.visit(node.left)
        node.right = self.visit(node.right)
        if isinstance(node.left, ast.Constant) and isinstance(node.right, ast.Constant):
            return _fold(self.text, node)
        if isinstance(node.op, ast.Div) and isinstance(node.right, ast.Constant) and node.right.value == 0.0:
            raise ExpressionError(f"formula {abbreviate(self.text)} {_arithmetic_failure(ZeroDivisionError())}")
        return node

    def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
        if not isinstance(node.op, ast.USub | ast.UAdd):
            raise self.fail(f"operator {type(node.op).__name__} is not allowed")
        node.operand = self.visit(node.operand)
        if isinstance(node.operand, ast.Constant):
            return _fold(self.text, node)
        return node

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        if isinstance(node.value, bool) or not isinstance(node.value, int | float):
            raise self.fail(f"constant {abbreviate(node.value, 24)} is not a number")
        try:
            value = float(node.value)
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            raise self.fail(f"the number {abbreviate(node.value, 24)} is not finite in floating point "
                            "(largest about 1.8e308)")
        return ast.copy_location(ast.Constant(value), node)

    def visit_Name(self, node: ast.Name) -> ast.AST:
        if node.id.startswith("__"):
            raise self.fail(f"name {abbreviate(node.id, 24)} is not allowed")
        if node.id in self.parameters:
            value = float(self.parameters[node.id])
            if not math.isfinite(value):
                raise self.fail(f"parameter {abbreviate(node.id, 30)} is not finite ({value})")
            return ast.copy_location(ast.Constant(value), node)
        if node.id in CONSTANTS:
            return ast.copy_location(ast.Constant(CONSTANTS[node.id]), node)
        if node.id in FUNCTIONS:
            raise self.fail(f"function {abbreviate(node.id, 30)} used without arguments")
        return node

    def visit_Call(self, node: ast.Call) -> ast.AST:
        if not isinstance(node.func, ast.Name) or node.keywords:
            raise self.fail("only calls like sin(x) are allowed")
        fname = node.func.id
        if fname == "shift":
            k = _int_literal(node.args[1]) if len(node.args) == 2 else None
            if k is None or not isinstance(node.args[0], ast.Name) or node.args[0].id.startswith("__"):
                raise self.fail("shift takes a variable and an integer, e.g. shift(p, 1)")
            if abs(k) > 1000:
                raise self.fail(f"shift by {k} samples: at most 1000 are allowed")
            # shift(p, 0) is p itself: one name for one value
            name = node.args[0].id if k == 0 else shift_name(node.args[0].id, k)
            return ast.copy_location(ast.Name(name, ast.Load()), node)
        if fname not in FUNCTIONS:
            raise self.fail(
                f"unknown function {abbreviate(fname, 24)}; allowed: {', '.join(sorted(FUNCTIONS))}, shift"
            )
        if len(node.args) != 1:
            raise self.fail(f"{fname} takes one argument")
        node.args = [self.visit(node.args[0])]
        if isinstance(node.args[0], ast.Constant):
            return _fold(self.text, node)
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


def _real(value: Any) -> Any:
    """A Python number or integer array as float (numpy scalar or array), so
    that arithmetic follows IEEE rules: ``1.0 / 0.0`` is ``inf``, not an exception."""
    if isinstance(value, complex) or np.iscomplexobj(value):
        return value
    return np.asarray(value, dtype=float)[()]


def _has_complex(result: object) -> bool:
    if isinstance(result, tuple):
        return any(isinstance(r, complex) for r in result)
    return isinstance(result, complex)


def _evaluate(compiled: _Compiled, values: Mapping[str, ArrayLike]) -> Any:
    code = compiled.code
    if not compiled.calls_numpy and all(type(v) is float for v in values.values()):
        # one sample (the per-step path) of plain arithmetic: Python floats need no
        # numpy error state unless something goes wrong, and then the general path
        # below gives the IEEE result
        try:
            result = eval(code, _GLOBALS, values)  # noqa: S307 (whitelisted AST)
        except (ZeroDivisionError, OverflowError, ValueError):
            result = None
        if result is not None and not _has_complex(result) and all(
                math.isfinite(r) for r in (result if isinstance(result, tuple) else (result,))):
            return result
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        try:
            result = eval(code, _GLOBALS, values)  # noqa: S307 (whitelisted AST)
        except (ZeroDivisionError, OverflowError):
            result = None  # Python numbers raise where IEEE arithmetic gives inf: again in numpy
        if result is None or (_has_complex(result) and not any(
                isinstance(v, complex) or np.iscomplexobj(v) for v in values.values())):
            # (a negative Python float to a fractional power is complex; in numpy it is nan)
            result = eval(code, _GLOBALS, {k: _real(v) for k, v in values.items()})  # noqa: S307
    return result


def _display_tree(tree: ast.AST) -> ast.AST:
    """A copy of ``tree`` with whole-number constants as integers (``t ** 2``,
    not ``t ** 2.0``), for display only."""

    class Ints(ast.NodeTransformer):
        def visit_Constant(self, node: ast.Constant) -> ast.AST:
            v = node.value
            if not isinstance(v, float | int) or isinstance(v, bool):
                return node
            shown = ast.Constant(int(abs(v)) if float(v).is_integer() and abs(v) < 1e15 else abs(v))
            if math.copysign(1.0, v) < 0:  # a sign ast.unparse would not bracket: "(-1) ** t", not "-1 ** t"
                return ast.copy_location(ast.UnaryOp(ast.USub(), shown), node)
            return ast.copy_location(shown, node)

    return Ints().visit(copy.deepcopy(tree))


@dataclass(frozen=True, eq=False)
class Expression:
    """A validated formula, callable on numpy arrays.

    Build one with :meth:`parse` (or :meth:`constant`, :meth:`derivative`),
    not with the constructor.

    Parameters
    ----------
    text : str
        The formula as given (a number as its ``repr``; a derivative as
        ``"d/dvar(text)"``), used in messages.
    tree : ast.Expression
        The validated syntax tree: numbers as floats, parameters and constants
        (``pi``, ``e``) replaced by their values, operations on constants
        folded, ``shift(p, k)`` as the name :func:`shift_name` ``(p, k)``.
    _code : _Compiled
        The compiled form of ``tree`` (internal).
    _names : frozenset of str, default frozenset()
        The free variable names of ``tree`` (internal; see :attr:`names`).

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
    _code: _Compiled = field(repr=False)
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

        Returns
        -------
        Expression
            The validated formula.

        Raises
        ------
        ExpressionError
            ``text`` is not a formula of the accepted kind (see the module
            documentation), longer than :data:`MAX_FORMULA_LENGTH` or nested
            deeper than :data:`MAX_FORMULA_DEPTH`, an operation on constants is
            undefined or not finite, or it uses a name not ``allowed``.
        """
        if isinstance(text, bool) or not isinstance(text, str | int | float):
            raise ExpressionError(f"formula {abbreviate(text)} is neither text nor a number")
        if not isinstance(text, str):
            try:
                number = float(text)
            except OverflowError:
                number = math.inf
            if not math.isfinite(number):
                raise ExpressionError(f"formula value {abbreviate(text, 24)} is not a finite number")
            src = repr(number)
        else:
            src = text
        if len(src) > MAX_FORMULA_LENGTH:
            raise ExpressionError(
                f"formula {abbreviate(src)} is too long: at most {MAX_FORMULA_LENGTH:,} characters"
            )
        try:
            # '^' is a power (math notation); replaced before parsing so that it
            # binds like '**' (Python's '^' binds looser than '*')
            with warnings.catch_warnings():  # e.g. "invalid decimal literal" for "1e": the error follows
                warnings.simplefilter("ignore", SyntaxWarning)
                tree = ast.parse(src.strip().replace("^", "**"), mode="eval")
        except SyntaxError as exc:
            raise ExpressionError(f"formula {abbreviate(src)} is not valid: {shorten(exc.msg, 80)}") from None
        except (ValueError, MemoryError, RecursionError):  # null bytes; nesting beyond the parser's stack
            raise ExpressionError(
                f"formula {abbreviate(src)} is not valid: nested deeper than {MAX_FORMULA_DEPTH} levels"
            ) from None
        if _depth(tree) > MAX_FORMULA_DEPTH + 1:
            raise ExpressionError(
                f"formula {abbreviate(src)} is nested deeper than {MAX_FORMULA_DEPTH} levels"
            )
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
                    f"formula {abbreviate(src)} uses unknown name {abbreviate(unknown[0], 24)} "
                    f"(known: {shorten(known, 60)})"
                )
        return expr

    @classmethod
    def _from_tree(cls, text: str, tree: ast.Expression) -> Expression:
        return cls(text, tree, _compile(tree.body), _free_names(tree))

    @classmethod
    def constant(cls, value: float) -> Expression:
        """The constant formula ``value``.

        Parameters
        ----------
        value : float
            A finite number.

        Returns
        -------
        Expression
            The formula, with text ``repr(float(value))``.
        """
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
        """The formula as canonical text (``shift`` restored; whole numbers
        without a decimal point)."""
        text = ast.unparse(_display_tree(self.tree))
        for n in self.names:
            if n.startswith(_SHIFT_PREFIX):
                text = text.replace(n, _shown(n))
        return text

    def __str__(self) -> str:
        return self.text

    # -- evaluation -----------------------------------------------------------
    def __call__(self, **values: ArrayLike) -> Any:
        return self.evaluate(values)

    def evaluate(self, values: Mapping[str, ArrayLike]) -> Any:
        """Evaluate with ``values`` for the free names (arrays broadcast).

        Arithmetic follows IEEE floating point whatever the type of the values
        (Python numbers or numpy arrays): a division by zero gives ``inf``, an
        overflow ``inf``, a negative number to a fractional power ``nan``;
        callers that need finite values check them (:meth:`value` does).

        Parameters
        ----------
        values : mapping of str to float or array_like
            A value for every free name (a shifted variable under
            :func:`shift_name`); arrays broadcast, extra names are ignored.

        Returns
        -------
        value : float or ndarray
            The formula's value, of the broadcast shape of the values it uses
            (a float for a constant formula).

        Raises
        ------
        ExpressionError
            A free name has no value.
        """
        missing = self._names - values.keys()
        if missing:
            shown = _shown(sorted(missing)[0])
            raise ExpressionError(f"formula {abbreviate(self.text)} needs a value for {shown!r}")
        return _evaluate(self._code, values)

    def value(self) -> float:
        """The value of a constant formula (finite: an error otherwise).

        Returns
        -------
        value : float
            The formula's value.

        Raises
        ------
        ExpressionError
            The formula uses a variable, or its value is not finite.
        """
        if not self.is_constant:
            shown = ", ".join(sorted(_shown(n) for n in self.names))
            raise ExpressionError(
                f"formula {abbreviate(self.text)} must be a constant here but uses the variable "
                f"{shorten(shown, 60)}"
            )
        value: Any = self.tree.body.value if isinstance(self.tree.body, ast.Constant) else self.evaluate({})
        value = float(value)
        if not math.isfinite(value):
            raise ExpressionError(f"formula {abbreviate(self.text)} has the value {value}, not a finite number")
        return value

    # -- calculus -------------------------------------------------------------
    def derivative(self, var: str) -> Expression:
        """The symbolic derivative with respect to ``var``.

        Parameters
        ----------
        var : str
            The variable (a shifted one under its :func:`shift_name`); a name
            the formula does not use gives the constant 0.

        Returns
        -------
        Expression
            The derivative, with text ``"d/dvar(text)"``.

        Raises
        ------
        ExpressionError
            The derivative, written out, has more than
            :data:`MAX_DERIVATIVE_SIZE` operations.
        """
        tree = ast.Expression(_diff(self.tree.body, var, {}))
        if _written_size(tree, MAX_DERIVATIVE_SIZE) > MAX_DERIVATIVE_SIZE:
            raise ExpressionError(
                f"formula {abbreviate(self.text)} is too complex to differentiate: its derivative has more than "
                f"{MAX_DERIVATIVE_SIZE:,} operations"
            )
        _locate(tree)
        return Expression._from_tree(f"d/d{var}({self.text})", tree)

    def monomial_exponents(self, names: tuple[str, ...]) -> tuple[int, ...] | None:
        """If the formula is a product of ``names`` to non-negative integer
        powers (coefficient 1), their exponents; otherwise ``None``.

        Parameters
        ----------
        names : tuple of str
            The variables, in the order of the exponents.

        Returns
        -------
        exponents : tuple of int or None
            One exponent per name (``x*x`` and ``x^2`` both give 2), or ``None``.
        """
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
                and isinstance(node.right.value, int | float)
                and float(node.right.value).is_integer()
                and node.right.value >= 0
            ):
                exps[index[node.left.id]] += int(node.right.value)
                return True
            return False

        return tuple(exps) if walk(self.tree.body) else None


# -- symbolic differentiation ------------------------------------------------
#
# The derivative is built with constructors that fold zeros, ones and constants
# as they go (no later simplification pass). Subtrees are shared, not copied:
# ``d(u v) = du v + u dv`` refers to ``u`` and ``v`` themselves, so the
# derivative of a formula of n operations and depth d has O(n) new nodes and at
# most O(n d) once written out, which :data:`MAX_DERIVATIVE_SIZE` bounds.

#: The largest derivative (operations, written out) :meth:`Expression.derivative`
#: builds; formulas within the length and depth limits stay well below it.
MAX_DERIVATIVE_SIZE = 20_000


def _c(v: float) -> ast.Constant:
    return ast.Constant(float(v))


def _is_c(node: ast.AST, v: float | None = None) -> bool:
    return isinstance(node, ast.Constant) and (v is None or node.value == v)


def _const_op(op: ast.operator, a: float, b: float) -> float:
    """``a op b`` as the evaluation would compute it: IEEE arithmetic (an
    overflow is inf, a negative number to a fractional power nan)."""
    x, y = np.float64(a), np.float64(b)
    with np.errstate(all="ignore"):
        if isinstance(op, ast.Add):
            return float(x + y)
        if isinstance(op, ast.Sub):
            return float(x - y)
        if isinstance(op, ast.Mult):
            return float(x * y)
        if isinstance(op, ast.Div):
            return float(x / y)
        return float(np.power(x, y))


def _bin(left: ast.expr, op: ast.operator, right: ast.expr) -> ast.expr:
    """``left op right`` with zeros, ones and constants folded."""
    if _is_c(left) and _is_c(right):
        return _c(_const_op(op, left.value, right.value))  # type: ignore[attr-defined]  # _is_c: ast.Constant
    if isinstance(op, ast.Add):
        if _is_c(left, 0.0):
            return right
        if _is_c(right, 0.0):
            return left
    elif isinstance(op, ast.Sub):
        if _is_c(right, 0.0):
            return left
        if _is_c(left, 0.0):
            return _neg(right)
    elif isinstance(op, ast.Mult):
        if _is_c(left, 0.0) or _is_c(right, 0.0):
            return _c(0.0)
        if _is_c(left, 1.0):
            return right
        if _is_c(right, 1.0):
            return left
    elif isinstance(op, ast.Div):
        if _is_c(left, 0.0):
            return _c(0.0)
        if _is_c(right, 1.0):
            return left
    elif isinstance(op, ast.Pow):
        if _is_c(right, 1.0):
            return left
        if _is_c(right, 0.0):
            return _c(1.0)
    return ast.BinOp(left, op, right)


def _call(fname: str, arg: ast.expr) -> ast.expr:
    return ast.Call(ast.Name(fname, ast.Load()), [arg], [])


def _neg(x: ast.expr) -> ast.expr:
    if _is_c(x):
        return _c(-x.value)  # type: ignore[attr-defined]  # _is_c: an ast.Constant
    if isinstance(x, ast.UnaryOp) and isinstance(x.op, ast.USub):
        return x.operand
    return ast.UnaryOp(ast.USub(), x)


def _diff(node: ast.expr, var: str, memo: dict[int, ast.expr]) -> ast.expr:
    """d node / d var; ``memo`` holds the derivative of every shared subtree once."""
    key = id(node)
    if key in memo:
        return memo[key]
    out = _diff_node(node, var, memo)
    memo[key] = out
    return out


def _diff_node(node: ast.expr, var: str, memo: dict[int, ast.expr]) -> ast.expr:
    if isinstance(node, ast.Constant):
        return _c(0.0)
    if isinstance(node, ast.Name):
        return _c(1.0 if node.id == var else 0.0)
    if isinstance(node, ast.UnaryOp):
        d = _diff(node.operand, var, memo)
        return _neg(d) if isinstance(node.op, ast.USub) else d
    if isinstance(node, ast.BinOp):
        u, v = node.left, node.right
        du, dv = _diff(u, var, memo), _diff(v, var, memo)
        if isinstance(node.op, ast.Add):
            return _bin(du, ast.Add(), dv)
        if isinstance(node.op, ast.Sub):
            return _bin(du, ast.Sub(), dv)
        if isinstance(node.op, ast.Mult):
            return _bin(_bin(du, ast.Mult(), v), ast.Add(), _bin(u, ast.Mult(), dv))
        if isinstance(node.op, ast.Div):
            if _is_c(dv, 0.0):  # u / c: no c**2 (which may overflow where c does not)
                return _bin(du, ast.Div(), v)
            num = _bin(_bin(du, ast.Mult(), v), ast.Sub(), _bin(u, ast.Mult(), dv))
            return _bin(num, ast.Div(), _bin(v, ast.Pow(), _c(2.0)))
        if isinstance(node.op, ast.Pow):
            if _is_c(dv, 0.0):  # u**c
                return _bin(_bin(v, ast.Mult(), _bin(u, ast.Pow(), _bin(v, ast.Sub(), _c(1.0)))), ast.Mult(), du)
            # u**v = exp(v log u)
            inner = _bin(_bin(dv, ast.Mult(), _call("log", u)), ast.Add(), _bin(v, ast.Mult(), _bin(du, ast.Div(), u)))
            return _bin(node, ast.Mult(), inner)
    if isinstance(node, ast.Call):
        assert isinstance(node.func, ast.Name)
        f, u = node.func.id, node.args[0]
        du = _diff(u, var, memo)
        if _is_c(du, 0.0):
            return _c(0.0)
        outer: dict[str, Callable[[], ast.expr]] = {
            "sin": lambda: _call("cos", u),
            "cos": lambda: _neg(_call("sin", u)),
            "tan": lambda: _bin(_c(1.0), ast.Add(), _bin(_call("tan", u), ast.Pow(), _c(2.0))),
            "exp": lambda: node,
            "log": lambda: _bin(_c(1.0), ast.Div(), u),
            "sqrt": lambda: _bin(_c(0.5), ast.Div(), node),
            "sinh": lambda: _call("cosh", u),
            "cosh": lambda: _call("sinh", u),
            "tanh": lambda: _bin(_c(1.0), ast.Sub(), _bin(node, ast.Pow(), _c(2.0))),
            "arctan": lambda: _bin(_c(1.0), ast.Div(), _bin(_c(1.0), ast.Add(), _bin(u, ast.Pow(), _c(2.0)))),
            "abs": lambda: _bin(u, ast.Div(), node),
        }
        return _bin(outer[f](), ast.Mult(), du)
    raise ExpressionError(f"cannot differentiate a {type(node).__name__}")  # pragma: no cover


def _locate(tree: ast.AST) -> None:
    """:func:`ast.fix_missing_locations` for a tree with shared subtrees
    (each node once; the compiler needs a location on every node)."""
    seen: set[int] = set()
    stack = [tree]
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if "lineno" in node._attributes:
            for attr in ("lineno", "col_offset", "end_lineno", "end_col_offset"):
                if getattr(node, attr, None) is None:
                    setattr(node, attr, 1 if "lineno" in attr else 0)
        stack.extend(ast.iter_child_nodes(node))


def _written_size(tree: ast.AST, limit: int) -> int:
    """The number of nodes of ``tree`` with shared subtrees counted at every
    use (what the compiler sees); stops counting past ``limit``."""
    sizes: dict[int, int] = {}
    stack: list[tuple[ast.AST, bool]] = [(tree, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in sizes:
            continue
        children = list(ast.iter_child_nodes(node))
        if done:
            sizes[id(node)] = min(limit + 1, 1 + sum(sizes[id(c)] for c in children))
        else:
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
    return sizes[id(tree)]


@dataclass(frozen=True, eq=False)
class FormulaMatrix:
    """A matrix whose entries are formulas (numbers are constant formulas).

    Parameters
    ----------
    entries : tuple of tuple of Expression
        The rows, all of the same non-zero length (build with :meth:`parse`,
        which checks it).

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
        """Parse a list of rows of formulas/numbers (a bare number or formula is 1x1).

        Parameters
        ----------
        rows : list of list of (str or float), or str or float
            The rows (lists or tuples) of equal, non-zero length.
        name : str, default "matrix"
            How errors call the matrix (an entry as ``name[i,j]``, 1-based).
        parameters : mapping of str to float, optional
            Named constants substituted at parse time (:meth:`Expression.parse`).
        allowed : iterable of str, optional
            Variable names the entries may use; ``None``: any.

        Returns
        -------
        FormulaMatrix
            The parsed matrix.

        Raises
        ------
        ExpressionError
            ``rows`` is not a list of rows of equal, non-zero length, or an entry
            is not a valid formula (the message names the entry).
        """
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

    def evaluate(self, values: Mapping[str, ArrayLike]) -> np.ndarray:
        """Evaluate every entry; array values give a stacked ``(..., rows, cols)``.

        Parameters
        ----------
        values : mapping of str to float or array_like
            A value for every free name (a shifted variable under
            :func:`shift_name`); arrays broadcast, extra names are ignored.

        Returns
        -------
        matrix : ndarray, shape (..., rows, cols)
            The matrix, ``...`` being the broadcast shape of the entries' values
            (none for scalar values).
        """
        vals = [[e.evaluate(values) for e in row] for row in self.entries]
        shape = np.broadcast_shapes(*(np.shape(v) for row in vals for v in row))
        out = np.empty((*shape, *self.shape))
        for i, row in enumerate(vals):
            for j, v in enumerate(row):
                out[..., i, j] = v
        return out

    def derivative(self, var: str) -> FormulaMatrix:
        """The entry-wise symbolic derivative with respect to ``var``.

        Parameters
        ----------
        var : str
            The variable (see :meth:`Expression.derivative`).

        Returns
        -------
        FormulaMatrix
            The matrix of the entries' derivatives.
        """
        return FormulaMatrix(tuple(tuple(e.derivative(var) for e in row) for row in self.entries))

    def to_list(self) -> list[list[float | str]]:
        """Entries as numbers (constants) or formula text, for model files.

        Returns
        -------
        rows : list of list of (float or str)
            The rows; a constant entry as its float, any other as its
            canonical text (:attr:`Expression.source`).
        """
        return [[e.value() if e.is_constant else e.source for e in row] for row in self.entries]


class FormulaVector:
    """Several formulas evaluated together by one compiled expression (the fast
    path for a per-sample evaluation, e.g. a simplex map inside an FMU).

    Parameters
    ----------
    formulas : iterable of Expression
        The formulas, in the order of the result's last axis.

    Examples
    --------
    >>> v = FormulaVector([Expression.parse("(1 - x)/2"), Expression.parse("(1 + x)/2")])
    >>> v.evaluate({"x": 0.5})
    array([0.25, 0.75])
    """

    def __init__(self, formulas: Iterable[Expression]) -> None:
        self.formulas = tuple(formulas)
        self._code = _compile(ast.Tuple([f.tree.body for f in self.formulas], ast.Load()), "<lpvest formulas>")
        self._names = frozenset().union(*(f.names for f in self.formulas))

    def evaluate(self, values: Mapping[str, ArrayLike]) -> np.ndarray:
        """The formulas' values, shape ``(n,)`` for scalar values or
        ``(*shape, n)`` for arrays of a common ``shape``.

        Parameters
        ----------
        values : mapping of str to float or array_like
            A value for every free name (a shifted variable under
            :func:`shift_name`); arrays broadcast, extra names are ignored.

        Returns
        -------
        values : ndarray, shape (n,) or (..., n)
            The ``n`` formulas' values along the last axis.

        Raises
        ------
        ExpressionError
            A formula's free name has no value (the message names the formula).
        """
        missing = self._names - values.keys()
        if missing:
            for f in self.formulas:
                f.evaluate(values)  # raises naming the formula
        vals = _evaluate(self._code, values)
        if all(isinstance(v, float | int) for v in vals):
            return np.array(vals, dtype=float)
        shape = np.broadcast_shapes(*(np.shape(v) for v in vals))
        return np.stack([np.broadcast_to(v, shape) for v in vals], axis=-1).astype(float)
