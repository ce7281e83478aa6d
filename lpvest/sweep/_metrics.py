"""Summary metrics of one co-simulation: one number per task and metric.

A metric reads recorded variables of a run (the structured array of
:meth:`lpvest.cosim.CoSimulation.run`: rows ``k = 0 .. N``, columns
``"comp.var[i]"``); a vector name (``"kalman.xhat"``) stands for all its
elements. ``start`` drops the rows ``k < start`` (a burn-in).

==================  ==============================  =================================================
kind                keys                            value
==================  ==============================  =================================================
``rms_error``       ``estimate``, ``truth``         ``sqrt(mean((estimate - truth)**2))`` over rows and elements
``max_abs_error``   ``estimate``, ``truth``         ``max |estimate - truth|``
``energy_ratio``    ``estimate``, ``truth``,        ``||estimate - truth||_2 / ||input||_2`` (sums of squares over rows
                    ``input``                       and elements): the empirical gain an H-infinity bound caps
``peak_ratio``      ``estimate``, ``truth``,        ``max |estimate - truth| / max |input|``
                    ``input``
``final_trace``     ``of`` (a square matrix)        ``sum_i of[i,i]`` in the last row (e.g. a covariance ``kalman.P``)
``final``           ``of`` (one element)            its value in the last row (e.g. ``kalman.loglik``)
``mean``            ``of``                          mean over rows and elements
``rms``             ``of``                          ``sqrt(mean(of**2))``
``max_abs``         ``of``                          ``max |of|``
==================  ==============================  =================================================

Every kind takes ``start`` (default 0) except ``final_trace`` and ``final``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["Metric", "METRIC_KINDS", "expand", "select", "compute"]

#: kind -> (required keys, takes ``start``)
METRIC_KINDS: dict[str, tuple[tuple[str, ...], bool]] = {
    "rms_error": (("estimate", "truth"), True),
    "max_abs_error": (("estimate", "truth"), True),
    "energy_ratio": (("estimate", "truth", "input"), True),
    "peak_ratio": (("estimate", "truth", "input"), True),
    "final_trace": (("of",), False),
    "final": (("of",), False),
    "mean": (("of",), True),
    "rms": (("of",), True),
    "max_abs": (("of",), True),
}


@dataclass(frozen=True)
class Metric:
    """One summary metric (see the module documentation for the kinds).

    Parameters
    ----------
    name : str
        Metric name, its column in the summary table.
    kind : str
        One of :data:`METRIC_KINDS` (``rms_error``, ``final_trace`` ...).
    variables : mapping of str to str
        Role (``estimate``, ``truth``, ``input``, ``of``) -> recorded name
        (``"comp.var"`` or one element ``"comp.var[i]"``).
    start : int, default 0
        First row used (rows ``k < start`` are a burn-in); ignored by
        ``final_trace`` and ``final``.
    """

    name: str
    kind: str
    variables: Mapping[str, str]
    start: int = 0

    def names(self) -> tuple[str, ...]:
        """The recorded variables it reads.

        Returns
        -------
        tuple of str
            The values of :attr:`variables`, in role order.
        """
        return tuple(self.variables.values())


def _element_key(name: str) -> tuple[int, ...]:
    m = re.search(r"\[(\d+(?:,\d+)*)\]$", name)
    return tuple(int(i) for i in m.group(1).split(",")) if m else ()


def expand(name: str, columns: Iterable[str]) -> list[str]:
    """The columns ``name`` stands for: itself, or its elements ``name[i]`` /
    ``name[i,j]`` in index order (row-major).

    Parameters
    ----------
    name : str
        A recorded variable or element name (``"kalman.xhat"``, ``"kalman.xhat[1]"``).
    columns : iterable of str
        The recorded column names.

    Returns
    -------
    list of str
        ``[name]`` if it is a column, else its element columns sorted by
        index; empty if there are none.
    """
    columns = list(columns)
    if name in columns:
        return [name]
    found = [c for c in columns if c.startswith(name + "[") and c.endswith("]")]
    return sorted(found, key=_element_key)


def select(data: np.ndarray, name: str) -> np.ndarray:
    """The columns of ``name`` in a recorded run as an array ``(rows, elements)``.

    Parameters
    ----------
    data : ndarray
        A recorded run: structured array with one field per column.
    name : str
        A variable or element name (see :func:`expand`).

    Returns
    -------
    ndarray, shape (rows, elements)
        The columns as floats, in :func:`expand` order.

    Raises
    ------
    KeyError
        If ``name`` matches no column.
    """
    cols = expand(name, data.dtype.names or ())
    if not cols:
        raise KeyError(f"no recorded variable {name!r}")
    return np.column_stack([np.asarray(data[c], dtype=float) for c in cols])


def check(metric: Metric, columns: Iterable[str]) -> str | None:
    """Why ``metric`` cannot be computed from these recorded columns, or ``None``."""
    columns = list(columns)
    sizes = {}
    for role, name in metric.variables.items():
        cols = expand(name, columns)
        if not cols:
            return f"{role} {name!r} is not a recorded variable"
        sizes[role] = cols
    if "estimate" in sizes and len(sizes["estimate"]) != len(sizes["truth"]):
        return (f"estimate {metric.variables['estimate']!r} has {len(sizes['estimate'])} element(s), "
                f"truth {metric.variables['truth']!r} {len(sizes['truth'])}")
    if metric.kind == "final_trace":
        keys = [_element_key(c) for c in sizes["of"]]
        n = int(round(len(keys) ** 0.5))
        if n * n != len(keys) or any(len(k) != 2 for k in keys):
            return f"of {metric.variables['of']!r} is not a square matrix variable (elements name[i,j])"
    if metric.kind == "final" and len(sizes["of"]) != 1:
        return f"of {metric.variables['of']!r} has {len(sizes['of'])} elements; final takes one (name one element)"
    return None


def compute(metric: Metric, data: np.ndarray) -> float:
    """The value of ``metric`` on one recorded run (see the module documentation).

    Parameters
    ----------
    metric : Metric
        The metric; its variables must be recorded (see :func:`check`).
    data : ndarray
        A recorded run: structured array with one field per column.

    Returns
    -------
    float
        The metric's value.
    """
    v = {role: select(data, name) for role, name in metric.variables.items()}
    rows = slice(metric.start, None)
    kind = metric.kind
    if kind in ("rms_error", "max_abs_error", "energy_ratio", "peak_ratio"):
        e = (v["estimate"] - v["truth"])[rows]
        if kind == "rms_error":
            return float(np.sqrt(np.mean(e**2)))
        if kind == "max_abs_error":
            return float(np.max(np.abs(e)))
        w = v["input"][rows]
        if kind == "energy_ratio":
            return float(np.sqrt(np.sum(e**2)) / np.sqrt(np.sum(w**2)))
        return float(np.max(np.abs(e)) / np.max(np.abs(w)))
    x = v["of"]
    if kind == "final_trace":
        cols = expand(metric.variables["of"], data.dtype.names or ())
        return float(sum(data[c][-1] for c in cols if len(set(_element_key(c))) == 1))
    if kind == "final":
        return float(x[-1, 0])
    x = x[rows]
    if kind == "mean":
        return float(np.mean(x))
    if kind == "rms":
        return float(np.sqrt(np.mean(x**2)))
    if kind == "max_abs":
        return float(np.max(np.abs(x)))
    raise ValueError(f"unknown metric kind {kind!r}")  # pragma: no cover - checked when the spec is read


def parse(name: str, table: object, where: str) -> Metric | str:
    """A :class:`Metric` from its table in a sweep spec, or the reason it is
    not one (a message for ``where``)."""
    if not isinstance(table, Mapping):
        return f"expected a table {{ kind = ..., ... }}, found {type(table).__name__}"
    kind = table.get("kind")
    if kind not in METRIC_KINDS:
        return f"kind: expected one of {', '.join(METRIC_KINDS)}, found {kind!r}"
    keys, takes_start = METRIC_KINDS[kind]
    allowed = {"kind", *keys} | ({"start"} if takes_start else set())
    unknown = sorted(set(table) - allowed)
    if unknown:
        return f"{unknown[0]}: unknown key for kind {kind!r} (expected: {', '.join(sorted(allowed))})"
    variables = {}
    for key in keys:
        value = table.get(key)
        if not isinstance(value, str) or "." not in value:
            return f"{key}: expected a recorded variable 'component.variable', found {value!r}"
        variables[key] = value
    start = table.get("start", 0)
    if isinstance(start, bool) or not isinstance(start, int) or start < 0:
        return f"start: expected a non-negative integer (a step), found {start!r}"
    return Metric(name, kind, variables, int(start))
