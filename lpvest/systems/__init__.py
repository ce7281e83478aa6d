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

from ._affine import (
    CONSTANT_TERM as CONSTANT_TERM,
    AffineDependence as AffineDependence,
    AffineLPV as AffineLPV,
    LPVTrajectory as LPVTrajectory,
    NoiseCovariance as NoiseCovariance,
    StateSpaceMatrices as StateSpaceMatrices,
)
from ._catalog import (
    ExampleEntry as ExampleEntry,
    example_systems as example_systems,
    find_system as find_system,
    models_dir as models_dir,
    stored_design as stored_design,
)
from ._innovation import (
    InnovationLPV as InnovationLPV,
    InnovationTrajectory as InnovationTrajectory,
    LPVInputOutput as LPVInputOutput,
)
from ._ltv import (
    LTVInputOutput as LTVInputOutput,
    LTVSolution as LTVSolution,
    LTVStateSpace as LTVStateSpace,
    LTVTrajectory as LTVTrajectory,
    TimeFunction as TimeFunction,
)
from ._modelfile import (
    MODEL_TYPES as MODEL_TYPES,
    Model as Model,
    ParameterRange as ParameterRange,
    SystemFile as SystemFile,
    dump_system as dump_system,
    load_system as load_system,
    loads_system as loads_system,
    save_system as save_system,
)
from ._polytopic import (
    FormulaSimplexMap as FormulaSimplexMap,
    MultilinearSimplexMap as MultilinearSimplexMap,
    PolytopicLPV as PolytopicLPV,
    PolytopicMatrices as PolytopicMatrices,
    PolytopicTrajectory as PolytopicTrajectory,
    SimplexMap as SimplexMap,
    affine_to_polytopic as affine_to_polytopic,
    hinf_setting as hinf_setting,
)
from ._streaming import (
    DiscretePlant as DiscretePlant,
    LTVPlant as LTVPlant,
    plant_supports as plant_supports,
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
    "DiscretePlant",
    "LTVPlant",
    "plant_supports",
    "SystemFile",
    "ParameterRange",
    "Model",
    "load_system",
    "loads_system",
    "dump_system",
    "save_system",
    "MODEL_TYPES",
    "models_dir",
    "example_systems",
    "find_system",
    "stored_design",
    "ExampleEntry",
]
