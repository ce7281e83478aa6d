"""The kill rate of a mutation run, per module: ``python -m tests.mutation_report [PROJECT]``.

Reads mutmut's results (``PROJECT/mutants/<module>.py.meta``, written by ``./dev mutate``) for
every module in ``[tool.mutmut] only_mutate`` of ``PROJECT/pyproject.toml`` and prints, per module,
the mutants killed (a covering test failed, or the run exceeded its time limit) out of all of its
mutants: a mutant no test reaches counts as surviving. ``--survivors`` lists the survivors'
names, for ``mutmut show NAME``.

``--sample N`` restricts everything to a seeded uniform sample of N mutants per module (all of a
module with fewer): ``--names`` prints the sample's names (``./dev mutate --sample N`` runs
them), the table the kill rate on the sample with its 95 % (Wilson) interval. A full run of every
mutant takes hours on two cores (docs/mutation.md); a sample estimates the rate in minutes.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
import tomllib
from collections import Counter
from pathlib import Path

# mutmut's exit codes (mutmut.stats.status_by_exit_code) in the classes reported here
_KILLED = {1: "killed", 3: "killed", 36: "timeout", -24: "timeout", 24: "timeout", 152: "timeout", 255: "timeout",
           37: "killed"}  # 37: caught by the type checker (not configured here)
_OTHER = {0: "survived", 5: "no tests", 33: "no tests", 34: "skipped", None: "not checked"}


def status(code: int | None) -> str:
    return _KILLED.get(code) or _OTHER.get(code) or ("segfault" if code in (-11, -9) else "suspicious")  # type: ignore[arg-type]


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a proportion k / n."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def results(project: Path, sample: int | None = None, seed: int = 24) -> dict[str, dict[str, int | None]]:
    """Per module, mutant name -> mutmut exit code (None: not run yet), for all mutants or a sample."""
    config = tomllib.loads((project / "pyproject.toml").read_text())["tool"]["mutmut"]
    out: dict[str, dict[str, int | None]] = {}
    for module in config["only_mutate"]:
        meta = project / "mutants" / f"{module}.meta"
        if not meta.is_file():
            continue
        codes = json.loads(meta.read_text())["exit_code_by_key"]
        if sample is not None and sample < len(codes):
            chosen = random.Random(f"{seed}:{module}").sample(sorted(codes), sample)
            codes = {k: codes[k] for k in sorted(chosen)}
        out[module] = codes
    return out


def report(project: Path, sample: int | None = None, seed: int = 24) -> tuple[list[str], dict[str, list[str]]]:
    """Lines of the table, and the survivors (not killed) per module."""
    head = "sample" if sample is not None else "total"
    lines = [f"{'module':<28} {'killed':>7} {head:>6} {'rate':>7}  {'95 % interval':>15}   "
             "by status (timeouts count as killed)"]
    survivors: dict[str, list[str]] = {}
    all_killed = all_total = 0
    for module, codes in results(project, sample, seed).items():
        counts = Counter(status(c) for c in codes.values())
        killed = counts["killed"] + counts["timeout"]
        total = len(codes)
        # timeouts are shown although they count as killed: on a busy machine they are not to be trusted
        rest = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()) if k != "killed")
        lo, hi = wilson(killed, total)
        interval = f"{100 * lo:.1f}-{100 * hi:.1f} %" if sample is not None else ""
        lines.append(f"{module:<28} {killed:>7} {total:>6} {100 * killed / max(total, 1):>6.1f}%  {interval:>15}   "
                     f"{rest}")
        survivors[module] = sorted(k for k, c in codes.items() if status(c) not in ("killed", "timeout"))
        all_killed, all_total = all_killed + killed, all_total + total
    lines.append(f"{'all':<28} {all_killed:>7} {all_total:>6} {100 * all_killed / max(all_total, 1):>6.1f}%")
    return lines, survivors


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("project", nargs="?", default=".", type=Path, help="the folder holding pyproject.toml")
    parser.add_argument("--survivors", action="store_true", help="list the mutants not killed")
    parser.add_argument("--sample", type=int, help="a seeded sample of this many mutants per module")
    parser.add_argument("--seed", type=int, default=24, help="the sample's seed (default 24)")
    parser.add_argument("--names", action="store_true", help="print the names of the (sampled) mutants only")
    args = parser.parse_args(argv)
    if args.names:
        for codes in results(args.project, args.sample, args.seed).values():
            print("\n".join(codes))
        return 0
    lines, survivors = report(args.project, args.sample, args.seed)
    print("\n".join(lines))
    if args.survivors:
        for module, names in survivors.items():
            for name in names:
                print(f"{module}: {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
