"""Sridhar, Ghoshal & Michalska, Section V: joint estimation of ``a_0(t)``,
``a_1`` and the state of (33) with B-splines (002_54d0f33f85fddffe.txt).

The system (``models/sridhar_ltv.toml``)::

    y'' + y' + (t^2 + 1) y - u / (t + 1000) = 0,   u = 120 sin t,   x(0) = (0, 0)

is simulated at 1 kHz (:meth:`LTVInputOutput.simulate`, DOP853 at tight
tolerances). The estimator (:func:`~lpvest.estimators.bspline.fit_kernel_model`)
treats ``a_0`` as an unknown quadratic B-spline (order 3, uniform knots),
``a_1`` as an unknown constant and ``b_0 = -1/(t + 1000)`` as known; every
sample is a regression instant. Errors are reported on the paper's inner
window.

- ``sridhar-noiseless`` (Section V-A, Figs. 1-3): window [0, 20] s, n = 86,
  inner window [5, 15] s; the paper reports a_1 = 0.9617.
- ``sridhar-noisy`` (Section V-B, Figs. 4-6): window [0, 9] s, n = 16, inner
  window [1.5, 7.5] s, output noise at 30 dB SNR; the paper reports
  a_1 = 0.8321. Mean and spread over 20 noise seeds (0..19). **SNR**:
  ``10 log10(P_y / sigma^2) = 30`` with ``P_y = mean(y_j^2)`` the power of the
  noise-free output over the window's samples and white Gaussian noise of
  variance ``sigma^2`` added to every sample (MATLAB's ``awgn(y, 30,
  'measured')``). Plain least squares (the paper's pseudo-inverse (31)) is the
  headline; the P-spline penalty with GCV is reported alongside.
- ``sridhar-sliding``: the sliding-window observer (what the observer FMU
  runs) over [0, 20] s: window 4 s, hop 0.5 s, n = 18, estimates at the window
  centre (delay 2 s). Not in the paper.

**Through FMUs** (:func:`sridhar_cosim`): the ``SridharLtvPlant`` FMU
generates the data (the model's DOP853 integration, kept from step to step) and
feeds the ``SridharLtvBSplineObserver`` FMU, one co-simulation over [0, 20] s
that serves the three experiments (run once per process,
:func:`sridhar_data`). The batch fits of Sections V-A and V-B use the plant
FMU's samples ([0, 9] s for V-B, plus measurement noise added to ``y`` per
seed: the plant runs once, not 20 times); the sliding experiment reads the
observer FMU. The library cross-check runs the streaming
:class:`~lpvest.systems.LTVPlant` (the same operations as the plant
FMU: bit for bit) and :class:`~lpvest.estimators.bspline.BSplineObserver` on
its samples. One batch integration over the whole window
(:meth:`~lpvest.systems.LTVInputOutput.simulate`) differs from both at the
integrator's tolerance (~1e-12 of scale); the fits on those data are reported
next to the FMU ones.
"""

from __future__ import annotations

import functools
import hashlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._version import __version__
from ..core._plotting import save_figure
from ..core._protocol import run_streaming
from ..estimators.bspline import BSplineObserver, KernelModel, UnknownConstant, UnknownSpline, fit_kernel_model
from ..parallel._prepared import Prepared
from ..parallel._tasks import Task, TaskResult, map_tasks
from ..systems import LTVInputOutput
from ..systems._modelfile import load_system
from . import Experiment, ExperimentResult, show_progress
from ._fmus import Agreement, CoSimSpec, ExperimentFmus, FmuRun, Timer, as_experiment_fmus, column
from ._studies import ExperimentStudy, StudySpec, select_task

if TYPE_CHECKING:
    from ..parallel._engine import Engine

__all__ = [
    "EXPERIMENTS",
    "PAPER_A1_NOISELESS",
    "PAPER_A1_NOISY",
    "SNR_DB",
    "noisy_output",
    "run_noiseless",
    "run_noisy",
    "run_sliding",
    "sridhar_cosim",
    "sridhar_data",
    "SridharData",
    "NoisySetup",
    "noisy_setup",
    "noisy_seed_task",
    "NOISY_METRICS",
    "prepare_noisy_study",
    "NOISY_STUDY",
]

#: Section V-A: "The estimated constant value of a_1 is 0.9617".
PAPER_A1_NOISELESS = 0.9617
#: Section V-B: "The estimated constant value of a_1 is 0.8321".
PAPER_A1_NOISY = 0.8321
#: Section V-B: "30 SNR".
SNR_DB = 30.0
#: Sample rate of the simulated data (Hz).
RATE = 1000.0


def _system():
    return load_system("sridhar-ltv").model("io", LTVInputOutput)


def noisy_output(y: np.ndarray, snr_db: float, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """``y`` plus white Gaussian noise at ``snr_db``: ``sigma^2 = mean(y^2) / 10^(snr_db / 10)``.

    Returns the noisy samples and ``sigma``.
    """
    sigma = float(np.sqrt(np.mean(y**2) / 10.0 ** (snr_db / 10.0)))
    return y + sigma * rng.standard_normal(y.shape), sigma


def _errors(fit, traj, inner: np.ndarray) -> dict[str, float]:
    t = traj.t
    a0_true = t**2 + 1.0
    return {
        "a1": float(fit.constants["a1"]),
        "a0_max_rel_error": float(np.max(np.abs(fit.values["a0"][inner] - a0_true[inner]) / a0_true[inner])),
        "y_max_error": float(np.max(np.abs(fit.y[inner] - traj.y[inner]))),
        "dy_max_error": float(np.max(np.abs(fit.dy[inner] - traj.x[inner, 1]))),
        "x_max_error": float(np.max(np.abs(fit.x[inner] - traj.x[inner]))),
    }


def _table(rows: list[tuple[str, str, str]]) -> str:
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    lines = [f"{r[0]:<{w0}}  {r[1]:>{w1}}  {r[2]}" for r in rows]
    lines.insert(1, "-" * max(len(line) for line in lines))
    return "\n".join(lines)


def _figure(path: Path, t: np.ndarray, panels: list[dict[str, Any]], title: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panels), 1, figsize=(7.5, 2.6 * len(panels)), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, panel in zip(axes, panels, strict=True):
        for label, values, style in panel["lines"]:
            ax.plot(t, values, style, label=label, lw=panel.get("lw", 1.2), ms=2)
        ax.set_ylabel(panel["ylabel"])
        if panel.get("log"):
            ax.set_yscale("log")
            ax.set_ylim(bottom=1e-17)
        ax.grid(alpha=0.3)
        if any(label for label, _, _ in panel["lines"]):
            ax.legend(loc="best", fontsize=8)
    axes[0].set_title(title)
    axes[-1].set_xlabel("t [s]")
    return save_figure(fig, path)


# -- the data, through FMUs ----------------------------------------------------------------------

#: The sliding observer's configuration (the observer FMU's defaults).
OBSERVER: dict[str, Any] = {"window": 4.0, "hop": 0.5, "n_basis": 18}
#: Length of the shared co-simulation (s): the longest window of the experiments.
T_END = 20.0


def sridhar_cosim(t_end: float = T_END, *, window: float = 4.0, hop: float = 0.5, n_basis: int = 18) -> CoSimSpec:
    """The plant FMU (``u = 120 sin t`` inside, its DOP853 integration kept from step to step) feeding the
    observer FMU (``a_0`` an ``n_basis``-function quadratic B-spline per window,
    ``a_1`` an unknown constant), 1 ms steps over ``[0, t_end]``."""
    h = 1.0 / RATE
    return CoSimSpec(
        components=(
            ("plant", "SridharLtvPlant", {}),
            ("observer", "SridharLtvBSplineObserver", {"dt": h, "window": window, "hop": hop,
                                                       "a0": f"spline:{n_basis}", "a1": "constant",
                                                       "b0": "known", "b1": "known", "penalty": 0.0}),
        ),
        connections=("plant.y -> observer.y", "plant.u_applied -> observer.u"),
        step_size=h,
        n_steps=int(round(t_end * RATE)),
        record=("plant.y", "plant.x", "plant.u_applied", "observer.t_est", "observer.yhat", "observer.dyhat",
                "observer.xhat", "observer.a0[1]", "observer.a1[1]", "observer.valid"),  # a0, a1: also parameters
    )


class _Trajectory:
    """``t``, ``u``, ``y``, ``x`` of one source of data (the shape the fits read)."""

    def __init__(self, t: np.ndarray, u: np.ndarray, y: np.ndarray, x: np.ndarray) -> None:
        self.t, self.u, self.y, self.x = t, u, y, x

    def head(self, n: int) -> _Trajectory:
        return _Trajectory(self.t[:n], self.u[:n], self.y[:n], self.x[:n])


@dataclass(frozen=True)
class SridharData:
    """The shared co-simulation and its library counterparts."""

    fmu: _Trajectory  #: the plant FMU's samples
    observer: dict[str, np.ndarray]  #: the observer FMU's outputs, (T, *shape)
    library: _Trajectory  #: the streaming LTVPlant's samples
    library_observer: dict[str, np.ndarray]  #: BSplineObserver on the library samples
    batch: _Trajectory  #: one DOP853 integration over [0, t_end] (LTVInputOutput.simulate)
    spec: CoSimSpec
    steps: int
    cosim_time: float  #: seconds in the co-simulation
    library_time: float  #: seconds in the streaming library run

    def plant_agreements(self, n: int | None = None) -> tuple[Agreement, ...]:
        """The plant FMU against the streaming LTVPlant over the first ``n`` samples."""
        f, lib = (self.fmu, self.library) if n is None else (self.fmu.head(n), self.library.head(n))
        return (
            Agreement.of("y (SridharLtvPlant FMU vs streaming LTVPlant)", f.y, lib.y),
            Agreement.of("x (SridharLtvPlant FMU vs streaming LTVPlant)", f.x, lib.x),
            Agreement.of("u applied (SridharLtvPlant FMU vs streaming LTVPlant)", f.u, lib.u),
        )

    def batch_note(self, n: int | None = None) -> str:
        f, b = (self.fmu, self.batch) if n is None else (self.fmu.head(n), self.batch.head(n))
        return (f"the plant FMU's integration (DOP853, kept from step to step) and one batch integration "
                f"(LTVInputOutput.simulate, solve_ivp) "
                f"differ by max |dy| = {np.max(np.abs(f.y - b.y)):.1e}, max |dx| = {np.max(np.abs(f.x - b.x)):.1e} "
                f"(max |y| = {np.max(np.abs(b.y)):.3g}, max |x| = {np.max(np.abs(b.x)):.3g})")


_SHARED: dict[tuple, SridharData] = {}


def sridhar_data(fmus: ExperimentFmus, *, progress: bool = False) -> SridharData:
    """Run :func:`sridhar_cosim` and its library counterparts, once per process
    and set of FMU files (the three Sridhar experiments share them)."""
    from ..systems._streaming import LTVPlant

    spec = sridhar_cosim()
    paths = [fmus.path(ident) for ident in spec.fmu_names]
    key = tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in paths)
    if key in _SHARED:
        return _SHARED[key]
    io = _system()
    timer = Timer()
    res = timer.run(spec, fmus, progress=progress)
    t = res["time"].copy()
    fmu = _Trajectory(t, column(res, "plant.u_applied")[:, 0], column(res, "plant.y")[:, 0], column(res, "plant.x"))
    observer = {name: column(res, f"observer.{name}") for name in
                ("t_est", "yhat", "dyhat", "xhat", "a0", "a1", "valid")}

    # library: the streaming plant with the master's communication points
    t0 = time.perf_counter()
    h, n = spec.step_size, spec.n_steps
    plant = LTVPlant(io)
    y, x, u = np.empty(n + 1), np.empty((n + 1, 2)), np.empty(n + 1)
    hold = {"u": np.zeros(1)}
    from ..core._progress import progress_bar

    for k in progress_bar(range(n + 1), desc="library plant", unit="step", show=progress, leave=False,
                          mininterval=0.5):
        out = plant.step(hold, dt=h, t_end=k * h + h) if k < n else plant.outputs(hold)
        y[k], x[k], u[k] = out["y"][0], out["x"], out["u_applied"][0]
    library = _Trajectory(np.arange(n + 1) * h, u, y, x)
    model = KernelModel.from_io(io, a0=UnknownSpline(OBSERVER["n_basis"], order=3), a1=UnknownConstant())
    obs = BSplineObserver(model, dt=h, window=OBSERVER["window"], hop=OBSERVER["hop"], penalty=None,
                          on_unidentifiable="hold")
    lib_obs = run_streaming(obs, {"u": u[:, None], "y": y[:, None]})
    library_time = time.perf_counter() - t0
    traj = io.simulate(library.t)
    batch = _Trajectory(traj.t, traj.u, traj.y, traj.x)
    data = SridharData(fmu, observer, library, lib_obs, batch, spec, timer.steps, timer.seconds, library_time)
    _SHARED.clear()
    _SHARED[key] = data
    return data


def _fmu_run(data: SridharData, description: str, agreements: tuple[Agreement, ...],
             notes: tuple[str, ...]) -> FmuRun:
    shared = ("one co-simulation of the plant and observer FMUs over [0, 20] s serves the three Sridhar "
              f"experiments (computed once per process: {data.cosim_time:.1f} s; the streaming library run "
              f"{data.library_time:.1f} s)")
    return FmuRun(description, data.spec.fmu_names, agreements, data.steps, data.cosim_time, (*notes, shared))


# -- Section V-A ---------------------------------------------------------------------------------


def run_noiseless(
    out_dir: Path | None = None, *, fmus: ExperimentFmus | str | Path | None = None, progress: bool | None = None
) -> ExperimentResult:
    """Section V-A: window [0, 20] s, n = 86 quadratic B-splines, inner window [5, 15] s,
    on the samples of the plant FMU (see the module documentation). ``progress``:
    progress bars (default: :func:`~lpvest.experiments.show_progress`)."""
    data = sridhar_data(as_experiment_fmus(fmus), progress=show_progress(progress, out_dir))
    io, traj = _system(), data.fmu
    model = KernelModel.from_io(io, a0=UnknownSpline(86, order=3), a1=UnknownConstant())
    fit = fit_kernel_model(model, traj.t, traj.u, traj.y)
    fit_batch = fit_kernel_model(model, data.batch.t, data.batch.u, data.batch.y)
    t = traj.t
    inner = (t >= 5.0) & (t <= 15.0)
    res: dict[str, Any] = _errors(fit, traj, inner)
    res.update(
        paper_a1=PAPER_A1_NOISELESS,
        a1_error=abs(res["a1"] - 1.0),
        window=[0.0, 20.0],
        inner_window=[5.0, 15.0],
        n_basis=86,
        order=3,
        samples=int(t.size),
        sample_rate_hz=RATE,
        condition=fit.condition,
        residual_rms=fit.residual_rms,
        a0_max_rel_error_full_window=float(np.max(np.abs(fit.values["a0"] - (t**2 + 1)) / (t**2 + 1))),
        a1_batch_integration=float(fit_batch.constants["a1"]),
        a1_difference_fmu_vs_batch=float(abs(fit.constants["a1"] - fit_batch.constants["a1"])),
    )
    table = _table([
        ("quantity (inner window [5, 15] s)", "paper", "ours"),
        ("a_1 (true 1)", f"{PAPER_A1_NOISELESS:.4f}", f"{res['a1']:.12f}"),
        ("|a_1 - 1|", f"{abs(PAPER_A1_NOISELESS - 1):.2e}", f"{res['a1_error']:.2e}"),
        ("max |a_0 - (t^2+1)| / (t^2+1)", "Fig. 1 (visual)", f"{res['a0_max_rel_error']:.2e}"),
        ("max |y_E - y|", "Fig. 2 (visual)", f"{res['y_max_error']:.2e}"),
        ("max |y_E' - y'|", "Fig. 3 (visual)", f"{res['dy_max_error']:.2e}"),
        ("cond(P, column-scaled)", "-", f"{res['condition']:.3g}"),
        ("a_1 on one batch integration's data", "-", f"{res['a1_batch_integration']:.12f}"),
    ])
    fmu = _fmu_run(
        data,
        "The SridharLtvPlant FMU generates the 20,001 samples (co-simulated with the observer FMU, whose "
        "outputs feed sridhar-sliding); the batch fit (31) runs on them (library: fit_kernel_model). "
        "Cross-check: the streaming LTVPlant (the same operations).",
        data.plant_agreements(),
        (data.batch_note(), f"a_1 from the FMU samples {res['a1']:.12f}, from the batch integration "
         f"{res['a1_batch_integration']:.12f} (difference {res['a1_difference_fmu_vs_batch']:.1e})"),
    )
    paper = (
        ("a_1 (true 1)", f"{PAPER_A1_NOISELESS:.4f}", f"{res['a1']:.10f}"),
        ("max |a_0 - (t^2+1)| / (t^2+1) on [5, 15] s", "Fig. 1 (visual)", f"{res['a0_max_rel_error']:.1e}"),
        ("max |y_E - y|, max |y_E' - y'|", "Figs. 2-3 (visual)",
         f"{res['y_max_error']:.1e}, {res['dy_max_error']:.1e}"),
    )
    figures: list[Path] = []
    if out_dir is not None:
        ti = t[inner]
        figures.append(_figure(out_dir / "fig1_a0.png", ti, [
            {"ylabel": "a_0(t)", "lines": [("true t^2 + 1", (ti**2 + 1), "k-"),
                                         ("estimate", fit.values["a0"][inner], "r--")]},
            {"ylabel": "relative error", "log": True,
             "lines": [("|a_0 est - a_0| / a_0", np.abs(fit.values["a0"][inner] - (ti**2 + 1)) / (ti**2 + 1),
                        "r-")]},
        ], "Fig. 1: estimated a_0, noiseless (n = 86, inner window)"))
        figures.append(_figure(out_dir / "fig2_y.png", ti, [
            {"ylabel": "y", "lines": [("true y", traj.y[inner], "k-"), ("y_E", fit.y[inner], "r--")]},
            {"ylabel": "|y_E - y|", "log": True, "lines": [("error", np.abs(fit.y - traj.y)[inner], "r-")]},
        ], "Fig. 2: estimated output y, noiseless"))
        figures.append(_figure(out_dir / "fig3_dy.png", ti, [
            {"ylabel": "y'", "lines": [("true y' = x_2", traj.x[inner, 1], "k-"), ("y_E'", fit.dy[inner], "r--")]},
            {"ylabel": "|y_E' - y'|", "log": True,
             "lines": [("error", np.abs(fit.dy - traj.x[:, 1])[inner], "r-")]},
        ], "Fig. 3: estimated derivative of y, noiseless"))
    return ExperimentResult("sridhar-noiseless", table, res, tuple(figures), paper, fmu)


# -- Section V-B ---------------------------------------------------------------------------------


#: The error measures of one fit (:func:`_errors`), per seed.
_ERROR_KEYS = ("a1", "a0_max_rel_error", "y_max_error", "dy_max_error", "x_max_error")
#: The metrics of :func:`noisy_seed_task`: least squares, P-spline + GCV (``gcv_``), ...
NOISY_METRICS = (*_ERROR_KEYS, *(f"gcv_{k}" for k in _ERROR_KEYS), "gcv_penalty", "a1_batch", "noise_sigma")


@dataclass(frozen=True)
class NoisySetup:
    """What every seed of Section V-B reads: the plant FMU's samples over
    [0, 9] s, one batch integration's over the same samples, the inner window."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    x: np.ndarray
    batch_t: np.ndarray
    batch_u: np.ndarray
    batch_y: np.ndarray
    inner: np.ndarray  #: bool, the inner window [1.5, 7.5] s
    n_basis: int = 16


def noisy_setup(data: SridharData) -> NoisySetup:
    """The set-up of :func:`noisy_seed_task` from the shared co-simulation."""
    n9 = int(round(9.0 * RATE)) + 1
    traj, batch = data.fmu.head(n9), data.batch.head(n9)
    return NoisySetup(traj.t, traj.u, traj.y, traj.x, batch.t, batch.u, batch.y,
                      (traj.t >= 1.5) & (traj.t <= 7.5))


@functools.cache
def _noisy_model(n_basis: int) -> KernelModel:
    return KernelModel.from_io(_system(), a0=UnknownSpline(n_basis, order=3), a1=UnknownConstant())


def noisy_seed_task(setup: NoisySetup, task: Task) -> TaskResult:
    """One noise realization of Section V-B (seed ``task.seed``): 30 dB noise
    from ``default_rng(seed)`` on the FMU samples' ``y`` (and, for the batch
    comparison, on the batch integration's), the least-squares fit and the
    P-spline + GCV fit. Metrics :data:`NOISY_METRICS`; signals ``a0``, ``y``,
    ``dy`` of the least-squares fit over [0, 9] s."""
    if task.seed is None:
        raise ValueError("sridhar-noisy: a task needs a seed")
    model = _noisy_model(setup.n_basis)
    traj = _Trajectory(setup.t, setup.u, setup.y, setup.x)
    y_meas, sigma = noisy_output(setup.y, SNR_DB, np.random.default_rng(task.seed))
    fit = fit_kernel_model(model, setup.t, setup.u, y_meas)
    y_batch, _ = noisy_output(setup.batch_y, SNR_DB, np.random.default_rng(task.seed))
    a1_batch = float(fit_kernel_model(model, setup.batch_t, setup.batch_u, y_batch).constants["a1"])
    fit_gcv = fit_kernel_model(model, setup.t, setup.u, y_meas, penalty="gcv")
    ls, gcv = _errors(fit, traj, setup.inner), _errors(fit_gcv, traj, setup.inner)
    metrics = {**ls, **{f"gcv_{k}": v for k, v in gcv.items()}, "gcv_penalty": float(fit_gcv.penalty),
               "a1_batch": a1_batch, "noise_sigma": sigma}
    return TaskResult(metrics, {"a0": fit.values["a0"], "y": fit.y, "dy": fit.dy})


def prepare_noisy_study(spec: StudySpec, fmus: ExperimentFmus) -> Prepared:
    """The Section V-B study of a sweep file: one :func:`noisy_seed_task` per
    seed, on the plant FMU's samples (:func:`noisy_setup`).

    Parameters
    ----------
    spec : StudySpec
        The sweep's spec: the metrics and signals kept.
    fmus : ExperimentFmus, str, Path or None
        The experiments' FMU cache (or its folder; ``None``: the default).

    Returns
    -------
    Prepared
        The task function, the set-up every task reads, the metrics; its
        identity names the samples by their SHA-256.
    """
    setup = noisy_setup(sridhar_data(as_experiment_fmus(fmus), progress=False))
    data_sha = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in
                                       (setup.t, setup.u, setup.y, setup.x, setup.batch_y))).hexdigest()
    signals = {s: ((setup.t.size,), ()) for s in spec.keep}
    return Prepared(select_task(noisy_seed_task, spec, NOISY_METRICS), setup, spec.metric_names or NOISY_METRICS,
                    signals, {"experiment": "sridhar-noisy", "lpvest": __version__, "data": data_sha}, setup.t,
                    "Sridhar et al. V-B: 30 dB output noise on the plant FMU's samples over [0, 9] s, "
                    "two fits per seed")


#: The noise realizations of ``sridhar-noisy`` as a study (``experiment = "sridhar-noisy"``).
NOISY_STUDY = ExperimentStudy("sridhar-noisy", "Sridhar et al. V-B: B-spline fits under 30 dB output noise, per seed",
                              prepare_noisy_study, {}, 20, {}, NOISY_METRICS, ("a0", "y", "dy"))


def run_noisy(
    out_dir: Path | None = None, *, seeds: int = 20, fmus: ExperimentFmus | str | Path | None = None,
    engine: Engine | None = None, progress: bool | None = None,
) -> ExperimentResult:
    """Section V-B: window [0, 9] s, n = 16, 30 dB output noise, inner window [1.5, 7.5] s;
    mean and spread over ``seeds`` noise realizations (seeds 0, 1, ...), on the
    plant FMU's samples over [0, 9] s with the noise added to ``y`` per seed.

    One task per seed (:func:`noisy_seed_task`), run in this process or, with
    ``engine`` (a :class:`lpvest.parallel.Engine`), on Dask workers: the same
    numbers either way. ``progress``: progress bars (default:
    :func:`~lpvest.experiments.show_progress`)."""
    progress = show_progress(progress, out_dir)
    data = sridhar_data(as_experiment_fmus(fmus), progress=progress)
    setup = noisy_setup(data)
    n9 = setup.t.size
    traj = data.fmu.head(n9)
    t, inner = setup.t, setup.inner
    runs: dict[str, list[dict[str, float]]] = {"ls": [], "gcv": []}
    a0_curves = []
    a1_batch: list[float] = []
    per_seed = map_tasks(noisy_seed_task, setup, [Task(i, seed=i) for i in range(seeds)], engine=engine,
                         progress=progress, desc="sridhar-noisy seeds")
    for r in per_seed:
        m = r.metrics
        runs["ls"].append({k: m[k] for k in _ERROR_KEYS} | {"penalty": 0.0})
        runs["gcv"].append({k: m[f"gcv_{k}"] for k in _ERROR_KEYS} | {"penalty": m["gcv_penalty"]})
        a0_curves.append(r.signals["a0"])
        a1_batch.append(m["a1_batch"])
    keep: dict[str, Any] = {"fit_y": per_seed[0].signals["y"], "fit_dy": per_seed[0].signals["dy"],
            "y_meas": noisy_output(setup.y, SNR_DB, np.random.default_rng(0))[0],
            "sigma": per_seed[0].metrics["noise_sigma"]}  # seed 0
    keys = _ERROR_KEYS

    def summary(rows: list[dict[str, float]]) -> dict[str, float]:
        out: dict[str, float] = {}
        for k in keys:
            vals = np.array([r[k] for r in rows])
            out[k] = float(np.mean(vals))
            out[f"{k}_std"] = float(np.std(vals))
            out[f"{k}_max"] = float(np.max(vals))
        out["a1_abs_error_mean"] = float(np.mean([abs(r["a1"] - 1.0) for r in rows]))
        return out

    ls, gcv = summary(runs["ls"]), summary(runs["gcv"])
    res: dict[str, Any] = dict(ls)
    res.update(
        paper_a1=PAPER_A1_NOISY,
        seeds=seeds,
        snr_db=SNR_DB,
        noise_sigma=keep["sigma"],
        snr_definition="10*log10(mean(y^2) over the window samples / sigma^2); white Gaussian noise per sample",
        window=[0.0, 9.0],
        inner_window=[1.5, 7.5],
        n_basis=16,
        order=3,
        samples=int(t.size),
        sample_rate_hz=RATE,
        gcv=gcv | {"penalty_median": float(np.median([r["penalty"] for r in runs["gcv"]]))},
        per_seed=[{k: r[k] for k in keys} for r in runs["ls"]],
        a1_batch_integration=float(np.mean(a1_batch)),
        a1_difference_fmu_vs_batch=float(np.max(np.abs(np.array([r["a1"] for r in runs["ls"]]) - a1_batch))),
    )
    table = _table([
        (f"quantity ({seeds} seeds, inner window [1.5, 7.5] s)", "paper", "ours: LS (mean +- std)  |  P-spline+GCV"),
        ("a_1 (true 1)", f"{PAPER_A1_NOISY:.4f}",
         f"{ls['a1']:.4f} +- {ls['a1_std']:.4f}  |  {gcv['a1']:.4f} +- {gcv['a1_std']:.4f}"),
        ("max |a_0 - (t^2+1)| / (t^2+1)", "Fig. 4 (visual)",
         f"{ls['a0_max_rel_error']:.4f} +- {ls['a0_max_rel_error_std']:.4f}  |  "
         f"{gcv['a0_max_rel_error']:.4f} +- {gcv['a0_max_rel_error_std']:.4f}"),
        ("max |y_E - y|", "Fig. 5 (visual)",
         f"{ls['y_max_error']:.2e} +- {ls['y_max_error_std']:.1e}  |  {gcv['y_max_error']:.2e}"),
        ("max |y_E' - y'|", "Fig. 6 (visual)",
         f"{ls['dy_max_error']:.2e} +- {ls['dy_max_error_std']:.1e}  |  {gcv['dy_max_error']:.2e}"),
        ("noise sigma (30 dB)", "-", f"{keep['sigma']:.3e}"),
        ("a_1 (LS mean) on one batch integration's data", "-", f"{res['a1_batch_integration']:.4f}"),
    ])
    fmu = _fmu_run(
        data,
        "The SridharLtvPlant FMU's samples over [0, 9] s (from the shared co-simulation) plus measurement noise "
        f"at {SNR_DB:g} dB added to y per seed (the noise is on the measurement, so the plant runs once, not "
        f"{seeds} times); the batch fits (least squares and P-spline + GCV) run on them. Cross-check: the "
        "streaming LTVPlant over the same samples.",
        data.plant_agreements(n9),
        (data.batch_note(n9), f"a_1 per seed, FMU samples vs batch integration: max difference "
         f"{res['a1_difference_fmu_vs_batch']:.1e}"),
    )
    paper = (
        ("a_1 (true 1)", f"{PAPER_A1_NOISY:.4f} (one realization)",
         f"{ls['a1']:.4f} +- {ls['a1_std']:.4f} ({seeds} seeds, LS)"),
        ("max |a_0 - (t^2+1)| / (t^2+1) on [1.5, 7.5] s", "Fig. 4 (visual)",
         f"{ls['a0_max_rel_error']:.3f} +- {ls['a0_max_rel_error_std']:.3f}"),
        ("max |y_E - y|, max |y_E' - y'|", "Figs. 5-6 (visual)",
         f"{ls['y_max_error']:.1e}, {ls['dy_max_error']:.1e}"),
    )
    figures: list[Path] = []
    if out_dir is not None:
        ti = t[inner]
        curves = np.array(a0_curves)[:, inner]
        figures.append(_figure(out_dir / "fig4_a0.png", ti, [
            {"ylabel": "a_0(t)", "lw": 0.8, "lines": [("true t^2 + 1", ti**2 + 1, "k-")]
             + [(f"{seeds} seeds" if i == 0 else None, curves[i], "r-") for i in range(curves.shape[0])]},
            {"ylabel": "relative error", "lines": [
                ("mean over seeds", np.mean(np.abs(curves - (ti**2 + 1)) / (ti**2 + 1), axis=0), "r-"),
                ("max over seeds", np.max(np.abs(curves - (ti**2 + 1)) / (ti**2 + 1), axis=0), "r:")]},
        ], "Fig. 4: estimated a_0, 30 dB output noise (n = 16)"))
        figures.append(_figure(out_dir / "fig5_y.png", ti, [
            {"ylabel": "y", "lines": [("measured (seed 0)", keep["y_meas"][inner], "0.7"),
                                      ("true y", traj.y[inner], "k-"), ("y_E", keep["fit_y"][inner], "r--")]},
            {"ylabel": "y_E - y", "lines": [("error (seed 0)", (keep["fit_y"] - traj.y)[inner], "r-")]},
        ], "Fig. 5: estimated output y, 30 dB noise"))
        figures.append(_figure(out_dir / "fig6_dy.png", ti, [
            {"ylabel": "y'", "lines": [("true y'", traj.x[inner, 1], "k-"), ("y_E'", keep["fit_dy"][inner], "r--")]},
            {"ylabel": "y_E' - y'", "lines": [("error (seed 0)", (keep["fit_dy"] - traj.x[:, 1])[inner], "r-")]},
        ], "Fig. 6: estimated derivative of y, 30 dB noise"))
    return ExperimentResult("sridhar-noisy", table, res, tuple(figures), paper, fmu)


# -- the streaming observer ----------------------------------------------------------------------


def run_sliding(
    out_dir: Path | None = None, *, fmus: ExperimentFmus | str | Path | None = None, progress: bool | None = None
) -> ExperimentResult:
    """The sliding-window observer over [0, 20] s: window 4 s, hop 0.5 s,
    a_0 an 18-function quadratic B-spline per window, report at the centre;
    the observer FMU co-simulated with the plant FMU. ``progress``: progress
    bars (default: :func:`~lpvest.experiments.show_progress`)."""
    data = sridhar_data(as_experiment_fmus(fmus), progress=show_progress(progress, out_dir))
    io, traj = _system(), data.fmu
    model = KernelModel.from_io(io, a0=UnknownSpline(OBSERVER["n_basis"], order=3), a1=UnknownConstant())
    obs = BSplineObserver(model, dt=1.0 / RATE, window=OBSERVER["window"], hop=OBSERVER["hop"])
    out = data.observer
    valid = out["valid"][:, 0] == 1.0
    lag = int(round(obs.delay * RATE))
    k = np.flatnonzero(valid)
    j = k - lag  # the sample the estimates refer to
    te = traj.t[j]
    a0_true = te**2 + 1
    lib = data.library_observer
    agreements = data.plant_agreements() + tuple(
        Agreement.of(f"{name} (SridharLtvBSplineObserver FMU vs BSplineObserver)", out[name],
                     lib[name].reshape(out[name].shape))
        for name in ("valid", "t_est", "a0", "a1", "yhat", "dyhat", "xhat")
    )
    fmu = _fmu_run(
        data,
        "The SridharLtvBSplineObserver FMU (window 4 s, hop 0.5 s, a_0 18 B-splines per window) runs on the "
        "SridharLtvPlant FMU's y and u in one co-simulation over [0, 20] s (20,000 steps of 1 ms); its outputs "
        "are the results. Cross-check: BSplineObserver on the streaming LTVPlant's samples.",
        agreements, (data.batch_note(),),
    )
    res: dict[str, Any] = {
        "delay_s": obs.delay,
        "window_s": 4.0,
        "hop_s": 0.5,
        "n_basis": 18,
        "first_valid_time": float(traj.t[k[0]]),
        "t_est_error": float(np.max(np.abs(out["t_est"][k, 0] - te))),
        "a1_max_error": float(np.max(np.abs(out["a1"][k, 0] - 1.0))),
        "a0_max_rel_error": float(np.max(np.abs(out["a0"][k, 0] - a0_true) / a0_true)),
        "y_max_error": float(np.max(np.abs(out["yhat"][k, 0] - traj.y[j]))),
        "dy_max_error": float(np.max(np.abs(out["dyhat"][k, 0] - traj.x[j, 1]))),
        "x_max_error": float(np.max(np.abs(out["xhat"][k] - traj.x[j]))),
    }
    table = _table([
        ("sliding window 4 s, hop 0.5 s, report at centre", "paper", "ours"),
        ("delay of the estimates", "-", f"{res['delay_s']:.3f} s"),
        ("first valid output at", "-", f"t = {res['first_valid_time']:.3f} s"),
        ("max |a_1 - 1|", "-", f"{res['a1_max_error']:.2e}"),
        ("max |a_0 - (t^2+1)| / (t^2+1)", "-", f"{res['a0_max_rel_error']:.2e}"),
        ("max |y_E - y|, max |y_E' - y'|", "-", f"{res['y_max_error']:.2e}, {res['dy_max_error']:.2e}"),
    ])
    figures: list[Path] = []
    if out_dir is not None:
        figures.append(_figure(out_dir / "sliding.png", te, [
            {"ylabel": "a_0", "lines": [("true", a0_true, "k-"), ("observer", out["a0"][k, 0], "r--")]},
            {"ylabel": "relative error a_0", "log": True,
             "lines": [(None, np.abs(out["a0"][k, 0] - a0_true) / a0_true, "r-")]},
            {"ylabel": "y, y'", "lines": [("y", traj.y[j], "k-"), ("yhat", out["yhat"][k, 0], "r--"),
                                          ("y'", traj.x[j, 1], "b-"), ("dyhat", out["dyhat"][k, 0], "m--")]},
        ], f"Sliding-window observer (delay {obs.delay:g} s), plotted at t_est"))
    paper = (
        ("sliding window (not in the paper): max |a_1 - 1|", "-", f"{res['a1_max_error']:.1e}"),
        ("max |a_0 - (t^2+1)| / (t^2+1)", "-", f"{res['a0_max_rel_error']:.1e}"),
        ("delay of the estimates", "-", f"{res['delay_s']:g} s"),
    )
    return ExperimentResult("sridhar-sliding", table, res, tuple(figures), paper, fmu)


#: The FMUs of the shared co-simulation (:func:`sridhar_cosim`); the three
#: experiments share it (:func:`sridhar_data`, once per process), so they run as one task.
_FMUS = ("SridharLtvPlant", "SridharLtvBSplineObserver")

EXPERIMENTS = [
    Experiment("sridhar-noiseless", "Sridhar et al. V-A: a_0(t), a_1, y, y' noiseless (n = 86)", run_noiseless,
               fmus=_FMUS, group="sridhar"),
    Experiment("sridhar-noisy", "Sridhar et al. V-B: 30 dB output noise, 20 seeds (n = 16)", run_noisy,
               reduced={"seeds": 5}, fmus=_FMUS, group="sridhar", study=NOISY_STUDY),
    Experiment("sridhar-sliding", "Sridhar et al.: sliding-window observer over [0, 20] s", run_sliding,
               fmus=_FMUS, group="sridhar"),
]
