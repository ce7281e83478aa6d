"""Run experiments (``lpvest reproduce NAME|all``): each writes its figures and
``results.json`` into ``OUT/<name>/``, and ``all`` writes ``OUT/report.md``.

The FMUs come from an :class:`~lpvest.experiments.fmus.ExperimentFmus` cache
(``OUT/fmu-cache`` from the command line), built on first use and reused while
up to date.

Examples
--------
>>> from lpvest.experiments.reproduce import reproduce_all
>>> runs = reproduce_all("out", reduced=True)                  # doctest: +SKIP
>>> [r.name for r in runs if not r.ok]                         # doctest: +SKIP
[]
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import LpvestError, abbreviate
from . import ExperimentResult, write_results
from .fmus import ExperimentFmus, as_experiment_fmus

__all__ = ["ExperimentRun", "reproduce", "reproduce_all"]


@dataclass(frozen=True)
class ExperimentRun:
    """One experiment as it ran: its result, where it wrote, how long it took."""

    name: str
    title: str
    result: ExperimentResult
    folder: Path
    results_path: Path
    seconds: float
    options: dict

    @property
    def ok(self) -> bool:
        """The FMU results agree with the library (True when there is no FMU part)."""
        return self.result.fmu is None or self.result.fmu.ok


def reproduce(
    names: Sequence[str],
    out: str | Path,
    *,
    fmus: ExperimentFmus | str | Path | None = None,
    reduced: bool = False,
    echo: Callable[[str], None] | None = None,
    backend: str | None = None,
) -> list[ExperimentRun]:
    """Run the experiments ``names`` into ``out/<name>/``; ``reduced`` uses each
    experiment's quicker configuration (:attr:`Experiment.reduced`); ``echo``
    receives the printable output (tables, FMU agreement, files written);
    ``backend``: the FMUs' backend (``"pythonfmu"`` or ``"native"``,
    :data:`lpvest.fmi.build.BACKENDS`; default: the given cache's, else
    ``"pythonfmu"``)."""
    from . import registry  # looked up at call time

    experiments = registry()
    unknown = [n for n in names if n not in experiments]
    if unknown:
        raise LpvestError(f"no experiment {abbreviate(unknown[0], 30)} (known: {', '.join(experiments) or 'none'})")
    cache = as_experiment_fmus(fmus, backend=backend)
    out = Path(out)
    say = echo or (lambda _text: None)
    runs = []
    for name in names:
        exp = experiments[name]
        options = dict(exp.reduced) if reduced else {}
        say(f"== {exp.name}: {exp.title}" + (f" (reduced: {options})" if options else ""))
        folder = out / name
        t = time.perf_counter()
        result = exp.run(folder, fmus=cache, **options)
        seconds = time.perf_counter() - t
        say(result.table)
        if result.fmu is not None:
            say("\n".join(result.fmu.lines()))
        path = write_results(result, folder)
        say(f"wrote {path}" + "".join(f"\nwrote {f}" for f in result.figures))
        say(f"({seconds:.1f} s)")
        runs.append(ExperimentRun(exp.name, exp.title, result, folder, path, seconds, options))
    return runs


def reproduce_all(
    out: str | Path,
    *,
    fmus: ExperimentFmus | str | Path | None = None,
    reduced: bool = False,
    echo: Callable[[str], None] | None = None,
    backend: str | None = None,
) -> list[ExperimentRun]:
    """Every registered experiment, then ``out/report.md``
    (:func:`lpvest.experiments.report.write_report`). ``fmus`` defaults to the
    cache ``out/fmu-cache`` (``out/fmu-cache-native`` for ``backend="native"``)."""
    from . import registry
    from .report import write_report

    out = Path(out)
    default = out / ("fmu-cache" if backend in (None, "pythonfmu") else f"fmu-cache-{backend}")
    cache = as_experiment_fmus(default if fmus is None else fmus, backend=backend)
    t = time.perf_counter()
    runs = reproduce(list(registry()), out, fmus=cache, reduced=reduced, echo=echo, backend=backend)
    path = write_report(runs, out, fmus=cache, seconds=time.perf_counter() - t, reduced=reduced)
    if echo is not None:
        echo(f"wrote {path}")
    return runs
