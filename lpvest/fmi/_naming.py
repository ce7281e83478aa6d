"""FMI variable names for vectors and matrices (structured naming, 1-based).

A port ``y`` of shape ``(2,)`` becomes the FMI variables ``y[1]``, ``y[2]``; a
port ``P`` of shape ``(2, 2)`` becomes ``P[1,1]``, ``P[1,2]``, ``P[2,1]``,
``P[2,2]`` (row-major); a scalar port (shape ``()``) is the variable ``name``
itself. This module imports only the standard library (and lpvest.core).

>>> element_names("y", (2,))
['y[1]', 'y[2]']
>>> element_names("P", (2, 2))
['P[1,1]', 'P[1,2]', 'P[2,1]', 'P[2,2]']
>>> fmu_name("peixoto-ex1")
'PeixotoEx1'
"""

from __future__ import annotations

import itertools
import re

from ..core._errors import ArgumentError

__all__ = ["element_names", "fmu_name", "parse_element"]

_ELEMENT = re.compile(r"^(?P<base>[A-Za-z_][\w.]*)(\[(?P<index>\d+(,\d+)*)\])?$")


def element_names(name: str, shape: tuple[int, ...]) -> list[str]:
    """The FMI variable names of a port, in row-major order.

    Parameters
    ----------
    name : str
        Port name, the base of every variable name.
    shape : tuple of int
        Port shape; ``()`` for a scalar port.

    Returns
    -------
    names : list of str
        ``name[i,j,...]`` with 1-based indices, row-major; ``[name]`` for a
        scalar port.
    """
    if len(shape) == 0:
        return [name]
    ranges = [range(1, n + 1) for n in shape]
    return [f"{name}[{','.join(str(i) for i in idx)}]" for idx in itertools.product(*ranges)]


def parse_element(variable: str) -> tuple[str, tuple[int, ...]]:
    """``"P[2,1]"`` -> ``("P", (2, 1))`` (1-based); ``"tau"`` -> ``("tau", ())``.

    Parameters
    ----------
    variable : str
        A structured FMI variable name, ``base`` or ``base[i,j,...]``.

    Returns
    -------
    base : str
        The port name.
    index : tuple of int
        The 1-based indices; ``()`` for a scalar.

    Raises
    ------
    ArgumentError
        If ``variable`` is not of that form.
    """
    m = _ELEMENT.match(variable)
    if not m:
        raise ArgumentError(f"{variable!r} is not a structured FMI variable name")
    index = m.group("index")
    return m.group("base"), tuple(int(i) for i in index.split(",")) if index else ()


def fmu_name(system_name: str) -> str:
    """CamelCase FMU name stem of a system name: ``"cox-toth-ex1"`` -> ``"CoxTothEx1"``.

    Parameters
    ----------
    system_name : str
        System name; split at every run of characters other than ASCII
        letters and digits.

    Returns
    -------
    stem : str
        The parts joined, each with its first letter upper-cased; prefixed
        with ``Model`` when empty or not starting with a letter.
    """
    parts = [p for p in re.split(r"[^A-Za-z0-9]+", system_name) if p]
    stem = "".join(p[:1].upper() + p[1:] for p in parts)
    if not stem or not stem[0].isalpha():
        stem = "Model" + stem
    return stem
