"""Estimators, each a streaming component (:mod:`lpvest.protocol`), so that one
FMU adapter serves them all:

- :mod:`~lpvest.estimators.kalman`: the exact LPV Kalman filter (Cox & Toth (4a)-(4e)),
  streaming and batch (:mod:`~lpvest.estimators.kalman.scan`: its parallel-in-time form);
- :mod:`~lpvest.estimators.truncated`: the truncated-memory filter (Theorem 1);
- :mod:`~lpvest.estimators.hinf`: the H-infinity filter (2) of Peixoto et al. for a design;
- :mod:`~lpvest.estimators.bspline` and :mod:`~lpvest.estimators.bspline.kernels`: the B-spline
  joint parameter and state estimator of Sridhar et al.
"""

__all__: list[str] = []
