"""Build-time designs of the H-infinity filter FMUs (named in :mod:`lpvest.fmi.registry`).

Each takes the model and returns the design as JSON text, which the FMU carries
as ``resources/design.json``. They run only when no design file is given
(``lpvest build --design FILE``, or the designs stored with the example
systems); they need cvxpy. The FMU itself never imports this module.
"""

from __future__ import annotations

from typing import Any

__all__ = ["hinf_pd", "hinf_robust"]


def _best(model: Any, kind: str) -> str:
    """The best design over every epsilon (:func:`lpvest.design.hinf.search_epsilon`), as JSON."""
    from ..design.hinf import search_epsilon

    return search_epsilon(model, kind=kind).design.to_json()


def hinf_pd(model: Any) -> str:
    """The parameter-dependent filter (Theorem 1), best epsilon."""
    from ..design.result import KIND_PD

    return _best(model, KIND_PD)


def hinf_robust(model: Any) -> str:
    """The robust filter (Corollary 1), best epsilon."""
    from ..design.result import KIND_ROBUST

    return _best(model, KIND_ROBUST)
