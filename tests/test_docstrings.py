"""Every public function and class of lpvest documents what it takes and what
it gives, in numpydoc form, checked by numpydoc's own validator.

Public means a name in ``__all__`` of a package a user imports
(:data:`PUBLIC_PACKAGES`) and the public methods of the classes among them.
The checks (numpydoc error codes):

- ``GL08``: the object has a docstring;
- ``PR01``/``PR02``: its Parameters section names every parameter of the
  signature, and nothing else;
- ``RT01``: a function or method that returns a value has a Returns section.

Properties are documented by their one-line docstring (numpydoc does not
validate them), dataclass-like classes list their fields under Parameters.
"""

from __future__ import annotations

import importlib
import inspect
import warnings

import numpydoc.validate as numpydoc_validate
import pytest

#: The packages whose ``__all__`` is the public API.
PUBLIC_PACKAGES = (
    "lpvest",
    "lpvest.systems",
    "lpvest.analysis",
    "lpvest.design",
    "lpvest.core",
    "lpvest.estimators",
    "lpvest.estimators.kalman",
    "lpvest.estimators.bspline",
    "lpvest.fmi",
    "lpvest.cosim",
    "lpvest.parallel",
    "lpvest.sweep",
    "lpvest.experiments",
)

CHECKS = ("GL08", "PR01", "PR02", "RT01")


def _public_objects() -> list[str]:
    """Import paths (``module.Qualname[.method]``) of every public function, class and method."""
    found: dict[str, None] = {}
    for package in PUBLIC_PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            obj = getattr(module, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            path = f"{obj.__module__}.{obj.__qualname__}"
            found[path] = None
            if inspect.isclass(obj):
                for attr, value in vars(obj).items():
                    if attr.startswith("_"):
                        continue
                    if inspect.isfunction(value) or isinstance(value, (classmethod, staticmethod)):
                        found[f"{path}.{attr}"] = None
    return list(found)


OBJECTS = _public_objects()


def test_the_public_api_is_found():
    # the walk above finds the API a user imports (so the test below cannot pass by finding nothing)
    assert "lpvest.estimators.kalman._batch.kalman_filter" in OBJECTS
    assert "lpvest.design._program.design_hinf" in OBJECTS
    assert "lpvest.sweep._run.run_sweep" in OBJECTS
    assert len(OBJECTS) > 250


@pytest.mark.parametrize("path", OBJECTS)
def test_numpydoc_sections(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # our own sections (Ports, Equations) are not numpydoc's
        report = numpydoc_validate.validate(path)
    errors = [f"{code}: {message}" for code, message in report["errors"] if code in CHECKS]
    assert not errors, f"{path} ({report['file']}:{report['file_line']}):\n  " + "\n  ".join(errors)
