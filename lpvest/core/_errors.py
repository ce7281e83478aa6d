"""The exception family of lpvest.

Every error lpvest raises on purpose derives from :class:`LpvestError` and from
the built-in exception a caller would expect (``ValueError`` for bad input,
``ArithmeticError`` for a numerical failure, ``RuntimeError`` for a failed
solver), so ``except ValueError`` keeps working for code that does not know
about lpvest.
"""

from __future__ import annotations

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
]

#: The longest message an input error should have (characters): one line a
#: terminal shows whole. Values quoted in a message are shortened by
#: :func:`abbreviate` so that a 20,000-character formula is never echoed whole.
MESSAGE_LIMIT = 300



class LpvestError(Exception):
    """Base class of every error raised by lpvest on purpose."""


class DimensionError(LpvestError, ValueError):
    """An array has the wrong shape, e.g. ``"Q has shape (3, 2); expected (3, 3)"``."""


class NonFiniteError(LpvestError, ValueError):
    """An input holds NaN or inf."""


class NotPositiveDefiniteError(LpvestError, ValueError):
    """A matrix that must be symmetric positive (semi)definite is not."""


class SchedulingRangeError(LpvestError, ValueError):
    """A scheduling value lies outside the declared range (box or simplex)."""


class ExpressionError(LpvestError, ValueError):
    """A formula in a model (basis function, coefficient, map) is not valid."""


class ModelFileError(LpvestError, ValueError):
    """A model file cannot be read; the message names the file and the field."""


class IdentifiabilityError(LpvestError, ValueError):
    """The data do not determine the unknowns (rank deficiency)."""


class NumericalError(LpvestError, ArithmeticError):
    """A numerical operation failed, e.g. a singular innovation covariance."""


class LMIInfeasibleError(LpvestError, RuntimeError):
    """An LMI problem is infeasible or the solver's answer fails the check.

    Parameters
    ----------
    message : str
        The error message.
    status : str, default ""
        The solver status string, kept as :attr:`status`.
    detail : str, default ""
        The record of every solve tried, kept as :attr:`detail`.

    Attributes
    ----------
    status : str
        The solver status string (``problem.status`` in cvxpy).
    detail : str
        Every solve tried and why it was rejected (the message shows its start).
    """

    def __init__(self, message: str, *, status: str = "", detail: str = "") -> None:
        super().__init__(message)
        self.status = status
        self.detail = detail


class SamplingError(LpvestError, ValueError):
    """Sample times are not strictly increasing or not uniformly spaced where a
    method needs a uniform grid (e.g. the B-spline kernel estimator)."""


class ArgumentError(LpvestError, ValueError):
    """An argument's value is outside what the function accepts, e.g.
    ``design_hinf(plant, kind="bad")`` or ``margin=-1``."""


class ArgumentTypeError(LpvestError, TypeError):
    """An argument has the wrong type, e.g. a polytopic model given to the
    Kalman filter, which needs an affine one."""


class InternalError(LpvestError, RuntimeError):
    """A check of lpvest's own consistency failed: a bug in lpvest (please
    report it), not a problem with the input."""


class OutputError(LpvestError, OSError):
    """An output file or folder cannot be written (the message names it)."""


def abbreviate(value: object, limit: int = 40) -> str:
    """``repr(value)`` for a message, at most about ``limit`` characters: a
    longer one keeps its start and end and says how long it was, e.g.
    ``'1+1+1+1+1+1+1+...+1+1' (199,999 characters)``.

    Parameters
    ----------
    value : object
        The value to show; a string is quoted and, when too long, cut in the
        middle, any other value cut at the end (``...``).
    limit : int, default 40
        The length aimed at (characters); the kept part is shown in no fewer
        than 8 characters, and keeps at least the first character.

    Returns
    -------
    text : str
        ``repr(value)``, shortened when longer than ``limit``.

    Examples
    --------
    >>> abbreviate("x" * 100, 20)
    "'xxxxxxx...xx' (100 characters)"
    >>> abbreviate(0.5)
    '0.5'
    """
    text = value if isinstance(value, str) else None
    shown = repr(value) if text is None else repr(text)
    if len(shown) <= limit:
        return shown
    if text is not None:
        # cut by the width the characters are shown in, not by their count: repr
        # shows a character as up to 10 (an escape such as \U0001b2fc)
        keep = max(limit - 10, 8)
        head = _shown_within(text, keep * 3 // 4) or text[:1]
        tail = _shown_within(text[len(head) :][::-1], keep // 4)[::-1]
        return f"{head + '...' + tail!r} ({len(text):,} characters)"
    return shown[: max(limit - 3, 8)] + "..."


def _shown_within(text: str, width: int) -> str:
    """The longest start of ``text`` that ``repr`` shows in at most ``width``
    characters (without its quotes)."""
    used = 0
    for i, char in enumerate(text):
        used += len(repr(char)) - 2
        if used > width:
            return text[:i]
    return text


def shorten(text: str, limit: int = 80) -> str:
    """``text`` for a message without quotes (a path, a list of names, another
    error's message), on one line and at most about ``limit`` characters.

    Parameters
    ----------
    text : str
        The text; any object is converted with ``str``. Runs of whitespace
        (newlines included) become one space.
    limit : int, default 80
        The length aimed at (characters); a longer text keeps its start and end
        and says how long it was.

    Returns
    -------
    shown : str
        The one-line, possibly shortened text.

    Examples
    --------
    >>> shorten("a, b, c")
    'a, b, c'
    >>> shorten("x" * 100, 20)
    'xxxxxxx...xx (100 characters)'
    """
    flat = " ".join(str(text).split())
    if len(flat) <= limit:
        return flat
    keep = max(limit - 10, 8)
    return f"{flat[: keep * 3 // 4]}...{flat[-(keep // 4):]} ({len(flat):,} characters)"


def one_line(exc: BaseException) -> str:
    """The error as one line for a command's ``error:`` message: an lpvest
    error's own message with its line breaks folded; for a system error
    (``OSError``), its reason and the file, shortened to about 80 characters.

    Parameters
    ----------
    exc : BaseException
        The error to show.

    Returns
    -------
    str
        One line, without a trailing newline.

    Examples
    --------
    >>> one_line(FileNotFoundError(2, "No such file or directory", "/data/run.toml"))
    'No such file or directory: /data/run.toml'
    >>> one_line(LpvestError("bad value\\n  in line 3"))
    'bad value in line 3'
    """
    if isinstance(exc, OSError) and not isinstance(exc, LpvestError):
        where = f": {shorten(str(exc.filename), 80)}" if exc.filename else ""
        return f"{exc.strerror or type(exc).__name__}{where}"
    return " ".join(str(exc).split())
