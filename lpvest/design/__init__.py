"""Filter design (at build time; cvxpy is imported inside the functions that
need it, so importing this package needs only numpy).

The H-infinity design of Peixoto et al. in three levels, each importing only
the ones before it: ``_lmis.py`` (the LMIs, written once for numpy and cvxpy),
``_program.py`` (:class:`HinfProgram`, compiled once: solver choice, the
eigenvalue check, retries, warm starts, the dual bound; :func:`design_hinf`)
and ``_search.py`` (the search over ``epsilon``); ``_result.py`` holds the
design (:class:`HinfDesign`) as data.

Examples
--------
Theorem 1 for Peixoto et al.'s Example 1 at the paper's ``epsilon = 150``
(Table 1 prints gamma = 1.2138):

>>> from lpvest import load_system
>>> design = design_hinf(load_system("peixoto-ex1").model(), epsilon=150.0)
>>> design.kind, round(design.gamma, 3)
('parameter-dependent', 1.214)
"""

from ._lmis import (
    LMIBlock as LMIBlock,
    lmi_matrices as lmi_matrices,
    multiplier as multiplier,
)
from ._program import (
    DEFAULT_MARGIN as DEFAULT_MARGIN,
    DEFAULT_SOLVER as DEFAULT_SOLVER,
    DesignAttempt as DesignAttempt,
    HinfProgram as HinfProgram,
    choose_solver as choose_solver,
    design_hinf as design_hinf,
)
from ._result import (
    DESIGN_FORMAT as DESIGN_FORMAT,
    DESIGN_FORMAT_VERSION as DESIGN_FORMAT_VERSION,
    KIND_PD as KIND_PD,
    KIND_ROBUST as KIND_ROBUST,
    FilterMatrices as FilterMatrices,
    HinfDesign as HinfDesign,
)
from ._search import (
    EpsilonCurve as EpsilonCurve,
    EpsilonSearch as EpsilonSearch,
    epsilon_curve as epsilon_curve,
    search_epsilon as search_epsilon,
)

__all__ = [
    "DEFAULT_MARGIN",
    "DEFAULT_SOLVER",
    "choose_solver",
    "DesignAttempt",
    "EpsilonCurve",
    "EpsilonSearch",
    "HinfProgram",
    "design_hinf",
    "epsilon_curve",
    "LMIBlock",
    "lmi_matrices",
    "multiplier",
    "search_epsilon",
    "DESIGN_FORMAT",
    "DESIGN_FORMAT_VERSION",
    "KIND_PD",
    "KIND_ROBUST",
    "FilterMatrices",
    "HinfDesign",
]
