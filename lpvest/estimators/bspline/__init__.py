"""Joint parameter and state estimation for LTV systems with B-splines.

Sridhar, Ghoshal & Michalska (002_54d0f33f85fddffe.txt), Sections III-IV, for
the second-order SISO input-output equation (11)::

    y'' + a_1(t) y' + a_0(t) y + b_1(t) u' + b_0(t) u = 0.

Each coefficient is declared :class:`Known` (a
:class:`~lpvest.systems.TimeFunction`), :class:`UnknownConstant` or
:class:`UnknownSpline` (a B-spline expansion (23)). The kernel identity (9)
with the kernels (13)-(19) is linear in the unknowns, so at every regression
instant ``t_j``::

    q(t_j) = y(t_j) - r_0(t_j) / C(t_j) = h(t_j) beta                   (28)-(30)

where ``r_0`` collects the kernel integrals that depend on no unknown (the
part of the kernel from the leading coefficient of ``y''``, which (24)/(28)
omit (ERRATA.md), and every known coefficient) and ``C = (t - a)^2 +
(b - t)^2``. The columns of ``h`` are kernel integrals of ``B_k y``,
``B_k' y``, ``B_k u``, ... computed by the cumulative product quadrature of
:mod:`lpvest.estimators.bspline` at *every* sample (the default regression
instants). The least-squares problem is solved by Householder QR of the
column-scaled ``[P, q]`` (no normal equations), optionally with a P-spline
difference penalty whose weight is given or chosen by generalized
cross-validation (GCV). ``P`` (``m x s``, dense) is never formed: between
consecutive starts of the B-splines' supports its rows lie in a space of
dimension about 10, so each such segment is first reduced by a small QR and
only the stacked triangular factors enter the final QR (a TSQR; see
:func:`~lpvest.estimators.bspline._fit.compressed_system`). :func:`kernel_regression` returns the dense ``P``.
The rank of ``P`` must equal the number of unknowns (practical
identifiability, Definition 1; the paper's "rank P = 2n"), otherwise
:class:`~lpvest.core.IdentifiabilityError` names the coefficients the data
do not determine.

With the estimated coefficients, ``y_E`` and ``y_E'`` follow from (9) and the
derivative identity (10) (the derivative kernels, obtained by differentiating
(12) and (15) in ``t``; see :mod:`lpvest.estimators.bspline`), and the state
from (32) (:func:`reconstruct_state`; for the realization
:meth:`~lpvest.systems.LTVInputOutput.to_state_space`,
``x = (y_E, y_E' + b_1 u)``).

:class:`BSplineObserver` runs the estimator on a sliding window over streaming
samples (a streaming component, :mod:`lpvest.core`).

Examples
--------
>>> import numpy as np
>>> from lpvest import load_system
>>> io = load_system("sridhar-ltv").model()
>>> t = np.linspace(0.0, 10.0, 5001)
>>> data = io.simulate(t)
>>> model = KernelModel(a0=UnknownSpline(20), a1=UnknownConstant(), b0=io.b[0])
>>> fit = fit_kernel_model(model, t, data.u, data.y)
>>> round(fit.constants["a1"], 6)
1.0

Modules: :mod:`~lpvest.estimators.bspline` (the kernel identity and
its quadrature), :mod:`~lpvest.estimators.bspline` (the coefficient
declarations), :mod:`~lpvest.estimators.bspline` (the B-spline basis),
:mod:`~lpvest.estimators.bspline` (the plan and the assembly of the
least-squares system), :mod:`~lpvest.estimators.bspline` (the solve),
:mod:`~lpvest.estimators.bspline` (state reconstruction),
:mod:`~lpvest.estimators.bspline` (the sliding-window observer).
"""

from __future__ import annotations

from ._basis import bspline_basis, spline_knots
from ._fit import KernelFit, KernelRegression, fit_kernel_model, kernel_regression, observer_supports
from ._kernels import KernelIdentity, kernel_identity
from ._model import COEFFICIENTS, KernelModel, Known, UnknownConstant, UnknownSpline
from ._observer import BSplineObserver
from ._state import reconstruct_state

__all__ = [
    "COEFFICIENTS",
    "Known",
    "UnknownConstant",
    "UnknownSpline",
    "KernelModel",
    "KernelFit",
    "fit_kernel_model",
    "KernelRegression",
    "kernel_regression",
    "bspline_basis",
    "spline_knots",
    "reconstruct_state",
    "BSplineObserver",
    "observer_supports",
    "KernelIdentity",
    "kernel_identity",
]
