"""Source FMU: the external input u and the disturbance w of an LPV model (slave script).

A thin adapter over :class:`lpvest.core._signals.SourceComponent` and
:mod:`lpvest.core._signals`. Outputs ``u[i]`` (when the model has inputs) and
``w[i]`` (the disturbance of a polytopic model; the external process noise of
an affine one). The value at each communication point is reported before
fmi2DoStep.

Parameters, for each signal ``s`` in ``u``, ``w``: ``s.kind`` (``zero``,
``sinusoid``, ``decaying`` (Peixoto et al.: ``w_k = sin(0.5 k) exp(-0.1 k)``
from ``k = 10``, the default for ``w`` of a polytopic model), ``gaussian``
(seeded), also ``constant``, ``random``, ``table``), ``s.amplitude[i]``,
``s.omega[i]``, ``s.phase[i]``, ``s.offset[i]``, ``s.decay[i]``,
``s.std[i]``, ``s.rate[i]``, ``s.onset`` (the onset step), ``s.seed``,
``s.table``.
"""

from lpvest.core._signals import SignalSpec, SourceComponent
from lpvest.fmi._parameters import Parameter
from lpvest.fmi._slave import LpvestSlave
from lpvest.systems._polytopic import PolytopicLPV

KINDS = ("zero", "sinusoid", "decaying", "gaussian", "constant", "random", "table")


def _signals(model):
    """The source's signals: name -> (size, default kind, description)."""
    out = {}
    nu = getattr(model, "nu", 0)
    if nu:
        out["u"] = (nu, "zero", "external input")
    if isinstance(model, PolytopicLPV):
        out["w"] = (model.nw, "decaying", "disturbance")
    elif hasattr(model, "nw"):
        out["w"] = (model.nw, "zero", "external process noise")
    return out


class LpvestSource(LpvestSlave):
    """External input and disturbance."""

    def declare(self):
        pars = []
        for s, (n, kind, what) in _signals(self.model()).items():
            paper = kind == "decaying"
            pars += [
                Parameter(f"{s}.kind", kind, f"{what}: {' | '.join(KINDS)}"),
                Parameter(f"{s}.amplitude", [1.0] * n, "amplitude (sinusoid, decaying)"),
                Parameter(f"{s}.omega", [0.5 if paper else 1.0] * n, "angular frequency in rad per unit of time"),
                Parameter(f"{s}.phase", [0.0] * n, "phase in rad"),
                Parameter(f"{s}.offset", [0.0] * n, "offset; value of constant"),
                Parameter(f"{s}.decay", [0.1 if paper else 0.0] * n, "decay rate (decaying)"),
                Parameter(f"{s}.std", [1.0] * n, "standard deviation (gaussian)"),
                Parameter(f"{s}.rate", [1.0] * n, "largest |ds/dt| (random)"),
                Parameter(f"{s}.onset", 10.0 if paper else 0.0, "onset: the signal holds its offset before it"),
                Parameter(f"{s}.seed", 1 if s == "w" else 0, "seed (gaussian, random)", minimum=0),
                Parameter(f"{s}.table", "", "rows 't s_1 ... s_n' separated by ';' (kind table)"),
            ]
        return pars

    def make_component(self, params):
        signals, descriptions = {}, {}
        for s, (n, _kind, what) in _signals(self.model()).items():
            kind = params[f"{s}.kind"]
            signals[s] = SignalSpec.build(
                kind, n, amplitude=params[f"{s}.amplitude"], omega=params[f"{s}.omega"],
                phase=params[f"{s}.phase"], offset=params[f"{s}.offset"], decay=params[f"{s}.decay"],
                std=params[f"{s}.std"], rate=params[f"{s}.rate"], onset=params[f"{s}.onset"],
                seed=params[f"{s}.seed"], table=params[f"{s}.table"] if kind == "table" else None,
                prefix=f"{s}.",
            )
            descriptions[s] = what
        return SourceComponent(signals, descriptions)
