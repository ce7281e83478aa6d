"""The reproduction report (``OUT/report.md``): one Markdown page with, per
experiment, the paper-versus-ours table, what ran through FMUs and how it
agrees with the library, the figures, and the full text table.

Links are relative to ``OUT``, so the folder can be moved or published as is.
"""

from __future__ import annotations

import platform
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ._fmus import ExperimentFmus
    from ._reproduce import ExperimentRun

__all__ = ["write_report", "render_report"]

_PAPERS = {
    "cox-toth": "Cox & Tóth",
    "peixoto": "Peixoto et al.",
    "sridhar": "Sridhar, Ghoshal & Michalska",
}


def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _paper(name: str) -> str:
    return next((v for k, v in _PAPERS.items() if name.startswith(k)), "-")


def _rel(path: Path, root: Path) -> str:
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return path.as_posix()


def render_report(
    runs: Sequence[ExperimentRun],
    out: Path,
    *,
    fmus: ExperimentFmus | None = None,
    seconds: float | None = None,
    reduced: bool = False,
) -> str:
    """The Markdown text of the report (see :func:`write_report`)."""
    from .._version import __version__

    ok = all(r.ok for r in runs)
    lines = [
        "# lpvest: the three papers reproduced through FMUs",
        "",
        f"`lpvest reproduce all --out {out.as_posix()}`" + (" `--quick`" if reduced else "")
        + (f" `--backend {fmus.backend}`" if fmus is not None and fmus.backend != "pythonfmu" else "")
        + f" · lpvest {__version__} · Python {platform.python_version()} · {time.strftime('%Y-%m-%d %H:%M')}",
        "",
    ]
    facts = []
    if seconds is not None:
        facts.append(f"wall time {seconds:.0f} s")
    if fmus is not None:
        facts.append(fmus.summary())
    if reduced:
        facts.append("**reduced configuration** (`--quick`: fewer Monte Carlo runs, seeds and values of rho)")
    facts.append("every FMU result agrees with the library" if ok else "**an FMU result disagrees with the library**")
    lines += ["; ".join(facts) + ".", ""]
    lines += [
        "Every experiment runs its plant and its filters as FMI 2.0 co-simulation FMUs (built by `lpvest build`'s "
        "builder) under `lpvest.cosim`, and repeats the computation with the library alone; the largest "
        "difference is reported per experiment (tolerance 1e-12 of the quantity's scale; 0 means bit for bit). "
        "Designs (LMIs) and batch fits are library computations; their FMU part is the data path or the "
        "designed filter in use, as each section says.",
        "",
        "## Summary",
        "",
        "| experiment | paper | FMUs | FMU vs library: max difference | time |",
        "|---|---|---|---|---|",
    ]
    for r in runs:
        fmu = r.result.fmu
        if fmu is None:
            agree, names = "no FMU part", "-"
        else:
            agree = "0 (bit for bit)" if fmu.bit_for_bit else f"{fmu.max_abs_difference:.1e}"
            agree += "" if fmu.ok else " **EXCEEDS 1e-12**"
            names = f"{len(fmu.fmus)} ({fmu.steps} steps)"
        lines.append(f"| [{r.name}](#{r.name}) | {_paper(r.name)} | {names} | {agree} | {r.seconds:.1f} s |")
    lines.append("")
    for r in runs:
        res = r.result
        lines += [f"<a id=\"{r.name}\"></a>", f"## {r.name}: {_cell(r.title)}", ""]
        if res.paper:
            lines += ["| quantity | paper | ours |", "|---|---|---|"]
            lines += [f"| {_cell(q)} | {_cell(p)} | {_cell(o)} |" for q, p, o in res.paper]
            lines.append("")
        if res.fmu is not None:
            lines += [f"**Through FMUs.** {res.fmu.description}", "",
                      f"{res.fmu.headline()} ({res.fmu.steps} communication steps, {res.fmu.wall_time:.1f} s; "
                      f"FMUs: {', '.join(f'`{n}`' for n in res.fmu.fmus)}).", ""]
            lines += ["<details><summary>every compared quantity</summary>", ""]
            lines += [f"- {_cell(a.line())}" for a in res.fmu.agreements]
            lines += [f"- note: {_cell(n)}" for n in res.fmu.notes]
            lines += ["", "</details>", ""]
        for fig in res.figures:
            rel = _rel(Path(fig), out)
            lines += [f"![{Path(fig).stem}]({rel})", ""]
        lines += ["<details><summary>full table (as printed)</summary>", "", "```text", res.table, "```", "",
                  "</details>", "",
                  f"Numbers: [{_rel(r.results_path, out)}]({_rel(r.results_path, out)})"
                  + (f" · options {r.options}" if r.options else "") + f" · {r.seconds:.1f} s", ""]
    return "\n".join(lines)


def write_report(
    runs: Sequence[ExperimentRun],
    out: str | Path,
    *,
    fmus: ExperimentFmus | None = None,
    seconds: float | None = None,
    reduced: bool = False,
) -> Path:
    """Write ``out/report.md`` for ``runs``; returns its path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "report.md"
    path.write_text(render_report(runs, out, fmus=fmus, seconds=seconds, reduced=reduced) + "\n", encoding="utf-8")
    return path
