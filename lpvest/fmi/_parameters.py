"""What an lpvest FMU carries in ``resources/``: the spec file and its parameters.

The builder writes ``resources/lpvest_fmu.json`` (:data:`SPEC_FILE`); the slave
reads it when it is instantiated. Only the standard library and numpy are
imported here (the FMU runs where lpvest is not installed).

Spec keys: ``format``, ``identifier`` (model identifier and FMU name, e.g.
``PeixotoEx1Plant``), ``role``, ``description``, ``lpvest_version`` (of the
bundled copy), ``system`` (system name), ``model_file`` (the model file, a
resource), ``model_key``, and for estimators ``estimator`` (the kind: role,
factory, parameters) and ``design_file`` (optional design, a resource).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core._errors import ArgumentTypeError, ModelFileError

__all__ = [
    "SPEC_FILE",
    "GUID_FILE",
    "SPEC_FORMAT",
    "Parameter",
    "ModelDefault",
    "MODEL_X0",
    "MODEL_P0",
    "SCHEDULING_CENTRE",
    "read_spec",
]

#: The spec file in an FMU's resources folder.
SPEC_FILE = "lpvest_fmu.json"
#: The GUID of a pythonfmu-backend FMU in its resources/, written by the build after the
#: model description: the status bridge compares the host's GUID with it (RESOURCE_GUID_FILE
#: in status_bridge.c), the slave binds its FMU states to it.
GUID_FILE = "lpvest_guid.txt"
#: Version tag of the spec format.
SPEC_FORMAT = "lpvest-fmu-2"


@dataclass(frozen=True)
class ModelDefault:
    """A parameter start value that comes from the model the FMU is built for:
    ``"x0"`` (its initial mean), ``"P0"`` (its initial covariance) or
    ``"scheduling-centre"`` (the centre of its scheduling box).

    Parameters
    ----------
    what : str
        ``"x0"``, ``"P0"`` or ``"scheduling-centre"``.
    """

    what: str

    def value(self, model: Any) -> Any:
        """The start value taken from ``model``.

        Parameters
        ----------
        model : object
            The model the FMU is built for (with ``x0``, ``P0`` or a
            scheduling ``space``, as :attr:`what` needs).

        Returns
        -------
        list
            ``x0`` as a list of floats, ``P0`` as nested lists of floats, or
            the scheduling box centre ``(lower + upper) / 2`` as a list of floats.

        Raises
        ------
        ModelFileError
            If :attr:`what` is none of the known defaults.
        """
        if self.what == "x0":
            return [float(v) for v in np.asarray(model.x0, dtype=float)]
        if self.what == "P0":
            return np.asarray(model.P0, dtype=float).tolist()
        if self.what == "scheduling-centre":
            space = model.space
            return [float(v) for v in (np.asarray(space.lower) + np.asarray(space.upper)) / 2]
        raise ModelFileError(f"unknown model default {self.what!r}")


#: Start value: the model's initial mean ``x0``.
MODEL_X0 = ModelDefault("x0")
#: Start value: the model's initial covariance ``P0``.
MODEL_P0 = ModelDefault("P0")
#: Start value: the centre of the model's scheduling box.
SCHEDULING_CENTRE = ModelDefault("scheduling-centre")


@dataclass(frozen=True)
class Parameter:
    """An FMU parameter (causality parameter, variability fixed).

    The FMI type follows ``start``: ``bool`` -> Boolean, ``int`` -> Integer,
    ``float`` -> Real, ``str`` -> String, a sequence of numbers -> a vector of
    Reals ``name[1] ... name[n]``. ``minimum``/``maximum`` (numbers) are
    declared in the model description and checked when the value is set.

    Parameters
    ----------
    name : str
        FMI variable name (the base name of a vector parameter).
    start : bool or int or float or str or sequence of float or ModelDefault
        Start value; its type sets the FMI type. A :class:`ModelDefault` is
        replaced by the model's value when the FMU is built (:meth:`for_model`).
    description : str, default ""
        Description in the model description.
    minimum : float, optional
        Declared minimum of a numeric parameter; ``None``: none.
    maximum : float, optional
        Declared maximum of a numeric parameter; ``None``: none.

    Examples
    --------
    >>> Parameter("tau", 10, "memory length", minimum=1).fmi_type
    'Integer'
    """

    name: str
    start: Any
    description: str = ""
    minimum: float | None = None
    maximum: float | None = None

    def for_model(self, model: object) -> Parameter:
        """This parameter with a :class:`ModelDefault` start replaced by the model's value.

        Parameters
        ----------
        model : object
            The model the FMU is built for (see :meth:`ModelDefault.value`).

        Returns
        -------
        Parameter
            A new parameter with the model's start value, or this parameter
            itself when its start is not a :class:`ModelDefault`.
        """
        if isinstance(self.start, ModelDefault):
            return Parameter(self.name, self.start.value(model), self.description, self.minimum, self.maximum)
        return self

    @property
    def fmi_type(self) -> str:
        s = self.start
        if isinstance(s, bool | np.bool_):
            return "Boolean"
        if isinstance(s, int | np.integer):
            return "Integer"
        if isinstance(s, float | np.floating):
            return "Real"
        if isinstance(s, str):
            return "String"
        if isinstance(s, list | tuple | np.ndarray):
            return "Real"
        raise ArgumentTypeError(f"parameter {self.name}: unsupported start value {s!r}")

    @property
    def shape(self) -> tuple[int, ...]:
        return np.shape(self.start) if isinstance(self.start, list | tuple | np.ndarray) else ()

    def to_json(self) -> dict[str, object]:
        """The parameter as stored in the FMU spec (inverse of :meth:`from_json`).

        Returns
        -------
        dict
            ``name``, ``start``, ``description``, ``minimum``, ``maximum`` and
            ``vector`` (whether ``start`` is an array). A vector start is a
            (nested) list of floats; a :class:`ModelDefault` start is
            ``{"model": what}`` (with ``vector`` true).
        """
        if isinstance(self.start, ModelDefault):
            return {"name": self.name, "start": {"model": self.start.what}, "description": self.description,
                    "minimum": self.minimum, "maximum": self.maximum, "vector": True}
        start = np.asarray(self.start, dtype=float).tolist() if self.shape else self.start
        return {"name": self.name, "start": start, "description": self.description,
                "minimum": self.minimum, "maximum": self.maximum, "vector": bool(self.shape)}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Parameter:
        """The parameter stored by :meth:`to_json`.

        Parameters
        ----------
        data : dict
            ``name`` and ``start`` (required); ``description``, ``minimum``,
            ``maximum`` and ``vector`` (optional). A ``start`` that is a dict
            becomes a :class:`ModelDefault`; with ``vector`` true, ``start``
            becomes a float array.

        Returns
        -------
        Parameter
            The parameter.
        """
        start = data["start"]
        if isinstance(start, dict):
            start = ModelDefault(str(start.get("model")))
        elif data.get("vector"):
            start = np.asarray(start, dtype=float)
        return cls(data["name"], start, data.get("description", ""), data.get("minimum"), data.get("maximum"))


def read_spec(resources: str | Path) -> dict[str, Any]:
    """The spec of the FMU whose resources folder is ``resources``.

    Parameters
    ----------
    resources : os.PathLike or str
        The FMU's ``resources`` folder, holding :data:`SPEC_FILE`.

    Returns
    -------
    dict
        The parsed spec (keys: see the module docs).

    Raises
    ------
    ModelFileError
        If the spec file is missing, not valid JSON, or not of
        :data:`SPEC_FORMAT`.
    """
    path = Path(resources) / SPEC_FILE
    try:
        spec = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelFileError(f"{path}: missing; this FMU was not built by lpvest's builder") from None
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{path}: not valid JSON: {exc}") from exc
    if spec.get("format") != SPEC_FORMAT:
        raise ModelFileError(f"{path}: format {spec.get('format')!r}; expected {SPEC_FORMAT!r}")
    return spec
