"""The FMUs behind the paper experiments: a build cache, the co-simulation
set-ups, and the record of how the FMU results agree with the library.

Every experiment of ``lpvest reproduce`` runs its plant and its filters as FMUs
under :mod:`lpvest.cosim` and repeats the computation with the library alone
as the cross-check. This module holds what they share:

- :class:`ExperimentFmus`, the FMUs the experiments need (:data:`CATALOG`),
  built on demand into a cache folder and reused while they are up to date
  (the build cache of :mod:`lpvest.fmi`; the example systems' designs
  are stored files: ``models/designs/``).
- :data:`PAPER_KINDS`: the H-infinity filter FMUs with the paper's
  ``epsilon = 150`` design (Peixoto et al., Table 1 and Fig. 1); the shipped
  ``HinfPD``/``HinfRobust`` FMUs carry the best-epsilon design.
- :class:`CoSimSpec`: components, connections, step and length of one
  co-simulation, so that an experiment and its regression reference
  (:mod:`lpvest.experiments`) run the same set-up.
- :class:`Agreement` and :class:`FmuRun`: FMU against library, per quantity:
  the largest absolute difference, the scale, and whether it is within
  ``1e-12`` (relative to ``max(1, max |library value|)``).

Examples
--------
>>> fmus = ExperimentFmus("out/fmu-cache")                    # doctest: +SKIP
>>> fmus["PeixotoEx1Plant"]                                    # doctest: +SKIP
PosixPath('out/fmu-cache/PeixotoEx1Plant.fmu')
"""

from __future__ import annotations

import functools
import re
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core._errors import ArgumentError, LpvestError, abbreviate
from ..fmi._cache import FmuCache, FmuCacheError, default_cache_dir
from ..fmi._registry import EstimatorKind, estimator_kinds

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..design._result import HinfDesign
    from ..fmi._build import FmuPlan
    from ..systems._affine import AffineLPV
    from ..systems._polytopic import PolytopicLPV

__all__ = [
    "PAPER_EPSILON",
    "PAPER_KINDS",
    "AGREEMENT_TOLERANCE",
    "FmuEntry",
    "CATALOG",
    "ExperimentFmus",
    "CoSimSpec",
    "Agreement",
    "FmuRun",
    "Timer",
    "column",
    "as_experiment_fmus",
    "hinf_pd_eps150",
    "hinf_robust_eps150",
    "carried_design",
    "design_difference",
]

#: The epsilon of Peixoto et al.'s Table 1 and Figs. 1-2.
PAPER_EPSILON = 150.0

#: FMU against library: largest difference allowed, relative to ``max(1, scale)``.
AGREEMENT_TOLERANCE = 1e-12

# ---------------------------------------------------------------------------
# the paper's epsilon = 150 designs, as estimator kinds
# ---------------------------------------------------------------------------
def hinf_pd_eps150(model: PolytopicLPV | AffineLPV) -> str:
    """Build-time design: Theorem 1 (parameter-dependent) at ``epsilon = 150``, as JSON."""
    from ..design import KIND_PD, design_hinf

    return design_hinf(model, epsilon=PAPER_EPSILON, kind=KIND_PD).to_json()


def hinf_robust_eps150(model: PolytopicLPV | AffineLPV) -> str:
    """Build-time design: Corollary 1 (robust) at ``epsilon = 150``, as JSON."""
    from ..design import KIND_ROBUST, design_hinf

    return design_hinf(model, epsilon=PAPER_EPSILON, kind=KIND_ROBUST).to_json()


#: Filter FMUs with the paper's epsilon (Peixoto et al. Table 1, Fig. 1).
PAPER_KINDS: tuple[EstimatorKind, ...] = (
    EstimatorKind("HinfPDEps150", "lpvest.fmi.factories._hinf:build", models=("polytopic",),
                  design="lpvest.experiments._fmus:hinf_pd_eps150",
                  description="gain-scheduled H-infinity filter (Peixoto et al. Theorem 1), epsilon = 150"),
    EstimatorKind("HinfRobustEps150", "lpvest.fmi.factories._hinf:build", models=("polytopic",),
                  design="lpvest.experiments._fmus:hinf_robust_eps150",
                  description="robust H-infinity filter (Peixoto et al. Corollary 1), epsilon = 150"),
)


# ---------------------------------------------------------------------------
# the catalog
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class FmuEntry:
    """One FMU the experiments use: an example system (optionally with its
    model-file parameters changed, which makes a variant system) and a role."""

    system: str
    role: str
    parameters: tuple[tuple[str, float], ...] = ()

    @property
    def system_name(self) -> str:
        """``"peixoto-ex2"``, or ``"peixoto-ex2-rho11"`` for a variant."""
        return self.system + "".join(f"-{k}{v:g}" for k, v in self.parameters)

    @property
    def identifier(self) -> str:
        from ..fmi._naming import fmu_name

        return fmu_name(self.system_name) + self.role


def _entries() -> dict[str, FmuEntry]:
    items = [
        FmuEntry("cox-toth-ex1", r) for r in ("Plant", "Scheduler", "Source")
    ] + [
        FmuEntry("cox-toth-truncation", r) for r in ("Plant", "Scheduler", "Source", "Kalman", "TruncatedKalman")
    ] + [
        FmuEntry("peixoto-ex1", r)
        for r in ("Plant", "Scheduler", "Source", "HinfPD", "HinfRobust", "HinfPDEps150", "HinfRobustEps150")
    ] + [
        FmuEntry("peixoto-ex2", r) for r in ("Plant", "Scheduler", "Source", "HinfPD")
    ] + [
        # Example 2's filter designed at other values of rho (the plant FMU takes rho as a parameter)
        FmuEntry("peixoto-ex2", "HinfPD", (("rho", 11.0),)),
        FmuEntry("peixoto-ex2", "HinfPD", (("rho", 21.0),)),
    ] + [
        FmuEntry("sridhar-ltv", r) for r in ("Plant", "BSplineObserver")
    ]
    return {e.identifier: e for e in items}


#: Every FMU the experiments use, by identifier (``"PeixotoEx1HinfPD"``).
CATALOG: dict[str, FmuEntry] = _entries()


def _kinds(role: str) -> list[EstimatorKind]:
    return [k for k in (*estimator_kinds(), *PAPER_KINDS) if k.role == role]


# ---------------------------------------------------------------------------
# the cache
# ---------------------------------------------------------------------------
def _with_value(m: re.Match[str], value: float) -> str:
    """The matched ``key = `` (or ``key = { value = ``) followed by ``value``."""
    return (m.group(1) or m.group(2)) + repr(value)


class ExperimentFmus(FmuCache):
    """The experiments' FMUs (:data:`CATALOG`) in a cache folder, built when
    missing or stale (:class:`~lpvest.fmi.FmuCache`); variant model
    files (other parameter values) are written to ``models/`` in the folder.

    Parameters
    ----------
    directory : str or Path
        The cache folder (created when needed).
    progress : callable, optional
        Called with a message before each build (the CLI prints it).
    backend : str, default "pythonfmu"
        The FMU backend (:data:`lpvest.fmi._build.BACKENDS`).

    Raises
    ------
    ArgumentError
        ``backend`` is not one of :data:`lpvest.fmi._build.BACKENDS`.

    Examples
    --------
    >>> fmus = ExperimentFmus("out/fmu-cache")                    # doctest: +SKIP
    >>> fmus["PeixotoEx1Plant"]                                    # doctest: +SKIP
    PosixPath('out/fmu-cache/PeixotoEx1Plant.fmu')
    """

    def known(self, identifier: str) -> bool:
        """Whether ``identifier`` is an FMU of :data:`CATALOG`.

        Parameters
        ----------
        identifier : str
            An FMU identifier (``PeixotoEx1Plant``).

        Returns
        -------
        bool
            True for a catalog FMU.
        """
        return identifier in CATALOG

    def _source(self, entry: FmuEntry) -> str | Path:
        """The model file of ``entry``: the example's, or a generated variant."""
        if not entry.parameters:
            return entry.system
        from ..systems._catalog import find_system

        text = find_system(entry.system).read_text(encoding="utf-8")
        text, n = re.subn(r'(?m)^name = "[^"]*"$', f'name = "{entry.system_name}"', text, count=1)
        if n != 1:
            raise FmuCacheError(f"{entry.system}: no 'name = ...' line to change for the variant")
        for key, value in entry.parameters:
            # `key = number` or `key = { value = number, lower = ..., ... }` (a declared range stays)
            text, n = re.subn(rf"(?m)^({re.escape(key)} = \{{ *value = )[^,}}]*|^({re.escape(key)} = )[^{{\n]*$",
                              functools.partial(_with_value, value=value), text, count=1)
            if n != 1:
                raise FmuCacheError(f"{entry.system}: no parameter line '{key} = ...' to change for the variant")
        header = (f"# Generated by lpvest.experiments from the example {entry.system!r} with "
                  + ", ".join(f"{k} = {v:g}" for k, v in entry.parameters) + ".\n")
        path = self.directory / "models" / f"{entry.system_name.replace('-', '_')}.toml"
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.is_file() or path.read_text(encoding="utf-8") != header + text:
            path.write_text(header + text, encoding="utf-8")
        from ..systems._modelfile import load_system

        loaded = load_system(path)
        for key, value in entry.parameters:
            if loaded.parameters.get(key) != value:  # pragma: no cover - guards the text edit above
                raise FmuCacheError(f"{path}: {key} = {loaded.parameters.get(key)}; expected {value}")
        return path

    def plan(self, identifier: str) -> FmuPlan:
        """The :class:`~lpvest.fmi.FmuPlan` of a catalog FMU.

        A variant's model file is written to ``models/`` in the cache folder
        first (rewritten only when its text changed).

        Parameters
        ----------
        identifier : str
            An FMU of :data:`CATALOG`.

        Returns
        -------
        FmuPlan
            The builder's plan of that FMU.

        Raises
        ------
        FmuCacheError
            ``identifier`` is not in :data:`CATALOG`, or its variant's
            parameter values cannot be written into the example's model file.
        """
        from ..fmi._build import plan_system

        entry = CATALOG.get(identifier)
        if entry is None:
            raise FmuCacheError(f"no experiment FMU {identifier!r} (known: {', '.join(CATALOG)})")
        plans, _ = plan_system(self._source(entry), kinds=_kinds(entry.role))
        for plan in plans:
            if plan.identifier == identifier:
                return plan
        raise FmuCacheError(f"{identifier}: the builder plans no such FMU for {entry.system_name}")  # pragma: no cover


def as_experiment_fmus(fmus: ExperimentFmus | str | Path | None, *, backend: str | None = None) -> ExperimentFmus:
    """``fmus`` itself, a cache in the given folder, or the default cache
    (``<default>-native`` for the native backend), building with ``backend``
    (default: a given cache's own, else ``"pythonfmu"``)."""
    if isinstance(fmus, ExperimentFmus):
        if backend is not None and fmus.backend != backend:
            raise ArgumentError(f"the FMU cache {fmus.directory} builds with backend {fmus.backend!r}, "
                                f"not {backend!r}")
        return fmus
    backend = backend or "pythonfmu"
    if fmus is None:
        folder = default_cache_dir()
        fmus = folder if backend == "pythonfmu" else folder.with_name(f"{folder.name}-{backend}")
    return ExperimentFmus(fmus, backend=backend)


# ---------------------------------------------------------------------------
# one co-simulation set-up
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CoSimSpec:
    """A co-simulation: components (``(name, FMU identifier, parameters)``),
    connections, step size and number of steps. :meth:`run` resolves the FMUs
    in an :class:`ExperimentFmus` and runs :func:`lpvest.cosim.simulate`.

    Parameters
    ----------
    components : tuple of (str, str, mapping of str to object)
        ``(instance name, FMU identifier, parameter values)`` of each
        component.
    connections : tuple of str
        ``"plant.y -> filter.y"`` (see :func:`lpvest.cosim.simulate`).
    step_size : float
        The communication step.
    n_steps : int
        Communication steps to run.
    record : tuple of str or None, default None
        Variables to record (``"comp.var"``); None: every output but String
        ones.
    """

    components: tuple[tuple[str, str, Mapping[str, object]], ...]
    connections: tuple[str, ...]
    step_size: float
    n_steps: int
    record: tuple[str, ...] | None = None

    @property
    def fmu_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(ident for _, ident, _ in self.components))

    def run(self, fmus: ExperimentFmus, *, progress: bool | None = None) -> np.ndarray:
        """Run the co-simulation with the FMUs of ``fmus``; a discarded step
        raises (an experiment needs every step).

        Parameters
        ----------
        fmus : ExperimentFmus
            The cache the FMUs come from (built there first when missing or
            stale).
        progress : bool or None, optional
            Show a progress bar; None: for more than 20,000 steps.

        Returns
        -------
        ndarray, shape (n_steps + 1,)
            The recorded values, as :func:`lpvest.cosim.simulate` returns them.

        Raises
        ------
        FmuCacheError
            An FMU is not served by ``fmus`` or fails validation.
        CoSimulationError
            A component failed, or discarded a step.
        """
        from ..cosim import Component, simulate

        comps = [Component(name, fmus.path(ident), dict(params)) for name, ident, params in self.components]
        return simulate(comps, list(self.connections), step_size=self.step_size, n_steps=self.n_steps,
                        record=None if self.record is None else list(self.record), progress=progress,
                        on_discard="error")  # an experiment needs every step

    def describe(self) -> str:
        """The components in order, then the steps.

        Returns
        -------
        str
            E.g. ``"sched = PeixotoEx1Scheduler, plant = PeixotoEx1Plant; 1000 steps of 1"``.
        """
        comps = ", ".join(f"{name} = {ident}" for name, ident, _ in self.components)
        return f"{comps}; {self.n_steps} steps of {self.step_size:g}"


def column(result: np.ndarray, base: str) -> np.ndarray:
    """The recorded elements ``base[1], base[2], ...`` (or ``base``) as an array ``(T, n)``;
    matrix elements ``base[i,j]`` in row-major order."""
    names = result.dtype.names or ()
    if base in names:
        return np.asarray(result[base], dtype=float)[:, None]
    pat = re.compile(re.escape(base) + r"\[(\d+(?:,\d+)*)\]$")
    found = sorted((tuple(int(i) for i in m.group(1).split(",")), n) for n in names if (m := pat.match(n)))
    if not found:
        raise ArgumentError(f"no recorded variable {abbreviate(base, 40)}")
    return np.column_stack([np.asarray(result[n], dtype=float) for _, n in found])


# ---------------------------------------------------------------------------
# FMU against library
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Agreement:
    """FMU co-simulation against the library-only computation for one quantity.

    ``max_abs_difference`` is ``max |fmu - library|`` over every sample and
    element, ``scale`` is ``max |library|``; they agree when the difference is
    at most ``tolerance * max(1, scale)``.
    """

    what: str
    max_abs_difference: float
    scale: float
    tolerance: float = AGREEMENT_TOLERANCE

    @classmethod
    def of(cls, what: str, fmu: ArrayLike, library: ArrayLike, *, tolerance: float = AGREEMENT_TOLERANCE) -> Agreement:
        a = np.asarray(fmu, dtype=float)
        b = np.asarray(library, dtype=float)
        if a.shape != b.shape:
            raise LpvestError(f"{what}: FMU result has shape {a.shape}, library result {b.shape}")
        if a.size == 0:
            return cls(what, 0.0, 0.0, tolerance)
        diff = np.abs(a - b)
        worst = float(np.max(diff)) if np.all(np.isfinite(diff)) else float("inf")
        return cls(what, worst, float(np.max(np.abs(b))), tolerance)

    @property
    def bit_for_bit(self) -> bool:
        return self.max_abs_difference == 0.0

    @property
    def ok(self) -> bool:
        return self.max_abs_difference <= self.tolerance * max(1.0, self.scale)

    def line(self) -> str:
        if self.bit_for_bit:
            verdict = "0 (bit for bit)"
        else:
            verdict = (f"{self.max_abs_difference:.2e} (max |value| {self.scale:.3g}; "
                       + ("within" if self.ok else "EXCEEDS") + f" {self.tolerance:g})")
        return f"{self.what}: max |FMU - library| = {verdict}"

    def to_json(self) -> dict[str, object]:
        return {"what": self.what, "max_abs_difference": self.max_abs_difference, "scale": self.scale,
                "tolerance": self.tolerance, "bit_for_bit": self.bit_for_bit, "ok": self.ok}


@dataclass(frozen=True)
class FmuRun:
    """What an experiment ran through FMUs, and how it agrees with the library."""

    description: str  #: what ran through FMUs, what is library-only
    fmus: tuple[str, ...]  #: FMU identifiers used
    agreements: tuple[Agreement, ...]
    steps: int = 0  #: communication steps, summed over the co-simulations
    wall_time: float = 0.0  #: seconds spent in co-simulations
    notes: tuple[str, ...] = field(default_factory=tuple)  #: other comparisons (not agreement checks)

    @property
    def ok(self) -> bool:
        return all(a.ok for a in self.agreements)

    @property
    def max_abs_difference(self) -> float:
        return max((a.max_abs_difference for a in self.agreements), default=0.0)

    @property
    def bit_for_bit(self) -> bool:
        return all(a.bit_for_bit for a in self.agreements)

    def headline(self) -> str:
        """One line: the largest difference over every compared quantity."""
        n = len(self.agreements)
        if self.bit_for_bit:
            verdict = "0 (bit for bit)"
        else:
            worst = max(self.agreements, key=lambda a: a.max_abs_difference / max(1.0, a.scale))
            verdict = (f"{self.max_abs_difference:.2e} ("
                       + ("within" if self.ok else "EXCEEDS") + f" {worst.tolerance:g} of scale)")
        return f"FMU co-simulation vs library: max |difference| = {verdict} over {n} quantities"

    def lines(self) -> list[str]:
        out = [self.headline(), f"  FMUs: {', '.join(self.fmus)} ({self.steps} steps, {self.wall_time:.1f} s)"]
        out += [f"  {a.line()}" for a in self.agreements]
        out += [f"  note: {n}" for n in self.notes]
        return out

    def to_json(self) -> dict[str, object]:
        return {
            "description": self.description,
            "fmus": list(self.fmus),
            "steps": self.steps,
            "wall_time": self.wall_time,
            "ok": self.ok,
            "bit_for_bit": self.bit_for_bit,
            "max_abs_difference": self.max_abs_difference,
            "agreements": [a.to_json() for a in self.agreements],
            "notes": list(self.notes),
        }


class Timer:
    """Accumulates co-simulation steps and wall time for an :class:`FmuRun`."""

    def __init__(self) -> None:
        self.steps = 0
        self.seconds = 0.0

    def run(self, spec: CoSimSpec, fmus: ExperimentFmus, *, progress: bool | None = None) -> np.ndarray:
        for ident in spec.fmu_names:  # build outside the timed part
            fmus.path(ident)
        t = time.perf_counter()
        out = spec.run(fmus, progress=progress)
        self.seconds += time.perf_counter() - t
        self.steps += spec.n_steps
        return out


# ---------------------------------------------------------------------------
# designs carried by FMUs
# ---------------------------------------------------------------------------
def carried_design(path: str | Path) -> HinfDesign:
    """The :class:`~lpvest.design.HinfDesign` an H-infinity filter FMU carries (``resources/design.json``)."""
    import zipfile

    from ..design import HinfDesign

    with zipfile.ZipFile(path) as z:
        return HinfDesign.from_json(z.read("resources/design.json").decode("utf-8"))


def design_difference(a: HinfDesign, b: HinfDesign) -> float:
    """Largest absolute difference between the filter matrices of two designs."""
    names = ("H", "Af", "Bf", "Cf", "Df")
    if any(np.shape(getattr(a, n)) != np.shape(getattr(b, n)) for n in names):
        return float("inf")
    return max(float(np.max(np.abs(np.asarray(getattr(a, n)) - np.asarray(getattr(b, n))))) for n in names)
