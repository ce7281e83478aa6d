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

from ..errors import ArgumentTypeError, ModelFileError

__all__ = [
    "SPEC_FILE",
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
#: Version tag of the spec format.
SPEC_FORMAT = "lpvest-fmu-2"


@dataclass(frozen=True)
class ModelDefault:
    """A parameter start value that comes from the model the FMU is built for:
    ``"x0"`` (its initial mean), ``"P0"`` (its initial covariance) or
    ``"scheduling-centre"`` (the centre of its scheduling box)."""

    what: str

    def value(self, model: Any) -> Any:
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

    >>> Parameter("tau", 10, "memory length", minimum=1).fmi_type
    'Integer'
    """

    name: str
    start: Any
    description: str = ""
    minimum: float | None = None
    maximum: float | None = None

    def for_model(self, model: Any) -> Parameter:
        """This parameter with a :class:`ModelDefault` start replaced by the model's value."""
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

    def to_json(self) -> dict[str, Any]:
        if isinstance(self.start, ModelDefault):
            return {"name": self.name, "start": {"model": self.start.what}, "description": self.description,
                    "minimum": self.minimum, "maximum": self.maximum, "vector": True}
        start = np.asarray(self.start, dtype=float).tolist() if self.shape else self.start
        return {"name": self.name, "start": start, "description": self.description,
                "minimum": self.minimum, "maximum": self.maximum, "vector": bool(self.shape)}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Parameter:
        start = data["start"]
        if isinstance(start, dict):
            start = ModelDefault(str(start.get("model")))
        elif data.get("vector"):
            start = np.asarray(start, dtype=float)
        return cls(data["name"], start, data.get("description", ""), data.get("minimum"), data.get("maximum"))


def read_spec(resources: str | Path) -> dict[str, Any]:
    """The spec of the FMU whose resources folder is ``resources``."""
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
