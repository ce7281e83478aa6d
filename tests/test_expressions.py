import warnings

import numpy as np
import pytest

from lpvest import Expression, ExpressionError, FormulaMatrix
from lpvest.core._expressions import shift_name
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
    with pytest.raises(ExpressionError, match=r"^A must be a list of rows, e.g. \[\[1, 0\], \[0, 'p'\]\]$"):
        FormulaMatrix.parse(["p", "q"], name="A")  # a list of formulas is not a list of rows
    # the derivative of a matrix is the matrix of the entries' derivatives
    d = FormulaMatrix.parse([["p^2", "3*p"], [1, "q*p"]]).derivative("p")
    np.testing.assert_array_equal(d.evaluate({"p": 2.0, "q": 5.0}), [[4.0, 3.0], [0.0, 5.0]])


def test_a_long_constant_that_is_not_a_number_is_shown_cut():
    with pytest.raises(ExpressionError, match=r"constant 'aaaaaaaaaa\.\.\.aaa' \(60 characters\) is not a number$"):
        Expression.parse("'" + "a" * 60 + "'")


# -- floating point, bounded size and depth (issue 12) ---------------------------------------


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("9**9**9", r"^formula '9\*\*9\*\*9' overflows"),  # was: a Python integer computation that never ended
        ("t + 9**9**9", r"^formula 't \+ 9\*\*9\*\*9' overflows"),
        ("10**400", r"^formula '10\*\*400' overflows"),
        ("1e308*10", r"^formula '1e308\*10' overflows"),
        ("exp(1000)", r"^formula 'exp\(1000\)' overflows"),
        ("1/0", r"^formula '1/0' divides by zero"),
        ("t/(1 - 1)", r"^formula 't/\(1 - 1\)' divides by zero"),
        ("0**-1", r"^formula '0\*\*-1' divides by zero"),
        ("log(0)", r"^formula 'log\(0\)' takes the log of zero"),
        ("sqrt(-1)", r"^formula 'sqrt\(-1\)' is undefined"),
        ("(-8)**(1/3)", r"^formula '\(-8\)\*\*\(1/3\)' is not a real number"),
        ("1e999", r"^formula '1e999': the number inf is not finite"),
        ("1" * 400, r"^formula '1111.*' \(400 characters\): the number 1111.* is not finite"),
        ("shift(p, 100000)", r"^formula 'shift\(p, 100000\)': shift by 100000 samples: at most 1000"),
    ],
)
def test_constant_arithmetic_is_checked_in_floating_point(text, match):
    with pytest.raises(ExpressionError, match=match):
        Expression.parse(text)


@pytest.mark.parametrize(
    "text",
    ["1" + "+1" * 100_000,  # 100k terms: was RecursionError
     "(" * 100_000 + "1" + ")" * 100_000,
     "-" * 100_000 + "1",  # 100k deep: was MemoryError
     "sin(" * 60_000 + "t" + ")" * 60_000],
)
def test_huge_formulas_are_refused_by_length(text):
    with pytest.raises(ExpressionError, match=r"is too long: at most 2,000 characters$") as info:
        Expression.parse(text)
    assert len(str(info.value)) < 120  # abbreviated, never echoed whole


@pytest.mark.parametrize(
    "text",
    ["1" + "+t" * 150, "-" * 150 + "t", "sin(" * 150 + "t" + ")" * 150],
)
def test_deep_formulas_are_refused_by_depth(text):
    with pytest.raises(ExpressionError, match=r"nested deeper than 100 levels$"):
        Expression.parse(text)


def test_parentheses_are_no_depth_up_to_the_parsers_limit():
    assert Expression.parse("(" * 150 + "t" + ")" * 150).source == "t"
    with pytest.raises(ExpressionError, match="is not valid: too many nested parentheses$"):
        Expression.parse("(" * 250 + "t" + ")" * 250)


def test_a_formula_at_the_limits_parses_differentiates_and_evaluates():
    text = "+".join(["t"] * 99)  # depth 99
    f = Expression.parse(text)
    assert float(f(t=2.0)) == 198.0
    assert float(f.derivative("t")(t=2.0)) == 99.0


def test_null_bytes_and_non_finite_numbers_are_typed_errors():
    with pytest.raises(ExpressionError, match=r"^formula 't\\x00' is not valid"):
        Expression.parse("t\x00")
    with pytest.raises(ExpressionError, match="^formula value nan is not a finite number"):
        Expression.parse(float("nan"))
    with pytest.raises(ExpressionError, match=r"^formula value 1000.* is not a finite number"):
        Expression.parse(10**400)
    with pytest.raises(ExpressionError, match="^formula 'rho': parameter 'rho' is not finite"):
        Expression.parse("rho", parameters={"rho": float("inf")})


def test_evaluation_follows_ieee_arithmetic_for_python_and_numpy_numbers():
    f = Expression.parse("1/t + t**0.5")
    assert f(t=0.0) == np.inf  # Python floats raise ZeroDivisionError; the formula gives inf as numpy does
    assert np.isnan(f(t=-1.0))  # Python gives a complex number; the formula nan
    np.testing.assert_array_equal(f(t=np.array([0.0, -1.0, 4.0])), [np.inf, np.nan, 2.25])
    assert Expression.parse("2**t")(t=2000.0) == np.inf


@pytest.mark.parametrize("text", ["10**t**t", "t**p", "(1 + t)**-2.5", "2**t - exp(p)**0.3"])
def test_one_sample_is_the_same_sample_of_an_array_evaluation_bit_for_bit(text):
    # the per-sample path (Python floats: FMUs, streaming) and the array path
    # (simulations) share numpy's power; Python's own ** (libm pow) differs from
    # numpy's SIMD pow in the last bit on AVX-512 machines at t = 0.5 in 10**t**t
    f = Expression.parse(text)
    t = np.linspace(0.05, 3.0, 60)
    p = np.linspace(-1.0, 1.0, 60)
    arrays = np.asarray(f(t=t, p=p), dtype=float)
    samples = np.array([f(t=float(a), p=float(b)) for a, b in zip(t, p, strict=True)])
    np.testing.assert_array_equal(samples, np.broadcast_to(arrays, t.shape))
    assert f(t=0.5, p=0.0) == np.asarray(f(t=np.array([0.5]), p=np.array([0.0])), dtype=float)[0]


def test_shifted_names_are_shown_as_written():
    with pytest.raises(ExpressionError, match=r"must be a constant here but uses the variable shift\(p, 1\)$"):
        Expression.parse("shift(p, 1)").value()


def test_source_shows_whole_numbers_as_integers():
    assert Expression.parse("t^2 + 2*t - (1 + 2)").source == "t ** 2 + 2 * t - 3"


@pytest.mark.parametrize("text", ["(-1.0)**(t)", "(-rho)**(p**538.0)", "(-2)**2", "-(2**t)", "(-0.0)*t"])
def test_source_reads_back_as_the_same_formula(text):
    # found by tests/test_properties.py: ast.unparse wrote the folded constant -1.0
    # as "-1.0 ** t", which reads back as -(1.0 ** t)
    f = Expression.parse(text, parameters={"rho": 2.0})
    again = Expression.parse(f.source)
    t = np.array([-1.0, 0.0, 0.5, 2.0])
    np.testing.assert_array_equal(again(t=t, p=t), f(t=t, p=t))


def test_derivative_of_a_division_by_a_huge_constant():
    # found by tests/test_properties.py: d(t/1e308) was (1e308 - 0)/1e308**2, whose
    # constant 1e308**2 raised OverflowError from the evaluation
    d = Expression.parse("t/1e308").derivative("t")
    assert d(t=1.0) == 1e-308
    assert Expression.parse("t*1e300*1e10").derivative("t")(t=0.5) == np.inf  # IEEE: the constant overflows


def test_a_malformed_number_is_an_error_without_a_python_warning(recwarn):
    # found by tests/test_properties.py: ast.parse warned "invalid decimal literal" before the error
    with pytest.raises(ExpressionError, match=r"^formula '1or p': BoolOp is not allowed in a formula$"):
        Expression.parse("1or p")
    with pytest.raises(ExpressionError, match=r"^formula '0x1for' is not valid: invalid syntax$"):
        Expression.parse("0x1for")
    assert not [w for w in recwarn if issubclass(w.category, SyntaxWarning)]


def test_value_of_a_constant_formula_is_finite_or_an_error():
    # a derivative folds its constants without the parser's overflow check
    d = Expression.parse("x * 1e200 * 1e200").derivative("x")
    with pytest.raises(ExpressionError, match="has the value inf, not a finite number"):
        d.value()
    assert Expression.parse("x * 1e100 * 1e100").derivative("x").value() == pytest.approx(1e200)


@pytest.mark.parametrize("caller", ["raise", "warn", "ignore", "call"])
def test_evaluation_neither_depends_on_nor_changes_the_callers_floating_point_error_state(caller):
    """Formulas give IEEE results (inf, nan) with no warning whatever numpy's error state in the
    caller (an FMU sets "call", a user may set "raise"), and leave that state as it was; a
    constant that is not finite is an error at parsing whatever that state."""
    seen = []
    f = Expression.parse("1/t + log(t) + exp(t)*exp(t) + sqrt(t - 5)")
    with np.errstate(all=caller, call=lambda kind, flag: seen.append(kind)), warnings.catch_warnings():
        warnings.simplefilter("error")
        before = np.geterr()
        assert np.isnan(f(t=0.0)) and np.isnan(f(t=np.array([0.0]))[0])  # inf - inf (1/0 + log 0)
        assert f(t=710.0) == np.inf  # exp overflows; Python floats and numpy alike
        np.testing.assert_array_equal(f(t=np.array([710.0, 1.0])), [np.inf, np.nan])
        assert Expression.parse("t**0.5")(t=-1.0) != Expression.parse("t**0.5")(t=-1.0)  # nan, not complex
        assert Expression.parse("t/2")(t=3.0) == 1.5 and Expression.parse("t*t")(t=1e200) == np.inf
        d = Expression.parse("1e300*(1e300*t)").derivative("t")  # folds 1e300 * 1e300 = inf
        with pytest.raises(ExpressionError, match=r"^formula 'd/dt\(1e300\*\(1e300\*t\)\)' has the value inf"):
            d.value()
        for text, why in (("1e308*10", "overflows"), ("1/0", "divides by zero"), ("log(0)", "takes the log of zero"),
                          ("sqrt(-1)", "is undefined"), ("(-8)**(1/3)", "is not a real number")):
            with pytest.raises(ExpressionError, match=why):
                Expression.parse(text)
        assert np.geterr() == before
    assert seen == []  # no floating-point callback reached the caller


def test_a_failed_evaluation_path_is_retried_in_ieee_arithmetic():
    """Python floats raise where IEEE arithmetic gives inf; the one-sample path retries in numpy."""
    f = Expression.parse("t / u - 2**u")
    assert f(t=1.0, u=0.0) == np.inf and f(t=-1.0, u=0.0) == -np.inf
    assert f(t=1.0, u=2000.0) == -np.inf  # 2**2000 overflows: OverflowError in Python
    plain = Expression.parse("t / u - u*u")  # no numpy call: one sample of Python floats stays Python
    assert plain(t=1.0, u=2.0) == -3.5 and type(plain(t=1.0, u=2.0)) is float
    assert plain(t=1.0, u=0.0) == np.inf and plain(t=1.0, u=1e200) == -np.inf
    assert type(plain(t=1.0, u=np.float64(2.0))) is not float  # a numpy value takes the general path
    assert np.isnan(Expression.parse("u**t")(t=0.5, u=-4.0))
    assert Expression.parse("u**t")(t=0.5, u=complex(-4.0, 0.0)) == pytest.approx(2j)  # complex in: complex out


@pytest.mark.parametrize(("text", "var", "source"), [
    ("t*t", "t", "t + t"), ("sin(t)*p", "p", "sin(t)"), ("0*t + p*t", "t", "p"), ("t**3", "t", "3 * t ** 2"),
    ("exp(2*t)", "t", "exp(2 * t) * 2"), ("p/t", "t", "-p / t ** 2"), ("log(t)", "t", "1 / t"),
    ("sqrt(t)", "t", "0.5 / sqrt(t)"), ("t - p", "p", "-1"), ("p + 3", "t", "0"),
])
def test_derivatives_are_written_with_zeros_and_ones_folded(text, var, source):
    """The derivative's text (what a kernel model shows) has no 0 + x, 1 * x or constant operations."""
    d = Expression.parse(text).derivative(var)
    assert d.source == source and d.text == f"d/d{var}({text})"


def test_constants_and_shift_names():
    c = Expression.constant(2.5)
    assert c.is_constant and c.value() == 2.5 and c.source == "2.5"
    with pytest.raises(ExpressionError, match=r"^formula 'shift\(__x, 1\)': shift takes a variable and an integer, "
                                              r"e\.g\. shift\(p, 1\)$"):
        Expression.parse("shift(__x, 1)")


@pytest.mark.parametrize(("formula", "shown"), [("sin(p) + t**2", "2 * t"), ("t**2 + sin(p)", "2 * t"),
                                                ("sin(p) - t**2", "-(2 * t)"), ("t**2 - sin(p)", "2 * t")])
def test_a_derivative_drops_the_terms_that_do_not_depend_on_the_variable(formula, shown):
    d = Expression.parse(formula, allowed=["t", "p"]).derivative("t")
    assert d.source == shown
    assert d.evaluate({"t": 1.5, "p": 0.3}) == (-1 if formula.startswith("sin(p) -") else 1) * 3.0


def test_messages_about_names_and_numbers_abbreviate_what_is_long():
    with pytest.raises(ExpressionError) as info:
        Expression.parse("a_very_long_unknown_name_of_thirty_c", allowed=["t", "p"])
    assert str(info.value) == ("formula 'a_very_long_unknown_name_of_thirty_c' uses unknown name 'a_very_lon...y_c' "
                               "(36 characters) (known: p, t)")  # the name cut to about 24 characters
    known = [f"name_{i:02d}_long" for i in range(10)]
    with pytest.raises(ExpressionError) as info:
        Expression.parse("q", allowed=["t", "p", *known])
    assert str(info.value) == ("formula 'q' uses unknown name 'q' (known: name_00_long, name_01_long, name_02_l..."
                               "9_long, p, t (144 characters))")  # the known names cut to about 60 characters
    with pytest.raises(ExpressionError) as info:
        Expression.parse("1e999")
    assert str(info.value) == "formula '1e999': the number inf is not finite in floating point (largest about 1.8e308)"
