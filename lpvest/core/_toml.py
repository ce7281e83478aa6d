"""Reading the TOML files lpvest uses: model files, co-simulation files,
sweep files and the example catalog.

Every file is read the same way and every mistake in it reads the same way:
a file that cannot be read, is not UTF-8 text, or is not valid TOML is a
one-line :class:`~lpvest.core.ModelFileError` naming it (:func:`read_toml`,
:func:`parse_toml`), and its content is checked with one reader,
:class:`TomlReader` and its :class:`TomlTable` getters, whose errors are
``"ORIGIN: WHERE: MESSAGE"``: the file, the field path of the value at fault
(``models.m.C[1,2]``, ``components.sched.fmu``, ``seeds.count``) and what was
expected versus found (``expected a positive integer, found a number (2.5)``;
``missing (expected a table)``; ``unknown key, did you mean 'steps'?
(expected one of: ...)``). Only the standard library and :mod:`lpvest.core`
are imported.

Examples
--------
>>> parse_toml('a = 1\\n[b]\\nc = "x"', "<text>")
{'a': 1, 'b': {'c': 'x'}}
>>> parse_toml("a = ", "my.toml")
Traceback (most recent call last):
...
lpvest.core._errors.ModelFileError: my.toml: not valid TOML: Invalid value (at end of document)
"""

from __future__ import annotations

import datetime
import difflib
import math
import re
import tomllib
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ._errors import LpvestError, ModelFileError, abbreviate, shorten

__all__ = ["parse_toml", "read_toml", "describe_value", "TomlReader", "TomlTable", "REQUIRED", "key_text",
           "field_path", "element_path", "close_match"]


def parse_toml(text: str, origin: str) -> dict[str, Any]:
    """The parsed TOML ``text``; malformed text is a one-line
    :class:`ModelFileError` naming ``origin``.

    Parameters
    ----------
    text : str
        The TOML document.
    origin : str
        What the text is called in an error (a file name, ``"<text>"``).

    Returns
    -------
    dict
        The document's top-level table.

    Raises
    ------
    ModelFileError
        The text is not valid TOML (also when nested too deeply).
    """
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ModelFileError(f"{origin}: not valid TOML: arrays or tables nested too deeply") from None
    except ValueError as exc:  # TOMLDecodeError, or an integer of more than 4300 digits
        raise ModelFileError(f"{origin}: not valid TOML: {shorten(str(exc), 160)}") from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """The parsed TOML file ``path``; an unreadable or malformed file is a
    one-line :class:`ModelFileError` naming it (shared by every file lpvest reads).

    Parameters
    ----------
    path : str or Path
        The file, read as UTF-8 (a byte-order mark is allowed).

    Returns
    -------
    dict
        The file's top-level table.

    Raises
    ------
    ModelFileError
        The file cannot be read, is not UTF-8 text or is not valid TOML.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot be read: {exc.strerror or type(exc).__name__}") from None
    except ValueError as exc:  # e.g. a NUL character in the path
        raise ModelFileError(f"{abbreviate(str(path))}: cannot be read: {shorten(str(exc), 80)}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ModelFileError(
            f"{path}: not a TOML text file: byte {exc.start + 1} ({raw[exc.start:exc.start + 1]!r}) is not UTF-8"
            + (" (the file is UTF-16; save it as UTF-8)" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else "")
        ) from None
    return parse_toml(text, str(path))


def describe_value(value: Any) -> str:
    """What a TOML value is, for a one-line message (numbers with their
    value, strings abbreviated).

    Parameters
    ----------
    value : object
        A value as :mod:`tomllib` parses it (or anything else).

    Returns
    -------
    str
        ``"a boolean (true)"``, ``"a number (2.5)"``, ``"a string ('x')"``,
        ``"a list"``, ``"a table"``, ...

    Examples
    --------
    >>> describe_value(True), describe_value(2.5), describe_value([1]), describe_value({})
    ('a boolean (true)', 'a number (2.5)', 'a list', 'a table')
    """
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, int | float):  # (a float's repr has at most 24 characters, a TOML integer's 20)
        return f"a number ({abbreviate(value, 40)})"
    if isinstance(value, str):
        return f"a string ({abbreviate(value, 30)})"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, datetime.date | datetime.time):
        return "a date/time"
    return type(value).__name__


# -- the one reader of model, co-simulation and sweep files --------------------------------------

#: A key written bare in a field path; any other key is quoted and shortened.
_PLAIN_KEY = re.compile(r"[A-Za-z0-9_-]{1,40}")

#: Marks a getter's key as required (no default).
REQUIRED: Any = object()


def key_text(key: object) -> str:
    """A TOML key as it appears in a field path: bare when it is a plain
    short name, else quoted and shortened.

    >>> key_text("step_size"), key_text("2 src"), key_text("k" * 50)
    ('step_size', "'2 src'", "'kkkkkkkkkkkkkkk...kkkkk' (50 characters)")
    """
    return key if isinstance(key, str) and _PLAIN_KEY.fullmatch(key) else abbreviate(key, 30)


def field_path(where: str, key: object) -> str:
    """The path of ``key`` inside the table at ``where`` (``""``: the file).

    >>> field_path("", "steps"), field_path("models.m", "A"), field_path("seeds", "k k")
    ('steps', 'models.m.A', "seeds.'k k'")
    """
    return f"{where}.{key_text(key)}" if where else key_text(key)


def element_path(where: str, index: int) -> str:
    """The path of the element ``index`` (from 0) of the array at ``where``,
    counted from 1 as a user counts: ``connections[2]``."""
    return f"{where}[{index + 1}]"


def _names(names: Iterable[object]) -> str:
    return shorten(", ".join(sorted(map(str, names))), 160) or "none"


def close_match(given: object, choices: Iterable[object]) -> str | None:
    """The choice ``given`` is most likely a typo of (difflib's closest), or ``None``.

    >>> close_match("stepz", ["steps", "step_size"]), close_match("x" * 101, ["x"])
    ('steps', None)
    """
    if len(str(given)) > 100:  # junk, not a typo (and no time spent comparing it)
        return None
    close = difflib.get_close_matches(str(given), [str(c) for c in choices], n=1)
    return close[0] if close else None


def _did_you_mean(given: object, choices: Iterable[object]) -> str:
    close = close_match(given, choices)
    return f", did you mean {abbreviate(close, 30)}?" if close is not None else ""


class TomlReader:
    """Checks the values of one parsed TOML file; every mistake is a one-line
    :class:`ModelFileError` ``"ORIGIN: WHERE: MESSAGE"``.

    ``WHERE`` is the field path of the value at fault: keys joined by ``.``
    (bare when plain, else quoted), array elements counted from 1
    (``connections[2]``, ``models.m.C[1,2]``); ``""`` for the file as a whole.
    ``MESSAGE`` says what was expected and what was found:
    ``expected a positive number, found a string ('1')``; a missing key is
    ``missing (expected ...)`` at the key's path; an unknown key is
    ``unknown key (expected one of: ...)`` at the key's path, with a
    did-you-mean when a known key is close.

    Parameters
    ----------
    origin : str or Path
        What the messages call the file (its path, or e.g. ``"sweep spec"``).

    Examples
    --------
    >>> r = TomlReader("run.toml")
    >>> top = r.root({"step_size": -1.0, "stepz": 3})
    >>> top.check_keys({"step_size", "steps"})
    Traceback (most recent call last):
    ...
    lpvest.core._errors.ModelFileError: run.toml: stepz: unknown key, did you mean 'steps'? (expected one of: ...)
    >>> top.number("step_size", positive=True)
    Traceback (most recent call last):
    ...
    lpvest.core._errors.ModelFileError: run.toml: step_size: expected a positive number, found a number (-1.0)
    """

    #: What a number is called in "expected ..." when it is not one (a format
    #: that also takes formulas says so).
    number_what = "a number"

    def __init__(self, origin: str | Path) -> None:
        self.origin = str(origin)

    def error(self, where: str, message: str) -> ModelFileError:
        """The error for a mistake at ``where`` (``""``: the file as a whole),
        to raise: ``"ORIGIN: WHERE: MESSAGE"``."""
        return ModelFileError(f"{self.origin}: {where}: {message}" if where else f"{self.origin}: {message}")

    @contextmanager
    def at(self, where: str) -> Iterator[None]:
        """Inside the block, an :class:`LpvestError` of the library (a bad
        formula, a matrix of the wrong shape) becomes this file's error at
        ``where``; a :class:`ModelFileError` passes unchanged."""
        try:
            yield
        except ModelFileError:
            raise
        except LpvestError as exc:
            raise self.error(where, str(exc)) from exc

    def expected(self, where: str, what: str, value: object) -> ModelFileError:
        """``WHERE: expected WHAT, found <value described>``."""
        return self.error(where, f"expected {what}, found {describe_value(value)}")

    def missing(self, where: str, what: str) -> ModelFileError:
        """``WHERE: missing (expected WHAT)``."""
        return self.error(where, f"missing (expected {what})")

    def root(self, data: object) -> TomlTable:
        """The file's top-level table (a mapping, else an error naming the file)."""
        return self.table(data, "")

    # -- one value, at its path -------------------------------------------------------------------

    def table(self, value: object, where: str, *, what: str = "a table") -> TomlTable:
        """``value`` as a :class:`TomlTable` at ``where``."""
        if not isinstance(value, Mapping):
            raise self.expected(where, what, value)
        return TomlTable(self, where, value)

    def array(self, value: object, where: str, *, what: str = "a list", nonempty: bool = False) -> list:
        """``value``, a list (``nonempty``: with at least one element)."""
        if not isinstance(value, list) or (nonempty and not value):
            raise self.expected(where, what, value)
        return value

    def string(self, value: object, where: str, *, what: str = "a string") -> str:
        """``value``, a string."""
        if not isinstance(value, str):
            raise self.expected(where, what, value)
        return value

    def number(self, value: object, where: str, *, positive: bool = False, what: str | None = None) -> float:
        """``value``, a finite number (an integer or a float, not a boolean)
        as a float; ``positive``: greater than 0."""
        what = what or ("a positive number" if positive else self.number_what)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.expected(where, what, value)
        try:
            number = float(value)
        except OverflowError:  # an integer of a Python dict beyond the float range
            number = math.inf
        if not math.isfinite(number):
            raise self.expected(where, "a finite number", value)
        if positive and not number > 0:
            raise self.expected(where, what, value)
        return number

    def integer(self, value: object, where: str, *, minimum: int | None = None) -> int:
        """``value``, an integer (not a boolean, not a float), at least
        ``minimum`` when given."""
        what = {None: "an integer", 0: "a non-negative integer", 1: "a positive integer"}.get(
            minimum, f"an integer >= {minimum}")
        if isinstance(value, bool) or not isinstance(value, int) or (minimum is not None and value < minimum):
            raise self.expected(where, what, value)
        return value

    def boolean(self, value: object, where: str) -> bool:
        """``value``, ``true`` or ``false``."""
        if not isinstance(value, bool):
            raise self.expected(where, "true or false", value)
        return value

    def choice(self, value: object, where: str, choices: Iterable[str], *, noun: str) -> str:
        """``value``, one of ``choices`` (a string); ``noun`` names what it
        is in the message (``unknown model type 'afine', did you mean ...``)."""
        choices = list(choices)
        text = self.string(value, where)
        if text not in choices:
            raise self.error(where, f"unknown {noun} {abbreviate(text, 30)}{_did_you_mean(text, choices)} "
                                    f"(expected one of: {', '.join(choices)})")
        return text

    def strings(self, value: object, where: str, *, what: str = "a string") -> list[str]:
        """``value``, a list of strings; ``what`` describes one element."""
        out = self.array(value, where, what="a list of strings")
        for i, v in enumerate(out):
            self.string(v, element_path(where, i), what=what)
        return list(out)

    def numbers(self, value: object, where: str) -> list[float]:
        """``value``, a list of finite numbers."""
        return [self.number(v, element_path(where, i))
                for i, v in enumerate(self.array(value, where, what="a list of numbers"))]

    def check_keys(self, data: Mapping, where: str, allowed: Iterable[str],
                   required: Mapping[str, str] | None = None) -> None:
        """The keys of the table ``data`` at ``where``: an unknown key (the
        first in sorted order) is an error at its path, with a did-you-mean;
        then a missing one of ``required`` (key -> what belongs there)."""
        allowed = set(allowed)
        unknown = sorted((k for k in data if k not in allowed), key=str)
        if unknown:
            key = unknown[0]
            raise self.error(field_path(where, key), f"unknown key{_did_you_mean(key, sorted(allowed))} "
                                                      f"(expected one of: {_names(allowed)})")
        for key in sorted(required or {}):
            if key not in data:
                raise self.missing(field_path(where, key), (required or {})[key])


class TomlTable(Mapping[str, Any]):
    """A table of a TOML file at its field path, with typed getters: each
    reads one key, says ``missing (expected ...)`` when a required key is
    absent and ``expected ..., found ...`` when its value does not fit, at
    the key's path (see :class:`TomlReader`). As a mapping it gives the raw
    values.

    Parameters
    ----------
    reader : TomlReader
        The file's reader (its origin and its error style).
    where : str
        The table's field path (``""``: the top level).
    data : mapping
        The parsed table.
    """

    def __init__(self, reader: TomlReader, where: str, data: Mapping[str, Any]) -> None:
        self.reader = reader
        self.where = where
        self.data = data

    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)

    def path(self, key: object) -> str:
        """The field path of ``key`` in this table."""
        return field_path(self.where, key)

    def error(self, key: object, message: str) -> ModelFileError:
        """The error for a mistake in the value of ``key`` (at its path)."""
        return self.reader.error(self.path(key), message)

    def check_keys(self, allowed: Iterable[str], required: Mapping[str, str] | None = None) -> None:
        """See :meth:`TomlReader.check_keys`."""
        self.reader.check_keys(self.data, self.where, allowed, required)

    def value(self, key: str, what: str) -> Any:
        """The raw value of the required ``key`` (``what`` says what belongs
        there, for the message when it is missing)."""
        if key not in self.data:
            raise self.reader.missing(self.path(key), what)
        return self.data[key]

    def _get(self, key: str, default: Any, what: str) -> tuple[bool, Any]:
        if key in self.data:
            return True, self.data[key]
        if default is REQUIRED:
            raise self.reader.missing(self.path(key), what)
        return False, default

    def table(self, key: str, *, required: bool = True, what: str = "a table") -> TomlTable:
        """The sub-table ``key``; an absent optional one is empty."""
        _, value = self._get(key, REQUIRED if required else {}, what)
        return self.reader.table(value, self.path(key), what=what)

    def array(self, key: str, default: Any = REQUIRED, *, what: str = "a list", nonempty: bool = False) -> list:
        """The list ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, what)
        return self.reader.array(value, self.path(key), what=what, nonempty=nonempty) if found else value

    def string(self, key: str, default: Any = REQUIRED, *, what: str = "a string") -> str:
        """The string ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, what)
        return self.reader.string(value, self.path(key), what=what) if found else value

    def number(self, key: str, default: Any = REQUIRED, *, positive: bool = False) -> float:
        """The finite number ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, "a positive number" if positive else self.reader.number_what)
        return self.reader.number(value, self.path(key), positive=positive) if found else value

    def integer(self, key: str, default: Any = REQUIRED, *, minimum: int | None = None) -> int:
        """The integer ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, "an integer")
        return self.reader.integer(value, self.path(key), minimum=minimum) if found else value

    def boolean(self, key: str, default: Any = REQUIRED) -> bool:
        """``true`` or ``false`` at ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, "true or false")
        return self.reader.boolean(value, self.path(key)) if found else value

    def choice(self, key: str, choices: Iterable[str], default: Any = REQUIRED, *, noun: str) -> str:
        """One of ``choices`` at ``key`` (``default`` when absent, if given)."""
        choices = list(choices)
        found, value = self._get(key, default, f"one of: {', '.join(choices)}")
        return self.reader.choice(value, self.path(key), choices, noun=noun) if found else value

    def strings(self, key: str, default: Any = REQUIRED, *, what: str = "a string") -> list[str]:
        """The list of strings ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, "a list of strings")
        return self.reader.strings(value, self.path(key), what=what) if found else value

    def numbers(self, key: str, default: Any = REQUIRED) -> list[float]:
        """The list of numbers ``key`` (``default`` when absent, if given)."""
        found, value = self._get(key, default, "a list of numbers")
        return self.reader.numbers(value, self.path(key)) if found else value
