"""The exception family (lpvest/core/_errors.py): every deliberate error of a public
function is an LpvestError subclass that is also the built-in a caller
expects, with a short message (issue 12: the places that raised plain
ValueError/TypeError/RuntimeError)."""

from __future__ import annotations

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._errors import (
    ArgumentError,
    ArgumentTypeError,
    InternalError,
    LpvestError,
    OutputError,
    abbreviate,
)
from lpvest.core._validation import as_rng
from lpvest.design import HinfProgram, design_hinf, lmi_matrices, search_epsilon
from lpvest.estimators._hinf import HinfFilter
from lpvest.estimators.kalman import LPVKalmanFilter, kalman_filter


@pytest.fixture(scope="module")
def plant():
    return load_system("peixoto-ex1").model()


def test_the_new_classes_derive_from_the_builtins_callers_expect():
    assert issubclass(ArgumentError, LpvestError) and issubclass(ArgumentError, ValueError)
    assert issubclass(ArgumentTypeError, LpvestError) and issubclass(ArgumentTypeError, TypeError)
    assert issubclass(OutputError, LpvestError) and issubclass(OutputError, OSError)
    assert issubclass(InternalError, LpvestError) and issubclass(InternalError, RuntimeError)


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda p: design_hinf(p, epsilon=1.0, kind="bad"), ArgumentError,
         "^kind must be 'parameter-dependent' or 'robust'; found 'bad'$"),
        (lambda p: design_hinf(p, epsilon=1.0, margin=-1), ArgumentError,
         "^margin must be a positive finite number; found -1$"),
        (lambda p: design_hinf(p, epsilon=1.0, margin=float("nan")), ArgumentError,
         "^margin must be a positive finite number; found nan$"),
        (lambda p: design_hinf(np.eye(2), epsilon=1.0), ArgumentTypeError,
         r"^the plant must be a PolytopicLPV or an AffineLPV \(general noise, converted by lpvest\.hinf_setting\); "
         "found ndarray$"),
        (lambda p: design_hinf(p, epsilon=1.0, kind="robust", program=HinfProgram.for_plant(p)), ArgumentError,
         "^the program is for a parameter-dependent filter, not 'robust'$"),
        (lambda p: search_epsilon(p, n_grid=2), ArgumentError, "^n_grid must be an integer, at least 3; found 2$"),
        (lambda p: HinfProgram.for_plant(p).attempt(p), ArgumentError, "^give exactly one of epsilon and phi$"),
        (lambda p: lmi_matrices(p, {}), ArgumentError, "^give exactly one of epsilon and multiplier_ab$"),
        (lambda p: HinfFilter(object()), ArgumentTypeError, "^design must be an HinfDesign; found object$"),
        (lambda p: LPVKalmanFilter(p), ArgumentTypeError,
         "^the Kalman filter needs an AffineLPV model, not PolytopicLPV$"),
        (lambda p: kalman_filter(load_system("cox-toth-truncation").model(), np.zeros((3, 1)), np.zeros((3, 1)),
                                 np.zeros((3, 2)), method="fast"), ArgumentError,
         "^method must be one of 'auto', 'scan', 'sequential'; found 'fast'$"),
        (lambda p: kalman_filter(load_system("cox-toth-truncation").model(), np.zeros((3, 1)), np.zeros((3, 1)),
                                 np.zeros((3, 2)), method=3), ArgumentTypeError,
         "^method must be a string, one of 'auto', 'scan', 'sequential'; found 3$"),
        (lambda p: as_rng("seed"), ArgumentTypeError, "^rng must be a numpy Generator, an integer seed or None"),
        (lambda p: as_rng(-1), ArgumentError, "^rng: a seed must be a non-negative integer; found -1$"),
    ],
    ids=["kind", "margin", "margin-nan", "plant-type", "program-kind", "n_grid", "epsilon-phi", "epsilon-ab",
         "design-type", "kalman-polytopic", "method-name", "method-type", "rng-type", "rng-negative"],
)
def test_public_api_arguments_raise_typed_errors(plant, call, error, match):
    with pytest.raises(error, match=match) as info:
        call(plant)
    assert type(info.value) is error


def test_a_long_value_is_never_echoed_whole(plant):
    with pytest.raises(ArgumentError, match=r"found 'xxxx.*' \(20,000 characters\)$") as info:
        design_hinf(plant, epsilon=1.0, kind="x" * 20_000)
    assert len(str(info.value)) < 120


@pytest.mark.parametrize(
    ("value", "limit", "shown"),
    [("short", 40, "'short'"), ("x" * 100, 20, "'xxxxxxx...xx' (100 characters)"), (0.5, 40, "0.5"),
     ([1] * 50, 20, "[1, 1, 1, 1, 1, 1..."), ("a\nb", 40, "'a\\nb'"),
     # characters repr shows as escapes count by their width: a name of three such characters
     # (found by test_properties under hypothesis 6.170) was "cut" to all three twice
     ("\U00018cd6\U00018d09\U0001b2fc", 30, "'\\U00018cd6...' (3 characters)"),
     ("\x00" * 40, 30, "'\\x00\\x00\\x00...\\x00' (40 characters)"),
     # a limit below the empty string's quotes: no first character to keep (an IndexError once)
     ("", 1, "'...' (0 characters)")],
)
def test_abbreviate(value, limit, shown):
    assert abbreviate(value, limit) == shown


def test_shorten():
    from lpvest.core._errors import shorten

    assert shorten("a,\n  b") == "a, b"
    assert shorten("x" * 100, 20) == "xxxxxxx...xx (100 characters)"


@pytest.mark.parametrize(
    ("source", "match"),
    [("a\x00b", r"^no example system 'a\\x00b' \(examples: "),
     ("x" * 5000, r"^no example system 'xxx.*' \(5,000 characters\) \(examples: "),
     ("y" * 5000 + ".toml", r"^yyy.*yyy\.toml \(5,005 characters\): no such model file$"),
     (3, r"^expected a model file or an example name, found int$")],
    ids=["nul", "long name", "long path", "int"],
)
def test_load_system_of_a_name_the_system_cannot_look_up(source, match):
    # a NUL character raised ValueError and a 5000-character name OSError from Path.exists()
    from lpvest.core._errors import ModelFileError

    with pytest.raises(ModelFileError, match=match):
        load_system(source)
