"""The example systems shipped with lpvest (the ``models/`` folder).

Examples
--------
>>> [e.name for e in example_systems()][:3]
['cox-toth-ex1', 'cox-toth-truncation', 'peixoto-ex1']
>>> find_system("peixoto-ex1").name
'peixoto_ex1.toml'
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..core._errors import ModelFileError, abbreviate, shorten

__all__ = ["models_dir", "example_systems", "find_system", "stored_design", "ExampleEntry"]


def models_dir() -> Path:
    """The folder holding the example model files: ``models/`` next to the
    package in a source checkout, else the copy installed as ``lpvest._models``.

    Returns
    -------
    folder : pathlib.Path
        The first of the two folders that holds a ``*.toml`` file.

    Raises
    ------
    ModelFileError
        Neither folder holds a model file.
    """
    here = Path(__file__).resolve().parent.parent  # lpvest/
    for candidate in (here.parent / "models", here / "_models"):
        if candidate.is_dir() and any(candidate.glob("*.toml")):
            return candidate
    raise ModelFileError(f"the example model files are missing (looked in {here.parent / 'models'})")


@dataclass(frozen=True)
class ExampleEntry:
    """One example system: its name, title and file (read without building it).

    Parameters
    ----------
    name : str
        The system's ``[system] name`` (the file's stem when it has none), by
        which :func:`find_system` and ``lpvest systems`` find it.
    title : str
        The system's ``[system] title`` (empty when it has none).
    path : pathlib.Path
        The model file.
    """

    name: str
    title: str
    path: Path


def example_systems() -> list[ExampleEntry]:
    """Every example system, sorted by name.

    Returns
    -------
    list of ExampleEntry
        One entry per ``*.toml`` file of :func:`models_dir`; only the
        ``[system]`` table is read (the models are not built).
    """
    from ..core._toml import read_toml

    out = []
    for path in sorted(models_dir().glob("*.toml")):
        meta = read_toml(path).get("system", {})
        out.append(ExampleEntry(str(meta.get("name", path.stem)), str(meta.get("title", "")), path))
    return sorted(out, key=lambda e: e.name)


def find_system(source: str | Path) -> Path:
    """The file for ``source``: an existing path, or an example system's name.

    Parameters
    ----------
    source : str or pathlib.Path
        A path to a model file (anything ending in ``.toml`` or naming an
        existing file), else the name of an example system
        (:attr:`ExampleEntry.name`).

    Returns
    -------
    path : pathlib.Path
        ``source`` as a path, or the example system's file.

    Raises
    ------
    ModelFileError
        ``source`` is not a string or path, a ``.toml`` path that does not exist
        or is a folder, or no example system's name.
    """
    if not isinstance(source, str | Path):
        raise ModelFileError(f"expected a model file or an example name, found {type(source).__name__}")
    path = Path(source)
    if path.suffix == ".toml" or _exists(path):
        if _exists(path) and path.is_dir():  # a name the system cannot look up is no folder
            raise ModelFileError(f"{shorten(str(path), 120)}: is a folder, not a model file")
        if not _exists(path):
            raise ModelFileError(f"{shorten(str(path), 120)}: no such model file")
        return path
    entries = example_systems()
    for e in entries:
        if e.name == str(source):
            return e.path
    names = ", ".join(e.name for e in entries)
    raise ModelFileError(f"no example system {abbreviate(str(source), 30)} (examples: {names}; or give a .toml file)")


def _exists(path: Path) -> bool:
    """``path.exists()``, and ``False`` for a name the system cannot look up
    (too long, a NUL character)."""
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


def stored_design(system_name: str, role: str) -> Path | None:
    """The design stored with the example systems for ``role`` of ``system_name``
    (``models/designs/<system>.<Role>.json``, written by ``lpvest design``), or
    ``None``. The FMU builder carries it instead of solving the LMIs again, so
    every machine builds the same filter; it checks that the design fits the
    plant (:meth:`lpvest.design.HinfDesign.check_model`).

    Parameters
    ----------
    system_name : str
        The system's name (``[system] name``, e.g. ``"peixoto-ex1"``).
    role : str
        The FMU role the design is for, e.g. ``"HinfPD"`` or ``"HinfRobust"``.

    Returns
    -------
    path : pathlib.Path or None
        The design file, or ``None`` when there is none (the file is not read).
    """
    path = models_dir() / "designs" / f"{system_name}.{role}.json"
    return path if path.is_file() else None
