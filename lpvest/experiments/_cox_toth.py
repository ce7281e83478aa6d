"""Cox & Tóth (000_dc6273d4fec795cd.txt): Example 1 and the truncated Kalman gain.

- ``cox-toth-example1``: the three realizations (21a), (21b), (21c) of
  Example 1, driven by the same ``u``, ``p``, ``e`` from rest, give the same
  ``y`` (the paper: to machine precision); inverting the innovation forms
  (21b), (21c) recovers ``e`` from ``y`` (``e`` is their innovation).
- ``cox-toth-truncation``: on the model ``cox-toth-truncation`` (2 states,
  ``S != 0``, scheduling-dependent ``G``, ``H``) with ``p_t = sin(0.25 t)``:
  the assumptions (5f)-(5h) and bound (8), the decay of
  ``max_t ||P - P^(tau)||`` and ``max_t ||K - K^(tau)||`` with ``tau`` for three
  start covariances of (6a), the ``tau`` needed for 1e-3 and 1e-6, whether
  the decrease is monotone in ``tau`` (Conjecture 1), and the one-step
  prediction-error variance of the exact, truncated and frozen-gain filters
  (exact second moments, checked by Monte Carlo).

Examples
--------
The co-simulation of Example 1 (the FMUs are built on first use, so it is
not run here):

>>> spec = example1_cosim(20)
>>> spec.describe()
'sched = CoxTothEx1Scheduler, source = CoxTothEx1Source, plant = CoxTothEx1Plant; 19 steps of 1'
>>> result = spec.run(ExperimentFmus("out/fmu-cache"))         # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._version import __version__
from ..analysis._fading_memory import (
    compare_filters,
    decay_rate,
    empirical_prediction_error,
    monotonicity,
    tau_needed,
    truncation_errors,
)
from ..core._plotting import save_figure
from ..core._rng import Stream
from ..estimators._truncated import assumption_bounds
from ..estimators.kalman import KalmanModel, kalman_filter
from ..parallel._prepared import Prepared
from ..parallel._tasks import Task, TaskResult, map_tasks
from ..systems import AffineLPV, InnovationLPV, LPVInputOutput
from ..systems._modelfile import load_system
from . import Experiment, ExperimentResult, show_progress
from ._fmus import Agreement, CoSimSpec, ExperimentFmus, FmuRun, Timer, as_experiment_fmus, column
from ._studies import ExperimentStudy, StudySpec, select_task

if TYPE_CHECKING:
    from ..analysis._fading_memory import FilterComparison, TruncationErrors
    from ..parallel._engine import Engine
    from ..systems._affine import LPVTrajectory

__all__ = [
    "EXPERIMENTS",
    "run_example1",
    "run_truncation",
    "example1_cosim",
    "truncation_cosim",
    "PREDICTION_FILTERS",
    "PredictionErrorSetup",
    "prediction_error_setup",
    "prediction_error_task",
    "TRUNCATION_METRICS",
    "TRUNCATION_STUDY_OPTIONS",
    "prepare_truncation_study",
    "TRUNCATION_STUDY",
]


# ---------------------------------------------------------------------------
# Example 1
# ---------------------------------------------------------------------------
def example1_cosim(steps: int = 200, *, seed: int = 2026) -> CoSimSpec:
    """Example 1 through FMUs: the Scheduler (``p_t = 0.6 + 0.3 sin(0.25 t)``),
    the Source (``u_t`` standard normal, seed ``seed``) and the Plant, which
    realizes (21c) and draws ``e_t`` itself (seed ``seed + 1``); ``steps`` samples."""
    return CoSimSpec(
        components=(
            ("sched", "CoxTothEx1Scheduler", {"kind": "sinusoid", "offset": [0.6], "amplitude": [0.3],
                                              "omega": [0.25]}),
            ("source", "CoxTothEx1Source", {"u.kind": "gaussian", "u.seed": seed}),
            ("plant", "CoxTothEx1Plant", {"noise": True, "seed": seed + 1}),
        ),
        connections=("sched.p -> plant.p", "source.u -> plant.u"),
        step_size=1.0,
        n_steps=steps - 1,
        record=("sched.p", "source.u", "plant.y", "plant.x"),
    )


def run_example1(
    out_dir: Path | None = None,
    *,
    steps: int = 200,
    seed: int = 2026,
    fmus: ExperimentFmus | str | Path | None = None,
    progress: bool | None = None,
) -> ExperimentResult:
    """(21a), (21b), (21c) driven by the same ``u``, ``p``, ``e`` (``progress``:
    nothing here takes long enough for a progress bar).

    ``p_t = 0.6 + 0.3 sin(0.25 t)`` (in [0.3, 0.9]: (21b) divides by
    ``p_{t+1}``), ``u_t`` standard normal from ``Stream(seed)``, ``e_t``
    standard normal from ``Stream(seed + 1)`` (:class:`lpvest.core.Stream`: the
    numbers the Source and Plant FMUs draw). Through FMUs: the
    Scheduler, Source and Plant FMUs co-simulate (21c) (the only one of the
    three with a streaming plant: (21a) has no state and (21b)'s gain needs
    ``p_{t+1}``); the library simulates all three.
    """
    del progress
    fmus = as_experiment_fmus(fmus)
    system = load_system("cox-toth-ex1")
    io = system.model("io", LPVInputOutput)
    minimal, augmented = system.model("minimal", InnovationLPV), system.model("augmented", InnovationLPV)
    k = np.arange(steps + 1)
    p = (0.6 + 0.3 * np.sin(0.25 * k))[:, None]  # one extra sample: (21b) needs p_{t+1}
    u = Stream(seed).normal((steps, 1))
    e = Stream(seed + 1).normal((steps, 1))
    y_io = io.simulate(p[:steps], u, e=e).y
    y_min = minimal.simulate(p, u, e=e).y
    aug = augmented.simulate(p[:steps], u, e=e)
    y_aug = aug.y
    e_min = minimal.innovations(p, u, y_io)
    e_aug = augmented.innovations(p[:steps], u, y_io)

    timer = Timer()
    spec = example1_cosim(steps, seed=seed)
    res = timer.run(spec, fmus)
    y_fmu = column(res, "plant.y")
    e_fmu = augmented.innovations(p[:steps], u, y_fmu)
    agreements = (
        Agreement.of("scheduling p (Scheduler FMU)", column(res, "sched.p"), p[:steps]),
        Agreement.of("input u (Source FMU)", column(res, "source.u"), u),
        Agreement.of("output y of (21c) (Plant FMU)", y_fmu, y_aug),
        Agreement.of("state x of (21c) (Plant FMU)", column(res, "plant.x"), aug.x),
    )
    fmu = FmuRun(
        "Scheduler, Source and Plant FMUs co-simulate (21c) (the Plant FMU draws e itself); the library "
        "simulates (21a), (21b) and (21c) with the same p, u, e and inverts (21b), (21c). (21a) and (21b) have "
        "no streaming plant ((21a) has no state, (21b)'s gain needs p_(t+1)), so they are library-only.",
        spec.fmu_names, agreements, timer.steps, timer.seconds,
    )
    scale = float(np.max(np.abs(y_io)))
    results = {
        "steps": steps,
        "seed": seed,
        "max_abs_y": scale,
        "max_diff_21b_21a": float(np.max(np.abs(y_min - y_io))),
        "max_diff_21c_21a": float(np.max(np.abs(y_aug - y_io))),
        "max_diff_21c_21b": float(np.max(np.abs(y_aug - y_min))),
        "max_innovation_error_21b": float(np.max(np.abs(e_min - e))),
        "max_innovation_error_21c": float(np.max(np.abs(e_aug - e))),
        "fmu_max_diff_21a": float(np.max(np.abs(y_fmu - y_io))),
        "fmu_max_diff_21b": float(np.max(np.abs(y_fmu - y_min))),
        "fmu_max_innovation_error_21c": float(np.max(np.abs(e_fmu - e))),
    }
    rows = [
        ("max |y(21b) - y(21a)|", results["max_diff_21b_21a"]),
        ("max |y(21c) - y(21a)|", results["max_diff_21c_21a"]),
        ("max |y(21c) - y(21b)|", results["max_diff_21c_21b"]),
        ("max |e^ - e|, (21b) inverted", results["max_innovation_error_21b"]),
        ("max |e^ - e|, (21c) inverted", results["max_innovation_error_21c"]),
        ("max |y(21c, FMU) - y(21a)|", results["fmu_max_diff_21a"]),
        ("max |y(21c, FMU) - y(21b)|", results["fmu_max_diff_21b"]),
        ("max |e^ - e|, FMU y, (21c) inverted", results["fmu_max_innovation_error_21c"]),
    ]
    lines = [
        f"Cox & Toth Example 1: {steps} samples, p_t = 0.6 + 0.3 sin(0.25 t), u, e ~ N(0, 1) "
        f"(seeds {seed}, {seed + 1})",
        f"max |y| = {scale:.3g}; the paper: the three give the same y (machine precision)",
        f"{'quantity':<38}{'ours':>12}",
        *(f"{name:<38}{val:>12.2e}" for name, val in rows),
    ]
    same_lib = max(v for _, v in rows[:3])
    same_fmu = max(v for _, v in rows[5:7])
    inverted = max(rows[3][1], rows[4][1], rows[7][1])
    paper = (
        ("(21a), (21b), (21c) give the same y", "machine precision",
         f"max difference {same_lib:.1e} (library), {same_fmu:.1e} (Plant FMU); max |y| = {scale:.2g}"),
        ("e recovered by inverting (21b), (21c)", "e is their innovation", f"max error {inverted:.1e}"),
    )
    figures: tuple[Path, ...] = ()
    if out_dir is not None:
        figures = (_plot_example1(out_dir, p[:steps, 0], y_io[:, 0], y_min[:, 0], y_aug[:, 0], y_fmu[:, 0]),)
    return ExperimentResult("cox-toth-example1", "\n".join(lines), results, figures, paper, fmu)


def _plot_example1(
    out_dir: Path, p: np.ndarray, y_io: np.ndarray, y_min: np.ndarray, y_aug: np.ndarray, y_fmu: np.ndarray
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    t = np.arange(p.shape[0])
    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    ax[0].plot(t, p, drawstyle="steps-post")
    ax[0].set_ylabel("p")
    ax[1].plot(t, y_io, label="(21a) input-output", lw=2.5, alpha=0.5)
    ax[1].plot(t, y_min, "--", label="(21b) minimal, rational K")
    ax[1].plot(t, y_aug, ":", label="(21c) augmented, static K")
    ax[1].plot(t, y_fmu, "k.", ms=2.5, label="(21c) Plant FMU, co-simulated")
    ax[1].set_ylabel("y")
    ax[1].legend(fontsize="small", loc="upper right")
    floor = 1e-18  # exact zeros are drawn at this floor
    ax[2].semilogy(t, np.maximum(np.abs(y_min - y_io), floor), ".", ms=3, label="|(21b) - (21a)|")
    ax[2].semilogy(t, np.maximum(np.abs(y_aug - y_io), floor), ".", ms=3, label="|(21c) - (21a)|")
    ax[2].semilogy(t, np.maximum(np.abs(y_fmu - y_io), floor), "x", ms=3, label="|(21c) FMU - (21a)|")
    eps = np.finfo(float).eps * float(np.max(np.abs(y_io)))
    ax[2].axhline(eps, color="gray", lw=0.8, ls="--", label="eps * max|y|")
    ax[2].set_ylim(floor / 3, 1e-12)
    ax[2].set_ylabel("difference")
    ax[2].set_xlabel("t")
    ax[2].legend(fontsize="small", loc="upper right")
    for a in ax:
        a.grid(alpha=0.3)
    return save_figure(fig, out_dir / "example1.png", title="Cox & Toth Example 1: three realizations, one output")


# ---------------------------------------------------------------------------
# truncation
# ---------------------------------------------------------------------------
TRUNCATION_TAUS = tuple(range(0, 61))
PREDICTION_TAUS = (0, 1, 2, 5, 10, 20)
#: The filters whose prediction-error variance is compared (the names of
#: :func:`~lpvest.analysis.compare_filters` with these taus and ``constant_p = 0``).
PREDICTION_FILTERS = ("exact", *(f"truncated tau={t}" for t in PREDICTION_TAUS), "frozen K_inf(p_t)",
                      "constant K_inf(0)")


def _truncation_signals(steps: int) -> tuple[np.ndarray, np.ndarray]:
    """``p_t = sin(0.25 t)`` and ``u_t = sin(0.1 t)``, ``t = 0 .. steps - 1``, as ``(steps, 1)``."""
    k = np.arange(steps)
    return np.sin(0.25 * k)[:, None], np.sin(0.1 * k)[:, None]


@dataclass(frozen=True)
class PredictionErrorSetup:
    """What every Monte Carlo member of the prediction-error check reads: the
    model, ``p``, ``u``, each filter's gains ``K_t`` and exact variance curve."""

    model: AffineLPV
    p: np.ndarray
    u: np.ndarray
    gains: Mapping[str, np.ndarray]  #: filter name -> gains, shape (T, n_x, n_y)
    exact_trace: Mapping[str, np.ndarray]  #: filter name -> trace of the exact second moment, shape (T,)
    mean_trace: Mapping[str, float]  #: filter name -> its mean over t >= burn_in
    runs: int
    seed: int
    burn_in: int


def prediction_error_setup(
    *, steps: int = 300, runs: int = 2000, burn_in: int = 50, seed: int = 7, comparison: FilterComparison | None = None,
) -> PredictionErrorSetup:
    """The set-up of :func:`prediction_error_task` on ``cox-toth-truncation``
    with ``p_t = sin(0.25 t)``, ``u_t = sin(0.1 t)``: the exact, truncated
    (theorem start, :data:`PREDICTION_TAUS`), frozen and constant gains
    (``comparison``: a :func:`~lpvest.analysis.compare_filters`
    result already computed on that set-up)."""
    model = load_system("cox-toth-truncation").model(None, AffineLPV)
    p, u = _truncation_signals(steps)
    cmp = comparison if comparison is not None else compare_filters(
        KalmanModel(model), p, PREDICTION_TAUS, constant_p=[0.0], burn_in=burn_in)
    return PredictionErrorSetup(
        model, p, u, dict(cmp.gains),
        {name: np.trace(cmp.errors[name].output, axis1=1, axis2=2) for name in cmp.gains},
        dict(cmp.mean_trace), runs, seed, burn_in,
    )


def prediction_error_task(setup: PredictionErrorSetup, task: Task) -> TaskResult:
    """One filter's Monte Carlo check (``task.point["filter"]``): ``runs``
    trajectories of (1) from ``default_rng(seed + 1)`` (the same for every
    filter: common random numbers), the sample one-step prediction-error
    covariance, the mean of its trace over ``t >= burn_in`` against the exact
    moment's."""
    name = task.point["filter"]
    if name not in setup.gains:
        raise KeyError(f"no filter {name!r} (filters: {', '.join(setup.gains)})")
    emp = empirical_prediction_error(setup.model, setup.p, setup.u, setup.gains[name], runs=setup.runs,
                                     rng=setup.seed + 1)
    trace = np.trace(emp, axis1=1, axis2=2)
    emp_mean = float(np.mean(trace[setup.burn_in:]))
    exact = setup.mean_trace[name]
    return TaskResult(
        {"mean_trace": exact, "monte_carlo_mean_trace": emp_mean, "relative_difference": emp_mean / exact - 1.0},
        {"monte_carlo_trace": trace, "exact_trace": setup.exact_trace[name]},
    )


#: The metrics of :func:`prediction_error_task`, in column order.
TRUNCATION_METRICS = ("mean_trace", "monte_carlo_mean_trace", "relative_difference")
#: The options of the truncation study and their defaults (those of :func:`run_truncation`).
TRUNCATION_STUDY_OPTIONS: dict[str, int] = {"steps": 300, "runs": 2000, "burn_in": 50, "seed": 7}


def prepare_truncation_study(spec: StudySpec, fmus: ExperimentFmus) -> Prepared:
    """The truncation study of a sweep file: one :func:`prediction_error_task`
    per filter, on :func:`prediction_error_setup` with the spec's options.

    Parameters
    ----------
    spec : StudySpec
        The sweep's spec: options (:data:`TRUNCATION_STUDY_OPTIONS`), the
        ``filter`` axis (names in :data:`PREDICTION_FILTERS`), the metrics and
        signals kept.
    fmus : object
        Not used (the study runs no FMU).

    Returns
    -------
    Prepared
        The task function, the set-up every task reads, the metrics.

    Raises
    ------
    Exception
        ``spec.error(...)`` for an option out of range or an unknown filter.
    """
    opts = {**TRUNCATION_STUDY_OPTIONS, **spec.options}
    for key, low in (("steps", 2), ("runs", 1), ("burn_in", 0), ("seed", 0)):
        if opts[key] < low:
            raise spec.error(f"options.{key}", f"expected an integer >= {low}, found {opts[key]!r}")
    if opts["burn_in"] >= opts["steps"]:
        raise spec.error("options.burn_in", f"expected fewer than steps = {opts['steps']}, found {opts['burn_in']}")
    setup = prediction_error_setup(steps=opts["steps"], runs=opts["runs"], burn_in=opts["burn_in"],
                                   seed=opts["seed"])
    for a in spec.axes:
        for j, v in enumerate(a.values):
            if v not in setup.gains:
                raise spec.error(f"parameters.filter[{j + 1}]", f"no filter {v!r} (filters: {', '.join(setup.gains)})")
    steps = opts["steps"]
    signals = {s: ((steps,), ()) for s in spec.keep}
    return Prepared(select_task(prediction_error_task, spec, TRUNCATION_METRICS), setup,
                    spec.metric_names or TRUNCATION_METRICS, signals,
                    {"experiment": "cox-toth-truncation", "lpvest": __version__, "options": opts},
                    np.arange(steps, dtype=float),
                    f"Cox & Toth prediction-error moments: {opts['runs']} Monte Carlo runs per filter, "
                    f"{steps} samples")


#: The Monte Carlo part of ``cox-toth-truncation`` as a study (``experiment = "cox-toth-truncation"``).
TRUNCATION_STUDY = ExperimentStudy(
    "cox-toth-truncation",
    "Cox & Toth: prediction-error variance of exact, truncated and frozen-gain filters, Monte Carlo against "
    "the exact moments",
    prepare_truncation_study, {"filter": PREDICTION_FILTERS}, 0, TRUNCATION_STUDY_OPTIONS, TRUNCATION_METRICS,
    ("monte_carlo_trace", "exact_trace"),
)


def run_truncation(
    out_dir: Path | None = None,
    *,
    steps: int = 300,
    runs: int = 2000,
    burn_in: int = 50,
    seed: int = 7,
    fmus: ExperimentFmus | str | Path | None = None,
    engine: Engine | None = None,
    progress: bool | None = None,
) -> ExperimentResult:
    """Fading memory of the Kalman gain on ``cox-toth-truncation``, ``p_t = sin(0.25 t)``.

    ``runs`` Monte Carlo trajectories (the same ones for every filter) check
    the exact prediction-error variances; averages are over ``t >= burn_in``.
    One task per filter (:func:`prediction_error_task`), run in this process
    or, with ``engine`` (a :class:`lpvest.parallel.Engine`), on Dask workers:
    the same numbers either way. ``progress``: progress bars (default:
    :func:`~lpvest.experiments.show_progress`).

    Through FMUs (:func:`truncation_cosim`): Scheduler, Source and Plant
    (noise seed ``seed``), the Kalman FMU and one TruncatedKalman FMU per
    ``tau`` in :data:`PREDICTION_TAUS` (theorem start), co-simulated over the
    ``steps`` samples. Cross-checks: the plant against ``model.simulate``, the
    filters against the library's streaming filters on the same data, and the
    FMUs' gains ``K_t``, ``K^(tau)_t`` against the truncation analysis. The
    Monte Carlo variances (``runs`` trajectories) and the exact second moments
    are library-only.
    """
    fmus = as_experiment_fmus(fmus)
    progress = show_progress(progress, out_dir)
    model = load_system("cox-toth-truncation").model(None, AffineLPV)
    km = KalmanModel(model)
    p, u = _truncation_signals(steps)

    bounds_grid = assumption_bounds(km)
    bounds_traj = assumption_bounds(km, p)
    # the data the Plant FMU generates: x_0 ~ N(x0, P0) first, then its noise (seed `seed`), as simulate draws
    data = model.simulate(p, u, rng=seed)
    # bound (8) on the exact filter along the trajectory (t >= 1)
    exact = kalman_filter(km, p, u, data.y)
    min_post = float(np.min(np.linalg.eigvalsh(exact.filtered_covariances[1:])))

    starts: dict[str, dict[str, Any]] = {
        "theorem": {"start": "theorem"},
        "steady-state at p=0": {"start": "steady-state", "start_p": [0.0]},
        "zero": {"start": np.zeros((km.nx, km.nx))},
    }
    decay: dict[str, Any] = {}
    errs_by_start = {}
    for name, kw in starts.items():
        err = truncation_errors(km, p, TRUNCATION_TAUS, progress=progress, **kw)
        errs_by_start[name] = err
        mk, mp = monotonicity(err, which="K"), monotonicity(err, which="P")
        decay[name] = {
            "start_covariance": err.start,
            "taus": err.taus,
            "max_P_error": err.max_P_error,
            "max_K_error": err.max_K_error,
            "tau_needed_K_1e-3": tau_needed(err, 1e-3),
            "tau_needed_K_1e-6": tau_needed(err, 1e-6),
            "tau_needed_P_1e-3": tau_needed(err, 1e-3, which="P"),
            "tau_needed_P_1e-6": tau_needed(err, 1e-6, which="P"),
            "decay_rate_K": decay_rate(err),
            "decay_rate_P": decay_rate(err, which="P"),
            "sup_monotone_K": mk.sup_monotone,
            "sup_monotone_P": mp.sup_monotone,
            "pointwise_pairs_K": mk.pairs,
            "pointwise_violations_K": mk.violations,
            "worst_violation_K": mk.worst,
            "pointwise_pairs_P": mp.pairs,
            "pointwise_violations_P": mp.violations,
            "min_ordering_eigenvalue": float(np.min(err.min_ordering_eigenvalue)),
        }

    fmu, fmu_k_error = _truncation_fmu(fmus, model, p, u, data, errs_by_start["theorem"], seed, steps)

    # prediction-error variances of exact, truncated (theorem start) and frozen-gain filters
    cmp = compare_filters(km, p, PREDICTION_TAUS, constant_p=[0.0], burn_in=burn_in)
    setup = prediction_error_setup(steps=steps, runs=runs, burn_in=burn_in, seed=seed, comparison=cmp)
    variance: dict[str, Any] = {}
    curves = {}
    names = list(cmp.gains)
    # common random numbers: every filter sees the same trajectories
    monte_carlo = map_tasks(prediction_error_task, setup, [{"filter": name} for name in names], engine=engine,
                            progress=progress, desc="prediction error (Monte Carlo)")
    for name, mc in zip(names, monte_carlo, strict=True):
        emp_mean = mc.metrics["monte_carlo_mean_trace"]
        curves[name] = setup.exact_trace[name]
        variance[name] = {
            "mean_trace": cmp.mean_trace[name],
            "excess_over_exact": cmp.excess[name],
            "monte_carlo_mean_trace": emp_mean,
            "monte_carlo_relative_difference": emp_mean / cmp.mean_trace[name] - 1.0,
        }

    results: dict[str, Any] = {
        "steps": steps,
        "schedule": "p_t = sin(0.25 t)",
        "assumptions_grid": bounds_grid._asdict(),
        "assumptions_trajectory": bounds_traj._asdict(),
        "assumptions_hold": bounds_grid.hold,
        "bound_8_lower": bounds_grid.posterior_lower_bound,
        "min_eig_filtered_covariance": min_post,
        "decay": decay,
        "prediction_error": variance,
        "monte_carlo_runs": runs,
        "burn_in": burn_in,
        "fmu_max_K_error": {str(t): v for t, v in fmu_k_error.items()},
    }
    table = _truncation_table(results)
    figures: tuple[Path, ...] = ()
    if out_dir is not None:
        figures = _plot_truncation(out_dir, errs_by_start, curves, p[:, 0])
    th, ss = decay["theorem"], decay["steady-state at p=0"]
    paper = (
        ("assumptions (5f)-(5h)", "needed by Theorem 1", "hold on the box" if bounds_grid.hold else "FAIL"),
        ("Theorem 1: K^(tau) -> K, exponentially in tau", "no numbers (our example)",
         f"rate {th['decay_rate_K']:.3f} per tau; tau = {_fmt_tau(th['tau_needed_K_1e-3'])} for 1e-3, "
         f"{_fmt_tau(th['tau_needed_K_1e-6'])} for 1e-6"),
        ("Conjecture 1: ||K - K^(tau)|| decreases in tau pointwise", "conjectured",
         f"holds with the theorem's start ({th['pointwise_violations_K']} of {th['pointwise_pairs_K']} pairs "
         f"fail); steady-state start: {ss['pointwise_violations_K']} fail"),
        ("max_t ||K - K^(tau)||, tau = 5 (FMUs | analysis)", "-",
         f"{fmu_k_error[5]:.3e} | {th['max_K_error'][5]:.3e}"),
    )
    return ExperimentResult("cox-toth-truncation", table, results, figures, paper, fmu)


def truncation_cosim(steps: int = 300, *, seed: int = 7, taus: Sequence[int] = PREDICTION_TAUS) -> CoSimSpec:
    """The truncation example through FMUs: Scheduler (``p_t = sin(0.25 t)``),
    Source (``u_t = sin(0.1 t)``, ``w = 0``), Plant (its own noise, seed
    ``seed``), the exact Kalman FMU and a TruncatedKalman FMU (theorem start)
    per ``tau``; ``steps`` samples."""
    filters: list[tuple[str, str, dict[str, Any]]] = [("kalman", "CoxTothTruncationKalman", {})]
    filters += [(f"trunc{t}", "CoxTothTruncationTruncatedKalman", {"tau": int(t), "start": "theorem"}) for t in taus]
    conns = ["sched.p -> plant.p", "source.u -> plant.u", "source.w -> plant.w"]
    record = ["sched.p", "source.u", "plant.y", "plant.x"]
    for name, _, _ in filters:
        conns += [f"sched.p -> {name}.p", f"source.u -> {name}.u", f"plant.y -> {name}.y"]
        record += [f"{name}.K", f"{name}.xhat", f"{name}.innovation"]
    return CoSimSpec(
        components=(
            ("sched", "CoxTothTruncationScheduler", {"kind": "sinusoid", "offset": [0.0], "amplitude": [1.0],
                                                     "omega": [0.25]}),
            ("source", "CoxTothTruncationSource", {"u.kind": "sinusoid", "u.amplitude": [1.0], "u.omega": [0.1],
                                                   "w.kind": "zero"}),
            ("plant", "CoxTothTruncationPlant", {"noise": True, "seed": seed}),
            *filters,
        ),
        connections=tuple(conns),
        step_size=1.0,
        n_steps=steps - 1,
        record=tuple(record),
    )


def _truncation_fmu(
    fmus: ExperimentFmus, model: AffineLPV, p: np.ndarray, u: np.ndarray, data: LPVTrajectory,
    theorem: TruncationErrors, seed: int, steps: int,
) -> tuple[FmuRun, dict[int, float]]:
    """Co-simulate :func:`truncation_cosim`; compare with the library."""
    from ..core._protocol import run_streaming
    from ..estimators._truncated import TruncatedKalmanFilter
    from ..estimators.kalman import LPVKalmanFilter

    timer = Timer()
    spec = truncation_cosim(steps, seed=seed)
    res = timer.run(spec, fmus)
    y = column(res, "plant.y")
    agreements = [
        Agreement.of("scheduling p (Scheduler FMU)", column(res, "sched.p"), p),
        Agreement.of("input u (Source FMU)", column(res, "source.u"), u),
        Agreement.of("output y (Plant FMU, own noise) vs model.simulate", y, data.y),
        Agreement.of("state x (Plant FMU) vs model.simulate", column(res, "plant.x"), data.x),
    ]
    nx, ny = model.nx, model.ny
    exact_K = column(res, "kalman.K").reshape(-1, nx, ny)
    lib = run_streaming(LPVKalmanFilter(model), {"p": p, "u": u, "y": data.y})
    agreements += [
        Agreement.of("Kalman FMU xhat vs LPVKalmanFilter", column(res, "kalman.xhat"), lib["xhat"]),
        Agreement.of("Kalman FMU innovation vs LPVKalmanFilter", column(res, "kalman.innovation"), lib["innovation"]),
        Agreement.of("Kalman FMU gain K_t vs truncation analysis", exact_K, theorem.exact_gains),
    ]
    k_error: dict[int, float] = {}
    taus = list(theorem.taus)
    for tau in PREDICTION_TAUS:
        name = f"trunc{tau}"
        K = column(res, f"{name}.K").reshape(-1, nx, ny)
        lib = run_streaming(TruncatedKalmanFilter(model, tau, start="theorem"), {"p": p, "u": u, "y": data.y})
        agreements += [
            Agreement.of(f"TruncatedKalman FMU (tau={tau}) xhat vs TruncatedKalmanFilter",
                         column(res, f"{name}.xhat"), lib["xhat"]),
            Agreement.of(f"TruncatedKalman FMU (tau={tau}) gain vs truncation analysis",
                         K, theorem.truncated_gains[taus.index(tau)]),
        ]
        k_error[tau] = float(np.max(np.linalg.norm(exact_K - K, ord=2, axis=(1, 2))))
    fmu = FmuRun(
        f"Scheduler, Source and Plant FMUs (noise drawn in the Plant FMU, seed {seed}) feed the Kalman FMU and "
        f"{len(PREDICTION_TAUS)} TruncatedKalman FMUs (tau = {', '.join(map(str, PREDICTION_TAUS))}, theorem start) "
        "in one co-simulation; the gains K_t, K^(tau)_t they output are compared with the truncation analysis. "
        "The assumption bounds, the analysis over tau = 0..60 and three start covariances, the exact "
        "prediction-error moments and the Monte Carlo check are library-only (they need no plant run, or "
        "thousands of them).",
        spec.fmu_names, tuple(agreements), timer.steps, timer.seconds,
    )
    return fmu, k_error


def _fmt_tau(v: int | None) -> str:
    return "never" if v is None else str(v)


def _truncation_table(r: dict[str, Any]) -> str:
    b = r["assumptions_grid"]
    lines = [
        f"Truncated Kalman gain on cox-toth-truncation, {r['steps']} samples, {r['schedule']}",
        "assumptions (5f)-(5h) on the box (ERRATA reading: alpha_2, beta_1, delta_2 lower bounds):",
        f"  alpha_2 = {b['alpha2']:.4g}, alpha_1 = {b['alpha1']:.4g}, beta_1 = {b['beta1']:.4g}, "
        f"beta_2 = {b['beta2']:.4g}, delta_2 = {b['delta2']:.4g}, delta_1 = {b['delta1']:.4g}: "
        + ("hold" if r["assumptions_hold"] else "FAIL"),
        f"  bound (8): min eig P_(t|t) = {r['min_eig_filtered_covariance']:.4g} >= "
        f"alpha_2/(alpha_2 beta_2 + 1) = {r['bound_8_lower']:.4g}",
        "",
        f"{'start P^_0 of (6a)':<22}{'tau(K<1e-3)':>12}{'tau(K<1e-6)':>12}{'rate':>8}"
        f"{'sup monotone':>14}{'Conj. 1 fails':>16}",
    ]
    for name, d in r["decay"].items():
        fails = f"{d['pointwise_violations_K']}/{d['pointwise_pairs_K']}"
        lines.append(
            f"{name:<22}{_fmt_tau(d['tau_needed_K_1e-3']):>12}{_fmt_tau(d['tau_needed_K_1e-6']):>12}"
            f"{d['decay_rate_K']:>8.3f}{'yes' if d['sup_monotone_K'] else 'no':>14}{fails:>16}"
        )
    lines += [
        "  (tau: smallest memory from which max_t ||K_t - K^(tau)_t||_2 stays below the tolerance;",
        "   Conj. 1 fails: (t, tau) pairs with ||K - K^(tau+1)|| >= ||K - K^(tau)||, errors > 1e-12)",
        "",
        "max_t ||K_t - K^(tau)_t||_2 (theorem start): "
        + ", ".join(
            f"tau={t}: {e:.2e}"
            for t, e in zip(r["decay"]["theorem"]["taus"], r["decay"]["theorem"]["max_K_error"], strict=True)
            if t in (0, 1, 2, 5, 10, 20, 30, 40)
        ),
        "",
        f"one-step prediction-error variance, mean over t >= {r['burn_in']} of trace E[(y - yhat)(y - yhat)^T]",
        f"{'filter':<22}{'exact moment':>14}{'vs exact':>10}{'Monte Carlo':>14}{'MC/exact-1':>12}",
    ]
    for name, v in r["prediction_error"].items():
        lines.append(
            f"{name:<22}{v['mean_trace']:>14.5f}{100 * v['excess_over_exact']:>9.2f}%"
            f"{v['monte_carlo_mean_trace']:>14.5f}{100 * v['monte_carlo_relative_difference']:>11.2f}%"
        )
    lines.append(f"  (Monte Carlo: {r['monte_carlo_runs']} trajectories of (1))")
    return "\n".join(lines)


def _plot_truncation(
    out_dir: Path, errs: dict[str, TruncationErrors], curves: dict[str, np.ndarray], p: np.ndarray
) -> tuple[Path, ...]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, err in errs.items():
        ax[0].semilogy(err.taus, np.maximum(err.max_K_error, 1e-17), marker=".", label=f"K, start: {name}")
        ax[1].semilogy(err.taus, np.maximum(err.max_P_error, 1e-17), marker=".", label=f"P, start: {name}")
    ax[0].set_ylabel(r"$\max_t \|K_t - K^{(\tau)}_t\|_2$")
    ax[1].set_ylabel(r"$\max_t \|P_{t|t-1} - \hat P^{(\tau)}_{t|t-1}\|_2$")
    for a in ax:
        a.axhline(1e-3, color="gray", lw=0.8, ls="--")
        a.axhline(1e-6, color="gray", lw=0.8, ls=":")
        a.set_xlabel(r"memory $\tau$")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize="small")
    decay_path = save_figure(
        fig, out_dir / "truncation_decay.png",
        title="Fading memory: truncation error against tau (cox-toth-truncation, p_t = sin(0.25 t))",
    )

    theorem = errs["theorem"]
    t = np.arange(theorem.K_error.shape[1])
    fig, ax = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    ax[0].plot(t, p)
    ax[0].set_ylabel("p")
    for tau in (1, 5, 10, 20):
        i = list(theorem.taus).index(tau)
        e = np.where(t > tau, np.maximum(theorem.K_error[i], 1e-17), np.nan)  # t <= tau: exact
        ax[1].semilogy(t, e, label=rf"$\tau$ = {tau}")
    ax[1].set_ylabel(r"$\|K_t - K^{(\tau)}_t\|_2$")
    ax[1].legend(fontsize="small", ncol=4)
    for name, c in curves.items():
        if name in ("truncated tau=0", "truncated tau=1", "truncated tau=2", "frozen K_inf(p_t)", "constant K_inf(0)"):
            ax[2].plot(t, 100 * (c / curves["exact"] - 1.0), label=name)
    ax[2].set_ylabel("excess prediction-error\nvariance over exact [%]")
    late = [100 * (c[20:] / curves["exact"][20:] - 1.0) for n, c in curves.items() if n != "exact"]
    top = float(np.max(late)) if late else 1.0
    ax[2].set_ylim(-0.1 * top, 1.5 * top)  # the first samples (frozen gains ignore P0) are off-scale
    ax[2].set_xlabel("t")
    ax[2].legend(fontsize="small", ncol=2)
    for a in ax:
        a.grid(alpha=0.3)
    time_path = save_figure(
        fig, out_dir / "truncation_over_time.png",
        title="Truncated (theorem start) and frozen gains along the trajectory",
    )
    return decay_path, time_path


EXPERIMENTS = [
    Experiment(
        "cox-toth-example1",
        "Cox & Toth Example 1: (21a), (21b), (21c) give the same y",
        run_example1,
        fmus=("CoxTothEx1Plant", "CoxTothEx1Scheduler", "CoxTothEx1Source"),
    ),
    Experiment(
        "cox-toth-truncation",
        "Cox & Toth Theorem 1 / Conjecture 1: truncated-memory Kalman gain",
        run_truncation,
        reduced={"runs": 200},
        fmus=("CoxTothTruncationPlant", "CoxTothTruncationScheduler", "CoxTothTruncationSource",
              "CoxTothTruncationKalman", "CoxTothTruncationTruncatedKalman"),
        study=TRUNCATION_STUDY,
    ),
]
