"""Build-time designs of the H-infinity filter FMUs (named in :mod:`lpvest.fmi`).

Each takes the model and returns the design as JSON text, which the FMU carries
as ``resources/design.json``. They run only when no design file is given
(``lpvest build --design FILE``, or the designs stored with the example
systems); they need cvxpy. The FMU itself never imports this module.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..systems._affine import AffineLPV
    from ..systems._polytopic import PolytopicLPV

__all__ = ["hinf_pd", "hinf_robust"]


def _best(model: PolytopicLPV | AffineLPV, kind: str, *, epsilon: float | None = None, solver: str = "AUTO",
          n_grid: int | None = None, progress: bool = False) -> str:
    """The design at ``epsilon``, or the best over every epsilon
    (:func:`lpvest.design.search_epsilon`, on its default grid or one of
    ``n_grid`` angles), as JSON. A model with general noise is taken in its
    H-infinity setting."""
    from ..design._program import design_hinf
    from ..design._search import search_epsilon

    if epsilon is not None:
        return design_hinf(model, epsilon=float(epsilon), kind=kind, solver=solver).to_json()
    if n_grid is None:
        return search_epsilon(model, kind=kind, solver=solver, progress=progress).design.to_json()
    return search_epsilon(model, kind=kind, solver=solver, progress=progress, n_grid=n_grid).design.to_json()


def hinf_pd(model: PolytopicLPV | AffineLPV, **options: Any) -> str:
    """The parameter-dependent filter (Theorem 1), best epsilon (options: see ``_best``)."""
    from ..design._result import KIND_PD

    return _best(model, KIND_PD, **options)


def hinf_robust(model: PolytopicLPV | AffineLPV, **options: Any) -> str:
    """The robust filter (Corollary 1), best epsilon (options: see ``_best``)."""
    from ..design._result import KIND_ROBUST

    return _best(model, KIND_ROBUST, **options)
