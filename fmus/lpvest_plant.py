"""Plant FMU: a discrete-time LPV plant from a model file (slave script).

A thin adapter over :class:`lpvest.systems._streaming.DiscretePlant`: a
polytopic model (Peixoto et al. (1)), an affine model with general noise
(Cox & Toth (1)-(3)), an innovation-form model with a gain of ``p_t`` or an
input-output model (Cox & Toth (21a); its state ``x`` is the memory of past
``y``, ``u`` and ``e``).

Inputs ``p[j]`` (``alpha[i]`` for a polytopic model without a scheduling map),
``u[i]``, ``w[i]`` (and ``v[i]`` / ``e[i]``: external noise added to the drawn
noise); outputs ``y[i]``, ``z[i]`` (polytopic), ``x[i]``. One fmi2DoStep is
one sample ``k -> k + 1``. ``y_k`` and ``z_k`` feed through: after the inputs
of sample k are set, they read ``C(p_k) x_k + D u_k + ...`` before fmi2DoStep;
``x_k`` does not depend on the inputs of sample k.

Parameters: ``noise`` and ``seed`` (models with a noise description),
``x0[i]`` (the initial state; for an affine model the mean of ``x_0``, drawn
from ``N(x0, P0)`` with the parameter ``P0[i,j]`` when the noise is on, as
``AffineLPV.simulate`` does: the same seed gives the same realization), and
the model file's own parameters (e.g. ``rho``).
"""

from lpvest.fmi._parameters import Parameter
from lpvest.fmi._slave import LpvestSlave
from lpvest.systems._affine import AffineLPV
from lpvest.systems._innovation import InnovationLPV, LPVInputOutput
from lpvest.systems._streaming import DiscretePlant


class LpvestPlant(LpvestSlave):
    """Discrete-time LPV plant."""

    def declare(self):
        model = self.model()
        pars = self.model_parameters()
        if isinstance(model, AffineLPV | InnovationLPV | LPVInputOutput):
            pars.append(Parameter("noise", True, "draw the model's noise inside the FMU"))
            pars.append(Parameter("seed", 0, "seed of the noise generator", minimum=0))
        x0 = model.x0 if isinstance(model, AffineLPV | InnovationLPV) else [0.0] * model.nx
        if isinstance(model, AffineLPV):
            pars.append(Parameter("x0", [float(v) for v in x0], "mean of the initial state x_0"))
            pars.append(Parameter("P0", model.P0.tolist(), "covariance of the initial state x_0 (drawn when noise)"))
        elif isinstance(model, LPVInputOutput):
            pars.append(Parameter("x0", [float(v) for v in x0],
                                  "initial memory: y, u, e before t = 0, newest first (zero: from rest)"))
        else:
            pars.append(Parameter("x0", [float(v) for v in x0], "initial state"))
        return pars

    def make_component(self, params):
        return DiscretePlant(
            self.model(params),
            noise=bool(params.get("noise", False)),
            seed=int(params.get("seed", 0)),
            x0=params["x0"],
            P0=params.get("P0"),
        )

    def input_range(self, port, index):
        return self.scheduling_range(port, index)
