"""Where lpvest keeps what it can make again: the user's cache folder."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["user_cache_dir"]


def user_cache_dir(*parts: str) -> Path:
    """``$XDG_CACHE_HOME/lpvest/<parts>``, or ``~/.cache/lpvest/<parts>`` when
    that variable is unset or empty (the XDG base-directory rule, on every
    platform): the FMU cache, the native runtime's sources, the resume key.
    Nothing is created here.

    Examples
    --------
    >>> user_cache_dir("fmus").parts[-2:]
    ('lpvest', 'fmus')
    """
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base, "lpvest", *parts)
