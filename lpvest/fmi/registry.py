"""Estimator kinds that get an FMU: one registration line per filter.

An :class:`EstimatorKind` names the FMU role (``Kalman`` -> ``PeixotoEx1Kalman.fmu``),
the factory that builds the :class:`~lpvest.estimators.base.StreamingEstimator`
from a model, its FMU parameters, the model types it applies to, and
optionally a design function run when the FMU is built (e.g. an LMI
synthesis: the FMU then carries the design as JSON in ``resources/`` and needs
no solver at run time). The estimator's ports become the FMU's inputs and
outputs (see ``fmus/lpvest_estimator.py``).

Factories and design functions are named as ``"module:function"`` strings so
that this module imports nothing heavy and the FMU imports only what it runs:

- ``factory(model, *, design=None, **parameters) -> StreamingEstimator``
  (``design`` is the dict the design function returned, or ``None``);
- ``design(model) -> dict | str`` (numpy arrays allowed; a ``str`` is a JSON
  document stored as readable ``resources/design.json``), at build time. The
  model of such an FMU is fixed at the file's parameter values (they are not
  FMU parameters: the design was made for them).

Adding a filter FMU is one line in :data:`ESTIMATOR_KINDS` below, e.g.::

    EstimatorKind("Kalman", "lpvest.estimators.kalman:fmu_estimator", models=("affine",),
                  parameters=(Parameter("tau", 0, "memory (0: exact)", minimum=0),)),
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .spec import Parameter

__all__ = ["EstimatorKind", "ESTIMATOR_KINDS", "estimator_kinds", "resolve"]


@dataclass(frozen=True)
class EstimatorKind:
    """How to build one kind of estimator FMU.

    Parameters
    ----------
    role : str
        FMU role, the suffix of the FMU name (``Kalman``, ``TruncatedKalman``,
        ``HinfPD``, ``HinfRobust``, ``BSplineObserver``).
    factory : str
        ``"module:function"`` building the estimator (see the module docs).
    models : tuple of str
        Model types (``lpvest.modelfile.MODEL_TYPES`` keys) it applies to.
    parameters : tuple of Parameter
        FMU parameters, passed to the factory as keywords.
    design : str, optional
        ``"module:function"`` run at build time; its result is carried in the FMU.
    description : str
        One line for the model description.
    files : tuple of Path
        Extra Python files or packages copied into ``resources/`` (for
        estimators that live outside lpvest, e.g. in a user's own module).
    supports : str, optional
        ``"module:function"`` returning why a model of the right type cannot
        have this estimator (``None`` when it can); the build plan leaves such
        an estimator out with a note.
    """

    role: str
    factory: str
    models: tuple[str, ...] = ("polytopic", "affine", "innovation")
    parameters: tuple[Parameter, ...] = ()
    design: str | None = None
    description: str = ""
    files: tuple[Path, ...] = field(default=())
    supports: str | None = None

    def applies_to(self, model: object) -> bool:
        from ..modelfile import MODEL_TYPES

        return any(isinstance(model, MODEL_TYPES[t]) for t in self.models if t in MODEL_TYPES)

    def unsupported(self, model: object) -> str | None:
        """Why this estimator cannot be built for ``model`` (``None``: it can)."""
        return None if self.supports is None else resolve(self.supports)(model)

    def to_json(self) -> dict[str, Any]:
        return {
            "role": self.role,
            "factory": self.factory,
            "parameters": [p.to_json() for p in self.parameters],
            "description": self.description,
        }


def resolve(target: str) -> Callable[..., Any]:
    """The function named ``"module:function"`` (``function`` may be dotted)."""
    module, sep, name = target.partition(":")
    if not sep or not module or not name:
        raise ValueError(f"{target!r} is not of the form 'module:function'")
    obj: Any = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    if not callable(obj):
        raise TypeError(f"{target} is not callable")
    return obj  # type: ignore[no-any-return]


#: The estimator FMUs built for every applicable model: one line per filter.
ESTIMATOR_KINDS: list[EstimatorKind] = [
    EstimatorKind("Kalman", "lpvest.fmi.factories:kalman", models=("affine",),
                  description="exact LPV Kalman filter in innovation form (Cox & Toth (4a)-(4e))"),
    EstimatorKind("TruncatedKalman", "lpvest.fmi.factories:truncated_kalman", models=("affine",),
                  parameters=(Parameter("tau", 10, "memory: the gain uses p_(t-tau)..p_t", minimum=0),
                              Parameter("start", "theorem", "start covariance of the restarted recursion: "
                                        "theorem | steady-state")),
                  description="truncated-memory LPV Kalman filter (Cox & Toth Theorem 1)"),
    EstimatorKind("BSplineObserver", "lpvest.fmi.factories:bspline_observer", models=("ltv-io",),
                  parameters=(Parameter("dt", 0.001, "sample time = communication step (s)", minimum=0.0),
                              Parameter("window", 4.0, "window length (s)", minimum=0.0),
                              Parameter("hop", 0.5, "time between refits (s)", minimum=0.0),
                              Parameter("a0", "spline:18", "a0: known | constant | spline:N[:order]"),
                              Parameter("a1", "constant", "a1: known | constant | spline:N[:order]"),
                              Parameter("b0", "known", "b0: known | constant | spline:N[:order]"),
                              Parameter("b1", "known", "b1: known | constant | spline:N[:order]"),
                              Parameter("penalty", 0.0, "P-spline penalty (0: none, < 0: by GCV)")),
                  description="sliding-window B-spline joint parameter and state observer (Sridhar et al.)",
                  supports="lpvest.estimators.bspline:observer_supports"),
    EstimatorKind("HinfPD", "lpvest.fmi.factories:hinf", models=("polytopic",),
                  design="lpvest.fmi.factories:hinf_pd_design",
                  description="gain-scheduled H-infinity filter (Peixoto et al. Theorem 1), best epsilon"),
    EstimatorKind("HinfRobust", "lpvest.fmi.factories:hinf", models=("polytopic",),
                  design="lpvest.fmi.factories:hinf_robust_design",
                  description="robust H-infinity filter (Peixoto et al. Corollary 1), best epsilon"),
]


def estimator_kinds() -> list[EstimatorKind]:
    """The registered kinds (a copy of :data:`ESTIMATOR_KINDS`)."""
    return list(ESTIMATOR_KINDS)
