"""Factories of the estimator FMUs (named in :mod:`lpvest.fmi.registry`).

Each builds a :class:`~lpvest.estimators.base.StreamingEstimator` from the
model carried by the FMU, the optional build-time design and the FMU's
parameters. They import only what the filter needs at run time (numpy).
"""

from __future__ import annotations

from typing import Any

from ..errors import LpvestError

__all__ = [
    "kalman",
    "truncated_kalman",
    "bspline_observer",
    "SampledObserver",
    "hinf",
    "hinf_pd_design",
    "hinf_robust_design",
]

#: Start covariances of the truncated filter selectable from an FMU parameter.
TRUNCATED_STARTS = ("theorem", "steady-state")


def kalman(model: Any, *, design: Any = None) -> Any:
    """The exact LPV Kalman filter (Cox & Toth (4a)-(4e)) of an affine model."""
    from ..estimators.kalman import LPVKalmanFilter

    return LPVKalmanFilter(model)


def truncated_kalman(model: Any, *, design: Any = None, tau: int, start: str) -> Any:
    """The truncated-memory Kalman filter (Theorem 1, ERRATA (6a)) with memory ``tau``."""
    from ..estimators.truncated import TruncatedKalmanFilter

    if start not in TRUNCATED_STARTS:
        raise LpvestError(f"start = {start!r}; expected one of {', '.join(TRUNCATED_STARTS)}")
    return TruncatedKalmanFilter(model, int(tau), start=start)


def _coefficient(name: str, spec: str) -> Any:
    """``"known"`` | ``"constant"`` | ``"spline:N"`` | ``"spline:N:ORDER"`` -> a declaration."""
    from ..estimators.bspline import UnknownConstant, UnknownSpline

    text = spec.strip().lower()
    if text == "known":
        return None
    if text == "constant":
        return UnknownConstant()
    parts = text.split(":")
    if parts[0] == "spline" and len(parts) in (2, 3) and all(p.isdigit() for p in parts[1:]):
        n = int(parts[1])
        order = int(parts[2]) if len(parts) == 3 else 3
        return UnknownSpline(n, order=order)
    raise LpvestError(
        f"{name} = {spec!r}; expected 'known', 'constant', 'spline:N' or 'spline:N:ORDER'"
    )


class SampledObserver:
    """The B-spline observer inside an FMU: one fmi2DoStep is one sample, so
    the communication step must equal the observer's sample time ``dt``; the
    first sample is at the experiment's start time."""

    timed = True

    def __init__(self, build: Any, dt: float) -> None:
        self._build = build
        self.dt = float(dt)
        self._obs = build(0.0)

    @property
    def input_ports(self) -> Any:
        return self._obs.input_ports

    @property
    def output_ports(self) -> Any:
        return self._obs.output_ports

    def reset(self, t0: float = 0.0) -> None:
        if float(t0) != self._obs.t0:
            self._obs = self._build(float(t0))
        self._obs.reset()

    def outputs(self, inputs: Any) -> Any:
        return self._obs.outputs(inputs)

    def step(self, inputs: Any, *, dt: float, t_end: float) -> Any:
        if abs(dt - self.dt) > 1e-9 * self.dt:
            raise LpvestError(
                f"communication step {dt:g} s differs from the observer's sample time dt = {self.dt:g} s "
                "(one fmi2DoStep is one sample)"
            )
        return self._obs.step(inputs)

    def get_state(self) -> Any:
        return self._obs.get_state()

    def set_state(self, state: Any) -> None:
        self._obs.set_state(state)


def bspline_observer(
    model: Any,
    *,
    design: Any = None,
    dt: float,
    window: float,
    hop: float,
    a0: str,
    a1: str,
    b0: str,
    b1: str,
    penalty: float,
) -> SampledObserver:
    """The sliding-window B-spline observer (Sridhar et al.) of a second-order
    LTV input-output model; each coefficient declared known, an unknown
    constant or an unknown B-spline per window; ``penalty`` < 0 chooses the
    P-spline penalty by GCV, 0 means none."""
    from ..estimators.bspline import BSplineObserver, KernelModel

    unknown = {}
    for name, spec in (("a0", a0), ("a1", a1), ("b0", b0), ("b1", b1)):
        decl = _coefficient(name, spec)
        if decl is not None:
            unknown[name] = decl
    kernel_model = KernelModel.from_io(model, **unknown)
    pen: float | str | None = "gcv" if penalty < 0 else (None if penalty == 0 else float(penalty))

    def build(t0: float) -> Any:
        return BSplineObserver(kernel_model, dt=dt, window=window, hop=hop, t0=t0, penalty=pen,
                               on_unidentifiable="hold")

    return SampledObserver(build, dt)


def _hinf_design(model: Any, kind: str) -> str:
    """The best design over every epsilon (:func:`lpvest.design.search_epsilon`), as JSON."""
    from ..design import search_epsilon

    return search_epsilon(model, kind=kind).design.to_json()


def hinf_pd_design(model: Any) -> str:
    """Build-time design of the parameter-dependent filter (Theorem 1), best epsilon."""
    from ..design import KIND_PD

    return _hinf_design(model, KIND_PD)


def hinf_robust_design(model: Any) -> str:
    """Build-time design of the robust filter (Corollary 1), best epsilon."""
    from ..design import KIND_ROBUST

    return _hinf_design(model, KIND_ROBUST)


def hinf(model: Any, *, design: Any) -> Any:
    """The H-infinity filter (2) of a design carried by the FMU (JSON text).

    A parameter-dependent filter is scheduled by the plant's physical
    scheduling ``p`` when the model has a map to ``alpha`` (range-checked),
    else by ``alpha`` (checked on the simplex); a robust one takes only ``y``."""
    from ..design import HinfDesign
    from ..estimators.hinf import HinfFilter

    if design is None:
        raise LpvestError("this FMU carries no filter design (resources/design.json)")
    d = design if isinstance(design, HinfDesign) else HinfDesign.from_json(design)
    mapping = getattr(model, "simplex_map", None) if d.scheduled else None
    return HinfFilter(d, simplex_map=mapping)
