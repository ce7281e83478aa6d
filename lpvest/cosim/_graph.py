"""The order of a co-simulation step, as pure functions over plain data.

The master (``_master.py``) sets and reads variables at every communication
point so that an output computed from an input at ``t_k`` reaches its
consumers at the same ``t_k``. That order depends only on the components'
direct feedthrough (which inputs each output depends on at the same instant)
and on the connections: a graph whose nodes are the components' inputs and
outputs (:class:`Port`), with an edge from every input to each output that
depends on it, and from every connected output to the inputs it drives.
:func:`evaluation_order` sorts it topologically (Kahn's algorithm, ties to the
lowest component index, inputs before outputs, then by name) or raises
:class:`~lpvest.cosim.AlgebraicLoopError` for a cycle; :func:`batches` groups
the sorted ports into the master's per-step operations.

Examples
--------
A source ``src`` (output ``y``, no inputs) drives ``gain.u``; ``gain.y``
depends on ``u``, ``gain.z`` on nothing:

>>> blocks = [Block("gain", {"y": {"u"}, "z": set()}), Block("src", {"y": set()})]
>>> order = evaluation_order(blocks, [((1, "y"), (0, "u"))])
>>> [f"{blocks[p.component].name}.{p.name}" for p in order]
['gain.z', 'src.y', 'gain.u', 'gain.y']
>>> for batch in batches(order, connected={(0, "u")}, read={(1, "y"), (0, "y")}):
...     print(batch)
Batch(op='get', component=1, names=['y'])
Batch(op='set', component=0, names=['u'])
Batch(op='get', component=0, names=['y'])
"""

from __future__ import annotations

import heapq
from collections.abc import Collection, Iterable, Mapping, Sequence
from typing import NamedTuple

from ._errors import AlgebraicLoopError

__all__ = ["Block", "Port", "Batch", "evaluation_order", "batches"]

#: One end of a connection: ``(component index, variable name)``.
Endpoint = tuple[int, str]


class Block(NamedTuple):
    """A component as the ordering sees it.

    Parameters
    ----------
    name : str
        The component's name (the algebraic-loop message names variables as ``name.variable``).
    depends : mapping of str to collection of str
        Every output of the component -> the inputs it depends on directly (its direct
        feedthrough; empty when the output depends on no input at the same instant).
    """

    name: str
    depends: Mapping[str, Collection[str]]


class Port(NamedTuple):
    """A node of the dependency graph: one input or output of one component.

    Ports compare as tuples: by component index, inputs before outputs, then by
    name; :func:`evaluation_order` resolves ties in that order.

    Parameters
    ----------
    component : int
        Index of the component (its position in the list given).
    is_output : bool
        An output (``True``) or an input (``False``).
    name : str
        The variable's name.
    """

    component: int
    is_output: bool
    name: str


class Batch(NamedTuple):
    """Consecutive operations of one kind on one component.

    Parameters
    ----------
    op : {"set", "get"}
        ``"set"``: copy upstream values into these inputs; ``"get"``: read these outputs.
    component : int
        Index of the component.
    names : list of str
        The variables, in evaluation order.
    """

    op: str
    component: int
    names: list[str]


def evaluation_order(blocks: Sequence[Block], links: Iterable[tuple[Endpoint, Endpoint]]) -> list[Port]:
    """The ports in an order where every port comes after those it depends on.

    An input depends on the output connected to it; an output on the inputs of
    its component it feeds through from. Among the ports ready at a time the
    smallest :class:`Port` comes first (lowest component index, then inputs
    before outputs, then name): every input of a component is then set before
    any of its outputs is read, so it computes its outputs once per step, and
    the operations on one component stay together.

    Parameters
    ----------
    blocks : sequence of Block
        The components, indexed by position.
    links : iterable of ((int, str), (int, str))
        The connections ``((source component, output), (target component, input))``, one per
        scalar variable.

    Returns
    -------
    list of Port
        Every output of every block, and every input that is connected or that an output depends on.

    Raises
    ------
    AlgebraicLoopError
        The connections close a loop through direct feedthrough; the message names the variables
        that could not be ordered (``where="connections"``).
    """
    edges: dict[Port, set[Port]] = {}
    for index, block in enumerate(blocks):
        for output, inputs in block.depends.items():
            edges.setdefault(Port(index, True, output), set())
            for name in inputs:
                edges.setdefault(Port(index, False, name), set()).add(Port(index, True, output))
    for (source, output), (target, name) in links:
        edges.setdefault(Port(source, True, output), set()).add(Port(target, False, name))
        edges.setdefault(Port(target, False, name), set())
    indegree = dict.fromkeys(edges, 0)
    for after in edges.values():
        for port in after:
            indegree[port] += 1
    # Kahn's algorithm: the smallest ready port first (ports are unique, so the order is total)
    ready = [port for port, n in indegree.items() if n == 0]
    heapq.heapify(ready)
    order: list[Port] = []
    while ready:
        port = heapq.heappop(ready)
        order.append(port)
        for nxt in edges[port]:
            indegree[nxt] -= 1
            if indegree[nxt] == 0:
                heapq.heappush(ready, nxt)
    if len(order) < len(indegree):
        names = sorted(f"{blocks[p.component].name}.{p.name}" for p, n in indegree.items() if n > 0)
        raise AlgebraicLoopError(
            "algebraic loop: these variables depend on each other through direct feedthrough: "
            + ", ".join(names)
            + " (declare feedthrough=False for a component whose outputs do not depend on its inputs)",
            where="connections",
        )
    return order


def batches(order: Iterable[Port], *, connected: Collection[Endpoint], read: Collection[Endpoint]) -> list[Batch]:
    """The per-step operations: ``order`` grouped into runs of one kind on one component.

    Parameters
    ----------
    order : iterable of Port
        The ports in evaluation order (:func:`evaluation_order`).
    connected : collection of (int, str)
        The inputs a connection drives; the others are not set.
    read : collection of (int, str)
        The outputs to read (connected or recorded); the others are not read.

    Returns
    -------
    list of Batch
        A ``"set"`` batch per run of consecutive connected inputs of one component, a ``"get"`` batch
        per run of consecutive read outputs of one component.
    """
    out: list[Batch] = []
    for port in order:
        if (port.component, port.name) not in (read if port.is_output else connected):
            continue
        op = "get" if port.is_output else "set"
        if out and out[-1].op == op and out[-1].component == port.component:
            out[-1].names.append(port.name)
        else:
            out.append(Batch(op, port.component, [port.name]))
    return out
