"""Scheduler FMU: the scheduling signal of an LPV model (slave script).

A thin adapter over :class:`lpvest.core._signals.SchedulerComponent` and
:mod:`lpvest.core._signals`. Outputs ``p[j]`` (declared range: the model's scheduling
box) and, for a polytopic model, ``alpha[i]`` on the unit simplex. The value
at each communication point ``t`` is reported before fmi2DoStep.

Parameters (per component ``j``): ``kind`` (``sinusoid`` (default),
``constant``, ``random`` (bounded rate, seeded), ``table`` (piecewise linear),
also ``zero``, ``decaying``), ``amplitude[j]``, ``omega[j]`` (rad per unit of
time), ``phase[j]``, ``offset[j]``, ``decay[j]``, ``rate[j]`` (largest
``|dp/dt|`` of ``random``), ``onset``, ``seed``, ``table``
(``"t p_1 ... p_n; t p_1 ... p_n; ..."``). A setting that can leave the
scheduling box is an error at initialization naming the parameter. Default:
``p = centre + half-width * sin(0.25 t)`` (Peixoto et al.: ``theta_k = sin(0.25 k)``).
"""

from lpvest.core._signals import SchedulerComponent, SignalSpec
from lpvest.fmi._parameters import Parameter
from lpvest.fmi._slave import LpvestSlave


class LpvestScheduler(LpvestSlave):
    """Scheduling signal."""

    def declare(self):
        space = self.model().space
        centre = [float(v) for v in (space.lower + space.upper) / 2]
        half = [float(v) for v in (space.upper - space.lower) / 2]
        n = space.dim
        return [
            Parameter("kind", "sinusoid", "sinusoid | constant | random | table | zero | decaying"),
            Parameter("amplitude", half, "amplitude (sinusoid, decaying)"),
            Parameter("omega", [0.25] * n, "angular frequency in rad per unit of time"),
            Parameter("phase", [0.0] * n, "phase in rad"),
            Parameter("offset", centre, "offset; value of constant; start of random"),
            Parameter("decay", [0.0] * n, "decay rate of decaying"),
            Parameter("rate", half, "largest |dp/dt| of random"),
            Parameter("onset", 0.0, "time before which the signal holds its offset"),
            Parameter("seed", 0, "seed of random", minimum=0),
            Parameter("table", "", "rows 't p_1 ... p_n' separated by ';' (kind table)"),
        ]

    def make_component(self, params):
        model = self.model()
        space = model.space
        signal = SignalSpec.build(
            params["kind"], space.dim, amplitude=params["amplitude"], omega=params["omega"],
            phase=params["phase"], offset=params["offset"], decay=params["decay"], rate=params["rate"],
            lower=space.lower, upper=space.upper, onset=params["onset"], seed=params["seed"],
            table=params["table"] if params["kind"] == "table" else None,
        )
        return SchedulerComponent(signal, space, getattr(model, "simplex_map", None))

    def output_range(self, port, index):
        return self.scheduling_range(port, index)
