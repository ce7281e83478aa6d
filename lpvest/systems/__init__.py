"""Model types: affine and polytopic LPV, innovation-form and input-output LPV,
continuous-time LTV."""

from .affine import (
    CONSTANT_TERM as CONSTANT_TERM,
    AffineDependence as AffineDependence,
    AffineLPV as AffineLPV,
    LPVTrajectory as LPVTrajectory,
    NoiseCovariance as NoiseCovariance,
    StateSpaceMatrices as StateSpaceMatrices,
)
from .innovation import (
    InnovationLPV as InnovationLPV,
    InnovationTrajectory as InnovationTrajectory,
    LPVInputOutput as LPVInputOutput,
)
from .ltv import (
    LTVInputOutput as LTVInputOutput,
    LTVStateSpace as LTVStateSpace,
    LTVTrajectory as LTVTrajectory,
    TimeFunction as TimeFunction,
)
from .polytopic import (
    FormulaSimplexMap as FormulaSimplexMap,
    MultilinearSimplexMap as MultilinearSimplexMap,
    PolytopicLPV as PolytopicLPV,
    PolytopicMatrices as PolytopicMatrices,
    PolytopicTrajectory as PolytopicTrajectory,
    SimplexMap as SimplexMap,
    affine_to_polytopic as affine_to_polytopic,
)

__all__ = [
    "CONSTANT_TERM",
    "AffineDependence",
    "AffineLPV",
    "LPVTrajectory",
    "NoiseCovariance",
    "StateSpaceMatrices",
    "InnovationLPV",
    "InnovationTrajectory",
    "LPVInputOutput",
    "LTVInputOutput",
    "LTVStateSpace",
    "LTVTrajectory",
    "TimeFunction",
    "FormulaSimplexMap",
    "MultilinearSimplexMap",
    "PolytopicLPV",
    "PolytopicMatrices",
    "PolytopicTrajectory",
    "SimplexMap",
    "affine_to_polytopic",
]
