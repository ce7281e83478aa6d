"""Factories of the estimator FMUs (named in :mod:`lpvest.fmi`), one
module per estimator kind so that an FMU carries only the estimator it runs.

Each module has ``build(model, *, design=None, **parameters)`` returning a
streaming component (:mod:`lpvest.core`):

- :mod:`~lpvest.fmi.factories`: the exact LPV Kalman filter (Cox & Toth (4a)-(4e));
- :mod:`~lpvest.fmi.factories`: the truncated-memory filter (Theorem 1, ERRATA (6a));
- :mod:`~lpvest.fmi.factories`: the sliding-window B-spline observer (Sridhar et al.);
- :mod:`~lpvest.fmi.factories`: the H-infinity filter (2) of a carried design (Peixoto et al.).

The build-time design functions are in :mod:`lpvest.fmi`.
"""

__all__: list[str] = []
