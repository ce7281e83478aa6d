"""lpvest: estimation for LPV and LTV systems, as Python and as FMI 2.0 FMUs.

The numerics import only numpy at import time (scipy, cvxpy, matplotlib and
fmpy are imported inside the functions that need them), so the FMUs that
carry this package run where only numpy is installed.

>>> import lpvest
>>> plant = lpvest.load_system("peixoto-ex1").model()
>>> plant.n_vertices
2
"""

__version__ = "0.1.0"

from .catalog import example_systems as example_systems
from .errors import (
    DimensionError as DimensionError,
)
from .errors import (
    ExpressionError as ExpressionError,
)
from .errors import (
    IdentifiabilityError as IdentifiabilityError,
)
from .errors import (
    LMIInfeasibleError as LMIInfeasibleError,
)
from .errors import (
    LpvestError as LpvestError,
)
from .errors import (
    ModelFileError as ModelFileError,
)
from .errors import (
    NonFiniteError as NonFiniteError,
)
from .errors import (
    NotPositiveDefiniteError as NotPositiveDefiniteError,
)
from .errors import (
    NumericalError as NumericalError,
)
from .errors import (
    SchedulingRangeError as SchedulingRangeError,
)
from .expressions import Expression as Expression
from .expressions import FormulaMatrix as FormulaMatrix
from .modelfile import (
    SystemFile as SystemFile,
)
from .modelfile import (
    dump_system as dump_system,
)
from .modelfile import (
    load_system as load_system,
)
from .modelfile import (
    loads_system as loads_system,
)
from .modelfile import (
    save_system as save_system,
)
from .scheduling import (
    CallableBasis as CallableBasis,
)
from .scheduling import (
    FormulaBasis as FormulaBasis,
)
from .scheduling import (
    Monomial as Monomial,
)
from .scheduling import (
    SchedulingSpace as SchedulingSpace,
)
from .systems import (
    AffineDependence as AffineDependence,
)
from .systems import (
    AffineLPV as AffineLPV,
)
from .systems import (
    FormulaSimplexMap as FormulaSimplexMap,
)
from .systems import (
    InnovationLPV as InnovationLPV,
)
from .systems import (
    LPVInputOutput as LPVInputOutput,
)
from .systems import (
    LTVInputOutput as LTVInputOutput,
)
from .systems import (
    LTVStateSpace as LTVStateSpace,
)
from .systems import (
    MultilinearSimplexMap as MultilinearSimplexMap,
)
from .systems import (
    NoiseCovariance as NoiseCovariance,
)
from .systems import (
    PolytopicLPV as PolytopicLPV,
)
from .systems import (
    TimeFunction as TimeFunction,
)
from .systems import (
    affine_to_polytopic as affine_to_polytopic,
)

__all__ = [
    "__version__",
    "example_systems",
    "DimensionError",
    "ExpressionError",
    "IdentifiabilityError",
    "LMIInfeasibleError",
    "LpvestError",
    "ModelFileError",
    "NonFiniteError",
    "NotPositiveDefiniteError",
    "NumericalError",
    "SchedulingRangeError",
    "Expression",
    "FormulaMatrix",
    "SystemFile",
    "dump_system",
    "load_system",
    "loads_system",
    "save_system",
    "CallableBasis",
    "FormulaBasis",
    "Monomial",
    "SchedulingSpace",
    "AffineDependence",
    "AffineLPV",
    "FormulaSimplexMap",
    "InnovationLPV",
    "LPVInputOutput",
    "LTVInputOutput",
    "LTVStateSpace",
    "MultilinearSimplexMap",
    "NoiseCovariance",
    "PolytopicLPV",
    "TimeFunction",
    "affine_to_polytopic",
]
