"""Model files: example systems and users' own systems as TOML.

A file describes one *system* (a paper's example) with one or more *models*
(realizations or views of it). Every error names the file, the field and what
was expected versus found, in one line::

    models/bad.toml: models.plant.Q: Q has shape (3, 2); expected (3, 3)

The format, by example (see ``models/*.toml`` for complete files)::

    [system]
    name = "my-plant"                 # how `lpvest systems show` finds it
    title = "One line about it"
    default = "plant"                 # the model used when none is named

    [parameters]                      # optional named numbers, usable in formulas
    gain = 1.0
    rho = { value = 1.0, lower = 1.0, upper = 21.0, description = "stiffness" }  # with a range

    [scheduling]                      # the scheduling box (LPV models)
    names = ["theta"]
    lower = [-1.0]
    upper = [1.0]

    [models.plant]
    type = "affine"                   # affine | polytopic | innovation | lpv-io | ltv-io | ltv-ss
    A = { "1" = [[0.5, 0.1], [0, 0.4]], theta = [[0.1, 0], [0, -0.1]] }
    C = [[1, 0]]                      # a plain array: constant in theta
    Q = [[0.1, 0], [0, 0.1]]
    R = [[0.01]]

Matrix entries may be formulas of the parameters (``"-0.05*rho"``); LTV
coefficients are formulas of ``t``. See :mod:`lpvest.core` for what a
formula may contain.

A parameter with ``lower``/``upper`` keeps them: an override outside is an
error naming the parameter, and an FMU built from the file declares them as
the FMI parameter's ``min``/``max`` (so a host refuses such a value too).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar, overload

import numpy as np

from ..core._errors import ModelFileError, OutputError, abbreviate, shorten
from ..core._expressions import CONSTANTS, FUNCTIONS, Expression, FormulaMatrix
from ..core._scheduling import (
    BasisFunction,
    SchedulingSpace,
    parse_basis,
)
from ..core._toml import TomlReader, TomlTable, describe_value, element_path, field_path, parse_toml, read_toml
from ._affine import CONSTANT_TERM, AffineDependence, AffineLPV
from ._innovation import InnovationLPV, LPVInputOutput
from ._ltv import LTVInputOutput, LTVStateSpace
from ._polytopic import (
    POLYTOPIC_INPUT_MATRICES,
    POLYTOPIC_MATRICES,
    FormulaSimplexMap,
    MultilinearSimplexMap,
    PolytopicLPV,
    SimplexMap,
)
from ._text import number

__all__ = [
    "SystemFile",
    "ParameterRange",
    "Model",
    "load_system",
    "loads_system",
    "dump_system",
    "save_system",
    "read_toml",
    "MODEL_TYPES",
]

Model = AffineLPV | PolytopicLPV | InnovationLPV | LPVInputOutput | LTVInputOutput | LTVStateSpace
_M = TypeVar("_M")

#: Model ``type`` names in files and the classes they load as.
MODEL_TYPES: dict[str, type] = {
    "affine": AffineLPV,
    "polytopic": PolytopicLPV,
    "innovation": InnovationLPV,
    "lpv-io": LPVInputOutput,
    "ltv-io": LTVInputOutput,
    "ltv-ss": LTVStateSpace,
}


@dataclass(frozen=True)
class ParameterRange:
    """The declared range and description of a model parameter (either
    bound may be absent).

    Parameters
    ----------
    lower : float or None, default None
        The least value allowed; ``None``: no lower bound.
    upper : float or None, default None
        The greatest value allowed; ``None``: no upper bound.
    description : str, default ""
        What the parameter is (the ``description`` of its table).
    """

    lower: float | None = None
    upper: float | None = None
    description: str = ""

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies within the declared bounds.

        Parameters
        ----------
        value : float
            The parameter value.

        Returns
        -------
        inside : bool
            ``lower <= value <= upper`` for the bounds that are given.
        """
        return (self.lower is None or value >= self.lower) and (self.upper is None or value <= self.upper)

    def text(self) -> str:
        """``[lower, upper]`` with ``-inf``/``inf`` for a missing bound.

        Returns
        -------
        text : str
            The range for a message, the bounds with up to 15 significant digits.
        """
        lo = "-inf" if self.lower is None else f"{self.lower:.15g}"
        hi = "inf" if self.upper is None else f"{self.upper:.15g}"
        return f"[{lo}, {hi}]"


@dataclass(frozen=True, eq=False)
class SystemFile:
    """A loaded model file: metadata, scheduling box and the models.

    Parameters
    ----------
    name : str
        The system's name (``[system] name``).
    title : str
        One line about the system (``[system] title``).
    models : mapping of str to Model
        The models by key (``[models.KEY]``), in file order.
    default : str
        The key of the model :meth:`model` gives when none is named.
    scheduling : SchedulingSpace or None, default None
        The scheduling box (``[scheduling]``); ``None`` when the file has none.
    parameters : mapping of str to float, default {}
        The parameter values the models were built with (the file's, with the
        overrides applied).
    source : str, default ""
        Where the system comes from (``[system] source``, e.g. a paper's
        equations).
    description : str, default ""
        The ``[system] description``.
    path : pathlib.Path or None, default None
        The file read; ``None`` for a system parsed from text.
    parameter_ranges : mapping of str to ParameterRange, default {}
        Declared ranges of the parameters that have one (``[parameters]`` tables).
    """

    name: str
    title: str
    models: Mapping[str, Model]
    default: str
    scheduling: SchedulingSpace | None = None
    parameters: Mapping[str, float] = field(default_factory=dict)
    source: str = ""
    description: str = ""
    path: Path | None = None
    parameter_ranges: Mapping[str, ParameterRange] = field(default_factory=dict)

    @overload
    def model(self, key: str | None = None) -> Model: ...

    @overload
    def model(self, key: str | None, kind: type[_M]) -> _M: ...

    def model(self, key: str | None = None, kind: type[Any] | None = None) -> Any:
        """The model named ``key`` (default: the file's default model).

        Parameters
        ----------
        key : str, optional
            The model's key in ``[models.KEY]``; default: the file's ``default``.
        kind : type, optional
            The model class the caller needs (e.g. :class:`~lpvest.systems.AffineLPV`):
            a model of another type is an error naming the file, the model and
            both types (and a type checker knows the result's type).

        Returns
        -------
        Model
            The model (an instance of ``kind`` when given).

        Raises
        ------
        ModelFileError
            No model ``key``, or it is not a ``kind``.

        Examples
        --------
        >>> from lpvest import AffineLPV, load_system
        >>> load_system("cox-toth-truncation").model(None, AffineLPV).nx
        2
        """
        key = self.default if key is None else key
        try:
            found = self.models[key]
        except KeyError:
            known = shorten(", ".join(self.models), 80)
            raise ModelFileError(
                f"{self.path or self.name}: no model {abbreviate(key, 30)} (models: {known})"
            ) from None
        if kind is not None and not isinstance(found, kind):
            raise ModelFileError(f"{self.path or self.name}: model {key} is a {type(found).__name__}; "
                                 f"expected a {kind.__name__}")
        return found


# -- reading -----------------------------------------------------------------


#: The largest magnitude of a number in a model file. A product of three such
#: numbers is still finite (1e300 < 1.8e308), so matrix products and a covariance
#: step ``A P A^T`` of the file's own data cannot overflow; larger numbers are
#: refused with the field named rather than simulated into ``inf``.
MAX_MAGNITUDE = 1e100

#: The most scheduling components a file may declare: the box has 2^n corners,
#: which the polytopic form of an affine model, multilinear maps and the
#: consistency checks enumerate.
MAX_SCHEDULING = 16

#: What belongs at a matrix key of a model (for "missing (expected ...)").
_MATRIX = "a matrix"
_TERMS = "a matrix or a table of terms"
_FORMULAS = "a list of formulas"


class _Reader(TomlReader):
    """The model-file reader: the one TOML reader (every problem a one-line
    :class:`ModelFileError` naming file and field), numbers that may be
    formulas of the parameters, matrices and the model types."""

    number_what = "a number or formula"

    def __init__(self, origin: str, parameters: Mapping[str, float]) -> None:
        super().__init__(origin)
        self.parameters = dict(parameters)
        self.system_name = ""

    def name_of(self, key: str) -> str:
        """A model's name: ``system/key`` (what errors from designs and
        simulations call it)."""
        return f"{self.system_name}/{key}" if self.system_name else key

    def number(self, value: object, where: str, *, positive: bool = False, what: str | None = None) -> float:
        """A number, or a formula of the parameters (its value); finite and at
        most :data:`MAX_MAGNITUDE` in magnitude."""
        if isinstance(value, str):
            with self.at(where):
                value = Expression.parse(value, parameters=self.parameters).value()
        number = super().number(value, where, positive=positive, what=what)
        if abs(number) > MAX_MAGNITUDE:
            raise self.error(where, f"{number:.6g} is too large: numbers in a model file are at most "
                                    f"{MAX_MAGNITUDE:g} in magnitude")
        return number

    def ranged_parameter(self, spec: TomlTable) -> tuple[float, ParameterRange]:
        """``{ value = V, lower = L, upper = U, description = "..." }`` (the
        bounds and the description optional): the value and its range."""
        where = spec.where
        spec.check_keys({"value", "lower", "upper", "description"}, {"value": self.number_what})
        value = spec.number("value")
        lower = spec.number("lower", None)
        upper = spec.number("upper", None)
        if lower is not None and upper is not None and not lower <= upper:
            raise self.error(where, f"lower {lower:.15g} is above upper {upper:.15g}")
        rng = ParameterRange(lower, upper, spec.string("description", ""))
        if not rng.contains(value):
            raise self.error(f"{where}.value", f"{value:.15g} is outside its declared range {rng.text()}")
        return value, rng

    def matrix(self, value: Any, where: str) -> np.ndarray:
        """A numeric matrix: list of rows of numbers/formulas of the parameters."""
        if isinstance(value, int | float | str) and not isinstance(value, bool):
            return np.array([[self.number(value, where)]])
        if not isinstance(value, list) or not value or not all(isinstance(r, list) for r in value):
            raise self.error(where, f"expected a matrix (list of rows), found {describe_value(value)}")
        widths = sorted({len(r) for r in value})
        if len(widths) != 1:
            shown = ", ".join(map(str, widths[:4])) + (", ..." if len(widths) > 4 else "")
            raise self.error(where, f"rows have different lengths [{shown}]; expected equal")
        if widths[0] == 0:
            raise self.error(where, "expected a matrix (list of rows), found empty rows")
        return np.array(
            [[self.number(v, f"{where}[{i + 1},{j + 1}]") for j, v in enumerate(r)] for i, r in enumerate(value)]
        ).reshape(len(value), widths[0])

    # -- pieces ---------------------------------------------------------------
    def scheduling(self, data: TomlTable) -> SchedulingSpace | None:
        if "scheduling" not in data:
            return None
        sch = data.table("scheduling")
        sch.check_keys({"names", "lower", "upper"},
                       {"names": "a list of strings", "lower": "a list of numbers", "upper": "a list of numbers"})
        names = sch.strings("names")
        if not 1 <= len(names) <= MAX_SCHEDULING:
            raise self.error("scheduling.names", f"has {len(names)} names; expected 1 to {MAX_SCHEDULING} "
                                                 "(the box has 2^n corners: polytopic forms, range checks)")
        lower = sch.numbers("lower")
        upper = sch.numbers("upper")
        for key, vals in (("lower", lower), ("upper", upper)):
            if len(vals) != len(names):
                raise self.error(
                    f"scheduling.{key}", f"has {len(vals)} entries; expected {len(names)} (one per name)"
                )
        clash = sorted(set(names) & set(self.parameters))
        if clash:
            raise self.error("scheduling.names", f"{abbreviate(clash[0], 30)} is also a parameter name")
        with self.at("scheduling"):
            return SchedulingSpace(names, lower, upper)

    def need_space(self, space: SchedulingSpace | None, where: str) -> SchedulingSpace:
        if space is None:
            raise self.error(where, "this model type needs a [scheduling] table in the file")
        return space

    def basis(self, spec: Mapping, space: SchedulingSpace, matrices: Mapping, where: str) -> list[BasisFunction]:
        bounds_tab = self.table(spec.get("bounds", {}), field_path(where, "bounds"))
        if "basis" in spec:
            texts = self.strings(spec["basis"], f"{where}.basis")
        else:  # order of first appearance in the matrices
            texts = []
            for val in matrices.values():
                if isinstance(val, dict):
                    texts.extend(k for k in val if k != CONSTANT_TERM and k not in texts)
        stray = sorted(set(bounds_tab) - set(texts))
        if stray:
            raise self.error(bounds_tab.path(stray[0]), "is not a basis function of this model "
                             f"(basis: {shorten(', '.join(texts), 60) or 'none'})")
        out: list[BasisFunction] = []
        for text in texts:
            b = bounds_tab.get(text)
            bnd = None
            if b is not None:
                nums = bounds_tab.numbers(text)
                if len(nums) != 2:
                    raise self.error(bounds_tab.path(text), "expected [lower, upper]")
                bnd = (nums[0], nums[1])
            with self.at(f"{where}.basis"):
                out.append(parse_basis(text, space, bounds=bnd))
        return out

    def affine_matrices(
        self, spec: Mapping, names: tuple[str, ...], where: str
    ) -> dict[str, np.ndarray | dict[str, np.ndarray]]:
        out: dict[str, Any] = {}
        for n in names:
            if n not in spec:
                continue
            val = spec[n]
            if isinstance(val, dict):
                if not val:
                    raise self.error(f"{where}.{n}", "has no terms")
                out[n] = {term: self.matrix(m, field_path(f"{where}.{n}", term)) for term, m in val.items()}
            else:
                out[n] = self.matrix(val, f"{where}.{n}")
        return out

    def dependence(
        self, spec: Mapping, space: SchedulingSpace, names: tuple[str, ...], where: str
    ) -> AffineDependence:
        mats = self.affine_matrices(spec, names, where)
        basis = self.basis(spec, space, spec, where)
        with self.at(where):
            return AffineDependence.build(space, basis, mats)

    # -- model types ----------------------------------------------------------
    def model(self, key: str, value: Any, space: SchedulingSpace | None) -> Model:
        spec = self.table(value, field_path("models", key))
        where = spec.where
        kind = spec.choice("type", MODEL_TYPES, noun="model type")
        readers: dict[str, Callable[[str, TomlTable, SchedulingSpace | None, str], Model]] = {
            "affine": self.affine,
            "polytopic": self.polytopic,
            "innovation": self.innovation,
            "lpv-io": self.lpv_io,
            "ltv-io": self.ltv_io,
            "ltv-ss": self.ltv_ss,
        }
        return readers[kind](key, spec, space, where)

    def affine(self, key: str, spec: TomlTable, space: SchedulingSpace | None, where: str) -> AffineLPV:
        names = ("A", "B", "C", "D", "G", "H")
        spec.check_keys(
            {"type", "title", "basis", "bounds", *names, "Q", "R", "S", "x0", "P0", "Cz"},
            {"A": _TERMS, "C": _TERMS, "Q": _MATRIX, "R": _MATRIX},
        )
        space = self.need_space(space, where)
        mats = self.affine_matrices(spec, names, where)
        basis = self.basis(spec, space, spec, where)
        noise = {k: self.matrix(spec[k], f"{where}.{k}") for k in ("Q", "R", "S") if k in spec}
        x0 = self.numbers(spec["x0"], f"{where}.x0") if "x0" in spec else None
        P0 = self.matrix(spec["P0"], f"{where}.P0") if "P0" in spec else None
        Cz = self.matrix(spec["Cz"], f"{where}.Cz") if "Cz" in spec else None
        with self.at(where):
            return AffineLPV.from_matrices(space, basis, **mats, **noise, x0=x0, P0=P0, name=self.name_of(key),
                                           Cz=Cz)

    def simplex_map(self, value: Any, space: SchedulingSpace | None, where: str) -> SimplexMap:
        spec = self.table(value, where)
        space = self.need_space(space, where)
        kind = spec.choice("kind", ("formulas", "multilinear"), noun="map kind")
        if kind == "formulas":
            spec.check_keys({"kind", "alpha"}, {"alpha": _FORMULAS})
            alpha = spec.array("alpha", what=_FORMULAS)
            with self.at(f"{where}.alpha"):
                return FormulaSimplexMap(
                    space, [Expression.parse(a, parameters=self.parameters, allowed=space.names) for a in alpha]
                )
        # kind == "multilinear"
        spec.check_keys({"kind", "over", "lower", "upper"},
                        {"over": "a list of strings", "lower": "a list of numbers", "upper": "a list of numbers"})
        over = spec.strings("over")
        if not 1 <= len(over) <= MAX_SCHEDULING:
            raise self.error(f"{where}.over", f"has {len(over)} coordinates; expected 1 to {MAX_SCHEDULING} "
                                              "(the map has 2^n vertices)")
        lower = spec.numbers("lower")
        upper = spec.numbers("upper")
        with self.at(where):
            coords = [parse_basis(o, space) for o in over]
            return MultilinearSimplexMap(space, coords, lower, upper)

    def polytopic(self, key: str, spec: TomlTable, space: SchedulingSpace | None, where: str) -> PolytopicLPV:
        spec.check_keys({"type", "title", "map", "vertex", "common", "affine"})
        mapping = self.simplex_map(spec["map"], space, f"{where}.map") if "map" in spec else None
        affine = None
        if "affine" in spec:
            aff = spec.table("affine")
            aff.check_keys({"basis", "bounds", *POLYTOPIC_MATRICES, *POLYTOPIC_INPUT_MATRICES},
                           dict.fromkeys(POLYTOPIC_MATRICES, _TERMS))
            aff_space = self.need_space(space, f"{where}.affine")
            affine = self.dependence(aff, aff_space, (*POLYTOPIC_MATRICES, *POLYTOPIC_INPUT_MATRICES),
                                     f"{where}.affine")
        if "vertex" not in spec:
            if affine is None:
                raise self.error(where, "give the vertices ([[...vertex]] tables) or the affine form ([...affine])")
            if "common" in spec:
                raise self.error(f"{where}.common", "only used together with [[...vertex]] tables")
            with self.at(where):
                model = PolytopicLPV.from_affine(affine, parameters=self.parameters, name=self.name_of(key))
            if mapping is not None:
                self.check_consistent(model.vertex_stacks(), mapping, affine, where)
                model = PolytopicLPV(model.vertex_stacks(), mapping, affine, self.parameters, self.name_of(key))
            return model
        vertices = spec["vertex"]
        if not isinstance(vertices, list) or not all(isinstance(v, dict) for v in vertices) or not vertices:
            raise self.error(f"{where}.vertex", "expected one or more [[vertex]] tables")
        common = spec.table("common", required=False)
        allowed = {*POLYTOPIC_MATRICES, *POLYTOPIC_INPUT_MATRICES}
        common.check_keys(allowed)
        # a known input (Bu, and Dzu, Dyu if not zero) is optional, but then at every vertex
        inputs = [n for n in POLYTOPIC_INPUT_MATRICES if n in common or any(n in vt for vt in vertices)]
        stacks: dict[str, list[np.ndarray]] = {}
        for i, vt in enumerate(vertices):
            vw = element_path(f"{where}.vertex", i)
            self.check_keys(vt, vw, allowed)
            for n in (*POLYTOPIC_MATRICES, *inputs):
                if n in vt and n in common:
                    raise self.error(f"{vw}.{n}", f"{n} is also given in [{where}.common]")
                if n in vt:
                    stacks.setdefault(n, []).append(self.matrix(vt[n], f"{vw}.{n}"))
                elif n in common:
                    stacks.setdefault(n, []).append(self.matrix(common[n], f"{where}.common.{n}"))
                else:
                    raise self.error(vw, f"missing {n} (give it here or in [{where}.common])")
        arrays = {}
        for n, mats in stacks.items():
            shapes = {m.shape for m in mats}
            if len(shapes) != 1:
                raise self.error(f"{where}.vertex", f"{n} has different shapes at the vertices: {sorted(shapes)}")
            arrays[n] = np.stack(mats)
        with self.at(where):
            model = PolytopicLPV(arrays, mapping, affine, self.parameters, self.name_of(key))
        if affine is not None:
            if mapping is None:
                raise self.error(where, "a model with both vertices and an affine form needs a [map]")
            self.check_consistent(arrays, mapping, affine, where)
        return model

    def check_consistent(
        self, vertices: Mapping[str, np.ndarray], mapping: SimplexMap, affine: AffineDependence, where: str
    ) -> None:
        """The vertices combined by the map must reproduce the affine form."""
        space = affine.space
        pts = np.vstack([space.corners(), space.sample(np.random.default_rng(0), 16)])
        alpha = mapping.evaluate(pts)
        direct = affine.evaluate_batch(pts, check=False)
        for n in (m for m in (*POLYTOPIC_MATRICES, *POLYTOPIC_INPUT_MATRICES) if m in vertices and m in direct):
            combo = np.einsum("ti,irc->trc", alpha, vertices[n])
            err = np.max(np.abs(combo - direct[n]))
            scale = max(1.0, float(np.max(np.abs(direct[n]))))
            if err > 1e-9 * scale:
                t = int(np.argmax(np.max(np.abs(combo - direct[n]), axis=(1, 2))))
                at = ", ".join(f"{k} = {v:g}" for k, v in zip(space.names, pts[t], strict=True))
                raise self.error(
                    f"{where}.vertex",
                    f"{n} at the vertices, combined by the map, differs from the affine form by "
                    f"{err:.3g} at {at}; expected agreement",
                )

    def innovation(self, key: str, spec: TomlTable, space: SchedulingSpace | None, where: str) -> InnovationLPV:
        names = ("A", "B", "C", "D")
        spec.check_keys(
            {"type", "title", "basis", "bounds", *names, "K", "innovation_covariance", "x0"},
            {**dict.fromkeys(names, _TERMS), "K": "a matrix of formulas", "innovation_covariance": _MATRIX},
        )
        space = self.need_space(space, where)
        dep = self.dependence(spec, space, names, where)
        with self.at(f"{where}.K"):
            K = FormulaMatrix.parse(spec["K"], name="K", parameters=self.parameters, allowed=space.names)
        omega = self.matrix(spec["innovation_covariance"], f"{where}.innovation_covariance")
        x0 = self.numbers(spec["x0"], f"{where}.x0") if "x0" in spec else None
        with self.at(where):
            return InnovationLPV(dep, K, omega, x0, self.name_of(key))

    def formulas(self, value: Any, where: str, allowed: list[str]) -> list[Expression]:
        out = []
        for i, v in enumerate(self.array(value, where, what=_FORMULAS)):
            with self.at(element_path(where, i)):
                out.append(Expression.parse(v, parameters=self.parameters, allowed=allowed))
        return out

    def lpv_io(self, key: str, spec: TomlTable, space: SchedulingSpace | None, where: str) -> LPVInputOutput:
        spec.check_keys({"type", "title", "y", "u", "e", "noise_variance"}, {"y": _FORMULAS, "u": _FORMULAS})
        space = self.need_space(space, where)
        names = list(space.names)
        y = self.formulas(spec["y"], f"{where}.y", names)
        u = self.formulas(spec["u"], f"{where}.u", names)
        e = self.formulas(spec.get("e", []), f"{where}.e", names)
        var = self.number(spec.get("noise_variance", 1.0), f"{where}.noise_variance")
        with self.at(where):
            return LPVInputOutput(space, y, u, e, var, self.name_of(key))

    def ltv_io(self, key: str, spec: TomlTable, space: SchedulingSpace | None, where: str) -> LTVInputOutput:
        spec.check_keys({"type", "title", "a", "b", "input", "x0"}, {"a": _FORMULAS, "b": _FORMULAS})
        a = self.formulas(spec["a"], f"{where}.a", ["t"])
        b = self.formulas(spec["b"], f"{where}.b", ["t"])
        u = self.formulas([spec["input"]], f"{where}.input", ["t"])[0] if "input" in spec else None
        x0 = self.numbers(spec["x0"], f"{where}.x0") if "x0" in spec else None
        with self.at(where):
            return LTVInputOutput(a, b, input=u, x0=x0, name=self.name_of(key))

    def ltv_ss(self, key: str, spec: TomlTable, space: SchedulingSpace | None, where: str) -> LTVStateSpace:
        spec.check_keys({"type", "title", "A", "B", "C", "input", "x0"}, dict.fromkeys("ABC", "a matrix of formulas"))
        mats = {}
        for n in ("A", "B", "C"):
            with self.at(f"{where}.{n}"):
                mats[n] = FormulaMatrix.parse(spec[n], name=n, parameters=self.parameters, allowed=["t"])
        u = self.formulas([spec["input"]], f"{where}.input", ["t"])[0] if "input" in spec else None
        x0 = self.numbers(spec["x0"], f"{where}.x0") if "x0" in spec else None
        with self.at(where):
            return LTVStateSpace(mats["A"], mats["B"], mats["C"], input=u, x0=x0, name=self.name_of(key))



def loads_system(
    text: str,
    *,
    origin: str = "<string>",
    parameters: Mapping[str, float] | None = None,
    allow_outside_range: bool = False,
) -> SystemFile:
    """Parse a model file from TOML text (``origin`` names it in errors).

    Parameters
    ----------
    text : str
        The file's content.
    origin : str, default "<string>"
        What errors call the text (e.g. the file it came from).
    parameters : mapping of str to float, optional
        Values overriding the file's ``[parameters]``; an override outside a
        parameter's declared range is an error unless ``allow_outside_range``.
    allow_outside_range : bool, default False
        Accept overrides outside a parameter's declared range, as
        :func:`load_system` does.

    Returns
    -------
    SystemFile
        The system, with ``path`` ``None``.

    Raises
    ------
    ModelFileError
        ``text`` is not a string or not a valid model file.
    """
    if not isinstance(text, str):
        raise ModelFileError(f"{origin}: expected the TOML text as a string, found {describe_value(text)}")
    return _build(parse_toml(text, origin), origin, parameters, None, allow_outside_range)


def load_system(
    source: str | Path, *, parameters: Mapping[str, float] | None = None, allow_outside_range: bool = False
) -> SystemFile:
    """Load a model file, or an example system by name.

    Parameters
    ----------
    source : str or Path
        A path to a ``.toml`` file, or the name of an example system
        (``lpvest systems`` lists them).
    parameters : mapping, optional
        Values overriding the file's ``[parameters]`` (e.g. ``{"rho": 5.0}``).
    allow_outside_range : bool, default False
        Accept overrides outside a parameter's declared range (a study of what
        happens beyond it, such as where the plant loses stability); by default
        such an override is an error naming the parameter.

    Returns
    -------
    SystemFile
        The system, with its models built.

    Raises
    ------
    ModelFileError
        No such file or example, or the file is not a valid model file.

    Examples
    --------
    >>> system = load_system("peixoto-ex2", parameters={"rho": 5.0})
    >>> system.model().vertices.A[0]
    array([[ 1.05,  0.35],
           [-0.41, -0.25]])
    """
    from ._catalog import find_system

    path = find_system(source)
    return _build(read_toml(path), str(path), parameters, path, allow_outside_range)


#: Names a parameter may not have: the time variable of LTV formulas and the
#: names formulas already give a meaning.
_RESERVED = frozenset({"t", "shift", *FUNCTIONS, *CONSTANTS})


def _names(keys: Iterable[str]) -> str:
    """A list of names for a message, shortened."""
    return shorten(", ".join(keys), 80) or "none"


def _build(
    data: dict, origin: str, overrides: Mapping[str, float] | None, path: Path | None,
    allow_outside_range: bool = False,
) -> SystemFile:
    r = _Reader(origin, {})
    top = r.root(data)
    top.check_keys({"system", "parameters", "scheduling", "models"},
                   {"system": "a table", "models": "a table [models.NAME] per model"})
    sysmeta = top.table("system")
    sysmeta.check_keys({"name", "title", "source", "description", "default"},
                       {"name": "a string", "title": "a string"})
    name = sysmeta.string("name")
    title = sysmeta.string("title")
    if not name.strip() or len(name) > 100 or not name.isprintable():
        raise r.error("system.name", f"expected a short printable name, found {abbreviate(name, 30)}")
    r.system_name = name
    params_tab = top.table("parameters", required=False)
    params: dict[str, float] = {}
    ranges: dict[str, ParameterRange] = {}
    for k, v in params_tab.items():
        if not k.isidentifier() or k.startswith("__"):
            raise params_tab.error(k, "is not a valid name (expected a letter, then letters, digits, _)")
        if k in _RESERVED:
            raise params_tab.error(k, f"{k!r} is a name formulas reserve (t, shift, the functions and "
                                      "constants); choose another")
        if isinstance(v, dict):
            params[k], ranges[k] = r.ranged_parameter(params_tab.table(k))
        else:
            params[k] = params_tab.number(k)
    for k, v in (overrides or {}).items():
        if k not in params:
            raise r.error("parameters", f"no parameter {abbreviate(k, 30)} to override (known: {_names(params)})")
        if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
            raise r.error(f"parameters.{k}", f"override: expected a number, found {describe_value(v)}")
        params[k] = r.number(float(v), f"parameters.{k} (override)")
        if k in ranges and not ranges[k].contains(params[k]) and not allow_outside_range:
            raise r.error(f"parameters.{k}", f"override {params[k]:.15g} is outside its declared range "
                                             f"{ranges[k].text()}")
    r.parameters = params
    space = r.scheduling(top)
    models_tab = top.table("models", what="a table [models.NAME] per model")
    if not models_tab:
        raise r.error("models", "expected at least one [models.NAME] table")
    models = {key: r.model(key, spec, space) for key, spec in models_tab.items()}
    default = sysmeta.string("default", next(iter(models)))
    if default not in models:
        raise r.error("system.default", f"no model {abbreviate(default, 30)} (models: {_names(models)})")
    return SystemFile(
        name=name,
        title=title,
        models=models,
        default=default,
        scheduling=space,
        parameters=params,
        source=sysmeta.string("source", ""),
        description=sysmeta.string("description", ""),
        path=path,
        parameter_ranges=ranges,
    )


# -- writing -----------------------------------------------------------------


def _model_out(model: Model) -> dict:
    to_toml = getattr(model, "to_toml", None)
    if to_toml is None:
        raise ModelFileError(f"{type(model).__name__} cannot be written to a model file")
    return to_toml()


def _parameter_out(value: float, rng: ParameterRange | None) -> Any:
    if rng is None:
        return number(value)
    out: dict[str, Any] = {"value": number(value)}
    if rng.lower is not None:
        out["lower"] = number(rng.lower)
    if rng.upper is not None:
        out["upper"] = number(rng.upper)
    if rng.description:
        out["description"] = rng.description
    return out


def dump_system(system: SystemFile) -> str:
    """The system as TOML text. Matrices are written with their values (model
    parameters already applied); loading the text gives the same models.

    Parameters
    ----------
    system : SystemFile
        The system; its ``path`` is not written.

    Returns
    -------
    text : str
        The TOML text.

    Raises
    ------
    ModelFileError
        A model cannot be written to a model file (it has no ``to_toml``).
    """
    import tomli_w

    meta = {"name": system.name, "title": system.title, "default": system.default}
    if system.source:
        meta["source"] = system.source
    if system.description:
        meta["description"] = system.description
    data: dict[str, Any] = {"system": meta}
    if system.parameters:
        data["parameters"] = {k: _parameter_out(v, system.parameter_ranges.get(k))
                              for k, v in system.parameters.items()}
    if system.scheduling is not None:
        s = system.scheduling
        data["scheduling"] = {
            "names": list(s.names),
            "lower": [number(v) for v in s.lower],
            "upper": [number(v) for v in s.upper],
        }
    data["models"] = {k: _model_out(m) for k, m in system.models.items()}
    return tomli_w.dumps(data)


def save_system(system: SystemFile, path: str | Path) -> Path:
    """Write :func:`dump_system` to ``path``.

    Parameters
    ----------
    system : SystemFile
        The system.
    path : os.PathLike or str
        The file to write (UTF-8; its folder is created); an existing file is
        replaced.

    Returns
    -------
    path : pathlib.Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputError
        The file cannot be written (the message names it and says why).
    """
    path = Path(path)
    text = dump_system(system)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write the model file {shorten(str(path), 60)}: "
                          f"{exc.strerror or type(exc).__name__}") from exc
    return path

