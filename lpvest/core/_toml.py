"""Reading the TOML files lpvest uses (model files, co-simulation files, the example catalog).

Every reader shares the same one-line errors: a file that cannot be read, is
not UTF-8 text, or is not valid TOML is a :class:`~lpvest.core.ModelFileError`
naming it. Only the standard library and :mod:`lpvest.core` are imported.

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
import tomllib
from pathlib import Path
from typing import Any

from ._errors import ModelFileError, abbreviate, shorten

__all__ = ["parse_toml", "read_toml", "describe_value"]


def parse_toml(text: str, origin: str) -> dict[str, Any]:
    """The parsed TOML ``text``; malformed text is a one-line
    :class:`ModelFileError` naming ``origin``."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ModelFileError(f"{origin}: not valid TOML: arrays or tables nested too deeply") from None
    except ValueError as exc:  # TOMLDecodeError, or an integer of more than 4300 digits
        raise ModelFileError(f"{origin}: not valid TOML: {shorten(str(exc), 160)}") from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """The parsed TOML file ``path``; an unreadable or malformed file is a
    one-line :class:`ModelFileError` naming it (shared by every file lpvest reads)."""
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

    >>> describe_value(True), describe_value(2.5), describe_value([1]), describe_value({})
    ('a boolean (true)', 'a number (2.5)', 'a list', 'a table')
    """
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, int | float):
        return f"a number ({value!r})"
    if isinstance(value, str):
        return f"a string ({abbreviate(value, 30)})"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, datetime.date | datetime.time):
        return "a date/time"
    return type(value).__name__
