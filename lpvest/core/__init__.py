"""The foundation every other package builds on: errors, validation, small
linear algebra, the one TOML reader, the random generator, the streaming
protocol, formulas, scheduling spaces, signals, interruption handling,
progress bars and figure output.

Layer 0 of :doc:`the architecture <../docs/architecture>`: nothing here
imports another lpvest package. Everything imports only numpy and the
standard library at import time, so the FMUs that carry these modules run
where only numpy is installed. The implementation modules are private
(``_errors.py``, ``_protocol.py``, ...); this ``__init__`` is the contract.
Library code imports a name from the module that defines it (an FMU then
carries only the modules it uses); users import from here or from
:mod:`lpvest`.

Examples
--------
>>> import numpy as np
>>> from lpvest.core import SignalSpec, sample_signal
>>> spec = SignalSpec.build("sinusoid", 1, amplitude=2.0, omega=0.5)
>>> sample_signal(spec, np.arange(3.0)).round(3).ravel().tolist()
[0.0, 0.959, 1.683]
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import LOAD_EXPORTS, lazy_exports

# the public names: seen by type checkers; run on first use (core/_lazy.py)
if TYPE_CHECKING or globals().get(LOAD_EXPORTS, False):
    # the exception family: every deliberate error derives from LpvestError; message helpers
    # isort: split
    from ._errors import (
        MESSAGE_LIMIT as MESSAGE_LIMIT,
        ArgumentError as ArgumentError,
        ArgumentTypeError as ArgumentTypeError,
        DimensionError as DimensionError,
        ExpressionError as ExpressionError,
        IdentifiabilityError as IdentifiabilityError,
        InternalError as InternalError,
        LMIInfeasibleError as LMIInfeasibleError,
        LpvestError as LpvestError,
        ModelFileError as ModelFileError,
        NonFiniteError as NonFiniteError,
        NotPositiveDefiniteError as NotPositiveDefiniteError,
        NumericalError as NumericalError,
        OutputError as OutputError,
        SamplingError as SamplingError,
        SchedulingRangeError as SchedulingRangeError,
        abbreviate as abbreviate,
        one_line as one_line,
        shorten as shorten,
    )

    # SIGINT/SIGTERM handling: interruptible regions, holds, exit statuses
    # isort: split
    from ._interrupt import (
        Interrupted as Interrupted,
        abandoned_calls as abandoned_calls,
        call_interruptibly as call_interruptibly,
        exit_status as exit_status,
        handling_signals as handling_signals,
        hold as hold,
        holds as holds,
        interruptible as interruptible,
        raise_if_pending as raise_if_pending,
    )

    # small dense helpers: matrix stacks evaluated at weights, batched transposes
    # isort: split
    from ._linalg import (
        MatrixStack as MatrixStack,
        mT as mT,
        sym as sym,
    )

    # the one validation module of every public entry point
    # isort: split
    from ._validation import (
        SIMPLEX_ATOL as SIMPLEX_ATOL,
        SYMMETRY_RTOL as SYMMETRY_RTOL,
        as_float_array as as_float_array,
        as_matrix as as_matrix,
        as_rng as as_rng,
        as_signal as as_signal,
        as_vector as as_vector,
        check_box as check_box,
        check_finite as check_finite,
        check_positive_definite as check_positive_definite,
        check_simplex as check_simplex,
        check_symmetric as check_symmetric,
    )

    # the TOML reader of model, co-simulation and sweep files
    # isort: split
    from ._toml import (
        describe_value as describe_value,
        parse_toml as parse_toml,
        read_toml as read_toml,
    )

    # the random generator both backends implement bit for bit
    # isort: split
    from ._rng import (
        Stream as Stream,
        as_stream as as_stream,
        log as log,
        lower_times as lower_times,
        normal_quantile as normal_quantile,
        normals_from_raw as normals_from_raw,
        psd_cholesky as psd_cholesky,
        uniforms_from_raw as uniforms_from_raw,
    )

    # the streaming protocol: ports, sampled and timed components
    # isort: split
    from ._protocol import (
        Component as Component,
        MeasurementDelay as MeasurementDelay,
        Port as Port,
        Sampled as Sampled,
        Timed as Timed,
        TimedComponent as TimedComponent,
        input_key as input_key,
        run_streaming as run_streaming,
        whole_samples as whole_samples,
    )

    # formulas in model files: parsed, checked, evaluated, differentiated
    # isort: split
    from ._expressions import (
        CONSTANTS as CONSTANTS,
        FUNCTIONS as FUNCTIONS,
        MAX_DERIVATIVE_SIZE as MAX_DERIVATIVE_SIZE,
        MAX_FORMULA_DEPTH as MAX_FORMULA_DEPTH,
        MAX_FORMULA_LENGTH as MAX_FORMULA_LENGTH,
        Expression as Expression,
        FormulaMatrix as FormulaMatrix,
        FormulaVector as FormulaVector,
        shift_name as shift_name,
    )

    # scheduling spaces and basis functions
    # isort: split
    from ._scheduling import (
        BasisFunction as BasisFunction,
        CallableBasis as CallableBasis,
        FormulaBasis as FormulaBasis,
        Monomial as Monomial,
        SchedulingSpace as SchedulingSpace,
        box_vertices as box_vertices,
        parse_basis as parse_basis,
    )

    # signal generators: the scheduler and source components
    # isort: split
    from ._signals import (
        SIGNAL_KINDS as SIGNAL_KINDS,
        SchedulerComponent as SchedulerComponent,
        SignalError as SignalError,
        SignalGenerator as SignalGenerator,
        SignalSpec as SignalSpec,
        SourceComponent as SourceComponent,
        parse_table as parse_table,
        sample_signal as sample_signal,
    )

    # how every lpvest figure is finished (matplotlib imported inside)
    # isort: split
    from ._plotting import (
        save_figure as save_figure,
    )
else:
    __getattr__, __dir__ = lazy_exports(__name__)


__all__ = [
    "LpvestError",
    "DimensionError",
    "NonFiniteError",
    "NotPositiveDefiniteError",
    "SchedulingRangeError",
    "ExpressionError",
    "ModelFileError",
    "IdentifiabilityError",
    "NumericalError",
    "LMIInfeasibleError",
    "SamplingError",
    "ArgumentError",
    "ArgumentTypeError",
    "OutputError",
    "InternalError",
    "abbreviate",
    "shorten",
    "one_line",
    "MESSAGE_LIMIT",
    "Interrupted",
    "handling_signals",
    "raise_if_pending",
    "call_interruptibly",
    "hold",
    "holds",
    "interruptible",
    "exit_status",
    "abandoned_calls",
    "MatrixStack",
    "mT",
    "sym",
    "as_float_array",
    "as_matrix",
    "as_vector",
    "as_signal",
    "as_rng",
    "check_finite",
    "check_symmetric",
    "check_positive_definite",
    "check_box",
    "check_simplex",
    "SYMMETRY_RTOL",
    "SIMPLEX_ATOL",
    "parse_toml",
    "read_toml",
    "describe_value",
    "Stream",
    "as_stream",
    "normal_quantile",
    "log",
    "normals_from_raw",
    "uniforms_from_raw",
    "psd_cholesky",
    "lower_times",
    "Port",
    "Sampled",
    "Timed",
    "Component",
    "TimedComponent",
    "MeasurementDelay",
    "whole_samples",
    "input_key",
    "run_streaming",
    "Expression",
    "FormulaMatrix",
    "FormulaVector",
    "FUNCTIONS",
    "CONSTANTS",
    "shift_name",
    "MAX_FORMULA_LENGTH",
    "MAX_FORMULA_DEPTH",
    "MAX_DERIVATIVE_SIZE",
    "SchedulingSpace",
    "BasisFunction",
    "Monomial",
    "FormulaBasis",
    "CallableBasis",
    "parse_basis",
    "box_vertices",
    "SIGNAL_KINDS",
    "SignalSpec",
    "SignalGenerator",
    "SchedulerComponent",
    "SourceComponent",
    "SignalError",
    "sample_signal",
    "parse_table",
    "save_figure",
]
