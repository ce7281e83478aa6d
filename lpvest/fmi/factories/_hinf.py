"""Factory of the HinfPD / HinfRobust FMUs: the H-infinity filter (2) of
Peixoto et al. with the design the FMU carries."""

from __future__ import annotations

from ...core._errors import LpvestError
from ...design._result import HinfDesign
from ...estimators._hinf import HinfFilter, needs_scheduling
from ...systems._polytopic import hinf_setting

__all__ = ["build"]


def build(model: object, *, design: HinfDesign | str | None) -> HinfFilter:
    """The H-infinity filter (2) of a design carried by the FMU (JSON text).

    A model with general noise (affine) is taken in its H-infinity setting
    (:func:`~lpvest.systems.hinf_setting`), and its known input
    ``u`` becomes an input of the filter, compensated exactly. A
    parameter-dependent filter is scheduled by the plant's physical
    scheduling ``p`` when the model has a map to ``alpha`` (range-checked),
    else by ``alpha`` (checked on the simplex); a robust one takes ``y`` (and
    ``u``), and the scheduling only where the response to ``u`` varies with it."""
    if design is None:
        raise LpvestError("this FMU carries no filter design (resources/design.json)")
    d = design if isinstance(design, HinfDesign) else HinfDesign.from_json(design)
    plant = hinf_setting(model)
    mapping = plant.simplex_map if needs_scheduling(d, plant) else None
    return HinfFilter(d, simplex_map=mapping, plant=plant)
