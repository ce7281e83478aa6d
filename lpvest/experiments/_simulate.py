"""Simulate any example system (or a user's model file) with default signals.

Used by ``lpvest simulate``: a scheduling signal given as a formula of the
step ``k`` (default: a sinusoid spanning 90 % of the box), the model's own
noise (seeded) or input, and the Peixoto et al. disturbance
``w_k = sin(0.5 k) exp(-0.1 k)`` from ``k = 10`` for polytopic plants.

Examples
--------
>>> from lpvest import load_system
>>> sim = simulate_system(load_system("peixoto-ex1"), steps=50, seed=1)
>>> list(sim.groups)
['scheduling', 'alpha', 'disturbance', 'output', 'to estimate', 'state']
>>> sim.columns["y"].shape
(50,)
>>> sim.write_csv("peixoto-ex1.csv")                         # doctest: +SKIP
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core._errors import ArgumentError, ArgumentTypeError, NonFiniteError, NumericalError, abbreviate, shorten
from ..core._expressions import Expression
from ..core._plotting import save_figure
from ..core._scheduling import SchedulingSpace
from ..systems import (
    AffineLPV,
    InnovationLPV,
    LPVInputOutput,
    LTVInputOutput,
    LTVStateSpace,
    PolytopicLPV,
)
from ..systems._modelfile import SystemFile

__all__ = ["Simulation", "simulate_system", "default_schedule", "peixoto_disturbance"]


@dataclass(frozen=True)
class Simulation:
    """Named columns of a simulation, each of shape (T,)."""

    system: str
    model: str
    time_name: str  #: "k" (discrete) or "t" (continuous)
    columns: dict[str, np.ndarray]
    groups: dict[str, list[str]]  #: plot panels: title -> column names

    def write_csv(self, path: Path) -> Path:
        names = list(self.columns)
        data = np.column_stack([self.columns[n] for n in names])
        np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        return path

    def plot(self, path: Path) -> Path:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        panels = [(title, cols) for title, cols in self.groups.items() if cols]
        fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.2 * len(panels)), sharex=True)
        axes = np.atleast_1d(axes)
        time = self.columns[self.time_name]
        for ax, (title, cols) in zip(axes, panels, strict=True):
            for c in cols:
                ax.plot(time, self.columns[c], label=c, drawstyle="steps-post" if self.time_name == "k" else "default")
            ax.set_ylabel(title)
            ax.legend(loc="upper right", fontsize="small", ncol=min(4, len(cols)))
            ax.grid(alpha=0.3)
        axes[-1].set_xlabel(self.time_name)
        return save_figure(fig, path, title=f"{self.system}: model {self.model}")


def default_schedule(space: SchedulingSpace) -> list[str]:
    """One formula of ``k`` per component: ``mid + 0.9*half*sin(0.25 k)``."""
    out = []
    for lo, hi in zip(space.lower, space.upper, strict=True):
        mid, half = (lo + hi) / 2.0, (hi - lo) / 2.0
        out.append(f"{float(mid)!r} + {float(0.9 * half)!r}*sin(0.25*k)")
    return out


def peixoto_disturbance(k: np.ndarray, onset: int = 10) -> np.ndarray:
    """``w_k = sin(0.5 k) exp(-0.1 k)`` for ``k >= onset``, else 0 (Peixoto et al., Fig. 2)."""
    k = np.asarray(k, dtype=float)
    return np.where(k >= onset, np.sin(0.5 * k) * np.exp(-0.1 * k), 0.0)


def _schedule(space: SchedulingSpace, formulas: list[str] | None, k: np.ndarray) -> np.ndarray:
    formulas = formulas or default_schedule(space)
    if len(formulas) != space.dim:
        given = f"{len(formulas)} formula{'s' * (len(formulas) != 1)}"
        raise ArgumentError(f"schedule: {given} given; expected {space.dim} (one per scheduling component: "
                            f"{shorten(', '.join(space.names), 60)})")
    cols = []
    for f in formulas:
        expr = Expression.parse(f, allowed=["k"])
        values = np.broadcast_to(np.asarray(expr.evaluate({"k": k}), dtype=float), k.shape)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise NonFiniteError(f"schedule: formula {abbreviate(f)} is {values[bad[0]]} at k = {k[bad[0]]:g}")
        cols.append(values)
    return np.column_stack(cols)


def _add(sim: Simulation, group: str, prefix: str, arr: np.ndarray) -> None:
    """Columns ``prefix`` (or ``prefix[i]``) of ``arr`` into ``sim``, in the plot panel ``group``."""
    arr = np.asarray(arr)
    arr = arr[:, None] if arr.ndim == 1 else arr
    names = [f"{prefix}[{i + 1}]" if arr.shape[1] > 1 else prefix for i in range(arr.shape[1])]
    for i, n in enumerate(names):
        sim.columns[n] = arr[:, i]
    sim.groups.setdefault(group, []).extend(names)


def simulate_system(
    system: SystemFile,
    model_key: str | None = None,
    *,
    steps: int = 100,
    schedule: list[str] | None = None,
    seed: int = 0,
    t_end: float = 20.0,
) -> Simulation:
    """Simulate one model of ``system`` with default signals (see module doc).

    Raises :class:`~lpvest.core.NumericalError` naming the signal and the
    first sample when the simulation leaves the floating-point range (an
    unstable model, or one with huge coefficients), rather than writing inf.
    """
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is reported below, by signal and sample
        sim = _simulate(system, model_key, steps=steps, schedule=schedule, seed=seed, t_end=t_end)
    for name, col in sim.columns.items():
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            at = f"{sim.time_name} = {sim.columns[sim.time_name][bad[0]]:g}"
            raise NumericalError(f"simulating {system.name} / model {sim.model}: {name} is {col[bad[0]]} at {at} "
                                 "(the model is unstable along this schedule, or its numbers are too large)")
    return sim


@dataclass(frozen=True)
class _Run:
    """What a default simulation of one model needs besides the model."""

    system: SystemFile
    key: str
    steps: int
    schedule: list[str] | None
    seed: int
    t_end: float

    def start(self, time_name: str, time: np.ndarray) -> Simulation:
        """An empty simulation of this model with its time column."""
        return Simulation(self.system.name, self.key, time_name, {time_name: time}, {})


def _simulate(
    system: SystemFile,
    model_key: str | None,
    *,
    steps: int,
    schedule: list[str] | None,
    seed: int,
    t_end: float,
) -> Simulation:
    key = model_key or system.default
    return _simulate_model(system.model(key), _Run(system, key, steps, schedule, seed, t_end))


@functools.singledispatch
def _simulate_model(model: object, run: _Run) -> Simulation:
    raise ArgumentTypeError(f"cannot simulate a {type(model).__name__}")  # pragma: no cover


@_simulate_model.register(LTVInputOutput)
@_simulate_model.register(LTVStateSpace)
def _(model: LTVInputOutput | LTVStateSpace, run: _Run) -> Simulation:
    t = np.linspace(0.0, run.t_end, run.steps)
    traj = model.simulate(t)
    sim = run.start("t", t)
    _add(sim, "input", "u", traj.u)
    _add(sim, "output", "y", traj.y)
    _add(sim, "state", "x", traj.x)
    return sim


@_simulate_model.register
def _(model: PolytopicLPV, run: _Run) -> Simulation:
    k = np.arange(run.steps, dtype=float)
    sim = run.start("k", k)
    if model.simplex_map is not None:
        p = _schedule(model.simplex_map.space, run.schedule, k)
        alpha = model.alpha_batch(p)
        _add(sim, "scheduling", model.simplex_map.space.names[0] if p.shape[1] == 1 else "p", p)
    else:
        raw = _schedule(SchedulingSpace(["s"], [0.0], [1.0]), run.schedule, k)[:, 0]
        alpha = np.column_stack([1.0 - raw, raw])
    _add(sim, "alpha", "alpha", alpha)
    w = np.tile(peixoto_disturbance(k)[:, None], (1, model.nw))
    traj = model.simulate(alpha, w)
    _add(sim, "disturbance", "w", w)
    _add(sim, "output", "y", traj.y)
    _add(sim, "to estimate", "z", traj.z)
    _add(sim, "state", "x", traj.x)
    return sim


@_simulate_model.register
def _(model: AffineLPV, run: _Run) -> Simulation:
    assert run.system.scheduling is not None
    k = np.arange(run.steps, dtype=float)
    sim = run.start("k", k)
    p = _schedule(run.system.scheduling, run.schedule, k)
    u = np.sin(0.1 * k)[:, None] * np.ones((1, model.nu))
    traj = model.simulate(p, u, rng=run.seed)
    _add(sim, "scheduling", "p", p)
    if model.nu:
        _add(sim, "input", "u", u)
    _add(sim, "output", "y", traj.y)
    _add(sim, "state", "x", traj.x)
    return sim


def _simulate_io(model: InnovationLPV | LPVInputOutput, run: _Run, window: tuple[int, int], nu: int,
                 state: bool) -> Simulation:
    assert run.system.scheduling is not None
    steps = run.steps
    k = np.arange(steps, dtype=float)
    sim = run.start("k", k)
    back, ahead = window
    p = _schedule(run.system.scheduling, run.schedule, np.arange(-back, steps + ahead, dtype=float))
    u = np.sin(0.1 * k)[:, None]
    e = np.random.default_rng(run.seed).standard_normal((steps, 1))
    traj = model.simulate(p, u[:, :nu], e=e)
    if state:
        _add(sim, "state", "x", traj.x)
    _add(sim, "scheduling", "p", p[back : back + steps])
    _add(sim, "input", "u", u)
    _add(sim, "noise", "e", e)
    _add(sim, "output", "y", traj.y)
    return sim


@_simulate_model.register
def _(model: InnovationLPV, run: _Run) -> Simulation:
    return _simulate_io(model, run, model.window, model.nu, state=True)


@_simulate_model.register
def _(model: LPVInputOutput, run: _Run) -> Simulation:
    return _simulate_io(model, run, (0, 0), 1, state=False)

