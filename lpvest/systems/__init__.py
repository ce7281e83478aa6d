"""Model types: affine and polytopic LPV, innovation-form and input-output LPV,
continuous-time LTV.

Examples
--------
>>> import numpy as np
>>> from lpvest import load_system
>>> plant = load_system("peixoto-ex1").model()              # a PolytopicLPV
>>> k = np.arange(20)
>>> traj = plant.simulate(plant.alpha_batch(np.sin(0.25 * k)[:, None]), np.zeros((20, 1)), x0=[1.0, 0.0])
>>> traj.x.shape, traj.y.shape
((20, 2), (20, 1))
"""

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
    LTVSolution as LTVSolution,
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
    hinf_setting as hinf_setting,
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
    "LTVSolution",
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
    "hinf_setting",
]
