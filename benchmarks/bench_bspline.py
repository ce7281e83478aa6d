"""Benchmark: one window estimate of the B-spline kernel estimator (issue 5).

The noiseless set-up of Sridhar et al. Section V-A: window [0, 20] s sampled at
1 kHz (20,001 samples), a_0 an unknown quadratic B-spline (n = 86), a_1 an
unknown constant, b_0 known; every sample a regression instant. Target: one
estimate in <= 50 ms.

Run::

    .venv/bin/python benchmarks/bench_bspline.py [--repeat 20]

It reports the median over ``--repeat`` runs of

- ``cold``: :func:`lpvest.estimators.bspline.fit_kernel_model` (builds the
  quadrature and the B-spline basis at the nodes, then fits);
- ``warm``: the fit with the window geometry prepared once, which is what
  :class:`~lpvest.estimators.bspline.BSplineObserver` does for every window;

and where the time of a warm fit goes: interpolation + cumulative quadrature
of the known part, the B-spline columns, the QR solve (with the rank check)
and the state reconstruction. Timings on a shared machine are noisy: compare
the numbers of one run with each other, not across runs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from lpvest import load_system
from lpvest.estimators import bspline as bs
from lpvest.estimators.kernels import window_weight


def _median_ms(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()

    io = load_system("sridhar-ltv").model()
    t = np.linspace(0.0, 20.0, 20001)
    data = io.simulate(t)
    model = bs.KernelModel.from_io(io, a0=bs.UnknownSpline(86, order=3), a1=bs.UnknownConstant())
    u, y = data.u, data.y
    m, h = t.size, t[1] - t[0]
    idx = np.arange(m)

    cold = _median_ms(lambda: bs.fit_kernel_model(model, t, u, y), args.repeat)
    plan = bs._build_plan(model, m, h, points=6, difference_order=2)
    warm = _median_ms(lambda: bs._fit(plan, 0.0, u, y, penalty=None, instants=idx, rank_rtol=1e-9), args.repeat)
    plan_ms = _median_ms(lambda: bs._build_plan(model, m, h, points=6, difference_order=2), args.repeat)

    # the pieces of a warm fit
    quad = plan.quad
    T, R = quad.samples, quad.b - quad.samples
    C = window_weight(quad.samples, quad.a, quad.b)
    block = plan.blocks[0]

    def known_part() -> None:
        yn, un = quad.interpolate(y), quad.interpolate(u)
        F, B = quad.cumulative(yn)
        bs.free_identity(F, B, T, R)
        bs.coefficient_terms(quad, 0, io.b[0](quad.x), None, un)
        quad.cumulative(yn)  # the constant a_1 column reuses the y moments; one more pass for symmetry

    y_nodes = quad.interpolate(y)
    P = np.empty((m, plan.n_unknowns + 1), order="F")
    columns = _median_ms(lambda: bs._spline_columns(block, quad, y_nodes, T, R, P), args.repeat)
    known = _median_ms(known_part, args.repeat)
    assemble = _median_ms(lambda: bs._assemble(plan, 0.0, u, y), args.repeat)

    A, terms = bs._assemble(plan, 0.0, u, y)
    s = plan.n_unknowns

    def solve() -> None:
        from scipy.linalg import qr

        B = A.copy(order="F")
        scale = np.sqrt(np.einsum("ij,ij->j", B[:, :s], B[:, :s]))
        B[:, :s] /= scale
        (_, _), Raug = qr(B, mode="raw", overwrite_a=True, check_finite=False)
        bs._rank_check(plan, Raug[:s, :s], 1e-9)
        bs._penalized_solve(Raug[:s, :s], Raug[:s, s], plan.penalty_matrix, 0.0)

    copy = _median_ms(lambda: A.copy(order="F"), args.repeat)
    solve_ms = _median_ms(solve, args.repeat) - copy
    beta = bs._fit(plan, 0.0, u, y, penalty=None, instants=idx, rank_rtol=1e-9).beta
    state = _median_ms(lambda: bs._fitted(plan, terms, beta, u), args.repeat)
    gcv = _median_ms(
        lambda: bs._fit(plan, 0.0, u, y, penalty="gcv", instants=idx, rank_rtol=1e-9), max(3, args.repeat // 4)
    )

    print(f"one window: {m} samples, {s} unknowns (n = 86 quadratic B-splines + a_1), every sample an instant")
    print(f"  cold fit (fit_kernel_model)           {cold:8.1f} ms")
    print(f"  warm fit (geometry prepared once)     {warm:8.1f} ms   target <= 50 ms")
    print(f"    assembly of [P, q]                  {assemble:8.1f} ms")
    print(f"      interpolation + known part        {known:8.1f} ms")
    print(f"      B-spline columns (a_0 block)      {columns:8.1f} ms")
    print(f"    QR of [P, q] + rank check + solve   {solve_ms:8.1f} ms")
    print(f"    coefficients, y_E, y_E' (state)     {state:8.1f} ms")
    print(f"  window geometry (quadrature + basis)  {plan_ms:8.1f} ms")
    print(f"  warm fit with GCV-chosen penalty      {gcv:8.1f} ms")
    del C


if __name__ == "__main__":
    main()
