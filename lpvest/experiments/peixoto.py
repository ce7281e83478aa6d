"""Peixoto et al. (001_00f62b5a0c49ad87.txt): Table 1, Figs. 1-2 and Fig. 3.

- ``peixoto-table1``: Example 1, the paper's Table 1 next to our Theorem 1 and
  Corollary 1 at ``epsilon = 150`` and at the best ``epsilon`` over the whole
  real line (:func:`lpvest.design.search_epsilon`); figure: ``gamma(epsilon)``.
- ``peixoto-fig1``: Example 1, ``theta_k = sin(0.25 k)``,
  ``w_k = sin(0.5 k) exp(-0.1 k)`` from ``k = 10``, zero initial state: the
  estimation errors ``e_k = z_k - z_{f,k}`` of both filters (Fig. 1), ``w_k``
  and ``alpha_k`` (Fig. 2), and ``||e||_2 / ||w||_2`` next to each ``gamma``.
- ``peixoto-example2``: Example 2, ``gamma(rho)`` of Theorem 1 with the best
  ``epsilon`` for ``rho = 1, 2, ..., 21`` (Fig. 3) and the plant's stability
  limit ``rho = 21.4``, worked out three ways (see :func:`stability_limits`).

In ``results.json`` an ``epsilon`` of ``null`` means ``epsilon = infinity``
(the limit of the rescaled LMIs; see :mod:`lpvest.design.hinf`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import Experiment, ExperimentResult

__all__ = [
    "EXPERIMENTS",
    "PAPER_TABLE1",
    "run_table1",
    "run_fig1",
    "run_example2",
    "stability_limits",
    "StabilityLimits",
    "fig1_signals",
]

#: Table 1 of the paper: (method, filter, gamma).
PAPER_TABLE1: tuple[tuple[str, str, float], ...] = (
    ("(Borges et al., 2010, Theorem 4) (it = 1)", "Robust", 19.41),
    ("(Borges et al., 2010, Theorem 4) (it = 2)", "Robust", 9.10),
    ("(Palma et al., 2020, Theorem 1)", "Robust", 8.74),
    ("Corollary 1 (paper, epsilon = 150)", "Robust", 8.18),
    ("(Borges et al., 2010, Theorem 4) (it = 2)", "PD", 1.22),
    ("(Borges et al., 2010, Theorem 4) (it = 2) [printed twice]", "PD", 1.22),
    ("(Palma et al., 2020, Theorem 1)", "PD", 1.21),
    ("Theorem 1 (paper, epsilon = 150)", "PD", 1.21),
)

#: The epsilon of the paper's Table 1 and Figs. 1-2.
PAPER_EPSILON = 150.0


def _eps(value: float) -> float | None:
    return None if math.isinf(value) else float(value)


def _eps_text(value: float) -> str:
    return "inf" if math.isinf(value) else f"{value:.4g}"


def _design_summary(design: Any) -> dict[str, Any]:
    return {
        "gamma": design.gamma,
        "epsilon": _eps(design.epsilon),
        "multiplier": list(design.multiplier),
        "status": design.status,
        "solver": design.solver,
        "lmi_margin": design.lmi_margin,
        "lyapunov_margin": design.lyapunov_margin,
        "compile_time": design.compile_time,
        "solve_time": design.solve_time,
    }


# ---------------------------------------------------------------------------
# Table 1
# ---------------------------------------------------------------------------
def run_table1(out_dir: Path | None = None) -> ExperimentResult:
    """Example 1: Theorem 1 and Corollary 1 at ``epsilon = 150`` and at the best
    ``epsilon``, next to the paper's Table 1."""
    from ..design import KIND_PD, KIND_ROBUST, design_hinf, search_epsilon
    from ..modelfile import load_system

    plant = load_system("peixoto-ex1").model()
    pd150 = design_hinf(plant, epsilon=PAPER_EPSILON, kind=KIND_PD)
    rob150 = design_hinf(plant, epsilon=PAPER_EPSILON, kind=KIND_ROBUST)
    pd_best = search_epsilon(plant, kind=KIND_PD)
    rob_best = search_epsilon(plant, kind=KIND_ROBUST)

    lines = [f"{'method':<58} {'filter':<7} {'gamma':>8}  {'epsilon':>9}", "-" * 86]
    for method, filt, gamma in PAPER_TABLE1:
        lines.append(f"{method:<58} {filt:<7} {gamma:>8.2f}")
    lines.append("-" * 86)
    ours = [
        ("Corollary 1 (lpvest, epsilon = 150)", "Robust", rob150),
        ("Corollary 1 (lpvest, best epsilon)", "Robust", rob_best.design),
        ("Theorem 1 (lpvest, epsilon = 150)", "PD", pd150),
        ("Theorem 1 (lpvest, best epsilon)", "PD", pd_best.design),
    ]
    for method, filt, d in ours:
        lines.append(f"{method:<58} {filt:<7} {d.gamma:>8.4f}  {_eps_text(d.epsilon):>9}")
    lines.append(
        "best epsilon: grid of 24 angles phi = atan(epsilon) (all signs and magnitudes, and epsilon = inf) "
        "+ bounded Brent refinement"
    )
    lines.append(
        f"Theorem 1: gamma(epsilon) is flat for |epsilon| >~ 1e3 (gamma(inf) = "
        f"{_gamma_at(pd_best, math.inf):.5f}); the best epsilon there is one point of a plateau."
    )
    results: dict[str, Any] = {
        "paper": {"theorem1": {"gamma": 1.21, "epsilon": PAPER_EPSILON},
                  "corollary1": {"gamma": 8.18, "epsilon": PAPER_EPSILON},
                  "table1": [{"method": m, "filter": f, "gamma": g} for m, f, g in PAPER_TABLE1]},
        "theorem1": _design_summary(pd150),
        "corollary1": _design_summary(rob150),
        "theorem1_best": {**_design_summary(pd_best.design), "n_evaluations": pd_best.n_evaluations},
        "corollary1_best": {**_design_summary(rob_best.design), "n_evaluations": rob_best.n_evaluations},
        "curves": {
            name: {"epsilon": [_eps(e) for e in s.curve.epsilon], "phi": s.curve.phi,
                   "gamma": [g if math.isfinite(g) else None for g in s.curve.gamma]}
            for name, s in (("theorem1", pd_best), ("corollary1", rob_best))
        },
    }
    figures: list[Path] = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        for name, d in (("theorem1_eps150", pd150), ("corollary1_eps150", rob150),
                        ("theorem1_best", pd_best.design), ("corollary1_best", rob_best.design)):
            d.to_json(out_dir / f"{name}.json")
        figures.append(_plot_curves(out_dir / "gamma_vs_epsilon.png", pd_best, rob_best))
    return ExperimentResult("peixoto-table1", "\n".join(lines), results, tuple(figures))


def _gamma_at(search: Any, epsilon: float) -> float:
    for e, g in zip(search.curve.epsilon, search.curve.gamma, strict=True):
        if e == epsilon:
            return float(g)
    return math.nan


def _plot_curves(path: Path, pd: Any, rob: Any) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for s, label in ((pd, "Theorem 1 (PD)"), (rob, "Corollary 1 (robust)")):
        ok = np.isfinite(s.curve.gamma)
        ax.plot(s.curve.phi[ok], s.curve.gamma[ok], ".-", label=label)
        ax.plot([math.atan(s.design.epsilon) if math.isfinite(s.design.epsilon) else math.pi / 2],
                [s.design.gamma], "k*", ms=10)
    ax.axvline(math.atan(PAPER_EPSILON), color="gray", ls=":", label="epsilon = 150")
    ticks = [-10, -3, -1, -0.3, 0, 0.3, 1, 3, 10]
    ax.set_xticks([-math.pi / 2] + [math.atan(t) for t in ticks] + [math.pi / 2],
                  ["-inf"] + [f"{t:g}" for t in ticks] + ["inf"])
    ax.set_xlabel("epsilon (axis: atan(epsilon))")
    ax.set_ylabel("gamma")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("Example 1: certified gamma as a function of epsilon (points evaluated by the search)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------
# Figs. 1-2
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Fig1Signals:
    """The paper's scenario for Figs. 1-2 (Example 1)."""

    k: np.ndarray  #: shape (T,)
    theta: np.ndarray  #: shape (T,)
    alpha: np.ndarray  #: shape (T, 2)
    w: np.ndarray  #: shape (T, 1)


def fig1_signals(steps: int = 100, *, plant: Any | None = None) -> Fig1Signals:
    """``theta_k = sin(0.25 k)``, ``w_k = sin(0.5 k) exp(-0.1 k)`` for ``k >= 10``."""
    from ..modelfile import load_system
    from .simulate import peixoto_disturbance

    plant = plant if plant is not None else load_system("peixoto-ex1").model()
    k = np.arange(steps, dtype=float)
    theta = np.sin(0.25 * k)
    alpha = plant.alpha_batch(theta[:, None])
    w = peixoto_disturbance(k)[:, None]
    return Fig1Signals(k, theta, alpha, w)


def run_fig1(out_dir: Path | None = None, *, steps: int = 100) -> ExperimentResult:
    """Example 1: e_k of the PD and robust filters (epsilon = 150) in the
    paper's scenario, run through the streaming :class:`~lpvest.estimators.hinf.HinfFilter`."""
    from ..design import KIND_PD, KIND_ROBUST, design_hinf
    from ..estimators.base import run_streaming
    from ..estimators.hinf import HinfFilter
    from ..modelfile import load_system

    plant = load_system("peixoto-ex1").model()
    sig = fig1_signals(steps, plant=plant)
    traj = plant.simulate(sig.alpha, sig.w)
    designs = {
        "theorem1": design_hinf(plant, epsilon=PAPER_EPSILON, kind=KIND_PD),
        "corollary1": design_hinf(plant, epsilon=PAPER_EPSILON, kind=KIND_ROBUST),
    }
    wnorm = float(np.linalg.norm(sig.w))
    errors: dict[str, np.ndarray] = {}
    results: dict[str, Any] = {"steps": steps, "w_norm": wnorm}
    lines = [f"{'filter':<26} {'||e||_2/||w||_2':>16} {'gamma':>9}", "-" * 53]
    for name, d in designs.items():
        if d.scheduled:
            filt = HinfFilter(d, simplex_map=plant.simplex_map)
            out = run_streaming(filt, {"p": sig.theta[:, None], "y": traj.y})
        else:
            filt = HinfFilter(d)
            out = run_streaming(filt, {"y": traj.y})
        e = traj.z - out["zhat"]
        errors[name] = e
        ratio = float(np.linalg.norm(e)) / wnorm
        results[name] = {"ratio": ratio, "gamma": d.gamma, "epsilon": _eps(d.epsilon),
                         "e_norm": float(np.linalg.norm(e)), "e_peak": float(np.max(np.abs(e)))}
        label = "Theorem 1 (PD)" if d.scheduled else "Corollary 1 (robust)"
        lines.append(f"{label:<26} {ratio:>16.4f} {d.gamma:>9.4f}")
    lines.append("theta_k = sin(0.25 k), w_k = sin(0.5 k) exp(-0.1 k) for k >= 10, zero initial state, epsilon = 150")
    figures: list[Path] = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        figures = _plot_fig1(out_dir, sig, errors)
        np.savetxt(
            out_dir / "signals.csv",
            np.column_stack([sig.k, sig.theta, sig.alpha, sig.w, errors["theorem1"], errors["corollary1"]]),
            delimiter=",", comments="", fmt="%.17g",
            header="k,theta,alpha1,alpha2,w,e1_pd,e2_pd,e1_robust,e2_robust",
        )
    return ExperimentResult("peixoto-fig1", "\n".join(lines), results, tuple(figures))


def _plot_fig1(out_dir: Path, sig: Fig1Signals, errors: dict[str, np.ndarray]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for c, ax in enumerate(axes):
        ax.plot(sig.k, errors["corollary1"][:, c], "r--", label="Corollary 1 (robust)")
        ax.plot(sig.k, errors["theorem1"][:, c], "b-", label="Theorem 1 (PD)")
        ax.set_ylabel(f"e_{c + 1},k")
        ax.grid(alpha=0.3)
    axes[0].legend()
    axes[-1].set_xlabel("k")
    fig.suptitle("Fig. 1: estimation error, epsilon = 150, xi(0) = 0 (Example 1)")
    fig.tight_layout()
    p1 = out_dir / "fig1.png"
    fig.savefig(p1, dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    axes[0].plot(sig.k, sig.w[:, 0], "k-")
    axes[0].set_ylabel("w_k")
    axes[1].plot(sig.k, sig.alpha[:, 0], label="alpha_1,k")
    axes[1].plot(sig.k, sig.alpha[:, 1], label="alpha_2,k")
    axes[1].set_ylabel("alpha_k")
    axes[1].legend()
    axes[-1].set_xlabel("k")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle("Fig. 2: disturbance and scheduling (Example 1)")
    fig.tight_layout()
    p2 = out_dir / "fig2.png"
    fig.savefig(p2, dpi=120)
    plt.close(fig)
    return [p1, p2]


# ---------------------------------------------------------------------------
# Example 2 (Fig. 3)
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class StabilityLimits:
    """Where the Example 2 plant stops being stable, three ways.

    ``frozen``: largest ``rho`` with every frozen ``A(alpha)`` Schur (spectral
    radius < 1 on the vertices and a grid of 101 points of the segment).
    ``quadratic``: largest ``rho`` with a common
    quadratic Lyapunov function ``A_i^T P A_i < P`` (stability under
    arbitrary switching of ``alpha`` on the simplex, which is what the filter
    certificate needs). ``jsr_lower``: a lower bound on the joint spectral
    radius just above the limit (products of vertex matrices).
    """

    frozen: float
    quadratic: float
    eigenvalue_at_limit: complex
    jsr_lower_above: float
    rho_above: float
    theorem1_above_status: str


def _ex2_vertices(rho: float) -> np.ndarray:
    from ..modelfile import load_system

    return np.array(load_system("peixoto-ex2", parameters={"rho": rho}).model().vertices.A)


def stability_limits(*, tol: float = 1e-6) -> StabilityLimits:
    """Stability limits of the Example 2 plant in ``rho`` (see :class:`StabilityLimits`)."""
    import cvxpy as cp
    from scipy.optimize import brentq

    from ..design import KIND_PD, HinfProgram
    from ..modelfile import load_system

    grid = np.linspace(0.0, 1.0, 101)

    def radius(rho: float) -> float:
        A = _ex2_vertices(rho)
        return max(float(np.max(np.abs(np.linalg.eigvals(t * A[0] + (1 - t) * A[1])))) for t in grid)

    frozen = brentq(lambda r: radius(r) - 1.0, 1.0, 40.0, xtol=1e-12)
    eig = np.linalg.eigvals(_ex2_vertices(frozen)[0])
    at_limit = complex(eig[np.argmax(np.abs(eig))])

    def quadratic_ok(rho: float) -> bool:
        A = _ex2_vertices(rho)
        P = cp.Variable((2, 2), symmetric=True)
        cons = [P >> np.eye(2)]
        cons += [a.T @ P @ a - P << -1e-7 * np.eye(2) for a in A]  # symmetric: P is
        prob = cp.Problem(cp.Minimize(0), cons)
        prob.solve(solver="CLARABEL")
        if prob.status != "optimal":
            return False
        Pv = 0.5 * (P.value + P.value.T)
        return bool(np.all(np.linalg.eigvalsh(Pv) > 0)) and all(
            np.max(np.linalg.eigvalsh(a.T @ Pv @ a - Pv)) < 0 for a in A
        )

    lo, hi = 1.0, frozen + 1.0
    if not quadratic_ok(lo):  # pragma: no cover - Example 2 is stable at rho = 1
        lo = math.nan
    else:
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if quadratic_ok(mid) else (lo, mid)
    rho_above = round(frozen + 0.1, 6)
    A = _ex2_vertices(rho_above)
    jsr = max(float(np.max(np.abs(np.linalg.eigvals(a)))) for a in A)
    plant = load_system("peixoto-ex2", parameters={"rho": rho_above}).model()
    res = HinfProgram.for_plant(plant, kind=KIND_PD).attempt(plant, 1.0)
    return StabilityLimits(float(frozen), float(lo), at_limit, jsr, rho_above, res.status)


def run_example2(
    out_dir: Path | None = None,
    *,
    rhos: Sequence[float] = tuple(float(r) for r in range(1, 22)),
    progress: bool | None = None,
) -> ExperimentResult:
    """Example 2: ``gamma(rho)`` of Theorem 1 with the best ``epsilon`` per ``rho``.

    One compiled LMI program serves every ``rho`` (the vertex matrices are
    parameters). ``progress=None`` shows a tqdm bar when stderr is a terminal.
    """
    from tqdm import tqdm

    from ..design import KIND_PD, HinfProgram, search_epsilon
    from ..modelfile import load_system

    rows: list[dict[str, Any]] = []
    program = None
    bar = tqdm(list(rhos), desc="Example 2: rho sweep", unit="rho", disable=None if progress is None else not progress)
    for rho in bar:
        plant = load_system("peixoto-ex2", parameters={"rho": float(rho)}).model()
        if program is None:
            program = HinfProgram.for_plant(plant, kind=KIND_PD)
        s = search_epsilon(plant, kind=KIND_PD, program=program)
        rows.append({"rho": float(rho), "epsilon": _eps(s.design.epsilon), "gamma": s.design.gamma,
                     "status": s.design.status, "n_evaluations": s.n_evaluations})
        bar.set_postfix(gamma=f"{s.design.gamma:.4f}")
    bar.close()
    lim = stability_limits()
    lines = [f"{'rho':>6} {'epsilon':>10} {'gamma':>9}", "-" * 27]
    for r in rows:
        eps = "inf" if r["epsilon"] is None else f"{r['epsilon']:.4g}"
        lines.append(f"{r['rho']:>6g} {eps:>10} {r['gamma']:>9.4f}")
    lines.append(
        "epsilon: the search's best point; gamma(epsilon) often has a flat minimum (rho = 1 and 11: constant "
        "to ~1e-6 over wide ranges of epsilon), so it is one point of that minimum."
    )
    explanation = (
        f"plant stability limit: rho = {lim.frozen:.6f} (paper: 21.4). Vertex 1 has the eigenvalue "
        f"{lim.eigenvalue_at_limit.real:+.6f} there: det(-I - A_1) = 2.1935 - 0.1025 rho = 0. "
        f"A common quadratic Lyapunov function (stability under arbitrary switching) exists up to "
        f"rho = {lim.quadratic:.6f}, so the frozen-vertex and the switching limits coincide; above it "
        f"the joint spectral radius is >= rho(A_1) = {lim.jsr_lower_above:.4f} at rho = {lim.rho_above:g}. "
        f"Theorem 1 certifies V(xi) = xi' P(alpha) xi > 0 decreasing along the plant-filter state, "
        f"which needs a stable plant: at rho = {lim.rho_above:g} the LMIs are infeasible "
        f"({lim.theorem1_above_status})."
    )
    lines.append(explanation)
    results: dict[str, Any] = {
        "curve": rows,
        "stability": {
            "frozen_vertex_limit": lim.frozen,
            "quadratic_lyapunov_limit": lim.quadratic,
            "eigenvalue_at_limit": [lim.eigenvalue_at_limit.real, lim.eigenvalue_at_limit.imag],
            "rho_above": lim.rho_above,
            "spectral_radius_above": lim.jsr_lower_above,
            "theorem1_status_above": lim.theorem1_above_status,
            "paper_limit": 21.4,
            "explanation": explanation,
        },
    }
    figures: list[Path] = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        figures.append(_plot_example2(out_dir / "fig3.png", rows, lim))
    return ExperimentResult("peixoto-example2", "\n".join(lines), results, tuple(figures))


def _plot_example2(path: Path, rows: list[dict[str, Any]], lim: StabilityLimits) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rho = np.array([r["rho"] for r in rows])
    gamma = np.array([r["gamma"] for r in rows])
    eps = np.array([math.inf if r["epsilon"] is None else r["epsilon"] for r in rows])
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(rho, gamma, "b-o", ms=4, label="Theorem 1, best epsilon (lpvest)")
    ax.axvline(lim.frozen, color="r", ls="--", label=f"plant unstable beyond rho = {lim.frozen:.2f}")
    ax.set_ylabel("gamma")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    ax.set_title("Fig. 3: H-infinity guaranteed performance, Example 2")
    ax2.plot(rho, np.arctan(eps), "k.")
    ticks = [-100, -3, -1, 0, 1, 3, 100]
    ax2.set_yticks([math.atan(t) for t in ticks], [f"{t:g}" for t in ticks])
    ax2.set_ylabel("best epsilon")
    ax2.set_title("epsilon found by the search (where gamma(epsilon) has a flat minimum, one point of it)",
                  fontsize="small")
    ax2.set_xlabel("rho")
    ax2.axvline(lim.frozen, color="r", ls="--")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


EXPERIMENTS = [
    Experiment("peixoto-table1", "Peixoto et al. Table 1: H-infinity bounds, Example 1", run_table1),
    Experiment("peixoto-fig1", "Peixoto et al. Figs. 1-2: estimation errors, Example 1", run_fig1),
    Experiment("peixoto-example2", "Peixoto et al. Fig. 3: gamma(rho) of Theorem 1, Example 2", run_example2),
]
