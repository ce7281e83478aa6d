"""The model data of a native FMU: ``model_data.c``, generated from the library's objects.

A native FMU is the runtime (``runtime/*.c``, one for every FMU) plus one
generated file that defines ``lpv_model_data`` (``runtime/lpv.h``): the FMI
variables of the Python FMU of the same role (read from its slave, so the two
declare the same names, kinds, ranges and start values), the ports, the
parameters, and the role's numbers and formulas. Numbers are C99 hex-float
literals (``0x1.8p+1``: exact, no decimal rounding); formulas are stack code
compiled from their parsed trees (:mod:`lpvest.fmi.native`). The
numbers are the library's own: the vertex or coefficient stacks of the model,
the Cholesky factor of its noise covariance, a Kalman filter's packed
coefficients (:attr:`lpvest.estimators.kalman.KalmanModel.packing`), the
truncated filter's theorem start covariance, an H-infinity design's matrices.

**Model parameters** (a model file's ``[parameters]`` that are FMU
parameters, e.g. ``rho``) reach the runtime as formulas of matrix entries:
the exporter builds the component again at other values of each parameter
and requires every carried number that changes to be a matrix entry that the
model file writes as a formula of the parameters (its formula is carried and
evaluated when the FMU is initialized). A parameter that changes anything
else (a Cholesky factor, a product of matrices, a map) cannot be followed by
the runtime: the build says so, naming the parameter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ...core._errors import LpvestError
from ...core._expressions import Expression
from ...core._scheduling import FormulaBasis, Monomial
from ._formulas import OPS, CompiledFormula, compile_formula

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ...core._protocol import Component, Port
    from ...core._signals import SchedulerComponent, SourceComponent
    from ...estimators._hinf import HinfFilter
    from ...estimators._truncated import TruncatedKalmanFilter
    from ...estimators.kalman._streaming import LPVKalmanFilter
    from ...systems._streaming import DiscretePlant

__all__ = ["NativeExportError", "RoleData", "role_data", "model_data_c", "native_unsupported", "ROLE_CODES"]

#: The runtime's role codes (``LPV_ROLE_*`` in ``runtime/lpv.h``).
ROLE_CODES = {"Plant": 1, "Scheduler": 2, "Source": 3, "Kalman": 4, "TruncatedKalman": 5, "HinfPD": 6,
              "HinfRobust": 6}


#: Model parameters a native FMU holds (``LPV_MAX_MODEL_PARAMS`` in runtime/lpv.h: an instance's
#: array of their values, which formulas index).
MAX_MODEL_PARAMS = 64


class NativeExportError(LpvestError, ValueError):
    """An FMU cannot be exported to the native backend (the message says why)."""


def native_unsupported(role: str, script: str) -> str | None:
    """Why a planned FMU gets no native build (``None``: it does).

    Parameters
    ----------
    role : str
        The FMU role (``Plant``, ``Kalman``, ...).
    script : str
        The role script of its plan (``lpvest_ltv_plant.py`` is the
        continuous-time LTV plant).

    Returns
    -------
    str or None
        The reason, or ``None``.
    """
    if script == "lpvest_ltv_plant.py":
        return "the continuous-time LTV plant integrates with scipy (DOP853): it stays a pythonfmu FMU"
    if role not in ROLE_CODES:
        return f"the {role} role has no native runtime: it stays a pythonfmu FMU"
    return None


# ---------------------------------------------------------------------------
# the role's data, as Python values (compared across parameter values, then written)
# ---------------------------------------------------------------------------


@dataclass
class RoleData:
    """What the runtime needs of one component: the C struct type of its data,
    its fields (ints, arrays, formulas, nested structs) and the name of the
    field that model-parameter entries write into (array 0)."""

    ctype: str
    fields: dict[str, _Field] = field(default_factory=dict)
    entries_target: str | None = None


@dataclass(frozen=True)
class _Formulas:
    items: tuple[CompiledFormula, ...]


@dataclass(frozen=True)
class _Strings:
    items: tuple[str, ...]


@dataclass(frozen=True)
class _Ints:
    items: tuple[int, ...]


@dataclass(frozen=True)
class _Struct:
    ctype: str
    fields: tuple[tuple[str, _Field], ...]


#: A value of a C struct field: a number, a string, NULL, an array of doubles, ints, strings or formulas, a
#: nested struct or an array of structs (what _Writer.value writes)
_Field = (None | bool | int | float | str | np.integer | np.bool_ | np.ndarray | _Ints | _Strings | _Formulas | _Struct
         | tuple[_Struct, ...])


def _doubles(a: ArrayLike) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).reshape(-1)


def _monomial_code(m: Monomial) -> CompiledFormula:
    """``out = 1.0; out *= p_j ** e_j`` for every ``e_j != 0`` (Monomial.__call__)."""
    code = [OPS["CONST"], 0]
    constants = [1.0]
    for j, e in enumerate(m.exponents):
        if e:
            if float(e) not in constants:
                constants.append(float(e))
            code += [OPS["VAR"], j, OPS["CONST"], constants.index(float(e)), OPS["POW"], OPS["MUL"]]
    code.append(OPS["END"])
    return CompiledFormula(tuple(code), tuple(constants), 3, m.name)


def _basis_code(b: object, names: Sequence[str]) -> CompiledFormula:
    if isinstance(b, Monomial):
        return _monomial_code(b)
    if isinstance(b, FormulaBasis):
        if tuple(b.names) != tuple(names):
            raise NativeExportError(f"basis function {b.name!r} is written over {b.names}; expected {tuple(names)}")
        return compile_formula(b.expression, names)
    raise NativeExportError(f"basis function {getattr(b, 'name', b)!r} is a Python callable: the native backend "
                            "needs formulas (build it with the pythonfmu backend)")


def _map(simplex_map: object, names: Sequence[str]) -> _Struct:
    """An lpv_map of a simplex map (None: LPV_MAP_NONE)."""
    from ...systems._polytopic import FormulaSimplexMap, MultilinearSimplexMap

    if simplex_map is None:
        return _Struct("lpv_map", (("kind", 0), ("n_out", 0), ("n_formulas", 0), ("formulas", _Formulas(())),
                                   ("lower", None), ("upper", None)))
    if isinstance(simplex_map, FormulaSimplexMap):
        forms = tuple(compile_formula(f, names) for f in simplex_map.formulas)
        return _Struct("lpv_map", (("kind", 1), ("n_out", len(forms)), ("n_formulas", len(forms)),
                                   ("formulas", _Formulas(forms)), ("lower", None), ("upper", None)))
    if isinstance(simplex_map, MultilinearSimplexMap):
        coords = tuple(_basis_code(c, names) for c in simplex_map.coordinates)
        return _Struct("lpv_map", (("kind", 2), ("n_out", simplex_map.n_vertices), ("n_formulas", len(coords)),
                                   ("formulas", _Formulas(coords)), ("lower", _doubles(simplex_map.lower)),
                                   ("upper", _doubles(simplex_map.upper))))
    raise NativeExportError(f"a simplex map of type {type(simplex_map).__name__} has no native form")


def _stack(named: Mapping[str, np.ndarray], order: Sequence[str]) -> tuple[_Struct, dict[str, int], np.ndarray]:
    """Matrices side by side (MatrixStack's layout): the lpv_stack, each name's offset, the rows."""
    arrays = [np.asarray(named[n], dtype=np.float64) for n in order if n in named]
    n_terms = arrays[0].shape[0]
    offsets: dict[str, int] = {}
    pos = 0
    for n in order:
        if n in named:
            offsets[n] = pos
            pos += int(np.prod(named[n].shape[1:], dtype=int))
    rows = np.concatenate([a.reshape(n_terms, -1) for a in arrays], axis=1)
    struct = _Struct("lpv_stack", (("n_terms", n_terms), ("width", rows.shape[1]), ("rows", _doubles(rows))))
    return struct, offsets, rows


def _port_offsets(ports: Sequence[Port]) -> dict[str, int]:
    out, pos = {}, 0
    for p in ports:
        out[p.name] = pos
        pos += p.size
    return out


def _plant(component: DiscretePlant, ins: dict[str, int], outs: dict[str, int]) -> RoleData:
    from ...systems._affine import AffineLPV
    from ...systems._innovation import InnovationLPV, LPVInputOutput
    from ...systems._polytopic import PolytopicLPV

    model = component.model
    f: dict[str, _Field] = {}
    nu = getattr(model, "nu", 0)
    if isinstance(model, PolytopicLPV):
        order: tuple[str, ...] = ("A", "Bw", "Cz", "Dz", "Cy", "Dy", "Bu", "Dzu", "Dyu")
        stack, off, _ = _stack(model.vertex_stacks(), order)
        names = model.space.names if model.space is not None else ()
        f.update(kind=0, nx=model.nx, nu=nu, ny=model.ny, nz=model.nz, nw=model.nw, nv=0,
                 n_p=len(names), stack=stack, mat=_Ints(tuple(off.get(n, -1) for n in order)),
                 map=_map(model.simplex_map, names), n_basis=0, basis=_Formulas(()), n_noise=0, chol=None,
                 K=_Formulas(()), K_text=None)
    elif isinstance(model, AffineLPV | InnovationLPV):
        dep = model.dependence
        order = ("A", "B", "C", "D", "G", "H")
        stack, off, _ = _stack(dep.coefficients, order)
        names = model.space.names
        chol = _doubles(np.linalg.cholesky(model.noise.joint if isinstance(model, AffineLPV)
                                           else model.innovation_covariance))
        n_noise = int(round(math.sqrt(chol.size)))
        K = _Formulas(())
        K_text = None
        if isinstance(model, InnovationLPV):
            entries = [e for row in model.K.entries for e in row]
            K = _Formulas(tuple(compile_formula(e, names) for e in entries))
            K_text = _Strings(tuple(e.text for e in entries))
        f.update(kind=1 if isinstance(model, AffineLPV) else 2, nx=model.nx, nu=nu, ny=model.ny, nz=0,
                 nw=getattr(model, "nw", 0), nv=getattr(model, "nv", 0), n_p=len(names), stack=stack,
                 mat=_Ints(tuple(off.get(n, -1) for n in order) + (-1, -1, -1)), map=_map(None, names),
                 n_basis=len(dep.basis), basis=_Formulas(tuple(_basis_code(b, names) for b in dep.basis)),
                 n_noise=n_noise, chol=chol, K=K, K_text=K_text)
    elif isinstance(model, LPVInputOutput):
        names = model.space.names
        coeffs = (*model.y_coefficients, *model.u_coefficients, *model.e_coefficients)
        empty = _Struct("lpv_stack", (("n_terms", 0), ("width", 0), ("rows", _doubles(np.zeros(0)))))
        f.update(kind=3, nx=model.nx, nu=model.nu, ny=1, nz=0, nw=0, nv=0, n_p=len(names), stack=empty,
                 mat=_Ints((-1,) * 9), map=_map(None, names), n_basis=0, basis=_Formulas(()), n_noise=1,
                 chol=_doubles(np.linalg.cholesky(np.array([[model.noise_variance]]))),
                 K=_Formulas(tuple(compile_formula(e, names) for e in coeffs)),
                 K_text=_Strings(tuple(e.text for e in coeffs)),
                 io_n=_Ints((len(model.y_coefficients), len(model.u_coefficients), len(model.e_coefficients))))
    else:
        raise NativeExportError(f"a plant of {type(model).__name__} has no native form")
    f.update(in_p=ins.get("p", -1), in_alpha=ins.get("alpha", -1), in_u=ins.get("u", -1), in_w=ins.get("w", -1),
             in_v=ins.get("v", -1), in_e=ins.get("e", -1), out_y=outs.get("y", -1), out_z=outs.get("z", -1),
             out_x=outs.get("x", -1))
    return RoleData("lpv_plant_data", f, "stack.rows")


def _scheduler(component: SchedulerComponent, outs: dict[str, int]) -> RoleData:
    space = component.space
    return RoleData("lpv_scheduler_data", {
        "n_p": space.dim, "lower": _doubles(space.lower), "upper": _doubles(space.upper),
        "names": _Strings(tuple(space.names)), "map": _map(component.simplex_map, space.names),
        "out_p": outs.get("p", -1), "out_alpha": outs.get("alpha", -1)})


def _source(component: SourceComponent, outs: dict[str, int]) -> RoleData:
    defs = tuple(_Struct("lpv_signal_def", (("name", name), ("prefix", f"{name}."), ("n", spec.n),
                                            ("out", outs[name])))
                 for name, spec in component.signals.items())
    return RoleData("lpv_source_data", {"n_signals": len(defs), "signals": defs})


def _kalman(
    component: LPVKalmanFilter | TruncatedKalmanFilter, ins: dict[str, int], outs: dict[str, int], truncated: bool
) -> RoleData:
    from ...estimators._truncated import theorem_start_covariance
    from ...estimators.kalman import KalmanModel

    model = component.kalman_model.model
    km = KalmanModel(model)
    packed, pairs, shape = km.packing
    names = model.space.names
    f: dict[str, _Field] = dict(
        nx=km.nx, nu=km.nu, ny=km.ny, n_p=model.n_p, n_basis=len(model.basis),
        basis=_Formulas(tuple(_basis_code(b, names) for b in model.basis)), n_z=packed.shape[0],
        pairs=_Ints(tuple(v for pq in pairs for v in pq)), f_rows=shape[0], f_cols=shape[1], packed=_doubles(packed),
        in_p=ins.get("p", -1), in_u=ins.get("u", -1), in_y=ins.get("y", -1),
        out_xhat=outs.get("xhat", -1), out_P=outs.get("P", -1), out_xpred=outs.get("xpred", -1),
        out_Ppred=outs.get("Ppred", -1), out_yhat=outs.get("yhat", -1), out_innovation=outs.get("innovation", -1),
        out_K=outs.get("K", -1), out_Omega=outs.get("Omega", -1), out_loglik=outs.get("loglik", -1),
        x0=_doubles(model.x0), P0=_doubles(model.P0), theorem_start=None, theorem_error=None,
        box_lower=_doubles(model.space.lower), box_upper=_doubles(model.space.upper), names=_Strings(tuple(names)))
    if truncated:
        try:
            f["theorem_start"] = _doubles(theorem_start_covariance(km))
        except LpvestError as exc:
            f["theorem_error"] = str(exc)
    return RoleData("lpv_kalman_data", f, "packed")


def _hinf(component: HinfFilter, ins: dict[str, int], outs: dict[str, int]) -> RoleData:
    design = component.design
    stack, off, _ = _stack({n: getattr(design, n) for n in ("H", "Af", "Bf", "Cf", "Df")},
                           ("H", "Af", "Bf", "Cf", "Df"))
    plant = component.plant
    names = component.simplex_map.space.names if component.simplex_map is not None else ()
    f: dict[str, _Field] = dict(
        nx=design.nx, ny=design.ny, nz=design.nz, scheduled=int(design.scheduled), n_vertices=design.n_vertices,
        design=stack, fmat=_Ints(tuple(off[n] for n in ("H", "Af", "Bf", "Cf", "Df"))),
        needs_alpha=int(component.scheduled), map=_map(component.simplex_map, names))
    path_order = ("A", "Cz", "Cy", "Bu", "Dzu", "Dyu")
    if plant is not None:
        pstack, poff, _ = _stack(plant.vertex_stacks(), path_order)
        f.update(has_u=1, nu=plant.nu, npx=plant.nx, path_varies=int(plant.input_path_varies()), path=pstack,
                 pmat=_Ints(tuple(poff[n] for n in path_order)))
    else:
        f.update(has_u=0, nu=0, npx=0, path_varies=0,
                 path=_Struct("lpv_stack", (("n_terms", 0), ("width", 0), ("rows", None))), pmat=_Ints((-1,) * 6))
    sched = ins.get("alpha", ins.get("p", -1))
    f.update(in_sched=sched, in_u=ins.get("u", -1), in_y=ins.get("y", -1), out_zhat=outs.get("zhat", -1),
             out_xf=outs.get("xf", -1))
    return RoleData("lpv_hinf_data", f)


def role_data(role: str, component: object) -> RoleData:
    """The runtime's data of a component (the slave's ``make_component``).

    Parameters
    ----------
    role : str
        The FMU role (a key of :data:`ROLE_CODES`).
    component : object
        The streaming component the Python FMU runs (a measurement delay
        wrapper is looked through: the runtime wraps its own).

    Returns
    -------
    RoleData
        Its data.
    """
    # the role names the component's class (what the role script's make_component builds)
    inner = cast("Component", getattr(component, "component", component))  # MeasurementDelay -> the filter
    ins = _port_offsets(inner.input_ports)
    outs = _port_offsets(inner.output_ports)
    if role == "Plant":
        return _plant(cast("DiscretePlant", inner), ins, outs)
    if role == "Scheduler":
        return _scheduler(cast("SchedulerComponent", inner), outs)
    if role == "Source":
        return _source(cast("SourceComponent", inner), outs)
    if role in ("Kalman", "TruncatedKalman"):
        return _kalman(cast("LPVKalmanFilter | TruncatedKalmanFilter", inner), ins, outs, role == "TruncatedKalman")
    if role in ("HinfPD", "HinfRobust"):
        return _hinf(cast("HinfFilter", inner), ins, outs)
    raise NativeExportError(f"the {role} role has no native runtime")


# ---------------------------------------------------------------------------
# model parameters: entries of the carried matrices that are formulas of them
# ---------------------------------------------------------------------------


def _flat(value: object, prefix: str, out: dict[str, object]) -> None:
    """Every leaf of a role's data by path (arrays as bytes, formulas as code)."""
    if isinstance(value, _Struct):
        for k, v in value.fields:
            _flat(v, f"{prefix}.{k}", out)
    elif isinstance(value, dict):
        for k, v in value.items():
            _flat(v, f"{prefix}.{k}" if prefix else k, out)
    elif isinstance(value, tuple) and value and isinstance(value[0], _Struct):
        for i, v in enumerate(value):
            _flat(v, f"{prefix}[{i}]", out)
    elif isinstance(value, np.ndarray):
        out[prefix] = value
    elif isinstance(value, _Formulas):
        out[prefix] = tuple((c.code, tuple(float(x).hex() for x in c.constants)) for c in value.items)
    else:
        out[prefix] = value


def _array_at(data: RoleData, path: str) -> np.ndarray:
    flat: dict[str, object] = {}
    _flat(data.fields, "", flat)
    return np.asarray(flat[path])


def _candidate_formulas(model_table: object, names: Iterable[str]) -> list[Expression]:
    """The model file's formulas (strings) that use the parameters ``names`` only."""
    wanted = set(names)
    found: list[Expression] = []
    seen: set[str] = set()
    stack = [model_table]
    while stack:
        v = stack.pop()
        if isinstance(v, dict):
            stack.extend(v.values())
        elif isinstance(v, list):
            stack.extend(v)
        elif isinstance(v, str) and v not in seen:
            seen.add(v)
            try:
                e = Expression.parse(v)
            except LpvestError:
                continue
            if e.names and e.names <= wanted:
                found.append(e)
    return found


@dataclass(frozen=True)
class Entry:
    """An element of the carried matrices that is a formula of the model parameters."""

    index: int
    formula: CompiledFormula


def parameter_entries(
    identifier: str,
    role: str,
    make: Callable[[dict[str, float | str]], object],
    params: Mapping[str, float | str],
    model_params: Sequence[str],
    ranges: Mapping[str, tuple[float | None, float | None]],
    model_table: object,
) -> list[Entry]:
    """The carried numbers that follow the model parameters, as formulas of them.

    ``make(params)`` builds the component for parameter values; each model
    parameter is moved to other values in its range (one at a time), and every
    carried number that changes must equal, at every value tried, a formula of
    the model file over the model parameters.

    Raises
    ------
    NativeExportError
        A parameter changes something else, or nothing can be matched.
    """
    if not model_params:
        return []
    if len(model_params) > MAX_MODEL_PARAMS:
        raise NativeExportError(
            f"{identifier}: {len(model_params)} model parameters; a native FMU takes at most {MAX_MODEL_PARAMS} "
            "(build it with the pythonfmu backend)")
    base = role_data(role, make(dict(params)))
    target = base.entries_target
    base_flat: dict[str, object] = {}
    _flat(base.fields, "", base_flat)
    candidates = _candidate_formulas(model_table, model_params)
    compiled = {id(e): compile_formula(e, list(model_params)) for e in candidates}
    changed: dict[int, list[tuple[dict[str, float], float]]] = {}
    default_values = {n: float(params[n]) for n in model_params}
    for name in model_params:
        lo, hi = ranges.get(name, (None, None))
        x = default_values[name]
        if lo is not None and hi is not None and hi > lo:
            trials = [lo + f * (hi - lo) for f in (0.3, 0.7, 0.1, 0.9)]
        else:
            trials = [x * 1.25 + 0.5, x * 0.75 - 0.25, x + 1.0, x - 1.0]
        trials = [t for t in trials if t != x]
        done = 0
        for value in trials:
            values = dict(default_values, **{name: value})
            try:
                other = role_data(role, make(dict(params, **values)))
            except LpvestError:
                continue
            other_flat: dict[str, object] = {}
            _flat(other.fields, "", other_flat)
            for key, v in base_flat.items():
                w = other_flat[key]
                same = (np.array_equal(np.asarray(v).view(np.uint8), np.asarray(w).view(np.uint8))
                        if isinstance(v, np.ndarray) else v == w)
                if same:
                    continue
                if key != target:
                    raise NativeExportError(
                        f"{identifier}: model parameter {name} changes {key.lstrip('.')} of the {role}, which the "
                        "native runtime does not compute (only matrix entries of the model file may be formulas of "
                        "a parameter in a native FMU); build it with backend='pythonfmu'")
                va, wa = np.asarray(v), np.asarray(w)
                for k in np.flatnonzero(va.view(np.uint64) != wa.view(np.uint64)).tolist():
                    changed.setdefault(int(k), []).append((values, float(wa[k])))
            done += 1
            if done >= 2:
                break
        if done < 2:
            raise NativeExportError(f"{identifier}: the model cannot be built at other values of parameter {name} "
                                    "to see what it changes (native backend)")
    if not changed:
        return []
    assert target is not None
    carried = _array_at(base, target)
    entries = []
    for i, seen_values in sorted(changed.items()):
        points = [(default_values, float(carried[i])), *seen_values]
        match = None
        for e in candidates:
            try:
                if all(float(e.evaluate(vals)).hex() == v.hex() for vals, v in points):
                    match = e
                    break
            except (LpvestError, ArithmeticError, ValueError):
                continue
        if match is None:
            raise NativeExportError(
                f"{identifier}: a number of the {role} follows the model parameters ({', '.join(model_params)}) "
                "but is no formula of the model file; build it with backend='pythonfmu'")
        entries.append(Entry(i, compiled[id(match)]))
    return entries


# ---------------------------------------------------------------------------
# C text
# ---------------------------------------------------------------------------


def _c_double(x: float) -> str:
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "HUGE_VAL" if x > 0 else "(-HUGE_VAL)"
    return float(x).hex()


def _c_string(text: str | None) -> str:
    if text is None:
        return "NULL"
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        if ch in '"\\':
            out.append("\\" + ch)
        elif 32 <= byte < 127 and ch != "?":
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


class _Writer:
    def __init__(self) -> None:
        self.decls: list[str] = []
        self.count = 0

    def name(self, base: str) -> str:
        self.count += 1
        return f"{base}{self.count}"

    def doubles(self, values: np.ndarray) -> str:
        if values.size == 0:
            return "NULL"
        n = self.name("d")
        body = ",\n    ".join(", ".join(_c_double(float(v)) for v in values[i:i + 4]) for i in range(0, values.size, 4))
        self.decls.append(f"static const double {n}[{values.size}] = {{\n    {body}}};")
        return n

    def ints(self, values: Sequence[int]) -> str:
        if not values:
            return "NULL"
        n = self.name("i")
        self.decls.append(f"static const int {n}[{len(values)}] = {{{', '.join(str(int(v)) for v in values)}}};")
        return n

    def strings(self, values: Sequence[str]) -> str:
        if not values:
            return "NULL"
        n = self.name("s")
        items = ", ".join(_c_string(v) for v in values)
        self.decls.append(f"static const char* const {n}[{len(values)}] = {{{items}}};")
        return n

    def formula(self, f: CompiledFormula) -> str:
        code = self.name("c")
        self.decls.append(f"static const int32_t {code}[{len(f.code)}] = {{{', '.join(str(c) for c in f.code)}}};")
        consts = self.doubles(np.asarray(f.constants, dtype=np.float64))
        return f"{{{code}, {consts}}}"

    def formulas(self, items: Sequence[CompiledFormula]) -> str:
        if not items:
            return "NULL"
        inits = [self.formula(f) for f in items]
        n = self.name("f")
        self.decls.append(f"static const lpv_formula {n}[{len(items)}] = {{{', '.join(inits)}}};")
        return n

    def value(self, v: object, key: str = "") -> str:
        if v is None:
            return "NULL"
        if isinstance(v, bool | np.bool_):
            return "1" if v else "0"
        if isinstance(v, int | np.integer):
            return str(int(v))
        if isinstance(v, float):
            return _c_double(v)
        if isinstance(v, str):
            return _c_string(v)
        if isinstance(v, np.ndarray):
            return self.doubles(_doubles(v))
        if isinstance(v, _Ints):  # an array inside the struct, or a pointer to one
            return "{" + ", ".join(str(i) for i in v.items) + "}" if key in _INLINE_INTS else self.ints(v.items)
        if isinstance(v, _Formulas):
            return self.formulas(v.items)
        if isinstance(v, _Strings):
            return self.strings(v.items)
        if isinstance(v, _Struct):
            return "{" + ", ".join(f".{k} = {self.value(x, k)}" for k, x in v.fields) + "}"
        if isinstance(v, tuple) and all(isinstance(x, _Struct) for x in v):
            n = self.name("a")
            ctype = v[0].ctype if v else "int"
            items = ", ".join(self.value(x) for x in v)
            self.decls.append(f"static const {ctype} {n}[{max(1, len(v))}] = {{{items}}};")
            return n
        raise NativeExportError(f"cannot write {type(v).__name__} into model_data.c")


#: The fields whose pointer arrays are written with a fixed size in the struct (ints inline)
_INLINE_INTS = {"mat", "fmat", "pmat", "io_n"}


def model_data_c(
    *,
    identifier: str,
    guid: str,
    version: str,
    role: str,
    table: Mapping[str, Any],
    data: RoleData,
    late_inputs: Sequence[str],
    model_params: Sequence[str],
    entries: Sequence[Entry],
    header: str,
) -> str:
    """The text of ``model_data.c`` (see the module documentation).

    Parameters
    ----------
    identifier, guid, version : str
        The FMU's model identifier and GUID, lpvest's version.
    role : str
        The FMU role.
    table : mapping
        The slave's :meth:`~lpvest.fmi._slave.LpvestSlave.variable_table`.
    data : RoleData
        :func:`role_data` of its component.
    late_inputs : sequence of str
        The inputs that may arrive late (measurement delay).
    model_params : sequence of str
        The model parameters that are FMU parameters, in formula order.
    entries : sequence of Entry
        :func:`parameter_entries`.
    header : str
        A comment for the top of the file.

    Returns
    -------
    str
        C99 source defining ``lpv_model_data``.
    """
    w = _Writer()
    # parameters: typed slots in declaration order
    counters = {"Real": 0, "Integer": 0, "Boolean": 0, "String": 0}
    type_code = {"Real": 0, "Integer": 1, "Boolean": 2, "String": 3}
    param_index: dict[str, int] = {}
    param_slot: dict[str, int] = {}
    param_inits = []
    for i, par in enumerate(table["parameters"]):
        t = par.fmi_type
        size = int(np.prod(par.shape, dtype=int)) if par.shape else 1
        slot = counters[t]
        counters[t] += size
        param_index[par.name] = i
        param_slot[par.name] = slot
        start_real = "NULL"
        start_int = 0
        start_string = "NULL"
        if t == "Real":
            start_real = w.doubles(_doubles(par.start))
        elif t in ("Integer", "Boolean"):
            start_int = int(par.start)
        else:
            start_string = _c_string(str(par.start))
        param_inits.append(f"{{{_c_string(par.name)}, {type_code[t]}, {size}, {slot}, {start_real}, {start_int}, "
                           f"{start_string}}}")
    # ports
    port_index: dict[tuple[str, str], int] = {}
    port_offset: dict[tuple[str, str], int] = {}

    def ports(kind: str, items: Sequence[Port]) -> tuple[str, int]:
        inits, pos = [], 0
        for i, p in enumerate(items):
            port_index[(kind, p.name)] = i
            port_offset[(kind, p.name)] = pos
            inits.append(f"{{{_c_string(p.name)}, {p.size}, {pos}, {int(getattr(p, 'direct', True))}, "
                         f"{int(p.name in late_inputs)}}}")
            pos += p.size
        if not inits:
            return "NULL", 0
        n = w.name("port")
        w.decls.append(f"static const lpv_port {n}[{len(inits)}] = {{\n    {(',' + chr(10) + '    ').join(inits)}}};")
        return n, pos

    in_ports, n_inputs = ports("input", table["inputs"])
    out_ports, n_outputs = ports("output", table["outputs"])
    # variables
    kinds = {"parameter": 0, "input": 1, "output": 2}
    var_inits = []
    for v in table["variables"]:
        kind = v["kind"]
        if kind == "parameter":
            owner, slot = param_index[v["owner"]], param_slot[v["owner"]] + v["index"]
        else:
            owner = port_index[(kind, v["owner"])]
            slot = port_offset[(kind, v["owner"])] + v["index"]
        lo, hi = v["minimum"], v["maximum"]
        var_inits.append(
            f"{{{_c_string(v['name'])}, {_c_string(v['what'])}, {kinds[kind]}, {type_code[v['type']]}, {owner}, "
            f"{slot}, {int(lo is not None)}, {int(hi is not None)}, {_c_double(float(lo or 0.0))}, "
            f"{_c_double(float(hi or 0.0))}, {_c_double(float(v['tol']))}}}")
    vars_name = w.name("var")
    w.decls.append(f"static const lpv_var {vars_name}[{len(var_inits)}] = {{\n    " + ",\n    ".join(var_inits) + "};")
    params_name = "NULL"
    if param_inits:
        params_name = w.name("param")
        w.decls.append(f"static const lpv_param {params_name}[{len(param_inits)}] = {{\n    "
                       + ",\n    ".join(param_inits) + "};")
    sample_time = param_slot["sample_time"] if table.get("sample_time") == "sample_time" else -1
    delay = param_slot.get("measurement_delay", -1) if "measurement_delay" in param_index else -1
    mp_slots = w.ints([param_slot[n] for n in model_params])
    entry_name = "NULL"
    if entries:
        inits = [f"{{0, {e.index}, {w.formula(e.formula)}}}" for e in entries]
        entry_name = w.name("entry")
        w.decls.append(f"static const lpv_entry {entry_name}[{len(inits)}] = {{{', '.join(inits)}}};")
    # the role's data
    fields = []
    for k, v in data.fields.items():
        fields.append(f".{k} = {w.value(v, k)}")
    data_name = w.name("role")
    w.decls.append(f"static const {data.ctype} {data_name} = {{\n    " + ",\n    ".join(fields) + "};")
    model = ",\n    ".join([
        f".identifier = {_c_string(identifier)}", f".guid = {_c_string(guid)}", f".version = {_c_string(version)}",
        f".role = {ROLE_CODES[role]}", f".n_vars = {len(var_inits)}", f".vars = {vars_name}",
        f".n_params = {len(param_inits)}", f".params = {params_name}",
        f".n_real = {counters['Real']}", f".n_int = {counters['Integer']}", f".n_bool = {counters['Boolean']}",
        f".n_string = {counters['String']}",
        f".n_in_ports = {len(table['inputs'])}", f".in_ports = {in_ports}", f".n_inputs = {n_inputs}",
        f".n_out_ports = {len(table['outputs'])}", f".out_ports = {out_ports}", f".n_outputs = {n_outputs}",
        f".timed = {int(bool(table['timed']))}", f".sample_time = {sample_time}", f".measurement_delay = {delay}",
        f".n_model_params = {len(model_params)}", f".model_params = {mp_slots}",
        f".n_entries = {len(entries)}", f".entries = {entry_name}", f".data = &{data_name}",
    ])
    lines = [f"/* {line} */" if line else "" for line in header.splitlines()]
    return "\n".join([*lines, "#include <math.h>", "#include <stddef.h>", "#include <stdint.h>", "",
                      '#include "lpv.h"', "", *w.decls, "",
                      f"const lpv_model lpv_model_data = {{\n    {model}}};", ""])
