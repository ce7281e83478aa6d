r"""The search over ``epsilon`` of Peixoto et al.'s LMIs: ``gamma(epsilon)``
sampled (:func:`epsilon_curve`) and minimised over the whole real line and its
limit ``epsilon -> infinity`` (:func:`search_epsilon`).

Each point is one :meth:`~lpvest.design.HinfProgram.attempt` of a program
compiled once (:mod:`lpvest.design._program`); ``epsilon = tan(phi)`` maps the
line plus infinity onto the angle ``phi`` in ``(-pi/2, pi/2]``, on which the
LMIs (:mod:`lpvest.design._lmis`) depend continuously.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core._errors import ArgumentError, LMIInfeasibleError, abbreviate
from ..systems._affine import AffineLPV
from ..systems._polytopic import PolytopicLPV
from ._lmis import canonical_phi, epsilon_of_phi
from ._program import (
    DEFAULT_MARGIN,
    DEFAULT_SOLVER,
    DesignAttempt,
    HinfProgram,
    hinf_plant,
    infeasible_message,
    instability,
    program_for,
)
from ._result import KIND_PD, HinfDesign

__all__ = [
    "search_epsilon",
    "epsilon_curve",
    "EpsilonCurve",
    "EpsilonSearch",
]


@dataclass(frozen=True, eq=False)
class EpsilonCurve:
    """``gamma(epsilon)`` sampled: the certified bound at each ``epsilon``.

    ``gamma`` is ``inf`` where no certified design exists (``status`` says why).
    ``phi = atan(epsilon)`` in ``(-pi/2, pi/2]`` (``epsilon = inf`` at ``pi/2``).
    ``gamma_lower`` is the solver's dual bound on the best ``gamma`` at each
    ``epsilon`` (:mod:`lpvest.design._program`, "Dual bound"): the best design at that
    ``epsilon`` lies in ``[gamma_lower, gamma]``, up to the solver's dual
    residual, so ``gamma - gamma_lower`` is how far each point may be from its
    own optimum (about 1e-8 relative with Clarabel, 1e-5 with SCS).

    Parameters
    ----------
    epsilon : ndarray, shape (M,)
        The sampled values of the paper's scalar.
    phi : ndarray, shape (M,)
        ``atan(epsilon)``.
    gamma : ndarray, shape (M,)
        The certified bound at each ``epsilon``; ``inf`` where no certified design exists.
    status : tuple of str, length M
        The final status of each solve (:attr:`DesignAttempt.status`).
    gamma_lower : ndarray, shape (M,)
        The dual bound at each ``epsilon``; nan where ``gamma`` is inf.
    """

    epsilon: np.ndarray
    phi: np.ndarray
    gamma: np.ndarray
    status: tuple[str, ...]
    gamma_lower: np.ndarray

    def __post_init__(self) -> None:
        for name in ("epsilon", "phi", "gamma", "gamma_lower"):  # read-only, as HinfDesign's arrays
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def best(self) -> tuple[float, float]:
        """``(epsilon, gamma)`` of the smallest sampled ``gamma``.

        Returns
        -------
        epsilon : float
            The ``epsilon`` of the first smallest ``gamma`` (of the first sample when every ``gamma`` is inf).
        gamma : float
            That ``gamma``.
        """
        k = int(np.argmin(self.gamma))
        return float(self.epsilon[k]), float(self.gamma[k])


@dataclass(frozen=True, eq=False)
class EpsilonSearch:
    """Result of :func:`search_epsilon`: the best design and every point tried.

    Parameters
    ----------
    design : HinfDesign
        The design at the evaluated ``epsilon`` with the smallest ``gamma``.
    curve : EpsilonCurve
        Every evaluated point, sorted by ``phi``.
    n_evaluations : int
        Epsilon values evaluated (a retry with a larger margin counts once).
    """

    design: HinfDesign
    curve: EpsilonCurve
    n_evaluations: int


def _curve(points: Mapping[float, DesignAttempt]) -> EpsilonCurve:
    phis = sorted(points)
    return EpsilonCurve(
        epsilon=np.array([epsilon_of_phi(p) for p in phis]),
        phi=np.array([canonical_phi(p) for p in phis]),
        gamma=np.array([points[p].gamma for p in phis]),
        status=tuple(points[p].status for p in phis),
        gamma_lower=np.array([points[p].gamma_lower for p in phis]),
    )


def epsilon_curve(
    plant: PolytopicLPV | AffineLPV,
    epsilons: Sequence[float] | np.ndarray,
    *,
    kind: str = KIND_PD,
    solver: str = DEFAULT_SOLVER,
    margin: float = DEFAULT_MARGIN,
    solver_options: Mapping[str, object] | None = None,
    program: HinfProgram | None = None,
) -> EpsilonCurve:
    """``gamma(epsilon)`` at the given ``epsilons`` (one compiled program).

    Parameters
    ----------
    plant : PolytopicLPV or AffineLPV
        The plant (1); a model with general noise is taken in its H-infinity setting
        (:func:`lpvest.systems.hinf_setting`).
    epsilons : sequence of float or ndarray
        The values of ``epsilon`` (flattened, shape (M,)); any real number or ``+-math.inf``.
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Theorem 1 (gain-scheduled filter) or Corollary 1 (robust filter).
    solver : str, default DEFAULT_SOLVER ("AUTO")
        ``"AUTO"`` (Clarabel or SCS by size, :func:`~lpvest.design.choose_solver`) or a cvxpy solver name.
    margin : float, default DEFAULT_MARGIN (1e-6)
        Strictness margin of the LMIs: ``M << -margin I``, ``P_i >> margin I``.
    solver_options : mapping, optional
        Extra keyword arguments for the solver.
    program : HinfProgram, optional
        A compiled program to reuse (by default one is compiled for the plant's dimensions and cached for
        the process). Its ``kind`` must be ``kind``; its own solver, margin and options are used.

    Returns
    -------
    EpsilonCurve
        One point per ``epsilon``, in the given order; a point without a certified design has
        ``gamma = inf`` (no error is raised).

    Examples
    --------
    >>> import lpvest
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> c = epsilon_curve(plant, [1.0, 150.0])
    >>> c.gamma.shape
    (2,)
    """
    plant = hinf_plant(plant)
    prog = program_for(plant, kind, solver, margin, solver_options, program)
    eps = np.asarray(epsilons, dtype=float).ravel()
    with prog.warm_starts():
        out = [prog.attempt(plant, float(e)) for e in eps]
    return EpsilonCurve(
        epsilon=np.where(np.isinf(eps), math.inf, eps),  # -inf and inf are one multiplier: phi = pi/2
        phi=np.array([math.pi / 2 if math.isinf(e) else math.atan(e) for e in eps]),
        gamma=np.array([r.gamma for r in out]),
        status=tuple(r.status for r in out),
        gamma_lower=np.array([r.gamma_lower for r in out]),
    )


def search_epsilon(
    plant: PolytopicLPV | AffineLPV,
    *,
    kind: str = KIND_PD,
    n_grid: int = 24,
    n_refine: int = 2,
    xatol: float = 1e-3,
    solver: str = DEFAULT_SOLVER,
    margin: float = DEFAULT_MARGIN,
    solver_options: Mapping[str, object] | None = None,
    program: HinfProgram | None = None,
    progress: bool = False,
) -> EpsilonSearch:
    """The best ``gamma`` over every real ``epsilon`` (and ``epsilon -> inf``).

    ``epsilon = tan(phi)`` maps the whole line plus infinity onto the circle
    ``phi in (-pi/2, pi/2]``, and the LMIs depend continuously on
    ``(sin phi, cos phi)`` (see :mod:`lpvest.design._lmis`). The search
    evaluates a uniform grid of ``n_grid`` angles (both signs of epsilon,
    magnitudes from ``pi/n_grid`` (``pi/(2 n_grid)`` for an odd ``n_grid``; an
    even one includes ``epsilon = 0``) up to infinity), then refines the
    ``n_refine`` best local minima of the grid by a bounded Brent search
    (``scipy.optimize.minimize_scalar``) between their grid neighbours, to
    ``xatol`` in ``phi``. A minimum whose two neighbours are equal to it within
    the solver's accuracy (their intervals ``[gamma_lower, gamma]``, see
    :class:`EpsilonCurve`, share a point) is not refined: the curve is flat
    there to what the solver can tell. Every evaluation reuses the compiled program (and,
    with SCS, starts from the previous evaluation's point: the search starts
    cold, so its result depends on the plant and the settings alone).
    ``progress=True`` shows a progress bar (tqdm) of the designs solved.

    Parameters
    ----------
    plant : PolytopicLPV or AffineLPV
        The plant (1); a model with general noise is taken in its H-infinity setting
        (:func:`lpvest.systems.hinf_setting`).
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Theorem 1 (gain-scheduled filter) or Corollary 1 (robust filter).
    n_grid : int, default 24
        Number of grid angles ``phi`` (at least 3), spaced ``pi / n_grid`` and ending at ``pi/2``
        (``epsilon = inf``).
    n_refine : int, default 2
        How many of the best local minima of the grid are refined (a minimum where the curve is flat to
        the solver's accuracy is skipped); 0: none.
    xatol : float, default 1e-3
        Absolute tolerance of the Brent search, in ``phi`` (radians).
    solver : str, default DEFAULT_SOLVER ("AUTO")
        ``"AUTO"`` (Clarabel or SCS by size, :func:`~lpvest.design.choose_solver`) or a cvxpy solver name.
    margin : float, default DEFAULT_MARGIN (1e-6)
        Strictness margin of the LMIs: ``M << -margin I``, ``P_i >> margin I``.
    solver_options : mapping, optional
        Extra keyword arguments for the solver.
    program : HinfProgram, optional
        A compiled program to reuse (by default one is compiled for the plant's dimensions and cached for
        the process). Its ``kind`` must be ``kind``; its own solver, margin and options are used.
    progress : bool, default False
        Show a tqdm progress bar.

    Returns
    -------
    EpsilonSearch
        ``design`` at the best ``epsilon`` found, ``curve`` of every evaluated
        point, ``n_evaluations``.

    Raises
    ------
    LMIInfeasibleError
        No grid point gives a certified design. Also raised at once, before any
        solve, when ``A(alpha)`` is not Schur somewhere on the simplex.

    Examples
    --------
    >>> import lpvest
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> best = search_epsilon(plant, kind="robust")
    >>> best.design.gamma < 8.18
    True
    """
    if isinstance(n_grid, bool) or not isinstance(n_grid, int) or n_grid < 3:
        raise ArgumentError(f"n_grid must be an integer, at least 3; found {abbreviate(n_grid, 30)}")
    plant = hinf_plant(plant)
    prog = program_for(plant, kind, solver, margin, solver_options, program)
    unstable = instability(plant)
    if unstable is not None:  # no epsilon can help: say so at once
        raise LMIInfeasibleError(infeasible_message(plant, prog, "every epsilon", unstable), status="infeasible",
                                 detail=unstable)
    points: dict[float, DesignAttempt] = {}
    bar = _progress_bar(progress, n_grid)

    def evaluate(phi: float) -> float:
        key = canonical_phi(phi)
        if key not in points:
            points[key] = prog.attempt(plant, phi=key)
            if bar is not None:
                best = min(p.gamma for p in points.values())
                if bar.n >= bar.total:  # the grid is done: each refinement step adds one
                    bar.total = bar.n + 1
                    bar.set_description_str("epsilon refine", refresh=False)
                bar.set_postfix_str(f"{prog.solver}, best gamma {best:.6g}", refresh=False)
                bar.update(1)
        return points[key].gamma

    with prog.warm_starts(), contextlib.ExitStack() as stack:
        if bar is not None:
            stack.callback(bar.close)
        return _search(plant, prog, evaluate, points, n_grid, n_refine, xatol)


def _progress_bar(progress: bool, total: int) -> Any:
    """A bar of the designs solved, out of ``total`` (the grid; a refinement
    raises it by one a step), with its ETA; it stays when done. Only on a
    terminal: never carriage returns into a redirected log; its count shows
    at any width (:func:`lpvest.core._progress.progress_bar`)."""
    from ..core._progress import on_terminal, progress_bar

    if not progress or not on_terminal():
        return None
    return progress_bar(desc="epsilon search", total=total, unit="design")


def _search(
    plant: PolytopicLPV,
    prog: HinfProgram,
    evaluate: Callable[[float], float],
    points: dict[float, DesignAttempt],
    n_grid: int,
    n_refine: int,
    xatol: float,
) -> EpsilonSearch:
    """The grid and the Brent refinements of :func:`search_epsilon`."""
    from scipy.optimize import minimize_scalar

    step = math.pi / n_grid
    grid = [-math.pi / 2 + step * (k + 1) for k in range(n_grid)]
    gam = [evaluate(p) for p in grid]
    finite = [g for g in gam if math.isfinite(g)]
    if not finite:
        tried = [points[canonical_phi(p)] for p in grid]
        statuses = sorted({t.status for t in tried})
        detail = "; ".join(sorted({t.detail for t in tried}))
        raise LMIInfeasibleError(
            infeasible_message(plant, prog, f"every epsilon tried ({n_grid} values)", detail),
            status=statuses[0] if len(statuses) == 1 else " | ".join(statuses), detail=detail,
        )
    penalty = 10.0 * max(finite) + 1.0
    minima = [
        k for k in range(n_grid)
        if math.isfinite(gam[k]) and gam[k] <= gam[k - 1] and gam[k] <= gam[(k + 1) % n_grid]
    ]
    minima.sort(key=lambda k: gam[k])

    def flat(k: int) -> bool:
        # the grid points k-1, k, k+1 are consistent with one constant gamma:
        # the intervals [gamma_lower, gamma] that hold each point's optimum share
        # a point. Refining there would chase the solver's tolerance (SCS's
        # 1e-5 makes a flat curve look rugged), not a better epsilon. A
        # neighbour whose solve failed (no certified design, but not proved
        # infeasible) tells nothing about the curve and is left out; an
        # infeasible neighbour is a real rise of the curve.
        tried = [points[canonical_phi(grid[i % n_grid])] for i in (k - 1, k, k + 1)]
        if any(t.status.startswith("infeasible") for t in tried):
            return False
        known = [t for t in tried if math.isfinite(t.gamma)]
        if len(known) < 2 or not all(math.isfinite(t.gamma_lower) for t in known):
            return False
        return max(min(t.gamma, t.gamma_lower) for t in known) <= min(max(t.gamma, t.gamma_lower) for t in known)

    for k in [k for k in minima if not flat(k)][: max(0, n_refine)]:
        minimize_scalar(
            lambda p: min(evaluate(p), penalty),
            bounds=(grid[k] - step, grid[k] + step),
            method="bounded",
            options={"xatol": xatol},
        )
    best_phi = min(points, key=lambda p: points[p].gamma)
    design = points[best_phi].design
    assert design is not None
    return EpsilonSearch(design=design, curve=_curve(points), n_evaluations=len(points))
