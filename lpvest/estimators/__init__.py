"""Estimators, each a streaming component (:mod:`lpvest.protocol`), so that one
FMU adapter serves them all:

- :mod:`~lpvest.estimators.kalman`: the exact LPV Kalman filter (Cox & Toth (4a)-(4e)),
  streaming and batch (:mod:`~lpvest.estimators.kalman.scan`: its parallel-in-time form);
- :mod:`~lpvest.estimators.truncated`: the truncated-memory filter (Theorem 1);
- :mod:`~lpvest.estimators.hinf`: the H-infinity filter (2) of Peixoto et al. for a design;
- :mod:`~lpvest.estimators.bspline` and :mod:`~lpvest.estimators.bspline.kernels`: the B-spline
  joint parameter and state estimator of Sridhar et al.

Examples
--------
The streaming filters share one protocol (:mod:`lpvest.protocol`):

>>> from lpvest import load_system
>>> from lpvest.estimators.kalman import LPVKalmanFilter
>>> kf = LPVKalmanFilter(load_system("cox-toth-truncation").model())
>>> [p.name for p in kf.input_ports], kf.step({"p": [0.0], "u": [1.0], "y": [0.1, -0.2]})["xhat"].shape
(['p', 'u', 'y'], (2,))
"""

__all__: list[str] = []
