"""Plant FMU: a continuous-time LTV plant (Sridhar et al., Section V) (slave script).

A thin adapter over :class:`lpvest.systems._streaming.LTVPlant`: the state
follows the model's :class:`lpvest.systems._ltv.LTVSolution`, one DOP853
integration (``rtol = 1e-12``, ``atol = 1e-14`` by default) kept from step to
step, whose own steps do not depend on the communication points: any step
size reads the same trajectory, and a 1 ms step mostly costs one
interpolation. A saved FMU state restores it exactly.

Input: by default (``use_model_input = true``) the model's input function of
time (``u = 120 sin t``) is evaluated inside every step, exactly; with
``use_model_input = false`` the input ``u`` is held over the step (zero-order
hold). Outputs ``y`` (``y[1]`` = ``C(t) x``), ``x[i]`` and ``u_applied[1]``
(the input at the communication point). Needs numpy and scipy.
"""

from lpvest.fmi._parameters import Parameter
from lpvest.fmi._slave import LpvestSlave
from lpvest.systems._streaming import LTVPlant


class LpvestLtvPlant(LpvestSlave):
    """Continuous-time LTV plant."""

    def declare(self):
        model = LTVPlant(self.model())
        x0 = model.get_state()["x"]
        return [
            Parameter("use_model_input", model.use_model_input,
                      "apply the model's input function of time (else hold the input u over each step)"),
            Parameter("x0", [float(v) for v in x0], "initial state"),
            Parameter("rtol", 1e-12, "relative tolerance of the integrator (DOP853)", minimum=1e-14, maximum=1e-3),
            Parameter("atol", 1e-14, "absolute tolerance of the integrator (DOP853)", minimum=1e-18, maximum=1e-3),
        ]

    def make_component(self, params):
        return LTVPlant(
            self.model(params),
            use_model_input=bool(params["use_model_input"]),
            x0=params["x0"],
            rtol=float(params["rtol"]),
            atol=float(params["atol"]),
        )

    def output_dependencies(self, port):
        # u_applied is the input u when use_model_input = false: declared so for every configuration
        return ["u"] if port.name == "u_applied" else super().output_dependencies(port)
