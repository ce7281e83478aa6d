"""The order of a co-simulation step (lpvest/cosim/_graph.py) as pure functions over plain data,
without FMUs: chains, direct feedthrough or not, loops broken by a component without it,
algebraic loops and their message, ties. tests/test_cosim_master.py checks the same orders
through the master over stand-in FMUs; the random graphs below are checked against the
definition of the order (every port after what it depends on, the smallest ready port first)
and a transitive closure, not against the algorithm."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lpvest.cosim import AlgebraicLoopError, CoSimulationError
from lpvest.cosim._graph import Batch, Block, Port, batches, evaluation_order

LOOP_HINT = " (declare feedthrough=False for a component whose outputs do not depend on its inputs)"


def steps(blocks, links, *, read=None):
    """The schedule as the master prints it (``CoSimulation.execution_order``); ``read``:
    the outputs read, by default every output (the master records them all)."""
    order = evaluation_order(blocks, links)
    if read is None:
        read = {(i, o) for i, b in enumerate(blocks) for o in b.depends}
    plan = batches(order, connected={target for _, target in links}, read=read)
    return [f"{b.op} {blocks[b.component].name}: {', '.join(b.names)}" for b in plan]


def names(blocks, order):
    return [f"{blocks[p.component].name}.{p.name}" for p in order]


SRC = {"y": set()}  # a source: an output, no input
GAIN = {"y": {"u"}}  # y = k u at the same instant
DELAY = {"x": set()}  # x = u one step late: no feedthrough


# -- chains ---------------------------------------------------------------------------------------


def test_a_chain_reads_each_output_after_setting_the_input_it_depends_on():
    blocks = [Block("src", SRC), Block("gain", GAIN), Block("delay", DELAY)]
    links = [((0, "y"), (1, "u")), ((1, "y"), (2, "u"))]
    order = evaluation_order(blocks, links)
    assert order == [Port(0, True, "y"), Port(1, False, "u"), Port(1, True, "y"), Port(2, False, "u"),
                     Port(2, True, "x")]
    assert steps(blocks, links) == ["get src: y", "set gain: u", "get gain: y", "set delay: u", "get delay: x"]


def test_the_master_s_chain_of_fake_fmus_has_the_same_schedule():
    """tests/test_cosim_master.py::test_a_chain_...: src -> gain (y from u, j from i, z from
    nothing) -> delay, Real and Integer outputs of src to gain; every output recorded."""
    blocks = [Block("src", {"y": set(), "n": set(), "on": set()}),
              Block("gain", {"y": {"u"}, "j": {"i"}, "z": set()}),
              Block("delay", {"x": set()})]
    links = [((0, "y"), (1, "u")), ((0, "n"), (1, "i")), ((1, "y"), (2, "u"))]
    assert steps(blocks, links) == ["get src: n, on, y", "set gain: i, u", "get gain: j, y, z", "set delay: u",
                                    "get delay: x"]


def test_components_are_ordered_by_dependency_not_by_the_order_given():
    blocks = [Block("delay", DELAY), Block("gain", GAIN), Block("src", SRC)]
    links = [((1, "y"), (0, "u")), ((2, "y"), (1, "u"))]
    assert steps(blocks, links, read={(0, "x"), (1, "y"), (2, "y")}) == [
        "get delay: x", "get src: y", "set gain: u", "get gain: y", "set delay: u"]


# -- feedthrough ----------------------------------------------------------------------------------


def test_an_output_with_feedthrough_is_read_after_its_input_one_without_before():
    # b comes first in the list: without feedthrough its output is ready at once and read first
    links = [((1, "y"), (0, "u"))]
    with_ft = [Block("b", {"y": {"u"}}), Block("src", SRC)]
    without = [Block("b", {"y": set()}), Block("src", SRC)]
    assert steps(with_ft, links) == ["get src: y", "set b: u", "get b: y"]
    assert steps(without, links) == ["get b: y", "get src: y", "set b: u"]


def test_an_output_depends_only_on_the_inputs_it_lists():
    # b.y from u1 only: it is read as soon as u1 is set, before u2 (driven by b's own z) is
    blocks = [Block("src", SRC), Block("b", {"y": {"u1"}, "z": set()})]
    links = [((0, "y"), (1, "u1")), ((1, "z"), (1, "u2"))]
    assert names(blocks, evaluation_order(blocks, links)) == ["src.y", "b.u1", "b.y", "b.z", "b.u2"]
    assert steps(blocks, links) == ["get src: y", "set b: u1", "get b: y, z", "set b: u2"]


def test_a_loop_through_a_component_without_feedthrough_is_ordered():
    """tests/test_cosim_master.py::test_a_declared_feedthrough_override_...: a.y -> b.u, b.y -> a.u
    with two gains is a loop; without feedthrough in b (every output depends on no input) b.y
    is read first and closes the loop one step late."""
    gain = {"y": {"u"}, "j": {"i"}, "z": set()}
    blocks = [Block("a", gain), Block("b", {o: set() for o in gain})]
    links = [((0, "y"), (1, "u")), ((1, "y"), (0, "u"))]
    assert steps(blocks, links) == ["get a: j, z", "get b: j, y", "set a: u", "get a: y", "set b: u", "get b: z"]


def test_an_unconnected_input_is_ordered_but_never_set_and_an_unread_output_never_read():
    blocks = [Block("src", SRC), Block("g", {"y": {"u", "free"}, "z": set()})]
    links = [((0, "y"), (1, "u"))]
    order = evaluation_order(blocks, links)
    assert Port(1, False, "free") in order and order.index(Port(1, False, "free")) < order.index(Port(1, True, "y"))
    assert steps(blocks, links, read={(0, "y"), (1, "y")}) == ["get src: y", "set g: u", "get g: y"]
    assert steps(blocks, links, read={(0, "y")}) == ["get src: y", "set g: u"]


def test_an_input_nothing_drives_or_depends_on_is_no_port():
    blocks = [Block("src", SRC), Block("d", {"x": set()})]
    assert evaluation_order(blocks, []) == [Port(0, True, "y"), Port(1, True, "x")]


# -- algebraic loops ------------------------------------------------------------------------------


def test_an_algebraic_loop_names_its_variables_sorted_in_one_message():
    blocks = [Block("a", GAIN), Block("b", GAIN)]
    with pytest.raises(AlgebraicLoopError, match=r"^algebraic loop: these variables depend on each other through "
                                                 r"direct feedthrough: a.u, a.y, b.u, b.y \(declare") as info:
        evaluation_order(blocks, [((0, "y"), (1, "u")), ((1, "y"), (0, "u"))])
    assert str(info.value) == ("algebraic loop: these variables depend on each other through direct feedthrough: "
                               "a.u, a.y, b.u, b.y" + LOOP_HINT)
    assert info.value.where == "connections" and isinstance(info.value, CoSimulationError)


def test_a_component_fed_back_into_itself_is_a_loop_and_what_hangs_off_a_loop_is_named_too():
    # g.y -> g.u closes a loop in g alone; h depends on g.y, so it cannot be ordered either;
    # src is upstream of nothing on the loop and is ordered
    blocks = [Block("src", SRC), Block("g", {"y": {"u"}}), Block("h", GAIN)]
    links = [((1, "y"), (1, "u")), ((1, "y"), (2, "u"))]
    with pytest.raises(AlgebraicLoopError) as info:
        evaluation_order(blocks, links)
    assert str(info.value) == ("algebraic loop: these variables depend on each other through direct feedthrough: "
                               "g.u, g.y, h.u, h.y" + LOOP_HINT)


def test_a_loop_through_three_components_is_found_and_broken_by_any_one_without_feedthrough():
    links = [((0, "y"), (1, "u")), ((1, "y"), (2, "u")), ((2, "y"), (0, "u"))]
    with pytest.raises(AlgebraicLoopError, match=r": a.u, a.y, b.u, b.y, c.u, c.y \(declare"):
        evaluation_order([Block("a", GAIN), Block("b", GAIN), Block("c", GAIN)], links)
    for k in range(3):
        blocks = [Block(n, {"y": set()} if i == k else GAIN) for i, n in enumerate("abc")]
        order = evaluation_order(blocks, links)
        # the component without feedthrough is read first, the loop then runs downstream from it
        loop = [Port(k, True, "y"), Port((k + 1) % 3, False, "u"), Port((k + 1) % 3, True, "y"),
                Port((k + 2) % 3, False, "u"), Port((k + 2) % 3, True, "y"), Port(k, False, "u")]
        assert order == loop


# -- ties and stability ---------------------------------------------------------------------------


def test_ties_go_to_the_lowest_component_then_inputs_before_outputs_then_names():
    # nothing depends on anything: the order is the ports sorted, whatever the order of the data
    blocks = [Block("p", {"z": set(), "a": {"m"}}), Block("q", {"b": set()})]
    order = evaluation_order(blocks, [((1, "b"), (0, "k"))])
    assert order == [Port(0, False, "m"), Port(0, True, "a"), Port(0, True, "z"), Port(1, True, "b"),
                     Port(0, False, "k")]
    # inputs before outputs: every input of a component is set before any of its outputs is read
    blocks = [Block("src", {"y1": set(), "y2": set()}), Block("g", {"y": {"u2"}, "w": {"u1"}})]
    links = [((0, "y1"), (1, "u1")), ((0, "y2"), (1, "u2"))]
    assert steps(blocks, links) == ["get src: y1, y2", "set g: u1, u2", "get g: w, y"]


def test_the_order_depends_on_the_data_not_on_the_order_of_dicts_sets_or_connections():
    gain = {"y": ["u1", "u2"], "w": ["u2"], "z": []}
    blocks = [Block("src", {"b": [], "a": []}), Block("g", gain), Block("d", {"x": []})]
    links = [((0, "a"), (1, "u1")), ((0, "b"), (1, "u2")), ((1, "y"), (2, "u")), ((1, "w"), (2, "v"))]
    first = evaluation_order(blocks, links)
    for perm in itertools.permutations(links):
        shuffled = [Block("src", {"a": [], "b": []}),
                    Block("g", {k: list(reversed(v)) for k, v in reversed(gain.items())}),
                    Block("d", {"x": []})]
        assert evaluation_order(shuffled, list(perm)) == first
    assert names(blocks, first) == ["src.a", "src.b", "g.u1", "g.u2", "g.w", "g.y", "g.z", "d.u", "d.v", "d.x"]


def test_batches_split_a_component_s_run_when_another_component_comes_between():
    order = [Port(0, True, "a"), Port(0, True, "b"), Port(1, False, "u"), Port(0, True, "c"), Port(0, False, "v"),
             Port(0, False, "w")]
    assert batches(order, connected={(1, "u"), (0, "v"), (0, "w")}, read={(0, "a"), (0, "b"), (0, "c")}) == [
        Batch("get", 0, ["a", "b"]), Batch("set", 1, ["u"]), Batch("get", 0, ["c"]), Batch("set", 0, ["v", "w"])]
    # a skipped port does not split a run
    assert batches(order, connected={(0, "v")}, read={(0, "a"), (0, "b")}) == [
        Batch("get", 0, ["a", "b"]), Batch("set", 0, ["v"])]
    assert batches([], connected=set(), read=set()) == []


# -- random graphs, against the definition ----------------------------------------------------------


def _random_graph(rng, n_blocks, p_dep, n_links):
    blocks = []
    for b in range(n_blocks):
        ins = [f"u{k}" for k in range(int(rng.integers(0, 4)))]
        outs = [f"y{k}" for k in range(int(rng.integers(1, 4)))]
        blocks.append(Block(f"c{b}", {o: {i for i in ins if rng.random() < p_dep} for o in outs}))
    inputs = [(b, f"u{k}") for b in range(n_blocks) for k in range(4)]
    targets = rng.permutation(len(inputs))[:n_links]  # each input driven at most once
    links = []
    for t in targets:
        src = int(rng.integers(n_blocks))
        outs = sorted(blocks[src].depends)
        links.append(((src, outs[int(rng.integers(len(outs)))]), inputs[t]))
    return blocks, links


def _predecessors(blocks, links):
    """port -> the ports it depends on directly (the graph from its definition)."""
    pred = {}
    for b, block in enumerate(blocks):
        for o, ins in block.depends.items():
            pred.setdefault(Port(b, True, o), set()).update(Port(b, False, i) for i in ins)
            for i in ins:
                pred.setdefault(Port(b, False, i), set())
    for (sb, so), (tb, ti) in links:
        pred.setdefault(Port(sb, True, so), set())
        pred.setdefault(Port(tb, False, ti), set()).add(Port(sb, True, so))
    return pred


def _stuck(pred):
    """Ports that no order can place: those with an ancestor (or themselves) on a cycle, from the
    transitive closure of the dependency relation."""
    ports = sorted(pred)
    index = {p: k for k, p in enumerate(ports)}
    reach = np.zeros((len(ports), len(ports)), dtype=bool)  # reach[a, b]: a depends on b, transitively
    for p, before in pred.items():
        for q in before:
            reach[index[p], index[q]] = True
    for k in range(len(ports)):
        reach |= reach[:, [k]] & reach[[k], :]
    on_cycle = np.diag(reach).copy()
    return {p for p in ports if on_cycle[index[p]] or (reach[index[p]] & on_cycle).any()}


@pytest.mark.parametrize("seed", range(40))
def test_random_graphs_are_ordered_as_defined_or_refused_naming_exactly_the_unorderable_ports(seed):
    rng = np.random.default_rng(seed)
    blocks, links = _random_graph(rng, int(rng.integers(1, 6)), 0.5, int(rng.integers(0, 10)))
    pred = _predecessors(blocks, links)
    stuck = _stuck(pred)
    if stuck:
        with pytest.raises(AlgebraicLoopError) as info:
            evaluation_order(blocks, links)
        named = str(info.value).split("feedthrough: ", 1)[1].removesuffix(LOOP_HINT).split(", ")
        assert named == sorted(f"{blocks[p.component].name}.{p.name}" for p in stuck)
        return
    order = evaluation_order(blocks, links)
    assert sorted(order) == sorted(pred)  # every port once
    placed = set()
    for port in order:
        assert pred[port] <= placed  # after everything it depends on
        ready = [p for p in pred if p not in placed and pred[p] <= placed]
        assert port == min(ready)  # the smallest ready port first
        placed.add(port)
