"""Estimator FMU: any streaming estimator of lpvest (slave script).

A generic adapter over the step protocol of
:class:`lpvest.core.Component`: the estimator is built by the factory its
registration names (``lpvest.fmi._registry``), from the model file and the
optional design carried in ``resources/``, with the FMU parameters as keywords.
Its input ports become FMI inputs (``p[j]`` with the scheduling box as declared
range, ``alpha[i]`` in [0, 1], ``u[i]``, ``y[i]``), its output ports FMI outputs
(``xhat[i]``, ``P[i,j]``, ...). After the inputs of sample k are set, the
outputs read ``outputs(inputs)`` (the estimates at k, no state change) before
fmi2DoStep; fmi2DoStep calls ``step(inputs)``. An estimator whose kind has
late inputs (the measurement ``y``) gets the parameter ``measurement_delay``:
``lpvest.fmi._registry.build_estimator`` pairs a measurement that arrives that
many samples late with the other inputs of its own sample
(``lpvest.core._protocol.MeasurementDelay``).
"""

from pathlib import Path

from lpvest.fmi._parameters import Parameter
from lpvest.fmi._registry import MEASUREMENT_DELAY, build_estimator
from lpvest.fmi._slave import LpvestSlave
from lpvest.fmi._state import decode_state


class LpvestEstimator(LpvestSlave):
    """Streaming estimator."""

    def declare(self):
        kind = self.spec["estimator"]
        model = self.model()
        pars = self.model_parameters() + [Parameter.from_json(p).for_model(model) for p in kind["parameters"]]
        return pars + ([MEASUREMENT_DELAY] if kind.get("late_inputs") else [])

    def make_component(self, params):
        kind = self.spec["estimator"]
        design = None
        if self.spec.get("design_file"):
            path = Path(self.resources) / self.spec["design_file"]
            if self.spec.get("design_format") == "text":
                design = path.read_text(encoding="utf-8")
            else:
                design = decode_state(path.read_bytes())
        return build_estimator(kind, self.model(params), design, params)

    def input_range(self, port, index):
        return self.scheduling_range(port, index)

