"""Experiments: importable, headless reproductions of the papers' examples.

Each module in this package may define ``EXPERIMENTS``, a sequence of
:class:`Experiment`; :func:`registry` collects them, and ``lpvest reproduce
NAME|all`` runs them. An experiment's ``run(out_dir, *, fmus=None, ...)``
returns an :class:`ExperimentResult` (a printable table, JSON-able numbers,
the figures it wrote, the paper-versus-ours rows of the report, and the
record of what ran through FMUs) and writes nothing when ``out_dir`` is
``None``. ``fmus`` is an :class:`~lpvest.experiments.fmus.ExperimentFmus`
(the FMU cache), a cache folder, or ``None`` for the default cache.
"""

from __future__ import annotations

import importlib
import json
import pkgutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import InternalError

if TYPE_CHECKING:
    from .fmus import FmuRun

__all__ = ["Experiment", "ExperimentResult", "registry", "write_results"]


@dataclass(frozen=True)
class ExperimentResult:
    """What an experiment produced."""

    name: str
    table: str  #: text table, paper next to ours
    results: Mapping[str, Any]  #: JSON-able numbers (written to results.json)
    figures: tuple[Path, ...] = field(default_factory=tuple)
    #: rows ``(quantity, paper, ours)`` of the report's paper-versus-ours table
    paper: tuple[tuple[str, str, str], ...] = field(default_factory=tuple)
    #: what ran through FMUs and how it agrees with the library (None: no FMU part)
    fmu: FmuRun | None = None


@dataclass(frozen=True)
class Experiment:
    """A named, runnable experiment.

    ``run(out_dir, *, fmus=None, **options)``; ``reduced`` holds the options of a
    quicker configuration (``lpvest reproduce all --quick``, the tests).
    """

    name: str
    title: str
    run: Callable[..., ExperimentResult]
    reduced: Mapping[str, Any] = field(default_factory=dict)


def registry() -> dict[str, Experiment]:
    """Every experiment of every module in :mod:`lpvest.experiments`, by name."""
    out: dict[str, Experiment] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        for exp in getattr(module, "EXPERIMENTS", ()):
            if exp.name in out:
                raise InternalError(f"experiment name {exp.name!r} is defined twice")
            out[exp.name] = exp
    return out


def _jsonable(value: Any) -> Any:
    import numpy as np

    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def write_results(result: ExperimentResult, out_dir: Path) -> Path:
    """Write ``results.json`` for ``result`` into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "results.json"
    data = dict(result.results)
    if result.fmu is not None:
        data["fmu_cosimulation"] = result.fmu.to_json()
    path.write_text(json.dumps(_jsonable(data), indent=2) + "\n", encoding="utf-8")
    return path
