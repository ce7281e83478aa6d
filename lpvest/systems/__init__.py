"""Model types: affine and polytopic LPV, innovation-form and input-output LPV,
continuous-time LTV."""

from .affine import (
    CONSTANT_TERM as CONSTANT_TERM,
)
from .affine import (
    AffineDependence as AffineDependence,
)
from .affine import (
    AffineLPV as AffineLPV,
)
from .affine import (
    LPVTrajectory as LPVTrajectory,
)
from .affine import (
    NoiseCovariance as NoiseCovariance,
)
from .affine import (
    StateSpaceMatrices as StateSpaceMatrices,
)
from .innovation import (
    InnovationLPV as InnovationLPV,
)
from .innovation import (
    InnovationTrajectory as InnovationTrajectory,
)
from .innovation import (
    LPVInputOutput as LPVInputOutput,
)
from .ltv import (
    LTVInputOutput as LTVInputOutput,
)
from .ltv import (
    LTVStateSpace as LTVStateSpace,
)
from .ltv import (
    LTVTrajectory as LTVTrajectory,
)
from .ltv import (
    TimeFunction as TimeFunction,
)
from .polytopic import (
    FormulaSimplexMap as FormulaSimplexMap,
)
from .polytopic import (
    MultilinearSimplexMap as MultilinearSimplexMap,
)
from .polytopic import (
    PolytopicLPV as PolytopicLPV,
)
from .polytopic import (
    PolytopicMatrices as PolytopicMatrices,
)
from .polytopic import (
    PolytopicTrajectory as PolytopicTrajectory,
)
from .polytopic import (
    SimplexMap as SimplexMap,
)
from .polytopic import (
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
