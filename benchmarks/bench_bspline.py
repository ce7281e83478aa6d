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

It reports the median over ``--repeat`` runs of

- ``cold``: :func:`lpvest.estimators.bspline.fit_kernel_model` (prepares the
  window geometry: quadrature nodes and the B-spline basis at the nodes, then fits);
- ``warm``: the fit with the geometry prepared once, which is what
  :class:`~lpvest.estimators.bspline.BSplineObserver` does for every window;

and where the time of a warm fit goes: interpolation and cumulative quadrature
(the known part, the constant column, the B-spline band moments), the
segment-wise QR of ``[P, q]``, the final QR + rank check + solve, and the
state reconstruction (y_E, y_E'). For comparison it also times forming the
dense ``P`` and a LAPACK QR of it (what a plain implementation would do).
Timings on a shared machine are noisy: compare numbers of one run with each
other, not across runs.
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


def _median_ms(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main() -> None:
    repeat = ARGS.repeat
    io = load_system("sridhar-ltv").model()
    t = np.linspace(0.0, 20.0, 20001)
    data = io.simulate(t)
    model = bs.KernelModel.from_io(io, a0=bs.UnknownSpline(86, order=3), a1=bs.UnknownConstant())
    u, y = data.u, data.y
    m, h = t.size, t[1] - t[0]
    idx = np.arange(m)
    plan = bs._build_plan(model, m, h, points=6, difference_order=2)
    s = plan.n_unknowns

    def warm_fit():
        return bs._fit(plan, 0.0, u, y, penalty=None, instants=idx, rank_rtol=1e-9)

    cold = _median_ms(lambda: bs.fit_kernel_model(model, t, u, y), repeat)
    warm = _median_ms(warm_fit, repeat)
    geometry = _median_ms(lambda: bs._build_plan(model, m, h, points=6, difference_order=2), repeat)
    parts_ms = _median_ms(lambda: bs._parts(plan, 0.0, u, y), repeat)
    parts = bs._parts(plan, 0.0, u, y)
    band_ms = _median_ms(lambda: bs._band(plan.blocks[0], parts.quad, parts.y_nodes), repeat)
    compress = _median_ms(lambda: bs._compressed_system(plan, parts, None), repeat)
    K = bs._compressed_system(plan, parts, None)

    def final_solve() -> None:
        A = K.copy()
        scale = np.sqrt(np.einsum("ij,ij->j", A[:, :s], A[:, :s]))
        A[:, :s] /= scale
        (_, _), Raug = qr(A, mode="raw", overwrite_a=True, check_finite=False)
        bs._rank_check(plan, Raug[:s, :s], 1e-9)
        bs._penalized_solve(Raug[:s, :s], Raug[:s, s], plan.penalty_matrix / scale, 0.0)

    solve = _median_ms(final_solve, repeat)
    beta = warm_fit().beta
    state = _median_ms(lambda: bs._fitted(plan, parts, beta, u), repeat)
    gcv = _median_ms(lambda: bs._fit(plan, 0.0, u, y, penalty="gcv", instants=idx, rank_rtol=1e-9),
                     max(3, repeat // 5))
    dense_form = _median_ms(lambda: bs._dense_system(plan, parts), max(3, repeat // 3))
    dense = bs._dense_system(plan, parts)
    dense_qr = _median_ms(lambda: qr(dense.copy(order="F"), mode="raw", overwrite_a=True, check_finite=False),
                          max(3, repeat // 3))

    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    print(f"one window: {m} samples, {s} unknowns (86 quadratic B-splines + a_1), every sample an instant;"
          f" median of {repeat}; BLAS threads: {threads}")
    print(f"  cold fit (fit_kernel_model)                 {cold:7.1f} ms")
    print(f"  warm fit (geometry prepared once)           {warm:7.1f} ms   target <= 50 ms")
    print(f"    quadrature: interpolation, moments        {parts_ms:7.1f} ms")
    print(f"      of which the a_0 band moments           {band_ms:7.1f} ms")
    print(f"    segment-wise QR of [P, q] -> {K.shape[0]:4d} rows  {compress:7.1f} ms")
    print(f"    final QR + rank check (SVD) + solve       {solve:7.1f} ms")
    print(f"    state: coefficients, y_E, y_E'            {state:7.1f} ms")
    print(f"  window geometry (nodes, basis, bands)       {geometry:7.1f} ms")
    print(f"  warm fit with GCV-chosen penalty            {gcv:7.1f} ms")
    print(f"  for comparison: dense P formed              {dense_form:7.1f} ms, LAPACK QR of it {dense_qr:7.1f} ms")


if __name__ == "__main__":
    main()
