"""Benchmark of the H-infinity LMI design (Peixoto et al.); a script, not a test.

    .venv/bin/python benchmarks/bench_hinf.py [--repeat 5] [--dense 180] [--paper-grid] [--own] [--out FILE.json]

1. One Theorem 1 design for Example 1 at epsilon = 150, split into compile
   (build the cvxpy problem and canonicalize it, once per program) and solve
   (parameter substitution, Clarabel, unpacking and the eigenvalue check), on
   fresh programs (the one-time ``import cvxpy`` is reported apart).
   Target: <= 0.3 s.
2. The whole Example 2 curve: rho = 1..21, each with the epsilon search
   (:func:`lpvest.design.search_epsilon`, one compiled program). Target: <= 60 s.
3. Each gamma(rho) of the search compared with the best of a dense grid of
   ``--dense`` angles phi = atan(epsilon) (every sign and magnitude, and
   epsilon = inf), and with ``--paper-grid`` also the paper's grid
   epsilon in [0.1, 6] step 0.02. Target: search <= 1.005 x dense minimum.
4. With ``--own``: a 3-state plant with two scheduling variables (4
   vertices, examples/own_plant.toml in its H-infinity setting): one design
   with Clarabel (0.1's default) and with AUTO (SCS at this size), and the
   epsilon searches. Targets: one design <= 3 s, a search <= 30 s.

Timings on a shared machine are noisy: compare numbers measured in one run.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="fresh programs for the single-design timing")
    parser.add_argument("--dense", type=int, default=180, help="angles in the dense epsilon grid (0 to skip)")
    parser.add_argument("--paper-grid", action="store_true", help="also epsilon in [0.1, 6] step 0.02")
    parser.add_argument("--own", action="store_true",
                        help="also the 3-state, 4-vertex plant of examples/own_plant.toml: one design with "
                             "Clarabel (0.1's default) and AUTO, and the epsilon searches")
    parser.add_argument("--out", help="write the measurements as JSON")
    args = parser.parse_args()

    t0 = time.perf_counter()
    import cvxpy  # noqa: F401 - measured: a one-time cost of the process

    import_time = time.perf_counter() - t0
    import numpy as np

    import lpvest
    from lpvest.design import KIND_PD, HinfProgram, search_epsilon

    report: dict = {"import_cvxpy_s": import_time}
    print(f"import cvxpy: {import_time:.3f} s (once per process)")

    # 1. one design ------------------------------------------------------------
    plant = lpvest.load_system("peixoto-ex1").model()
    compiles, solves, walls, gammas = [], [], [], []
    for _ in range(args.repeat):
        w0 = time.perf_counter()
        program = HinfProgram.for_plant(plant, kind=KIND_PD)
        design = program.solve(plant, 150.0)
        walls.append(time.perf_counter() - w0)
        compiles.append(program.compile_time)
        solves.append(design.solve_time)
        gammas.append(design.gamma)
    one = {
        "compile_s_median": statistics.median(compiles),
        "solve_s_median": statistics.median(solves),
        "total_s_median": statistics.median(walls),
        "total_s_all": walls,
        "gamma": gammas[0],
    }
    report["one_design_ex1_theorem1_eps150"] = one
    print(f"Example 1, Theorem 1, epsilon = 150 (median of {args.repeat} fresh programs): "
          f"compile {one['compile_s_median']:.3f} s + solve {one['solve_s_median']:.3f} s "
          f"= {one['total_s_median']:.3f} s wall; gamma = {gammas[0]:.5f}")

    # 2. the Example 2 curve --------------------------------------------------
    rhos = [float(r) for r in range(1, 22)]
    w0 = time.perf_counter()
    program = None
    searched = []
    for rho in rhos:
        p = lpvest.load_system("peixoto-ex2", parameters={"rho": rho}).model()
        if program is None:
            program = HinfProgram.for_plant(p, kind=KIND_PD)
        s = search_epsilon(p, kind=KIND_PD, program=program)
        searched.append((rho, s.design.epsilon, s.design.gamma, s.n_evaluations))
    curve_time = time.perf_counter() - w0
    n_solves = sum(r[3] for r in searched)
    report["example2_curve"] = {
        "wall_s": curve_time,
        "n_evaluations": n_solves,
        "rows": [{"rho": r, "epsilon": None if math.isinf(e) else e, "gamma": g, "n_evaluations": n}
                 for r, e, g, n in searched],
    }
    print(f"Example 2 curve, 21 values of rho with the epsilon search: {curve_time:.1f} s wall, "
          f"{n_solves} epsilon evaluations ({curve_time / n_solves * 1e3:.1f} ms each, compile included)")

    # 3. dense grid -------------------------------------------------------------
    if args.dense > 0:
        phis = np.linspace(-math.pi / 2, math.pi / 2, args.dense + 1)[1:]
        eps_grid = [math.inf if abs(p - math.pi / 2) < 1e-12 else math.tan(p) for p in phis]
        if args.paper_grid:
            eps_grid += list(np.round(np.arange(0.1, 6.0 + 1e-9, 0.02), 10))
        worst_ratio = 0.0
        rows = []
        w0 = time.perf_counter()
        print(f"{'rho':>5} {'search eps':>11} {'search gamma':>13} {'dense min':>10} {'ratio':>8}")
        for rho, eps, gamma, _ in searched:
            p = lpvest.load_system("peixoto-ex2", parameters={"rho": rho}).model()
            dense = min(program.attempt(p, e).gamma for e in eps_grid)
            ratio = gamma / dense
            worst_ratio = max(worst_ratio, ratio)
            rows.append({"rho": rho, "search_gamma": gamma, "dense_min": dense, "ratio": ratio})
            print(f"{rho:>5g} {eps:>11.4g} {gamma:>13.6f} {dense:>10.6f} {ratio:>8.5f}")
        report["dense_grid"] = {"n_epsilon": len(eps_grid), "wall_s": time.perf_counter() - w0, "rows": rows,
                                "worst_ratio": worst_ratio}
        verdict = "within" if worst_ratio <= 1.005 else "NOT within"
        print(f"dense grid of {len(eps_grid)} epsilon values: worst search/dense ratio {worst_ratio:.5f} "
              f"({verdict} 0.5 %)")
    # 4. a user's own plant: 3 states, 2 scheduling variables (4 vertices) -------
    if args.own:
        from pathlib import Path

        from lpvest.systems._polytopic import hinf_setting

        own = hinf_setting(lpvest.load_system(Path(__file__).parent.parent / "examples" / "own_plant.toml").model())
        print(f"own plant: N = {own.n_vertices}, nx = {own.nx}, nz = {own.nz}, nw = {own.nw}")
        rows_own = {}
        for label, solver in (("0.1 default (Clarabel)", "CLARABEL"), ("AUTO", "AUTO")):
            w0 = time.perf_counter()
            prog = HinfProgram.for_plant(own, kind=KIND_PD, solver=solver)
            d = prog.solve(own, 1.0)
            rows_own[label] = {"solver": d.solver, "gamma": d.gamma, "wall_s": time.perf_counter() - w0,
                               "compile_s": prog.compile_time, "solve_s": d.solve_time}
            print(f"own plant, one design at epsilon = 1, {label}: {d.solver}, gamma = {d.gamma:.7f}, "
                  f"compile {prog.compile_time:.2f} s + solve {d.solve_time:.2f} s")
        for kind in (KIND_PD, "robust"):
            w0 = time.perf_counter()
            s = search_epsilon(own, kind=kind)
            wall = time.perf_counter() - w0
            rows_own[f"search {kind}"] = {"solver": s.design.solver, "gamma": s.design.gamma, "wall_s": wall,
                                          "n_evaluations": s.n_evaluations}
            clarabel_estimate = s.n_evaluations * rows_own["0.1 default (Clarabel)"]["solve_s"]
            print(f"own plant, epsilon search ({kind}, AUTO): {wall:.1f} s, {s.n_evaluations} designs, "
                  f"gamma = {s.design.gamma:.7f} (with Clarabel: about {clarabel_estimate:.0f} s)")
        report["own_plant"] = rows_own
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=1)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
