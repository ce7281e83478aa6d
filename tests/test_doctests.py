"""Every example in lpvest's docstrings runs and prints what it shows.

One test per module (``doctest`` with ``ELLIPSIS`` and
``NORMALIZE_WHITESPACE``); examples that need a built FMU, a display or a
long computation are marked ``# doctest: +SKIP`` where they stand. The
examples run in a temporary working directory, so one that writes a file
leaves nothing behind.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import lpvest

MODULES = sorted(m.name for m in pkgutil.walk_packages(lpvest.__path__, "lpvest."))


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, report=True)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed (output above)"
