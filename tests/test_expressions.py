import numpy as np
import pytest

from lpvest import Expression, ExpressionError, FormulaMatrix
from lpvest.expressions import shift_name
from tests.tolerances import roundoff


def test_evaluates_on_arrays_and_reads_caret_as_power():
    f = Expression.parse("theta^2 + 2*theta - 1")
    x = np.linspace(-1, 1, 7)
    np.testing.assert_allclose(f(theta=x), x**2 + 2 * x - 1, rtol=0, atol=roundoff(4.0, 2))  # 3 terms <= 2


def test_parameters_are_substituted_and_constants_known():
    f = Expression.parse("-0.05*rho + pi", parameters={"rho": 4.0})
    assert f.is_constant
    assert f.value() == pytest.approx(-0.2 + np.pi, abs=roundoff(np.pi, 1))  # a product and a sum


@pytest.mark.parametrize(
    "text",
    ["t**2 + 1", "-1/(t + 1000)", "120*sin(t)", "exp(-t)*cos(3*t)", "sqrt(t + 2)*log(t + 3)",
     "tanh(t)/(1 + t**2)", "arctan(t)*sinh(t) - cosh(t)", "t**t", "tan(t/3)"],
)
def test_symbolic_derivative_matches_complex_step(text):
    # oracle: complex-step derivative of the same formula, exact to round-off
    f = Expression.parse(text)
    t = np.linspace(0.3, 2.7, 11)
    h = 1e-30
    expected = np.imag(f(t=t + 1j * h)) / h
    # complex step: exact to the rounding of the complex evaluation; the
    # symbolic derivative: up to ~10 operations on terms of size <= 10 |f'| + 1
    # (the formulas above on [0.3, 2.7]; sums of such terms may cancel)
    size = 10.0 * float(np.max(np.abs(expected))) + 1.0
    np.testing.assert_allclose(f.derivative("t")(t=t), expected, rtol=0, atol=roundoff(1.0, 10) * size)


def test_shift_is_tracked_and_evaluated():
    f = Expression.parse("(1 - shift(p, 1)) / shift(p, 1) + shift(p, -2)")
    assert f.shifts == {"p": {1, -2}}
    val = f.evaluate({shift_name("p", 1): 0.5, shift_name("p", -2): 3.0})
    assert val == pytest.approx(4.0, abs=roundoff(4.0, 3))  # (1 - 0.5) / 0.5 + 3: a few roundings at most


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("__import__('os')", "unknown function '__import__'"),
        ("__class__", "name '__class__' is not allowed"),
        ("t.real", "Attribute is not allowed"),
        ("(lambda: 1)()", "only calls like sin"),
        ("t if t else 1", "IfExp is not allowed"),
        ("open('x')", "unknown function 'open'"),
        ("sin(t, t)", "sin takes one argument"),
        ("t +", "is not valid"),
        ("'text'", "is not a number"),
        ("t % 2", "operator Mod is not allowed"),
        ("shift(p, 0.5)", "shift takes a variable and an integer"),
        ("sin", "used without arguments"),
    ],
)
def test_unsafe_or_malformed_formulas_are_rejected(text, match):
    with pytest.raises(ExpressionError, match=match):
        Expression.parse(text)


def test_unknown_names_are_rejected_when_names_are_declared():
    with pytest.raises(ExpressionError, match="unknown name 'q' \\(known: p\\)"):
        Expression.parse("p + q", allowed=["p"])


def test_missing_value_is_named():
    with pytest.raises(ExpressionError, match="needs a value for 'shift\\(p, 1\\)'"):
        Expression.parse("shift(p, 1)").evaluate({})


def test_monomial_detection():
    names = ("p1", "p2")
    assert Expression.parse("p1*p2^2").monomial_exponents(names) == (1, 2)
    assert Expression.parse("p1*p1").monomial_exponents(names) == (2, 0)
    assert Expression.parse("2*p1").monomial_exponents(names) is None
    assert Expression.parse("sin(p1)").monomial_exponents(names) is None


def test_formula_matrix_shapes_and_errors():
    m = FormulaMatrix.parse([[0, 1], ["-(t**2 + 1)", -1]], name="A", allowed=["t"])
    np.testing.assert_array_equal(m.evaluate({"t": 2.0}), [[0, 1], [-5, -1]])
    stacked = m.evaluate({"t": np.array([0.0, 1.0, 2.0])})
    assert stacked.shape == (3, 2, 2)
    with pytest.raises(ExpressionError, match="A has rows of lengths \\[2, 1\\]"):
        FormulaMatrix.parse([[0, 1], [2]], name="A")
    with pytest.raises(ExpressionError, match="A\\[2,1\\]: formula 'x' uses unknown name 'x'"):
        FormulaMatrix.parse([[0, 1], ["x", 1]], name="A", allowed=["t"])
