"""Progress bars that stay readable in a narrow terminal.

tqdm writes ``desc: 50%|█████     | 12/24 [00:03<00:03, 3.75design/s, postfix]``
and, when that is wider than the terminal, cuts it at the right edge: with a
long description, a terminal of 80 columns or fewer showed the description
and nothing of the count. The bars of lpvest give up their parts in the order
a user misses them least (the postfix, the rate, the bar, the times, the
percentage, the description's tail) so that the count ``n/total`` is on
screen at any width from 20 columns up, and follow the terminal's width as it
changes (``dynamic_ncols``).

Bars are for terminals only: :func:`progress_bar` gives a disabled bar unless
stderr is a terminal, so that a redirected log gets no carriage returns.
tqdm is imported when a bar is made, never at import time of this module.
"""

from __future__ import annotations

import functools
import sys
from typing import Any

__all__ = ["progress_bar", "fit_meter", "on_terminal"]

#: The layouts a bar tries, richest first; the first that fits the terminal is shown
#: (``None``: tqdm's own, with the postfix). A layout with ``{bar}`` fits when its bar
#: keeps at least :data:`MIN_BAR` cells.
_LAYOUTS: tuple[str | None, ...] = (
    None,
    "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}, {rate_fmt}]",
    "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}]",
    "{desc}: {n_fmt}/{total_fmt} {percentage:3.0f}% [{elapsed}<{remaining}]",
    "{desc}: {n_fmt}/{total_fmt} {percentage:3.0f}%",
    "{desc}: {n_fmt}/{total_fmt}",
)

#: The fewest cells of a bar worth drawing.
MIN_BAR = 8


def on_terminal() -> bool:
    """Whether stderr (where bars go) is a terminal.

    Returns
    -------
    bool
        True when ``sys.stderr`` is a terminal.
    """
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # a replaced or closed stream
        return False


def fit_meter(n: float, total: float | None, elapsed: float, ncols: int | None, prefix: str = "",
              postfix: Any = None, **kwargs: Any) -> str:
    """One line of a bar that fits in ``ncols`` columns with its count ``n/total``.

    Parameters
    ----------
    n, total, elapsed, prefix, postfix, **kwargs
        As :meth:`tqdm.tqdm.format_meter` (``prefix`` is the description).
    ncols : int or None
        The terminal's width; None: tqdm's own line, not fitted.

    Returns
    -------
    str
        The richest layout of :data:`_LAYOUTS` that fits; at the narrowest, the
        description shortened (ending in ``…``) before ``: n/total``.
    """
    from tqdm import tqdm
    from tqdm.utils import disp_len

    kwargs.pop("bar_format", None)
    if not ncols or not total:  # no width known, or no total: tqdm's line as it is
        return tqdm.format_meter(n, total, elapsed, ncols=ncols, prefix=prefix, postfix=postfix, **kwargs)
    for layout in _LAYOUTS:
        # measured without the bar, which stretches to whatever is left
        bare = tqdm.format_meter(n, total, elapsed, ncols=None, prefix=prefix, postfix=postfix if layout is None
                                 else None, bar_format=(layout or "{l_bar}{bar}{r_bar}").replace("{bar}", ""),
                                 **kwargs)
        room = ncols - 1 - disp_len(bare)  # one column spare: no wrap at the right edge
        if room >= (MIN_BAR if layout is None or "{bar}" in layout else 0):
            return tqdm.format_meter(n, total, elapsed, ncols=ncols - 1, prefix=prefix,
                                     postfix=postfix if layout is None else None, bar_format=layout, **kwargs)
    count = f": {n:g}/{total:g}"
    keep = max(0, ncols - 1 - len(count) - 1)
    short = prefix if len(prefix) <= keep else prefix[:keep].rstrip() + "…"
    return (short + count)[: ncols - 1] if short else count[2:]


@functools.cache
def _bar_class() -> type:
    from tqdm import tqdm

    class ProgressBar(tqdm):
        """tqdm with :func:`fit_meter`'s line."""

        format_meter = staticmethod(fit_meter)

    return ProgressBar


def progress_bar(iterable: Any = None, *, desc: str, unit: str, total: int | None = None, show: bool | None = None,
                 leave: bool = True, **kwargs: Any) -> Any:
    """A tqdm bar on stderr that keeps its count in a narrow terminal and
    follows the terminal's width (the one way lpvest makes a bar).

    Parameters
    ----------
    iterable : iterable, optional
        What to iterate over (as tqdm).
    desc : str
        A short description (a word or two: the bar's count must fit beside it).
    unit : str
        What is counted (``"FMU"``, ``"task"``, ...).
    total : int, optional
        How many (default: ``len(iterable)``).
    show : bool or None, default None
        Show the bar (True: even when stderr is no terminal, the caller's
        explicit choice); None: when stderr is a terminal. A bar not shown is
        disabled (a no-op with the same methods).
    leave : bool, default True
        The finished bar stays on screen.
    **kwargs
        More tqdm options (``smoothing``, ...).

    Returns
    -------
    tqdm.tqdm
        The bar (disabled unless shown on a terminal).
    """
    shown = on_terminal() if show is None else bool(show)
    return _bar_class()(iterable, desc=desc, unit=unit, total=total, leave=leave, disable=not shown,
                        dynamic_ncols=True, file=sys.stderr, **kwargs)
