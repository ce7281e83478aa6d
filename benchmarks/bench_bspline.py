"""Benchmark: one window estimate of the B-spline kernel estimator (issue 5).

The noiseless set-up of Sridhar et al. Section V-A: window [0, 20] s sampled at
1 kHz (20,001 samples), a_0 an unknown quadratic B-spline (n = 86), a_1 an
unknown constant, b_0 known; every sample a regression instant. Target: one
estimate in <= 50 ms.

Run::

    .venv/bin/python benchmarks/bench_bspline.py [--repeat 30] [--threads N]

``--threads`` sets the BLAS threads (OPENBLAS_NUM_THREADS etc., before numpy
is imported); the default leaves BLAS alone. On a loaded machine several BLAS
threads spinning against other processes can be much slower than one.

It reports the median over ``--repeat`` runs (wall clock, and the process's
CPU time, which a shared machine disturbs less) of

- ``cold``: :func:`lpvest.estimators.bspline.fit_kernel_model` (prepares the
  window geometry, then fits): what a single call on a window costs;
- ``warm``: the fit with the geometry prepared once, which is what
  :class:`~lpvest.estimators.bspline.BSplineObserver` does for every window;

and where the time goes. The geometry: the quadrature (pieces between the
samples and the knots, Gauss nodes, moment weights, Lagrange weights) and the
B-spline block (the basis at the nodes and the samples, the bands). A warm
fit: interpolation of u, y at the nodes and the cumulative moments (the known
part, the constant columns, the B-spline band moments), the segment-wise QR of
``[P, q]``, the final QR + rank check + solve, and the state reconstruction
(y_E, y_E'). Then a warm fit with a GCV-chosen penalty and its lambda search.
For comparison it also times forming the dense ``P`` and a LAPACK QR of it
(what a plain implementation would do). Timings on a shared machine are
noisy: compare numbers of one run with each other, not across runs; the load
average is printed.

The cold figure includes the operating system's price for fresh memory pages
(the geometry is a few MB; where freed memory goes back to the system, as on
small VMs, this is a visible share, and the cold time exceeds geometry + warm).
A first call in a fresh process also pays the imports and first-touch costs.
"""

from __future__ import annotations

import argparse
import os
import sys
import time


def _parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description="one window estimate of the B-spline kernel estimator")
    parser.add_argument("--repeat", type=int, default=30)
    parser.add_argument("--threads", type=int, default=None, help="BLAS threads (default: leave as is)")
    return parser.parse_args()


ARGS = _parse()
if ARGS.threads is not None:
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(ARGS.threads)
    if "numpy" in sys.modules:  # pragma: no cover
        raise SystemExit("numpy was imported before the thread count was set")

import numpy as np  # noqa: E402
from scipy.linalg import qr  # noqa: E402

from lpvest import load_system  # noqa: E402
from lpvest.estimators import bspline as bs  # noqa: E402
from lpvest.estimators.bspline import _fit as bfit, _regression as breg  # noqa: E402
from lpvest.estimators.bspline._kernels import product_quadrature  # noqa: E402


def _median_ms(fn, repeat: int) -> tuple[float, float]:
    """Median wall-clock and CPU milliseconds of ``fn()`` over ``repeat`` runs (after one warm-up)."""
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return 1e3 * float(np.median(wall)), 1e3 * float(np.median(cpu))


def main() -> None:
    repeat = ARGS.repeat
    io = load_system("sridhar-ltv").model()
    t = np.linspace(0.0, 20.0, 20001)
    data = io.simulate(t)
    model = bs.KernelModel.from_io(io, a0=bs.UnknownSpline(86, order=3), a1=bs.UnknownConstant())
    u, y = data.u, data.y
    m, h = t.size, t[1] - t[0]
    idx = np.arange(m)
    plan = breg.build_plan(model, m, h, points=6, difference_order=2)
    s = plan.n_unknowns
    spline = plan.blocks[0]
    knots = spline.knots

    def warm_fit(penalty=None):
        return bfit.fit_window(plan, 0.0, u, y, penalty=penalty, instants=idx, rank_rtol=1e-9)

    parts = breg.kernel_parts(plan, 0.0, u, y)
    K = breg.compressed_system(plan, parts, None)

    def final_solve() -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        A = K.copy()
        scale = np.sqrt(np.einsum("ij,ij->j", A[:, :s], A[:, :s]))
        A[:, :s] /= scale
        (_, _), Raug = qr(A, mode="raw", overwrite_a=True, check_finite=False)
        bfit._rank_check(plan, Raug[:s, :s], 1e-9)
        bfit._penalized_solve(Raug[:s, :s], Raug[:s, s], plan.penalty_matrix / scale, 0.0)
        return Raug[:s, :s], Raug[:s, s], float(Raug[s, s] ** 2), plan.penalty_matrix / scale

    R, z, rho2, D = final_solve()
    beta = warm_fit().beta
    dense = breg.dense_system(plan, parts)
    few = max(3, repeat // 3)
    rows = [
        ("cold fit (fit_kernel_model)", _median_ms(lambda: bs.fit_kernel_model(model, t, u, y), repeat),
         "target <= 50 ms"),
        ("  window geometry (_build_plan)", _median_ms(
            lambda: breg.build_plan(model, m, h, points=6, difference_order=2), repeat), ""),
        ("    quadrature: pieces, nodes, weights", _median_ms(
            lambda: product_quadrature(0.0, h, m, breakpoints=knots, points=6), repeat), ""),
        ("    B-spline basis at nodes/samples, bands", _median_ms(
            lambda: breg._spline_block("a0", 0, spline.spline, plan.quad, t[-1] - t[0]), repeat), ""),
        ("warm fit (geometry prepared once)", _median_ms(warm_fit, repeat), ""),
        ("  quadrature: interpolation, moments", _median_ms(lambda: breg.kernel_parts(plan, 0.0, u, y), repeat), ""),
        ("    of which the a_0 band moments", _median_ms(
            lambda: breg._band(spline, parts.quad, parts.y_nodes), repeat), ""),
        (f"  segment-wise QR of [P, q] -> {K.shape[0]} rows", _median_ms(
            lambda: breg.compressed_system(plan, parts, None), repeat), ""),
        ("  final QR + rank check (SVD) + solve", _median_ms(final_solve, repeat), ""),
        ("  state: coefficients, y_E, y_E'", _median_ms(lambda: bfit._fitted(plan, parts, beta, u), repeat), ""),
        ("warm fit with GCV-chosen penalty", _median_ms(lambda: warm_fit("gcv"), repeat), ""),
        ("  of which the lambda search", _median_ms(lambda: bfit._choose_penalty(R, z, rho2, D, m), repeat), ""),
        ("for comparison: dense P formed", _median_ms(lambda: breg.dense_system(plan, parts), few), ""),
        ("  LAPACK QR of the dense [P, q]", _median_ms(
            lambda: qr(dense.copy(order="F"), mode="raw", overwrite_a=True, check_finite=False), few), ""),
    ]
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    print(f"one window: {m} samples, {s} unknowns (86 quadratic B-splines + a_1), every sample an instant;"
          f" median of {repeat}; BLAS threads: {threads}; load average {os.getloadavg()[0]:.2f}")
    print(f"  {'':44s} {'wall':>8s} {'cpu':>8s}")
    for label, (wall, cpu), note in rows:
        print(f"  {label:44s} {wall:6.1f} ms {cpu:6.1f} ms   {note}".rstrip())


if __name__ == "__main__":
    main()
