"""Rounding-error tolerances: eps times a stated amplification, never a number
one machine printed.

Every numerical tolerance in tests/ is one of

- a rounding bound built here: ``EPS`` times a count of rounding stages
  times the size of what is rounded times an amplification the test computes
  (a condition number, the Kalman scan's ``amp``);
- a statistical bound (k standard errors of a seeded Monte Carlo estimate);
- a method bound (quadrature, ODE integrator, interior-point solver,
  truncation of a series) stated with its source.

The rounding model (Higham, *Accuracy and Stability of Numerical
Algorithms*, 2nd ed., 2002, (3.4)-(3.5)): a sum of ``n`` products formed in
any order, with or without fused multiply-adds (every BLAS kernel), is
within ``gamma_n = n eps / (1 - n eps)`` of the exact value *relative to the
sum of the absolute products*. Two computations of the same quantity (a
library routine and a test's oracle, the same formula under two kernels)
therefore differ by at most twice that per stage; a chain of ``k`` such
stages adds up (first order). Where a solve or a factorisation is involved
the forward error is at most the backward error times the condition number
(Higham (7.2), (10.5), (20.1)). The constants below are these counts,
rounded up, with a safety factor of about 10 for what the first-order
model leaves out; the ratio of the measured error to each tolerance was
checked under the OpenBLAS kernels Haswell, Sandybridge and Nehalem.
"""

from __future__ import annotations

import numpy as np

EPS = float(np.finfo(float).eps)  #: 2.2e-16, the unit roundoff times two


def roundoff(size: float, stages: float = 1.0, *, n: int = 1, amp: float = 1.0) -> float:
    """``10 * 2 * stages * n * EPS * amp * size``: two computations of a
    quantity that goes through ``stages`` sums of at most ``n`` products, of
    total absolute size ``size``, amplified by ``amp`` (1 for a
    straightforward evaluation; a condition number where a solve is in
    between). The factor 10 is the safety factor of the module notes."""
    return 20.0 * stages * n * EPS * amp * float(size)


def lstsq_rtol(cond: float, residual_ratio: float, n: int) -> float:
    """Normwise relative forward error of a least-squares solution computed by
    a backward-stable method (Householder QR, SVD), against another such
    solution: Wedin's bound (Higham (20.1)) with backward error ``eta``,
    ``eta (2 cond + cond^2 ||r|| / (||P|| ||beta||))``. ``eta`` is taken as
    ``10 n EPS`` (``n`` columns; the worst-case bound ``gamma_{cmn}`` is
    never approached in practice, Higham 19.3); twice, for two solutions.

    ``cond``: 2-norm condition number of the (column-scaled) matrix;
    ``residual_ratio``: ``||r|| / (||P|| ||beta||)``.
    """
    eta = 10.0 * n * EPS
    return 2.0 * eta * (2.0 * cond + cond * cond * residual_ratio)


#: Two certified H-infinity designs of one LMI program (same plant, same
#: epsilon) solved separately, e.g. a design stored in models/designs and the
#: same design solved again on this machine: relative difference of gamma.
#: A method bound, not rounding: the interior-point solver (Clarabel) stops
#: anywhere in its tolerance band, relative duality gap and primal/dual
#: residuals 1e-8 (its defaults), and where it stops depends on the rounding of
#: its dense kernels, which faer picks at run time (AVX2 or AVX-512; OpenBLAS is
#: not involved, so the second-kernel rerun does not vary it). The gap bounds
#: the objective delta = gamma^2 to 1e-8 relative; a residual of 1e-8 moves it
#: by up to the residual times the size of the multipliers, here up to ~1e2 (the
#: LMI variables P, X of Examples 1-2 relative to the plant data): 1e-6 on delta,
#: 5e-7 on gamma, rounded up to 1e-6. Measured across an AVX2 and an AVX-512
#: machine: 7.5e-9 (Example 1, epsilon = 150), 2.2e-7 (Example 2, rho = 1).
#: Searches over epsilon add their own resolution (see test_peixoto_experiments).
LMI_RESOLVE_GAMMA_RTOL = 1e-6
