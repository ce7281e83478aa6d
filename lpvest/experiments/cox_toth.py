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
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.fading_memory import (
    compare_filters,
    decay_rate,
    empirical_prediction_error,
    monotonicity,
    tau_needed,
    truncation_errors,
)
from ..estimators.kalman import KalmanModel, kalman_filter
from ..estimators.truncated import assumption_bounds
from ..modelfile import load_system
from ..systems.innovation import _window_values
from . import Experiment, ExperimentResult

__all__ = ["EXPERIMENTS", "run_example1", "run_truncation"]


# ---------------------------------------------------------------------------
# Example 1
# ---------------------------------------------------------------------------
def _recover_innovations(model: Any, p: np.ndarray, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Invert an innovation form: ``e_t = y_t - C x^_t - D u_t``,
    ``x^_{t+1} = A x^_t + B u_t + K_t e_t`` from ``x^_0 = x0``."""
    back, ahead = model.window
    T = y.shape[0]
    m = model.dependence.evaluate_batch(p[back : back + T], check=False)
    K = np.broadcast_to(model.K.evaluate(_window_values(model.space, p, back, T)), (T, model.nx, model.ny))
    x = model.x0.copy()
    e = np.empty_like(y)
    for t in range(T):
        e[t] = y[t] - m["C"][t] @ x - m["D"][t] @ u[t]
        x = m["A"][t] @ x + m["B"][t] @ u[t] + K[t] @ e[t]
    return e


def run_example1(out_dir: Path | None = None, *, steps: int = 200, seed: int = 2026) -> ExperimentResult:
    """(21a), (21b), (21c) driven by the same ``u``, ``p``, ``e``.

    ``p_t = 0.6 + 0.3 sin(0.25 t)`` (in [0.3, 0.9]: (21b) divides by
    ``p_{t+1}``), ``u_t``, ``e_t`` standard normal (seeded).
    """
    system = load_system("cox-toth-ex1")
    io, minimal, augmented = system.model("io"), system.model("minimal"), system.model("augmented")
    k = np.arange(steps + 1)
    p = (0.6 + 0.3 * np.sin(0.25 * k))[:, None]  # one extra sample: (21b) needs p_{t+1}
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((steps, 1))
    e = rng.standard_normal((steps, 1))
    y_io = io.simulate(p[:steps], u, e=e).y
    y_min = minimal.simulate(p, u, e=e).y
    y_aug = augmented.simulate(p[:steps], u, e=e).y
    e_min = _recover_innovations(minimal, p, u, y_io)
    e_aug = _recover_innovations(augmented, p[:steps], u, y_io)
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
    }
    rows = [
        ("max |y(21b) - y(21a)|", results["max_diff_21b_21a"]),
        ("max |y(21c) - y(21a)|", results["max_diff_21c_21a"]),
        ("max |y(21c) - y(21b)|", results["max_diff_21c_21b"]),
        ("max |e^ - e|, (21b) inverted", results["max_innovation_error_21b"]),
        ("max |e^ - e|, (21c) inverted", results["max_innovation_error_21c"]),
    ]
    lines = [
        f"Cox & Toth Example 1: {steps} samples, p_t = 0.6 + 0.3 sin(0.25 t), u, e ~ N(0, 1) (seed {seed})",
        f"max |y| = {scale:.3g}; the paper: the three give the same y (machine precision)",
        f"{'quantity':<32}{'ours':>12}",
        *(f"{name:<32}{val:>12.2e}" for name, val in rows),
    ]
    figures: tuple[Path, ...] = ()
    if out_dir is not None:
        figures = (_plot_example1(out_dir, p[:steps, 0], y_io[:, 0], y_min[:, 0], y_aug[:, 0]),)
    return ExperimentResult("cox-toth-example1", "\n".join(lines), results, figures)


def _plot_example1(out_dir: Path, p: np.ndarray, y_io: np.ndarray, y_min: np.ndarray, y_aug: np.ndarray) -> Path:
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
    ax[1].set_ylabel("y")
    ax[1].legend(fontsize="small", loc="upper right")
    floor = 1e-18  # exact zeros are drawn at this floor
    ax[2].semilogy(t, np.maximum(np.abs(y_min - y_io), floor), ".", ms=3, label="|(21b) - (21a)|")
    ax[2].semilogy(t, np.maximum(np.abs(y_aug - y_io), floor), ".", ms=3, label="|(21c) - (21a)|")
    eps = np.finfo(float).eps * float(np.max(np.abs(y_io)))
    ax[2].axhline(eps, color="gray", lw=0.8, ls="--", label="eps * max|y|")
    ax[2].set_ylim(floor / 3, 1e-12)
    ax[2].set_ylabel("difference")
    ax[2].set_xlabel("t")
    ax[2].legend(fontsize="small", loc="upper right")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("Cox & Toth Example 1: three realizations, one output")
    fig.tight_layout()
    path = out_dir / "example1.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------
# truncation
# ---------------------------------------------------------------------------
TRUNCATION_TAUS = tuple(range(0, 61))
PREDICTION_TAUS = (0, 1, 2, 5, 10, 20)


def run_truncation(
    out_dir: Path | None = None,
    *,
    steps: int = 300,
    runs: int = 2000,
    burn_in: int = 50,
    seed: int = 7,
) -> ExperimentResult:
    """Fading memory of the Kalman gain on ``cox-toth-truncation``, ``p_t = sin(0.25 t)``.

    ``runs`` Monte Carlo trajectories (the same ones for every filter) check
    the exact prediction-error variances; averages are over ``t >= burn_in``.
    """
    progress = out_dir is not None
    model = load_system("cox-toth-truncation").model()
    km = KalmanModel(model)
    k = np.arange(steps)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]

    bounds_grid = assumption_bounds(km)
    bounds_traj = assumption_bounds(km, p)
    # bound (8) on the exact filter along the trajectory (t >= 1)
    data = model.simulate(p, u, rng=seed)
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

    # prediction-error variances of exact, truncated (theorem start) and frozen-gain filters
    cmp = compare_filters(km, p, PREDICTION_TAUS, constant_p=[0.0], burn_in=burn_in)
    variance: dict[str, Any] = {}
    items = list(cmp.gains.items())
    if progress:
        from tqdm import tqdm

        items = tqdm(items, desc="prediction error (Monte Carlo)", unit="filter", leave=False)
    curves = {}
    for name, K in items:
        # common random numbers: every filter sees the same trajectories
        emp = empirical_prediction_error(model, p, u, K, runs=runs, rng=seed + 1)
        emp_mean = float(np.mean(np.trace(emp[burn_in:], axis1=1, axis2=2)))
        curves[name] = np.trace(cmp.errors[name].output, axis1=1, axis2=2)
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
    }
    table = _truncation_table(results)
    figures: tuple[Path, ...] = ()
    if out_dir is not None:
        figures = _plot_truncation(out_dir, errs_by_start, curves, p[:, 0])
    return ExperimentResult("cox-toth-truncation", table, results, figures)


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
    out_dir: Path, errs: dict[str, Any], curves: dict[str, np.ndarray], p: np.ndarray
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
    fig.suptitle("Fading memory: truncation error against tau (cox-toth-truncation, p_t = sin(0.25 t))")
    fig.tight_layout()
    decay_path = out_dir / "truncation_decay.png"
    fig.savefig(decay_path, dpi=120)
    plt.close(fig)

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
    fig.suptitle("Truncated (theorem start) and frozen gains along the trajectory")
    fig.tight_layout()
    time_path = out_dir / "truncation_over_time.png"
    fig.savefig(time_path, dpi=120)
    plt.close(fig)
    return decay_path, time_path


EXPERIMENTS = [
    Experiment(
        "cox-toth-example1",
        "Cox & Toth Example 1: (21a), (21b), (21c) give the same y",
        run_example1,
    ),
    Experiment(
        "cox-toth-truncation",
        "Cox & Toth Theorem 1 / Conjecture 1: truncated-memory Kalman gain",
        run_truncation,
    ),
]
