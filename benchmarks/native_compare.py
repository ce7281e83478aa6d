"""The same native FMUs built by two (or more) runtimes, stepped side by side in
the bare C host (``benchmarks/native_step.c``, :func:`native_bench.step_times`).

For a change to the C runtime: build the FMUs once with the runtime before the
change and once after (``bench_kalman.py --native-fmus DIR`` and
``bench_cosim.py --native-fmus DIR`` build theirs into DIR, or ``lpvest build
--backend native``), then::

    .venv/bin/python benchmarks/native_compare.py BEFORE_DIR AFTER_DIR [--rounds 5]

Every FMU found in all the folders (by file name) is timed in every folder,
interleaved (round r times the folders in turn, the order reversed every other
round) so that the load of a shared machine hits both sides alike; the table
shows the best of the rounds in nanoseconds per sample, ``fmi2DoStep`` alone
and set inputs + ``fmi2DoStep`` + get outputs, and the ratio of the doStep
times to the first folder's. The last column says whether the outputs
agree (the sum of every output over the run, equal in all folders or not).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from native_bench import host_run  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+", type=Path, help="folders of native FMUs (the first is the reference)")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (default 5; the best counts)")
    parser.add_argument("--steps", type=int, default=40_000, help="samples per timed loop (default 40000)")
    parser.add_argument("--repeat", type=int, default=3, help="loops per FMU and round (default 3)")
    args = parser.parse_args()
    common = set.intersection(*({p.name for p in f.glob("*.fmu")} for f in args.folders))
    if not common:
        raise SystemExit("no FMU file name is in every folder")
    names = sorted(common)
    best = {(f, n): (float("inf"), float("inf")) for f in args.folders for n in names}
    sums: dict[tuple[Path, str], str] = {}
    for r in range(args.rounds):
        for n in names:
            for f in args.folders if r % 2 == 0 else args.folders[::-1]:
                full, step, checksum = host_run(f / n, steps=args.steps, repeat=args.repeat)
                old = best[(f, n)]
                best[(f, n)] = (min(old[0], full), min(old[1], step))
                sums[(f, n)] = checksum
    ref = args.folders[0]
    print(f"ns per sample, best of {args.rounds} interleaved rounds of {args.repeat} x {args.steps} samples")
    print(f"{'FMU':40}" + "".join(f"{'doStep':>10}{'set+step+get':>14}{'ratio':>7}" for _ in args.folders)
          + f"{'outputs':>10}")
    print(f"{'':40}" + "".join(f"{'(' + f.name + ')':>31}" for f in args.folders))
    for n in names:
        row = f"{n.removesuffix('.fmu'):40}"
        for f in args.folders:
            full, step = best[(f, n)]
            row += f"{step:>10.0f}{full:>14.0f}{step / best[(ref, n)][1]:>7.2f}"
        agree = len({sums[(f, n)] for f in args.folders}) == 1
        print(row + f"{'same' if agree else 'DIFFER':>10}")


if __name__ == "__main__":
    main()
