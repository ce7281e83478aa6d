"""Estimator kinds that get an FMU: one registration line per filter.

An :class:`EstimatorKind` names the FMU role (``Kalman`` -> ``PeixotoEx1Kalman.fmu``),
the factory that builds the streaming component (:mod:`lpvest.core`)
from a model, its FMU parameters, the model types it applies to, and
optionally a design function run when the FMU is built (e.g. an LMI
synthesis: the FMU then carries the design as JSON in ``resources/`` and needs
no solver at run time). The estimator's ports become the FMU's inputs and
outputs (see ``fmus/lpvest_estimator.py``).

Factories and design functions are named as ``"module:function"`` strings so
that this module imports nothing heavy and the FMU imports only what it runs:

- ``factory(model, *, design=None, **parameters) -> Sampled | Timed`` (:mod:`lpvest.core`)
  (``design`` is the carried design, or ``None``), in its own module so
  that an FMU carries only the estimator it runs (:mod:`lpvest.fmi`);
- ``design(model) -> dict | str`` (numpy arrays allowed; a ``str`` is a JSON
  document stored as readable ``resources/design.json``), at build time. The
  model of such an FMU is fixed at the file's parameter values (they are not
  FMU parameters: the design was made for them).

Adding a filter FMU is one line in :data:`ESTIMATOR_KINDS` below, e.g.::

    EstimatorKind("Kalman", "lpvest.fmi.factories._kalman:build", models=("affine",),
                  parameters=(Parameter("x0", MODEL_X0, "mean of the initial state x_0"),)),

Examples
--------
>>> [k.role for k in estimator_kinds()]
['Kalman', 'TruncatedKalman', 'BSplineObserver', 'HinfPD', 'HinfRobust']
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core._errors import ArgumentError, ArgumentTypeError
from ..core._protocol import MeasurementDelay, Sampled, Timed
from ._parameters import MODEL_P0, MODEL_X0, SCHEDULING_CENTRE, Parameter

__all__ = ["EstimatorKind", "ESTIMATOR_KINDS", "MEASUREMENT_DELAY", "estimator_kinds", "resolve", "build_estimator"]

#: The parameter of every estimator FMU whose kind has late inputs
#: (:attr:`EstimatorKind.late_inputs`): how many samples its measurement
#: arrives late; 1 under a master that steps the FMUs in parallel (Jacobi).
MEASUREMENT_DELAY = Parameter(
    "measurement_delay", 0,
    "samples by which the measurement arrives late (1 under a Jacobi master: libcosim, fmpy's simulate_ssp); "
    "it is paired with the other inputs of its own sample, and the estimate of sample k is output at step "
    "k + measurement_delay (every output 0 before the first measurement)",
    minimum=0, maximum=100_000)


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
        Model types (``lpvest.systems.MODEL_TYPES`` keys) it applies to.
    parameters : tuple of Parameter
        FMU parameters, passed to the factory as keywords.
    design : str, optional
        ``"module:function"`` run at build time when no design file is given;
        its result is carried in the FMU.
    description : str
        One line for the model description.
    files : tuple of Path
        Extra Python modules (files or packages) the factory lives in, for
        estimators outside lpvest (e.g. a user's own module): carried in the
        FMU's private package (:mod:`lpvest.fmi`), their ``lpvest``
        imports bound to the FMU's own copy.
    requirements : tuple of str
        Third-party packages the estimator imports inside functions (its
        module-level imports are found by the builder), e.g. ``("scipy",)``.
    sample_time : str, optional
        The parameter that is the estimator's sample time, for a component
        that keeps time itself (``timed``); default: a discrete-time filter,
        which gets the FMU parameter ``sample_time`` (one fmi2DoStep is one
        sample).
    supports : str, optional
        ``"module:function"`` returning why a model of the right type cannot
        have this estimator (``None`` when it can); the build plan leaves such
        an estimator out with a note.
    late_inputs : tuple of str
        The measurement inputs a master may deliver late (``("y",)``): the
        FMU then has the parameter ``measurement_delay`` (:data:`MEASUREMENT_DELAY`),
        and a value ``d > 0`` wraps the estimator in
        :class:`~lpvest.core.MeasurementDelay` (:func:`build_estimator`).
        Empty (the default): no such parameter. Only for a sampled estimator.
    """

    role: str
    factory: str
    models: tuple[str, ...] = ("polytopic", "affine", "innovation")
    parameters: tuple[Parameter, ...] = ()
    design: str | None = None
    description: str = ""
    files: tuple[Path, ...] = field(default=())
    requirements: tuple[str, ...] = ()
    sample_time: str | None = None
    supports: str | None = None
    late_inputs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.late_inputs and self.sample_time is not None:
            raise ArgumentError(f"estimator {self.role}: a timed estimator (sample_time = {self.sample_time!r}) "
                                "cannot have late inputs (a measurement delay pairs samples)")

    def applies_to(self, model: object) -> bool:
        """Whether ``model`` is an instance of one of the model types in :attr:`models`.

        Parameters
        ----------
        model : object
            A loaded model (e.g. :class:`~lpvest.systems.AffineLPV`).

        Returns
        -------
        bool
            ``True`` if this kind applies to ``model``'s type; model types
            unknown to ``lpvest.systems.MODEL_TYPES`` are ignored.
        """
        from ..systems._modelfile import MODEL_TYPES

        return any(isinstance(model, MODEL_TYPES[t]) for t in self.models if t in MODEL_TYPES)

    def unsupported(self, model: object) -> str | None:
        """Why this estimator cannot be built for ``model`` (``None``: it can).

        Parameters
        ----------
        model : object
            A model of a type the kind applies to.

        Returns
        -------
        str or None
            The reason given by the :attr:`supports` function; always ``None``
            when the kind has no such function.
        """
        return None if self.supports is None else resolve(self.supports)(model)

    def to_json(self) -> dict[str, Any]:
        """The kind as written to the FMU spec (``estimator`` key).

        Returns
        -------
        dict
            ``role``, ``factory``, ``parameters`` (each :meth:`Parameter.to_json`),
            ``description``, ``sample_time`` and ``late_inputs``.
        """
        return {
            "role": self.role,
            "factory": self.factory,
            "parameters": [p.to_json() for p in self.parameters],
            "description": self.description,
            "sample_time": self.sample_time,
            "late_inputs": list(self.late_inputs),
        }


def resolve(target: str) -> Callable[..., Any]:
    """The function named ``"module:function"`` (``function`` may be dotted).

    Parameters
    ----------
    target : str
        ``"module:function"``; the module is imported.

    Returns
    -------
    callable
        The object found.

    Raises
    ------
    ArgumentError
        If ``target`` is not of the form ``"module:function"``.
    ArgumentTypeError
        If the object found is not callable.
    """
    module, sep, name = target.partition(":")
    if not sep or not module or not name:
        raise ArgumentError(f"{target!r} is not of the form 'module:function'")
    obj: object = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    if not callable(obj):
        raise ArgumentTypeError(f"{target} is not callable")
    return obj


def build_estimator(kind: dict[str, Any], model: object, design: object, params: dict[str, Any]) -> Sampled | Timed:
    """The streaming component of an estimator FMU: the kind's factory called
    with the kind's parameters, wrapped in :class:`~lpvest.core.MeasurementDelay`
    when the kind has late inputs and ``params["measurement_delay"]`` is > 0.

    Parameters
    ----------
    kind : dict
        The kind as stored in the FMU spec (:meth:`EstimatorKind.to_json`).
    model : object
        The model the FMU was built for.
    design : object
        The carried design, or ``None``.
    params : dict
        The FMU's parameter values by name (the kind's parameters, and
        ``measurement_delay`` when it has late inputs).

    Returns
    -------
    Sampled or Timed
        The component (:mod:`lpvest.core`).
    """
    options = {p["name"]: params[p["name"]] for p in kind["parameters"]}
    component = resolve(kind["factory"])(model, design=design, **options)
    late = tuple(kind.get("late_inputs") or ())
    delay = int(params.get(MEASUREMENT_DELAY.name, 0)) if late else 0
    return MeasurementDelay(component, delay=delay, late=late) if delay else component


#: The estimator FMUs built for every applicable model: one line per filter.
ESTIMATOR_KINDS: list[EstimatorKind] = [
    EstimatorKind("Kalman", "lpvest.fmi.factories._kalman:build", models=("affine",),
                  parameters=(Parameter("x0", MODEL_X0, "mean of the initial state x_0"),
                              Parameter("P0", MODEL_P0, "covariance of the initial state x_0")),
                  description="exact LPV Kalman filter in innovation form (Cox & Toth (4a)-(4e))",
                  late_inputs=("y",)),
    EstimatorKind("TruncatedKalman", "lpvest.fmi.factories._truncated:build", models=("affine",),
                  parameters=(Parameter("tau", 10, "memory: the gain uses p_(t-tau)..p_t", minimum=0,
                                        maximum=100_000),
                              Parameter("start", "theorem", "start covariance of the restarted recursion: "
                                        "theorem | steady-state (at start_p)"),
                              Parameter("start_p", SCHEDULING_CENTRE,
                                        "scheduling value the steady-state start is computed at")),
                  requirements=("scipy",),  # the steady-state start solves a DARE with scipy
                  description="truncated-memory LPV Kalman filter (Cox & Toth Theorem 1)", late_inputs=("y",)),
    # no late inputs: the observer's plant (continuous time, y(t) = C(t) x(t)) has no feedthrough, so a
    # Jacobi master delivers y(t_k) and u(t_k) together, in time (docs/fmus.md, "Measurement delay")
    EstimatorKind("BSplineObserver", "lpvest.fmi.factories._bspline:build", models=("ltv-io",),
                  parameters=(Parameter("dt", 0.001, "sample time = communication step (s)", minimum=1e-12),
                              Parameter("window", 4.0, "window length (s)", minimum=0.0),
                              Parameter("hop", 0.5, "time between refits (s)", minimum=0.0),
                              Parameter("a0", "spline:18", "a0: known | constant | spline:N[:order]"),
                              Parameter("a1", "constant", "a1: known | constant | spline:N[:order]"),
                              Parameter("b0", "known", "b0: known | constant | spline:N[:order]"),
                              Parameter("b1", "known", "b1: known | constant | spline:N[:order]"),
                              Parameter("penalty", 0.0, "P-spline penalty (0: none, < 0: by GCV)")),
                  requirements=("scipy",), sample_time="dt",
                  description="sliding-window B-spline joint parameter and state observer (Sridhar et al.)",
                  supports="lpvest.estimators.bspline:observer_supports"),
    EstimatorKind("HinfPD", "lpvest.fmi.factories._hinf:build", models=("polytopic", "affine"),
                  design="lpvest.fmi._designs:hinf_pd",
                  description="gain-scheduled H-infinity filter (Peixoto et al. Theorem 1), best epsilon",
                  late_inputs=("y",)),
    EstimatorKind("HinfRobust", "lpvest.fmi.factories._hinf:build", models=("polytopic", "affine"),
                  design="lpvest.fmi._designs:hinf_robust",
                  description="robust H-infinity filter (Peixoto et al. Corollary 1), best epsilon",
                  late_inputs=("y",)),
]


def estimator_kinds() -> list[EstimatorKind]:
    """The registered kinds (a copy of :data:`ESTIMATOR_KINDS`).

    Returns
    -------
    list of EstimatorKind
        A new list; changing it does not change the registry.
    """
    return list(ESTIMATOR_KINDS)
