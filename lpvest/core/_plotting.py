"""Shared plotting glue (matplotlib is imported inside, never at import time)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["save_figure"]


def save_figure(fig: Figure, path: str | Path, *, title: str | None = None, title_size: str | None = None) -> Path:
    """Finish a matplotlib figure the way every lpvest figure is finished:
    optional ``suptitle``, ``tight_layout``, saved at 120 dpi into ``path``
    (its folder created), then close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure; it is closed afterwards.
    path : str or pathlib.Path
        The file; matplotlib picks the format from its suffix (``.png`` for
        the figures lpvest writes).
    title : str or None, optional
        The figure's ``suptitle``; None: none.
    title_size : str or None, optional
        The title's font size (e.g. ``"small"``); None: matplotlib's default.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib.pyplot as plt

    path = Path(path)
    if title is not None:
        if title_size is None:
            fig.suptitle(title)
        else:
            fig.suptitle(title, fontsize=title_size)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
