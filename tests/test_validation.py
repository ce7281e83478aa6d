import numpy as np
import pytest

from lpvest import (
    DimensionError,
    NonFiniteError,
    NotPositiveDefiniteError,
    SchedulingRangeError,
)
from lpvest.core._validation import (
    as_matrix,
    as_rng,
    as_signal,
    check_positive_definite,
    check_simplex,
)


def test_shape_error_names_parameter_and_both_shapes():
    with pytest.raises(DimensionError, match=r"^Q has shape \(3, 2\); expected \(3, 3\)$"):
        as_matrix(np.zeros((3, 2)), "Q", (3, 3))


def test_signal_shape_error():
    with pytest.raises(DimensionError, match=r"^u has shape \(10, 3\); expected \(10, 2\)$"):
        as_signal(np.zeros((10, 3)), "u", 2, 10)


def test_non_finite_is_named_with_index():
    m = np.eye(2)
    m[1, 0] = np.nan
    with pytest.raises(NonFiniteError, match=r"^R holds a non-finite value \(nan\) at index \(1, 0\)$"):
        as_matrix(m, "R")


@pytest.mark.parametrize("scale", [1e-12, 1.0, 1e12])
def test_definiteness_is_relative_to_scale(scale, rng):
    # a well-conditioned SPD matrix at any scale is accepted (an absolute epsilon
    # would reject the small one and accept a rounding-level negative large one)
    a = rng.standard_normal((4, 4))
    m = scale * (a @ a.T + 4 * np.eye(4))
    check_positive_definite(m, "Q")


def test_tiny_asymmetry_from_rounding_is_accepted_but_real_asymmetry_is_not(rng):
    a = rng.standard_normal((3, 3))
    m = a @ a.T + np.eye(3)
    m_round = m.copy()
    m_round[0, 1] += 1e-14 * np.abs(m).max()
    check_positive_definite(m_round, "Q")
    m_bad = m.copy()
    m_bad[0, 1] += 1e-3 * np.abs(m).max()
    with pytest.raises(NotPositiveDefiniteError, match="^Q is not symmetric"):
        check_positive_definite(m_bad, "Q")


def test_singular_and_indefinite_are_rejected():
    with pytest.raises(NotPositiveDefiniteError, match="^S is not positive definite: smallest eigenvalue"):
        check_positive_definite(np.array([[1.0, 1.0], [1.0, 1.0]]), "S")
    with pytest.raises(NotPositiveDefiniteError, match="^P is not positive semidefinite"):
        check_positive_definite(np.diag([1.0, -0.1]), "P", semidefinite=True)
    check_positive_definite(np.diag([1.0, 0.0]), "P", semidefinite=True)


def test_simplex_check():
    check_simplex(np.array([0.25, 0.75]))
    with pytest.raises(SchedulingRangeError, match=r"alpha\[2\] = -0.1 < 0"):
        check_simplex(np.array([1.1, -0.1]))
    with pytest.raises(SchedulingRangeError, match="sum to 0.9, not 1"):
        check_simplex(np.array([0.5, 0.4]))


def test_as_rng():
    g = np.random.default_rng(1)
    assert as_rng(g) is g
    assert as_rng(5).standard_normal() == np.random.default_rng(5).standard_normal()
    with pytest.raises(TypeError, match="rng must be"):
        as_rng("seed")


def test_a_value_just_outside_the_box_is_printed_with_the_digits_that_show_it():
    # issue 12: 1 + 1e-7 was printed as "p = 1 is outside its declared range [-1, 1]"
    from lpvest import SchedulingRangeError
    from lpvest.core._validation import check_box

    with pytest.raises(SchedulingRangeError, match=r"^scheduling value p = 1\.0000001 is outside its declared "
                                                   r"range \[-1, 1\]$"):
        check_box(np.array([1.0 + 1e-7]), np.array([-1.0]), np.array([1.0]), ["p"])


@pytest.mark.parametrize(("entry", "match"), [(-1e308, "Q is not positive definite: smallest eigenvalue -1e\\+308"),
                                              (1e308, None)])
def test_definiteness_of_matrices_near_the_float_range(entry, match):
    # issue 12: an entry of -1e308 raised LinAlgError (Q + Q^T overflowed to inf before eigvalsh)
    from lpvest import NotPositiveDefiniteError
    from lpvest.core._validation import check_positive_definite

    q = np.array([[entry, 0.0], [0.0, 1.0 if match else 0.5e308]])
    if match is None:
        np.testing.assert_array_equal(check_positive_definite(q, "Q"), q)
    else:
        with pytest.raises(NotPositiveDefiniteError, match=match):
            check_positive_definite(q, "Q")
