"""Factories of the estimator FMUs (named in :mod:`lpvest.fmi.registry`), one
module per estimator kind so that an FMU carries only the estimator it runs.

Each module has ``build(model, *, design=None, **parameters)`` returning a
streaming component (:mod:`lpvest.core`):

- :mod:`~lpvest.fmi.factories.kalman`: the exact LPV Kalman filter (Cox & Toth (4a)-(4e));
- :mod:`~lpvest.fmi.factories.truncated`: the truncated-memory filter (Theorem 1, ERRATA (6a));
- :mod:`~lpvest.fmi.factories.bspline`: the sliding-window B-spline observer (Sridhar et al.);
- :mod:`~lpvest.fmi.factories.hinf`: the H-infinity filter (2) of a carried design (Peixoto et al.).

The build-time design functions are in :mod:`lpvest.fmi.designs`.
"""

__all__: list[str] = []
