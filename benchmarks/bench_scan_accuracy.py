"""Accuracy of the parallel-in-time Kalman scan against the sequential recursion.

Not a test: it measures the figures that the module notes of
:mod:`lpvest.estimators.kalman._scan` ("Accuracy"), ``SCAN_MAX_AMPLIFICATION``
and the scan tests' tolerances are derived from.

Both algorithms compute the same exact filter (4a)-(4e); they round
differently. The scan works on the decorrelated model, whose
``Abar_t = A - J_t C_t`` and ``c_t = ... + J_t y_t`` carry terms of size
``amp = max_t ||J_t C_t||`` that cancel against the filtered estimate, so its
rounding errors are amplified by about ``amp^2`` (the covariance goes through
``Abar P Abar^T``). For every case this prints

- ``amp``: :func:`~lpvest.estimators.kalman._scan.scan_amplification`
  (``max_t ||J_t||_F ||C_t||_F``, what ``method="auto"`` gates on);
- ``err``: the largest difference between ``method="scan"`` and
  ``method="sequential"`` over every output field (means, covariances,
  outputs, innovations, gains, log-likelihood terms), each relative to that
  field's largest entry;
- ``err / (eps (kappa + (1 + amp)^2))``: the constant of the error model,
  ``kappa = max_t cond(Omega_t)`` (two backward-stable computations of the
  gains differ by about ``eps kappa`` even without amplification).

Cases: ``T`` = 64 ... 1e5 samples; amplifications from 0.3 to 3000, made by
scaling the measurement noise ``v -> r v`` (``R -> r^2 R``, ``S -> r S``) of
a fixed model, so ``J ~ 1 / r`` while the correlation of ``w`` and ``v``
stays the same; four model families (a scalar-output model with correlation
0.9, and three random systems of ``tests/kalman_helpers.py`` with two to five
outputs and a random schedule).

Run (``--seeds 1``: about 30 minutes on one core of a loaded machine;
``--quick``, ``T <= 4096``: about 3)::

    .venv/bin/python benchmarks/bench_scan_accuracy.py [--quick] [--seeds 1] [--lengths 64 1024 100000]

and under another BLAS kernel, e.g. ``OPENBLAS_CORETYPE=Sandybridge``. The
figures in the module notes of :mod:`lpvest.estimators.kalman._scan` come
from ``--seeds 1`` (Haswell) and ``--quick`` (Sandybridge, Nehalem).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import pathlib  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from lpvest import AffineLPV, Monomial, NumericalError, SchedulingSpace  # noqa: E402
from lpvest.estimators.kalman import KalmanModel, kalman_filter  # noqa: E402
from lpvest.estimators.kalman._scan import decorrelate_stack, scan_amplification  # noqa: E402
from lpvest.systems._affine import NoiseCovariance  # noqa: E402
from tests.kalman_helpers import random_schedule, random_system  # noqa: E402

EPS = float(np.finfo(float).eps)

FIELDS = (
    "predicted_means", "predicted_covariances", "filtered_means", "filtered_covariances",
    "predicted_outputs", "innovations", "innovation_covariances", "gains", "filter_gains",
    "log_likelihood_terms",
)


def max_rel(a, b) -> float:
    """max |a - b| / max |b| over every field of two KalmanResults."""
    return max(
        float(np.max(np.abs(getattr(a, f) - getattr(b, f))) / np.max(np.abs(getattr(b, f)))) for f in FIELDS
    )


def scalar_model() -> AffineLPV:
    """Scalar output, correlation 0.9 between w_1 and v (``r = 1``: amp ~ 1)."""
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    return AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A={"1": [[0.6, 0.3], [-0.2, 0.5]], "p": [[0.1, 0.0], [0.0, 0.1]]}, C=[[1.0, 0.4]],
        Q=np.diag([1.0, 0.5]), R=[[1.0]], S=[[0.9], [0.0]], P0=np.eye(2),
    )


def families() -> dict[str, tuple[AffineLPV, str]]:
    return {
        "scalar n_y=1": (scalar_model(), "sin"),
        "random 3x2": (random_system(np.random.default_rng(1000), nx=3, ny=2, nu=1), "random"),
        "random 4x3": (random_system(np.random.default_rng(1001), nx=4, ny=3, nu=1, nw=5, nv=3), "random"),
        "random 3x5": (random_system(np.random.default_rng(1002), nx=3, ny=5, nu=1, nw=2, nv=6), "random"),
    }


def scaled(model: AffineLPV, r: float) -> AffineLPV:
    """The same model with measurement noise ``r v``."""
    n = model.noise
    return dataclasses.replace(model, noise=NoiseCovariance(n.Q, r * r * n.R, r * n.S))


def measure(model: AffineLPV, schedule: str, T: int, seed: int, max_amp: float) -> tuple[float, float, float]:
    """``(amp, kappa, err)`` of one case, ``kappa = max_t cond(Omega_t)``; ``err`` is
    NaN when ``amp > max_amp`` (not run) and inf when the scan broke down
    (NumericalError)."""
    rng = np.random.default_rng(seed)
    p = np.sin(0.25 * np.arange(T))[:, None] if schedule == "sin" else random_schedule(model, rng, T)
    u = rng.standard_normal((T, model.nu)) if model.nu else None
    y = model.simulate(p, u, rng=rng).y
    mats = KalmanModel(model).matrices_batch(p)
    amp = scan_amplification(decorrelate_stack(*mats, np.zeros((T, 0)) if u is None else u, y), mats.C)
    if amp > max_amp:
        return amp, math.nan, math.nan
    seq = kalman_filter(model, p, u, y, method="sequential")
    kappa = float(np.max(np.linalg.cond(seq.innovation_covariances)))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # beyond the gate method="scan" warns
            scan = kalman_filter(model, p, u, y, method="scan")
    except NumericalError:  # far beyond the gate the scan can break down
        return amp, kappa, math.inf
    return amp, kappa, max_rel(scan, seq)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lengths", type=int, nargs="+", default=[64, 256, 1024, 4096, 16384, 100_000])
    ap.add_argument("--scales", type=float, nargs="+",
                    default=[30.0, 10.0, 3.0, 1.0, 0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4])
    ap.add_argument("--seeds", type=int, default=2, help="data seeds per case")
    ap.add_argument("--max-amp", type=float, default=1e4, help="skip cases above this amplification")
    ap.add_argument("--quick", action="store_true", help="T <= 4096, one seed")
    args = ap.parse_args()
    lengths = [T for T in args.lengths if T <= 4096] if args.quick else args.lengths
    seeds = 1 if args.quick else args.seeds
    try:
        from threadpoolctl import threadpool_info

        kernels = sorted({str(i.get("architecture")) for i in threadpool_info() if i.get("user_api") == "blas"})
    except ImportError:
        kernels = ["?"]
    print(f"BLAS kernel(s): {', '.join(kernels)}; eps = {EPS:.3g}")
    print("each cell: err @ amp (worst over the seeds); '-': amp above --max-amp, not run; inf: NumericalError")
    print(f"{'family':14s} {'r':>7s} " + " ".join(f"{'T=' + str(T):>17s}" for T in lengths))
    cases = []  # (amp, kappa, err)
    for name, (base, schedule) in families().items():
        for r in args.scales:
            model = scaled(base, r)
            cells = []
            for T in lengths:
                amp, err = 0.0, 0.0
                for s in range(seeds):
                    a, k, e = measure(model, schedule, T, 10 * T + s, args.max_amp)
                    cases.append((a, k, e))
                    amp, err = max(amp, a), (e if math.isnan(e) else max(err, e))
                cells.append("-" if math.isnan(err) else f"{err:7.1e} @ {amp:7.2g}")
            print(f"{name:14s} {r:7.0e} " + " ".join(f"{c:>17s}" for c in cells), flush=True)
    print("\nworst err and err / (eps (kappa + (1 + amp)^2)) by amplification (cases run; kappa = max cond(Omega_t)):")
    for lo, hi in ((0, 3), (3, 10), (10, 30), (30, 100), (100, 300), (300, 1000), (1000, math.inf)):
        sel = [(a, k, e) for a, k, e in cases if lo <= a < hi and not math.isnan(e)]
        if sel:
            worst = max(e for _, _, e in sel)
            c = max(e / (EPS * (k + (1 + a) ** 2)) for a, k, e in sel)
            print(f"  amp in [{lo:g}, {hi:g}): worst err {worst:.2g}, err / (eps (kappa + (1 + amp)^2)) <= {c:.3g}"
                  f"  ({len(sel)} cases)")


if __name__ == "__main__":
    main()
