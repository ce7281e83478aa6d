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
(the limit of the rescaled LMIs; see :mod:`lpvest.design`).

Examples
--------
>>> lim = stability_limits()
>>> f"{lim.frozen:.4f}"        # the paper: "for rho > 21.4, the system is unstable"
'21.4000'
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._version import __version__
from ..core._plotting import save_figure
from ..parallel._prepared import Prepared
from ..parallel._tasks import Task, TaskResult, map_tasks
from ..systems import PolytopicLPV
from . import Experiment, ExperimentResult, Split, show_progress
from ._fmus import (
    Agreement,
    CoSimSpec,
    ExperimentFmus,
    FmuRun,
    Timer,
    as_experiment_fmus,
    carried_design,
    column,
    design_difference,
)
from ._studies import ExperimentStudy, StudySpec, select_task

if TYPE_CHECKING:
    from ..design._program import HinfProgram
    from ..design._result import HinfDesign
    from ..design._search import EpsilonSearch
    from ..parallel._engine import Engine

__all__ = [
    "EXPERIMENTS",
    "PAPER_TABLE1",
    "run_table1",
    "run_fig1",
    "run_example2",
    "split_example2",
    "example2_part",
    "stability_limits",
    "StabilityLimits",
    "fig1_signals",
    "hinf_cosim",
    "HinfFmuResult",
    "EXAMPLE2_FMU_RHOS",
    "example2_cosim",
    "example2_task",
    "EXAMPLE2_METRICS",
    "prepare_example2_study",
    "EXAMPLE2_STUDY",
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


def _design_summary(design: HinfDesign) -> dict[str, object]:
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
# the paper's scenario through FMUs
# ---------------------------------------------------------------------------
def hinf_cosim(
    filters: Sequence[tuple[str, str]],
    *,
    system: str = "PeixotoEx1",
    steps: int = 100,
    plant_parameters: dict[str, Any] | None = None,
) -> CoSimSpec:
    """The scenario of Figs. 1-2 through FMUs: the Scheduler
    (``theta_k = sin(0.25 k)``), the Source (``w_k = sin(0.5 k) exp(-0.1 k)``
    from ``k = 10``), the Plant (zero initial state) and the filter FMUs
    ``filters`` (``(component name, FMU identifier)``; a parameter-dependent
    filter gets ``theta``, a robust one only ``y``); ``steps`` samples."""
    comps: list[tuple[str, str, Mapping[str, object]]] = [
        ("sched", f"{system}Scheduler", {"kind": "sinusoid", "offset": [0.0], "amplitude": [1.0],
                                         "omega": [0.25]}),
        ("source", f"{system}Source", {"w.kind": "decaying", "w.amplitude": [1.0], "w.omega": [0.5],
                                       "w.decay": [0.1], "w.onset": 10.0}),
        ("plant", f"{system}Plant", dict(plant_parameters or {})),
    ]
    conns = ["sched.p -> plant.p", "source.w -> plant.w"]
    record = ["sched.p", "sched.alpha", "source.w", "plant.y", "plant.z"]
    for name, ident in filters:
        comps.append((name, ident, {}))
        if "Robust" not in ident:
            conns.append(f"sched.p -> {name}.p")
        conns.append(f"plant.y -> {name}.y")
        record += [f"{name}.zhat"]
    return CoSimSpec(tuple(comps), tuple(conns), 1.0, steps - 1, tuple(record))


@dataclass(frozen=True)
class HinfFmuResult:
    """One co-simulation of the paper's scenario, with its library cross-check."""

    errors: dict[str, np.ndarray]  #: component -> e_k = z_k - zhat_k (FMUs), (T, n_z)
    ratios: dict[str, float]  #: component -> ||e||_2 / ||w||_2 (FMUs)
    agreements: tuple[Agreement, ...]
    carried: dict[str, HinfDesign]  #: component -> the design the FMU carries
    design_differences: dict[str, float]  #: component -> max |carried - library design| (filter matrices)
    gamma_differences: dict[str, float]  #: component -> |gamma carried - gamma library| / gamma library
    signals: Fig1Signals


def _hinf_fmus(
    fmus: ExperimentFmus,
    res: np.ndarray,
    spec: CoSimSpec,
    plant: PolytopicLPV,
    designs: dict[str, HinfDesign],
    *,
    plant_name: str = "plant",
    label: str = "",
    signals: bool = True,
) -> HinfFmuResult:
    """Compare the co-simulation ``res`` of ``spec`` with the library, which
    runs the same scenario (``plant.simulate``,
    :class:`~lpvest.estimators.HinfFilter`) with the design each filter
    FMU carries; ``designs`` (filter component -> the library's own design) are
    compared with the carried ones. ``signals=False`` leaves out the checks of
    the Scheduler and Source outputs (already made for another plant)."""
    from ..core._protocol import run_streaming
    from ..estimators._hinf import HinfFilter

    steps = spec.n_steps + 1
    sig = fig1_signals(steps, plant=plant)
    traj = plant.simulate(sig.alpha, sig.w)
    tag = f" ({label})" if label else ""
    agreements = [
        Agreement.of(f"theta (Scheduler FMU){tag}", column(res, "sched.p"), sig.theta[:, None]),
        Agreement.of(f"alpha (Scheduler FMU){tag}", column(res, "sched.alpha"), sig.alpha),
        Agreement.of(f"w (Source FMU){tag}", column(res, "source.w"), sig.w),
    ] if signals else []
    agreements += [
        Agreement.of(f"y (Plant FMU){tag}", column(res, f"{plant_name}.y"), traj.y),
        Agreement.of(f"z (Plant FMU){tag}", column(res, f"{plant_name}.z"), traj.z),
    ]
    z_fmu = column(res, f"{plant_name}.z")
    wnorm = float(np.linalg.norm(sig.w))
    errors, ratios, carried, diffs, gdiffs = {}, {}, {}, {}, {}
    idents = {name: ident for name, ident, _ in spec.components}
    for name, design in designs.items():
        d = carried[name] = carried_design(fmus.path(idents[name]))
        diffs[name] = design_difference(d, design)
        gdiffs[name] = abs(d.gamma - design.gamma) / design.gamma
        if d.scheduled:
            out = run_streaming(HinfFilter(d, simplex_map=plant.simplex_map), {"p": sig.theta[:, None], "y": traj.y})
        else:
            out = run_streaming(HinfFilter(d), {"y": traj.y})
        zhat = column(res, f"{name}.zhat")
        agreements.append(Agreement.of(f"zhat ({idents[name]} FMU vs HinfFilter){tag}", zhat, out["zhat"]))
        errors[name] = z_fmu - zhat
        ratios[name] = float(np.linalg.norm(errors[name])) / wnorm
    return HinfFmuResult(errors, ratios, tuple(agreements), carried, diffs, gdiffs, sig)


def _fmu_run(description: str, spec: CoSimSpec, timer: Timer, runs: Sequence[HinfFmuResult],
             labels: dict[str, str]) -> FmuRun:
    """The :class:`FmuRun` of H-infinity co-simulations, with notes on the designs."""
    notes = []
    for run in runs:
        for name, diff in run.design_differences.items():
            notes.append(
                f"{labels.get(name, name)}: design carried by the FMU (stored in models/designs) vs the library's: "
                f"gamma {run.carried[name].gamma:.6f}, relative difference {run.gamma_differences[name]:.1e}; "
                f"filter matrices differ by {diff:.1e}"
            )
    if any(d > 0 for run in runs for d in run.design_differences.values()):
        notes.append("a design is an interior-point solution: two solves of the same LMIs agree to the solver's "
                     "accuracy and the epsilon search's resolution, not bit for bit (see the report); the FMUs "
                     "carry the stored designs and are checked against the library's HinfFilter on them")
    agreements = tuple(a for run in runs for a in run.agreements)
    return FmuRun(description, spec.fmu_names, agreements, timer.steps, timer.seconds, tuple(notes))


# ---------------------------------------------------------------------------
# Table 1
# ---------------------------------------------------------------------------
def run_table1(
    out_dir: Path | None = None, *, fmus: ExperimentFmus | str | Path | None = None, progress: bool | None = None
) -> ExperimentResult:
    """Example 1: Theorem 1 and Corollary 1 at ``epsilon = 150`` and at the best
    ``epsilon``, next to the paper's Table 1 (``progress``: no progress bar here).

    Table 1 is a design (LMIs), so the FMU part is the designs in use: the
    shipped ``PeixotoEx1HinfPD`` and ``PeixotoEx1HinfRobust`` FMUs, which carry
    the stored best-epsilon designs (models/designs), co-simulated with the
    Scheduler, Source and Plant FMUs in the paper's scenario (Figs. 1-2); the
    library runs the designs found here on the same scenario.
    """
    del progress
    fmus = as_experiment_fmus(fmus)
    from ..design import KIND_PD, KIND_ROBUST, design_hinf, search_epsilon
    from ..systems._modelfile import load_system

    plant = load_system("peixoto-ex1").model(None, PolytopicLPV)
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
    timer = Timer()
    spec = hinf_cosim([("pd", "PeixotoEx1HinfPD"), ("robust", "PeixotoEx1HinfRobust")])
    run = _hinf_fmus(fmus, timer.run(spec, fmus), spec, plant, {"pd": pd_best.design, "robust": rob_best.design})
    lines.append(
        "through FMUs (best-epsilon FMUs, Figs. 1-2 scenario): ||e||_2/||w||_2 = "
        f"{run.ratios['pd']:.4f} <= gamma {run.carried['pd'].gamma:.4f} (PD), "
        f"{run.ratios['robust']:.4f} <= gamma {run.carried['robust'].gamma:.4f} (robust)"
    )
    fmu = _fmu_run(
        "Table 1 is an LMI design (library only: cvxpy + Clarabel). Through FMUs: the shipped PeixotoEx1HinfPD and "
        "PeixotoEx1HinfRobust FMUs, which carry the best-epsilon designs made when they were built, run with the "
        "Scheduler, Source and Plant FMUs on the scenario of Figs. 1-2 (100 samples); cross-check: "
        "plant.simulate and HinfFilter on the carried designs, which are compared with the best-epsilon designs "
        "found here.",
        spec, timer, [run], {"pd": "PD", "robust": "robust"},
    )
    results: dict[str, Any] = {
        "paper": {"theorem1": {"gamma": 1.21, "epsilon": PAPER_EPSILON},
                  "corollary1": {"gamma": 8.18, "epsilon": PAPER_EPSILON},
                  "table1": [{"method": m, "filter": f, "gamma": g} for m, f, g in PAPER_TABLE1]},
        "theorem1": _design_summary(pd150),
        "corollary1": _design_summary(rob150),
        "theorem1_best": {**_design_summary(pd_best.design), "n_evaluations": pd_best.n_evaluations},
        "corollary1_best": {**_design_summary(rob_best.design), "n_evaluations": rob_best.n_evaluations},
        "fmu_ratios": {"theorem1_best": run.ratios["pd"], "corollary1_best": run.ratios["robust"]},
        "fmu_gammas": {"theorem1_best": run.carried["pd"].gamma, "corollary1_best": run.carried["robust"].gamma},
        "fmu_gamma_relative_difference": {"theorem1_best": run.gamma_differences["pd"],
                                          "corollary1_best": run.gamma_differences["robust"]},
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
    paper = (
        ("Theorem 1 (PD), epsilon = 150: gamma", "1.21", f"{pd150.gamma:.4f}"),
        ("Corollary 1 (robust), epsilon = 150: gamma", "8.18", f"{rob150.gamma:.4f}"),
        ("Theorem 1, best epsilon: gamma", "-",
         f"{pd_best.design.gamma:.4f} (epsilon {_eps_text(pd_best.design.epsilon)})"),
        ("Corollary 1, best epsilon: gamma", "-",
         f"{rob_best.design.gamma:.4f} (epsilon {_eps_text(rob_best.design.epsilon)})"),
        ("best Robust of the other methods (Palma et al.)", "8.74", "-"),
        ("best-epsilon FMUs, Figs. 1-2 scenario: ||e||/||w|| (PD, robust)", "-",
         f"{run.ratios['pd']:.4f}, {run.ratios['robust']:.4f}"),
    )
    return ExperimentResult("peixoto-table1", "\n".join(lines), results, tuple(figures), paper, fmu)


def _gamma_at(search: EpsilonSearch, epsilon: float) -> float:
    for e, g in zip(search.curve.epsilon, search.curve.gamma, strict=True):
        if e == epsilon:
            return float(g)
    return math.nan


def _plot_curves(path: Path, pd: EpsilonSearch, rob: EpsilonSearch) -> Path:
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
    return save_figure(fig, path)


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


def fig1_signals(steps: int = 100, *, plant: PolytopicLPV | None = None) -> Fig1Signals:
    """``theta_k = sin(0.25 k)``, ``w_k = sin(0.5 k) exp(-0.1 k)`` for ``k >= 10``."""
    from ..systems._modelfile import load_system
    from ._simulate import peixoto_disturbance

    plant = plant if plant is not None else load_system("peixoto-ex1").model(None, PolytopicLPV)
    k = np.arange(steps, dtype=float)
    theta = np.sin(0.25 * k)
    alpha = plant.alpha_batch(theta[:, None])
    w = peixoto_disturbance(k)[:, None]
    return Fig1Signals(k, theta, alpha, w)


def run_fig1(
    out_dir: Path | None = None, *, steps: int = 100, fmus: ExperimentFmus | str | Path | None = None,
    progress: bool | None = None,
) -> ExperimentResult:
    """Example 1: e_k of the PD and robust filters (epsilon = 150) in the
    paper's scenario, co-simulated as FMUs (``progress``: no progress bar here).

    The Scheduler, Source and Plant FMUs drive ``PeixotoEx1HinfPDEps150`` and
    ``PeixotoEx1HinfRobustEps150``, filter FMUs built with the paper's
    ``epsilon = 150`` designs (:data:`~lpvest.experiments._fmus.PAPER_KINDS`;
    the shipped HinfPD/HinfRobust carry the best-epsilon designs instead). The
    figures show the FMU results. The library designs at ``epsilon = 150``
    here and runs the streaming :class:`~lpvest.estimators.HinfFilter`
    on ``plant.simulate`` as the cross-check.
    """
    from ..design import KIND_PD, KIND_ROBUST, design_hinf
    from ..systems._modelfile import load_system

    del progress
    fmus = as_experiment_fmus(fmus)
    plant = load_system("peixoto-ex1").model(None, PolytopicLPV)
    designs = {
        "theorem1": design_hinf(plant, epsilon=PAPER_EPSILON, kind=KIND_PD),
        "corollary1": design_hinf(plant, epsilon=PAPER_EPSILON, kind=KIND_ROBUST),
    }
    timer = Timer()
    spec = hinf_cosim([("theorem1", "PeixotoEx1HinfPDEps150"), ("corollary1", "PeixotoEx1HinfRobustEps150")],
                      steps=steps)
    run = _hinf_fmus(fmus, timer.run(spec, fmus), spec, plant, designs)
    sig, errors = run.signals, run.errors
    wnorm = float(np.linalg.norm(sig.w))
    results: dict[str, Any] = {"steps": steps, "w_norm": wnorm,
                               "design_gamma_relative_difference": run.gamma_differences,
                               "design_matrix_difference": run.design_differences}
    lines = [f"{'filter (FMU, epsilon = 150)':<30} {'||e||_2/||w||_2':>16} {'gamma':>9}", "-" * 57]
    for name in designs:
        d = run.carried[name]
        e = errors[name]
        ratio = run.ratios[name]
        results[name] = {"ratio": ratio, "gamma": d.gamma, "epsilon": _eps(d.epsilon),
                         "e_norm": float(np.linalg.norm(e)), "e_peak": float(np.max(np.abs(e)))}
        label = "Theorem 1 (PD)" if d.scheduled else "Corollary 1 (robust)"
        lines.append(f"{label:<30} {ratio:>16.4f} {d.gamma:>9.4f}")
    lines.append("theta_k = sin(0.25 k), w_k = sin(0.5 k) exp(-0.1 k) for k >= 10, zero initial state, epsilon = 150")
    fmu = _fmu_run(
        "Scheduler, Source and Plant FMUs drive PeixotoEx1HinfPDEps150 and PeixotoEx1HinfRobustEps150 (FMUs built "
        "with the paper's epsilon = 150 designs) on the scenario of Figs. 1-2; the figures and ratios are the FMU "
        "results. Library cross-check: plant.simulate and HinfFilter on the designs the FMUs carry; the designs "
        "are compared with the epsilon = 150 designs made here.",
        spec, timer, [run], {"theorem1": "PD", "corollary1": "robust"},
    )
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
    pd, rob = results["theorem1"], results["corollary1"]
    paper = (
        ("Fig. 1: the PD filter's error is the smaller", "visual",
         f"||e|| = {pd['e_norm']:.3f} (PD) < {rob['e_norm']:.3f} (robust); peaks {pd['e_peak']:.3f}, "
         f"{rob['e_peak']:.3f}"),
        ("||e||_2/||w||_2 <= gamma (PD)", "gamma 1.21", f"{pd['ratio']:.4f} <= {pd['gamma']:.4f}"),
        ("||e||_2/||w||_2 <= gamma (robust)", "gamma 8.18", f"{rob['ratio']:.4f} <= {rob['gamma']:.4f}"),
    )
    return ExperimentResult("peixoto-fig1", "\n".join(lines), results, tuple(figures), paper, fmu)


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
    p1 = save_figure(
        fig, out_dir / "fig1.png",
        title="Fig. 1: estimation error, epsilon = 150, xi(0) = 0 (Example 1; co-simulated FMUs)",
    )

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
    p2 = save_figure(fig, out_dir / "fig2.png", title="Fig. 2: disturbance and scheduling (Example 1)")
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
    from ..systems._modelfile import load_system

    # the stability study leaves the paper's range [1, 21] on purpose
    system = load_system("peixoto-ex2", parameters={"rho": rho}, allow_outside_range=True)
    return np.array(system.model(None, PolytopicLPV).vertices.A)


def stability_limits(*, tol: float = 1e-6) -> StabilityLimits:
    """Stability limits of the Example 2 plant in ``rho`` (see :class:`StabilityLimits`)."""
    import cvxpy as cp
    from scipy.optimize import brentq

    from ..design import KIND_PD, HinfProgram
    from ..systems._modelfile import load_system

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
        assert P.value is not None  # optimal: the variable has a value
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
    plant = load_system("peixoto-ex2", parameters={"rho": rho_above}, allow_outside_range=True).model(None,
                                                                                                   PolytopicLPV)
    res = HinfProgram.for_plant(plant, kind=KIND_PD).attempt(plant, 1.0)
    return StabilityLimits(float(frozen), float(lo), at_limit, jsr, rho_above, res.status)


#: The values of rho at which Example 2's designs are co-simulated as FMUs.
EXAMPLE2_FMU_RHOS = (1.0, 11.0, 21.0)


def example2_cosim(rhos: Sequence[float] = EXAMPLE2_FMU_RHOS, *, steps: int = 100) -> CoSimSpec:
    """Example 2 through FMUs: one Scheduler and Source drive a Plant FMU per
    ``rho`` (its parameter ``rho``) and the HinfPD FMU designed at that ``rho``
    (``PeixotoEx2HinfPD`` at the file's ``rho = 1``, ``PeixotoEx2Rho11HinfPD``
    ...), in the scenario of Figs. 1-2."""
    base = hinf_cosim([], system="PeixotoEx2", steps=steps)
    comps = [c for c in base.components if c[0] != "plant"]
    conns = [c for c in base.connections if "plant" not in c]
    record = [r for r in (base.record or ()) if not r.startswith("plant.")]
    for rho in rhos:
        tag = f"{rho:g}".replace(".", "_")
        plant, filt = f"plant_rho{tag}", f"pd_rho{tag}"
        ident = "PeixotoEx2HinfPD" if rho == 1.0 else f"PeixotoEx2Rho{rho:g}HinfPD"
        comps += [(plant, "PeixotoEx2Plant", {"rho": float(rho)}), (filt, ident, {})]
        conns += [f"sched.p -> {plant}.p", f"source.w -> {plant}.w", f"sched.p -> {filt}.p", f"{plant}.y -> {filt}.y"]
        record += [f"{plant}.y", f"{plant}.z", f"{filt}.zhat"]
    return CoSimSpec(tuple(comps), tuple(conns), base.step_size, base.n_steps, tuple(record))


@functools.cache
def _example2_program() -> HinfProgram:
    """The LMI program of Theorem 1 for Example 2's dimensions, compiled once
    per process (every rho has the same dimensions: one program serves all)."""
    from ..design import KIND_PD, HinfProgram
    from ..systems._modelfile import load_system

    return HinfProgram.for_plant(load_system("peixoto-ex2").model(None, PolytopicLPV), kind=KIND_PD)


def example2_task(_shared: object, task: Task) -> TaskResult:
    """Theorem 1 on Example 2 at ``task.point["rho"]``: the best epsilon
    (:func:`~lpvest.design.search_epsilon`), or the design at
    ``task.point["epsilon"]`` when the point gives one. Metrics ``gamma``,
    ``design_epsilon`` (``inf`` for the limit) and ``n_evaluations``; the value is
    the :class:`~lpvest.design.HinfDesign`."""
    from ..design import KIND_PD, design_hinf, search_epsilon
    from ..systems._modelfile import load_system

    plant = load_system("peixoto-ex2", parameters={"rho": float(task.point["rho"])}).model(None, PolytopicLPV)
    if "epsilon" in task.point:
        design = design_hinf(plant, epsilon=float(task.point["epsilon"]), kind=KIND_PD, program=_example2_program())
        n = 1
    else:
        s = search_epsilon(plant, kind=KIND_PD, program=_example2_program())
        design, n = s.design, s.n_evaluations
    return TaskResult({"gamma": float(design.gamma), "design_epsilon": float(design.epsilon),
                       "n_evaluations": float(n)}, value=design)


#: The metrics of :func:`example2_task`, in column order.
EXAMPLE2_METRICS = ("gamma", "design_epsilon", "n_evaluations")


def prepare_example2_study(spec: StudySpec, fmus: ExperimentFmus) -> Prepared:
    """The Example 2 study of a sweep file: one :func:`example2_task` per
    ``rho`` (and ``epsilon``, when swept).

    Parameters
    ----------
    spec : StudySpec
        The sweep's spec: the metrics kept.
    fmus : object
        Not used (the study runs no FMU).

    Returns
    -------
    Prepared
        The task function and the metrics (no shared data, no signals).
    """
    return Prepared(select_task(example2_task, spec, EXAMPLE2_METRICS), None, spec.metric_names or EXAMPLE2_METRICS,
                    {}, {"experiment": "peixoto-example2", "lpvest": __version__}, None,
                    "Peixoto et al. Example 2: Theorem 1 per rho (best epsilon, or the given epsilon)")


#: The gamma(rho) curve of ``peixoto-example2`` as a study (``experiment = "peixoto-example2"``).
EXAMPLE2_STUDY = ExperimentStudy(
    "peixoto-example2", "Peixoto et al. Example 2: gamma of Theorem 1 over rho (and epsilon)", prepare_example2_study,
    {"rho": tuple(float(r) for r in range(1, 22)), "epsilon": None}, 0, {}, EXAMPLE2_METRICS, (),
)


def split_example2(
    out_dir: Path | None = None,
    *,
    rhos: Sequence[float] = tuple(map(float, range(1, 22))),
    progress: bool | None = None,
    fmus: ExperimentFmus | str | Path | None = None,
) -> Split:
    """Example 2 as tasks, the plant's stability limits (:func:`stability_limits`),
    the FMU co-simulation (:func:`example2_cosim`) and one design per ``rho``
    (:func:`example2_task`), and the rest (:func:`run_example2`: the FMU
    results against the library, the table, the figure) as the last step: what
    ``lpvest reproduce`` spreads over its workers.

    Parameters
    ----------
    out_dir : Path or None, default None
        Where the last step writes the figure (``None``: nothing written).
    rhos : sequence of float, default 1, 2, ..., 21
        The values of ``rho``.
    progress : bool or None, default None
        Not used: the last step shows no progress bar (the same options as :func:`run_example2`).
    fmus : ExperimentFmus, str, Path or None, default None
        The FMU cache of the co-simulation (the tasks' shared data, and the last step's).

    Returns
    -------
    Split
        ``2 + len(rhos)`` tasks (:func:`example2_part`) and the last step.
    """
    del progress  # the tasks' progress is their caller's
    rhos = tuple(float(r) for r in rhos)
    fmu_rhos = tuple(r for r in EXAMPLE2_FMU_RHOS if r in rhos)
    cache = as_experiment_fmus(fmus)
    tasks = (Task(0, {"stability_limits": 1}), Task(1, {"cosim_rhos": fmu_rhos}),
             *(Task(i + 2, {"rho": rho}) for i, rho in enumerate(rhos)))
    finish = functools.partial(_finish_example2, out_dir, rhos, cache)
    return Split(example2_part, cache, tasks, finish, "Example 2: rho sweep",
                 ("stability limits", "FMU co-simulation", *(f"rho = {rho:g}" for rho in rhos)))


def example2_part(fmus: ExperimentFmus, task: Task) -> TaskResult:
    """A task of :func:`split_example2`: the design at ``task.point["rho"]``
    (:func:`example2_task`); the plant's stability limits (value: the
    :class:`StabilityLimits`) for ``{"stability_limits": 1}``; the FMU
    co-simulation at the values of ``task.point["cosim_rhos"]`` (value: the
    recorded results, the steps and the seconds it took)."""
    if "rho" in task.point:
        return example2_task(None, task)
    if "cosim_rhos" in task.point:
        timer = Timer()
        res = timer.run(example2_cosim(task.point["cosim_rhos"]), fmus)
        return TaskResult(value=(res, timer.steps, timer.seconds))
    return TaskResult(value=stability_limits())


def run_example2(
    out_dir: Path | None = None,
    *,
    rhos: Sequence[float] = tuple(map(float, range(1, 22))),
    progress: bool | None = None,
    fmus: ExperimentFmus | str | Path | None = None,
    engine: Engine | None = None,
) -> ExperimentResult:
    """Example 2: ``gamma(rho)`` of Theorem 1 with the best ``epsilon`` per ``rho``.

    One compiled LMI program serves every ``rho`` (the vertex matrices are
    parameters), one per process. ``progress=None`` shows a tqdm bar when
    writing files with stderr a terminal (:func:`~lpvest.experiments.show_progress`).
    One task per ``rho`` (:func:`example2_task`, :func:`split_example2`), run in
    this process or, with ``engine`` (a :class:`lpvest.parallel.Engine`), on Dask
    workers: the same numbers either way.

    Fig. 3 is a design sweep (library only). Through FMUs
    (:func:`example2_cosim`): at each ``rho`` of :data:`EXAMPLE2_FMU_RHOS` in
    ``rhos``, the HinfPD FMU designed (best epsilon) at that ``rho`` runs with
    the Plant FMU at that ``rho`` in the scenario of Figs. 1-2; its ``gamma`` is
    compared with the sweep's and ``||e||_2 / ||w||_2 <= gamma`` is checked.
    """
    split = split_example2(out_dir, rhos=rhos, fmus=fmus)
    results = map_tasks(split.fn, split.shared, split.tasks, engine=engine, progress=show_progress(progress, out_dir),
                        desc=split.desc)
    return split.finish(results)


def _finish_example2(out_dir: Path | None, rhos: tuple[float, ...], fmus: ExperimentFmus,
                     outcomes: Sequence[TaskResult]) -> ExperimentResult:
    """Example 2 from its tasks' results (the stability limits, the FMU
    co-simulation, then one design per rho): the table, the FMU results against
    the library, the figure."""
    from ..systems._modelfile import load_system

    lim: StabilityLimits = outcomes[0].value
    res, steps, seconds = outcomes[1].value
    curve = outcomes[2:]
    rows: list[dict[str, Any]] = []
    designs: dict[float, HinfDesign] = {}
    for rho, r in zip(rhos, curve, strict=True):
        design = r.value
        designs[float(rho)] = design
        rows.append({"rho": float(rho), "epsilon": _eps(design.epsilon), "gamma": design.gamma,
                     "status": design.status, "n_evaluations": int(r.metrics["n_evaluations"])})
    lines = [f"{'rho':>6} {'epsilon':>10} {'gamma':>9}", "-" * 27]
    for row in rows:
        eps = "inf" if row["epsilon"] is None else f"{row['epsilon']:.4g}"
        lines.append(f"{row['rho']:>6g} {eps:>10} {row['gamma']:>9.4f}")
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

    fmu_rhos = [r for r in EXAMPLE2_FMU_RHOS if r in designs]
    spec = example2_cosim(fmu_rhos)
    timer = Timer()
    timer.steps, timer.seconds = steps, seconds
    runs: list[HinfFmuResult] = []
    fmu_rows: list[dict[str, Any]] = []
    for rho in fmu_rhos:
        tag = f"{rho:g}".replace(".", "_")
        plant = load_system("peixoto-ex2", parameters={"rho": rho}).model(None, PolytopicLPV)
        run = _hinf_fmus(fmus, res, spec, plant, {f"pd_rho{tag}": designs[rho]}, plant_name=f"plant_rho{tag}",
                         label=f"rho = {rho:g}", signals=not runs)
        runs.append(run)
        d = run.carried[f"pd_rho{tag}"]
        fmu_rows.append({"rho": rho, "gamma_fmu": d.gamma, "gamma_sweep": designs[rho].gamma,
                         "gamma_relative_difference": run.gamma_differences[f"pd_rho{tag}"],
                         "ratio": run.ratios[f"pd_rho{tag}"]})
        lines.append(f"through FMUs, rho = {rho:g}: HinfPD FMU gamma {d.gamma:.4f} (sweep {designs[rho].gamma:.4f}), "
                     f"||e||_2/||w||_2 = {run.ratios[f'pd_rho{tag}']:.4f} in the Figs. 1-2 scenario")
    fmu = _fmu_run(
        "Fig. 3 is an LMI design sweep (library only). Through FMUs: at rho = "
        + ", ".join(f"{r:g}" for r in fmu_rhos)
        + " the HinfPD FMU carrying the best-epsilon design for that rho (models/designs) runs with the "
        "PeixotoEx2Plant FMU (parameter rho) on the scenario of Figs. 1-2, one co-simulation with a Scheduler and a "
        "Source; cross-check: plant.simulate and HinfFilter on the carried designs, compared with the sweep's designs.",
        spec, timer, runs, {},
    )
    results: dict[str, Any] = {
        "fmu": fmu_rows,
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
    g = np.array([r["gamma"] for r in rows])
    paper = (
        ("Fig. 3: gamma(rho) grows with rho", "visual (rho = 1..21)",
         f"{rows[0]['gamma']:.4f} at rho = {rows[0]['rho']:g} to {rows[-1]['gamma']:.4f} at rho = {rows[-1]['rho']:g}; "
         + ("increasing" if np.all(np.diff(g) > 0) else "NOT monotone")),
        ("plant unstable for rho >", "21.4", f"{lim.frozen:.4f}"),
        *((f"HinfPD FMU at rho = {r['rho']:g}: ||e||/||w|| <= gamma", "-",
           f"{r['ratio']:.4f} <= {r['gamma_fmu']:.4f}") for r in fmu_rows),
    )
    return ExperimentResult("peixoto-example2", "\n".join(lines), results, tuple(figures), paper, fmu)


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
    return save_figure(fig, path)


EXPERIMENTS = [
    Experiment("peixoto-table1", "Peixoto et al. Table 1: H-infinity bounds, Example 1", run_table1,
               fmus=("PeixotoEx1Plant", "PeixotoEx1Scheduler", "PeixotoEx1Source", "PeixotoEx1HinfPD",
                     "PeixotoEx1HinfRobust")),
    Experiment("peixoto-fig1", "Peixoto et al. Figs. 1-2: estimation errors, Example 1", run_fig1,
               fmus=("PeixotoEx1Plant", "PeixotoEx1Scheduler", "PeixotoEx1Source", "PeixotoEx1HinfPDEps150",
                     "PeixotoEx1HinfRobustEps150")),
    Experiment("peixoto-example2", "Peixoto et al. Fig. 3: gamma(rho) of Theorem 1, Example 2", run_example2,
               reduced={"rhos": EXAMPLE2_FMU_RHOS},
               fmus=("PeixotoEx2Plant", "PeixotoEx2Scheduler", "PeixotoEx2Source", "PeixotoEx2HinfPD",
                     "PeixotoEx2Rho11HinfPD", "PeixotoEx2Rho21HinfPD"),
               split=split_example2, study=EXAMPLE2_STUDY),
]
