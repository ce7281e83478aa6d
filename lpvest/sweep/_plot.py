"""A figure per metric of a sweep: its mean and spread over the seeds, against
the swept axis.

The x axis is the first parameter axis with more than one value (numbers, or
one-element vectors, on a numeric axis; anything else as categories); every
combination of the other multi-valued axes is one line. At each point: the
mean over the seeds (line and markers), mean +- one standard deviation (band)
and the smallest and largest value (thin dotted lines). Without a parameter
axis the figure is the histogram of the metric over the seeds. Failed tasks
are left out (their count is in the title).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core._plotting import save_figure
from ._sweepfile import Axis, SweepSpec

if TYPE_CHECKING:
    from ..core._typing import ArrowTable

__all__ = ["plot_metrics", "metric_statistics"]


def _scalar(v: Any) -> float | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, int | float):
        return float(v)
    if isinstance(v, tuple) and len(v) == 1:
        return float(v[0])
    return None


def _label(v: object) -> str:
    if isinstance(v, tuple):
        return "[" + ", ".join(f"{x:g}" for x in v) + "]"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def metric_statistics(summary: ArrowTable, spec: SweepSpec, metric: str) -> list[dict[str, Any]]:
    """Per parameter point (in task order): the point, the number of finished
    seeds, and mean, std, min, max of ``metric`` over the successful ones."""
    rows = summary.to_pylist()
    by_point: dict[int, list[dict[str, Any]]] = {}
    n_seeds = len(spec.seeds.keys) if spec.seeds else 1
    for r in rows:
        by_point.setdefault(r["task"] // n_seeds, []).append(r)
    points = spec.points()
    out = []
    for p_i, members in sorted(by_point.items()):
        vals = np.array([r[metric] for r in members if r["status"] == "ok" and r[metric] is not None], dtype=float)
        vals = vals[np.isfinite(vals)]
        stats = {"point": points[p_i], "n": len(members), "ok": int(vals.size), "values": vals}
        if vals.size:
            stats.update(mean=float(np.mean(vals)), std=float(np.std(vals)), min=float(np.min(vals)),
                         max=float(np.max(vals)))
        out.append(stats)
    return out


def _file_name(metric: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", metric) + ".png"


def plot_metrics(summary: ArrowTable, spec: SweepSpec, metrics: Sequence[str], folder: str | Path) -> list[Path]:
    """Write ``folder/<metric>.png`` for each metric; return the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = Path(folder)
    swept = [a for a in spec.axes if len(a.values) > 1]
    x_axis: Axis | None = next((a for a in swept if all(_scalar(v) is not None for v in a.values)), None)
    if x_axis is None and swept:
        x_axis = swept[0]
    others = [a for a in swept if a is not x_axis]
    n_seeds = len(spec.seeds.keys) if spec.seeds else 1
    title = spec.title or Path(spec.origin).name
    paths = []
    for metric in metrics:
        stats = metric_statistics(summary, spec, metric)
        failed = sum(s["n"] - s["ok"] for s in stats)
        note = f" ({failed} failed or non-finite left out)" if failed else ""
        fig, ax = plt.subplots(figsize=(7.5, 4.2))
        if x_axis is None:
            vals = np.concatenate([s["values"] for s in stats]) if stats else np.array([])
            if vals.size > 1:
                ax.hist(vals, bins=min(40, max(5, vals.size // 5)), color="tab:blue", alpha=0.7)
                ax.axvline(float(np.mean(vals)), color="k", lw=1.5,
                           label=f"mean {np.mean(vals):.4g}, std {np.std(vals):.3g}")
                ax.set_ylabel("tasks")
                ax.legend(fontsize="small")
            elif vals.size == 1:
                ax.plot([0], vals, "o")
                ax.set_xticks([])
            ax.set_xlabel(metric)
            heading = f"{metric} over {vals.size} task(s){note}"
        else:
            numeric = all(_scalar(v) is not None for v in x_axis.values)
            positions = {v: (_scalar(v) if numeric else float(i)) for i, v in enumerate(x_axis.values)}
            lines: dict[tuple, list[dict[str, Any]]] = {}
            for s in stats:
                key = tuple(s["point"][a.name] for a in others)
                lines.setdefault(key, []).append(s)
            for key, members in lines.items():
                members = [m for m in members if m["ok"]]
                if not members:
                    continue
                x = np.array([positions[m["point"][x_axis.name]] for m in members])
                order = np.argsort(x, kind="stable")
                x = x[order]
                mean = np.array([members[i]["mean"] for i in order])
                std = np.array([members[i]["std"] for i in order])
                label = ", ".join(f"{a.name} = {_label(v)}" for a, v in zip(others, key, strict=True)) or None
                (line,) = ax.plot(x, mean, "o-", ms=4, label=label)
                if n_seeds > 1:
                    ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2, lw=0)
                    ax.plot(x, [members[i]["min"] for i in order], ":", color=line.get_color(), lw=0.8)
                    ax.plot(x, [members[i]["max"] for i in order], ":", color=line.get_color(), lw=0.8)
            if not numeric:
                ax.set_xticks([float(v) for v in positions.values() if v is not None],
                              [_label(v) for v in x_axis.values],
                              rotation=30 if len(x_axis.values) > 4 else 0, ha="right" if len(x_axis.values) > 4
                              else "center", fontsize="small")
            ax.set_xlabel(x_axis.name)
            ax.set_ylabel(metric)
            if others and len(lines) > 1:
                ax.legend(fontsize="x-small", ncol=2)
            spread = "mean, +- std (band), min and max (dotted) over " + f"{n_seeds} seeds" if n_seeds > 1 else "value"
            heading = f"{metric}: {spread}{note}"
        ax.grid(alpha=0.3)
        ax.set_title(heading, fontsize="small")
        paths.append(save_figure(fig, folder / _file_name(metric), title=title, title_size="medium"))
    return paths
