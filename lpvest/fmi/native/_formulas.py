"""Formulas of lpvest's safe language compiled to the native runtime's stack code.

The compiler walks the validated syntax tree of an
:class:`~lpvest.core.Expression` (never its text): numbers become
entries of a constant pool, names are resolved against the variables the
formula may use (the scheduling components, the model parameters) and any
other name is refused here, at export time, with the formula named; ``+ - * /
**`` and unary signs become stack operations, the functions of
:data:`lpvest.core.FUNCTIONS` calls by index. The deepest stack the
code needs is computed and checked against the runtime's
``LPV_VM_STACK`` (``runtime/lpv_core.h``). ``lpv_vm.c`` evaluates the code
with IEEE arithmetic, as numpy evaluates the tree.

>>> from lpvest.core import Expression
>>> c = compile_formula(Expression.parse("(1 - theta)/2"), ["theta"])
>>> c.code, c.constants, c.depth
((1, 0, 2, 0, 4, 1, 1, 6, 0), (1.0, 2.0), 2)
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from dataclasses import dataclass

from ...core._errors import ExpressionError, abbreviate
from ...core._expressions import FUNCTIONS, Expression

__all__ = ["CompiledFormula", "compile_formula", "VM_STACK", "OPS", "FUNCTION_INDEX"]

#: The runtime's stack depth (``LPV_VM_STACK`` in ``runtime/lpv_core.h``).
VM_STACK = 128

#: Operation codes (``LPV_OP_*`` in ``runtime/lpv_core.h``).
OPS = {"END": 0, "CONST": 1, "VAR": 2, "ADD": 3, "SUB": 4, "MUL": 5, "DIV": 6, "POW": 7, "NEG": 8, "CALL": 9}
_BIN = {ast.Add: OPS["ADD"], ast.Sub: OPS["SUB"], ast.Mult: OPS["MUL"], ast.Div: OPS["DIV"], ast.Pow: OPS["POW"]}

#: Function index (``LPV_FN_*``): the order of :data:`lpvest.core.FUNCTIONS`.
FUNCTION_INDEX = {name: i for i, name in enumerate(FUNCTIONS)}


@dataclass(frozen=True)
class CompiledFormula:
    """A formula as runtime code.

    Parameters
    ----------
    code : tuple of int
        Code words, ending with ``END`` (0).
    constants : tuple of float
        The constant pool the code indexes.
    depth : int
        The deepest stack the code needs.
    text : str
        The formula as written (for messages).
    """

    code: tuple[int, ...]
    constants: tuple[float, ...]
    depth: int
    text: str


def compile_formula(expr: Expression, variables: Sequence[str]) -> CompiledFormula:
    """The stack code of ``expr`` over ``variables`` (their order is the
    runtime's variable vector).

    Parameters
    ----------
    expr : Expression
        A parsed, validated formula.
    variables : sequence of str
        The names the formula may use, in the order the runtime passes their
        values.

    Returns
    -------
    CompiledFormula
        The code, its constants and its stack depth.

    Raises
    ------
    ExpressionError
        The formula uses a name that is not among ``variables`` (or a shifted
        variable, which the native runtime does not keep), or needs a deeper
        stack than the runtime has.
    """
    index = {name: i for i, name in enumerate(variables)}
    code: list[int] = []
    constants: list[float] = []
    pool: dict[bytes, int] = {}

    def const(value: float) -> int:
        key = float(value).hex().encode()
        if key not in pool:
            pool[key] = len(constants)
            constants.append(float(value))
        return pool[key]

    def fail(what: str) -> ExpressionError:
        return ExpressionError(f"formula {abbreviate(expr.text)}: {what} (native FMU)")

    # an explicit stack of (node, children done): formulas nest up to 100 levels
    depth = 0
    height = 0
    todo: list[tuple[ast.AST, bool]] = [(expr.tree.body, False)]
    while todo:
        node, done = todo.pop()
        if isinstance(node, ast.Constant):
            code += [OPS["CONST"], const(float(node.value))]  # type: ignore[arg-type]  # numbers only (validated)
            height += 1
        elif isinstance(node, ast.Name):
            if node.id not in index:
                shown = "a shifted variable" if node.id.startswith("__shift__") else f"the name {node.id!r}"
                known = ", ".join(variables) or "none"
                raise fail(f"uses {shown}, which is not a variable here (variables: {known})")
            code += [OPS["VAR"], index[node.id]]
            height += 1
        elif isinstance(node, ast.BinOp):
            op = _BIN.get(type(node.op))
            if op is None:
                raise fail(f"operator {type(node.op).__name__} is not allowed")
            if done:
                code.append(op)
                height -= 1
            else:
                todo += [(node, True), (node.right, False), (node.left, False)]
        elif isinstance(node, ast.UnaryOp):
            if done:
                if isinstance(node.op, ast.USub):
                    code.append(OPS["NEG"])
            elif isinstance(node.op, ast.USub | ast.UAdd):
                todo += [(node, True), (node.operand, False)]
            else:
                raise fail(f"operator {type(node.op).__name__} is not allowed")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTION_INDEX:
            if done:
                code += [OPS["CALL"], FUNCTION_INDEX[node.func.id]]
            elif len(node.args) != 1 or node.keywords:
                raise fail(f"{node.func.id} takes one argument")
            else:
                todo += [(node, True), (node.args[0], False)]
        else:
            raise fail(f"{type(node).__name__} is not allowed")
        depth = max(depth, height)
    code.append(OPS["END"])
    if depth > VM_STACK:
        raise fail(f"needs a stack of {depth} values; the native runtime has {VM_STACK}")
    return CompiledFormula(tuple(code), tuple(constants), depth, expr.text)
