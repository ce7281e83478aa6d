"""The result of an H-infinity filter design, and its JSON file (numpy only).

A :class:`HinfDesign` holds the filter of eq. (2) of Peixoto et al.
(001_00f62b5a0c49ad87.txt)::

    H(alpha_k) x_{f,k+1} = A_f(alpha_k) x_{f,k} + B_f(alpha_k) y_k
    z_{f,k}              = C_f(alpha_k) x_{f,k} + D_f(alpha_k) y_k,

by its vertex matrices ``H_i, A_{f,i}, B_{f,i}, C_{f,i}, D_{f,i}`` (one set for a
robust filter, Corollary 1), the certified bound ``gamma``, the line-search
scalar ``epsilon``, the Lyapunov matrices that certify it, how the solver fared
and how the certificate checked. The filter FMU carries the JSON file written
by :meth:`HinfDesign.to_json`; reading it needs only numpy.

JSON format (``"format": "lpvest.hinf-design"``, ``"version": 1``)::

    {
      "format": "lpvest.hinf-design", "version": 1,
      "kind": "parameter-dependent" | "robust",
      "plant": "peixoto-ex1",                  # name of the plant (informative)
      "model_digest": "3f2a...",               # SHA-256 of the plant's vertex matrices (optional)
      "n_vertices": N, "nx": nx, "ny": ny, "nz": nz, "nw": nw,
      "gamma": 1.2087,                         # certified l2-gain bound
      "epsilon": 150.0,                        # null when epsilon = infinity
      "multiplier": [a, b],                    # epsilon = a / b, a^2 + b^2 = 1
      "filter": {"H": [[[...]]], "Af": ..., "Bf": ..., "Cf": ..., "Df": ...},
      "lyapunov": [[[...]]],                   # P_i, shape (N, 2 nx, 2 nx)
      "solver": {"name": "CLARABEL", "status": "optimal",
                 "compile_time": 0.12, "solve_time": 0.01},
      "check": {"lmi_margin": 1.0e-6, "lyapunov_margin": 3.2e-3, "n_lmis": 6}
    }

Each filter matrix is a list over vertices (length ``N`` for a
parameter-dependent filter, 1 for a robust one) of row lists. Floats are
written with ``repr`` precision, so a round trip is exact.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, cast

import numpy as np

from ..core._errors import ArgumentError, DimensionError, ModelFileError, abbreviate
from ..core._linalg import MatrixStack
from ..core._validation import as_vector, check_simplex

if TYPE_CHECKING:
    from ..systems._polytopic import PolytopicLPV

__all__ = [
    "HinfDesign",
    "FilterMatrices",
    "KIND_PD",
    "KIND_ROBUST",
    "DESIGN_FORMAT",
    "DESIGN_FORMAT_VERSION",
    "model_digest",
    "without_timings",
]

#: ``kind`` of a parameter-dependent (gain-scheduled) filter, Theorem 1.
KIND_PD = "parameter-dependent"
#: ``kind`` of a robust filter (constant matrices), Corollary 1.
KIND_ROBUST = "robust"
#: ``format`` tag of the JSON file.
DESIGN_FORMAT = "lpvest.hinf-design"
#: Version of the JSON file format.
DESIGN_FORMAT_VERSION = 1

_FILTER_NAMES = ("H", "Af", "Bf", "Cf", "Df")
_PLANT_NAMES = ("A", "Bw", "Cz", "Dz", "Cy", "Dy")


def model_digest(plant: PolytopicLPV) -> str:
    """SHA-256 of a polytopic plant's vertex matrices (their float64 values,
    shapes and names): a design made for the plant records it, and a filter is
    built from the design only for a plant with the same digest. Model files
    are parsed exactly, so the same file gives the same digest on every machine.

    Parameters
    ----------
    plant : PolytopicLPV
        The plant; its ``vertices`` ``A, Bw, Cz, Dz, Cy, Dy`` (shape ``(N, rows, cols)`` each) enter the digest.

    Returns
    -------
    str
        The SHA-256 digest, 64 hexadecimal digits.
    """
    h = hashlib.sha256(b"lpvest.polytopic-vertices/1\0")
    for name in _PLANT_NAMES:
        arr = np.ascontiguousarray(getattr(plant.vertices, name), dtype="<f8")
        h.update(f"{name}{arr.shape}".encode() + arr.tobytes())
    return h.hexdigest()


class FilterMatrices(NamedTuple):
    """The filter matrices of eq. (2) at one ``alpha``.

    Parameters
    ----------
    H : ndarray, shape (nx, nx)
        ``H(alpha)``, which multiplies ``x_{f,k+1}``.
    Af : ndarray, shape (nx, nx)
        ``A_f(alpha)``, which multiplies ``x_{f,k}``.
    Bf : ndarray, shape (nx, ny)
        ``B_f(alpha)``, which multiplies the measurement ``y_k`` in the state equation.
    Cf : ndarray, shape (nz, nx)
        ``C_f(alpha)``: the estimate ``z_{f,k}`` from ``x_{f,k}``.
    Df : ndarray, shape (nz, ny)
        ``D_f(alpha)``: the estimate ``z_{f,k}`` from ``y_k`` (feedthrough).
    """

    H: np.ndarray
    Af: np.ndarray
    Bf: np.ndarray
    Cf: np.ndarray
    Df: np.ndarray


@dataclass(frozen=True, eq=False)
class HinfDesign:
    """A designed H-infinity filter (Theorem 1 or Corollary 1) and its certificate.

    Parameters
    ----------
    kind : {"parameter-dependent", "robust"}
        Theorem 1 (gain-scheduled filter, ``KIND_PD``) or Corollary 1 (robust filter, ``KIND_ROBUST``).
    H, Af : ndarray, shape (N_f, nx, nx)
        Vertex matrices; ``N_f = N`` (parameter-dependent) or ``1`` (robust).
    Bf : ndarray, shape (N_f, nx, ny)
    Cf : ndarray, shape (N_f, nz, nx)
    Df : ndarray, shape (N_f, nz, ny)
    gamma : float
        The certified bound on the l2-induced gain from ``w`` to ``e = z - z_f``.
    epsilon : float
        The paper's scalar (``math.inf`` for the limit ``epsilon -> infinity``).
    multiplier : (float, float)
        ``(a, b)`` with ``epsilon = a / b`` and ``a^2 + b^2 = 1``. The matrices
        are the paper's filter at ``epsilon`` in the state coordinates
        ``b * x_f`` (an exact rescaling, see :mod:`lpvest.design`).
    lyapunov : ndarray, shape (N, 2 nx, 2 nx)
        ``P_i = [[P_{1,i}, P_{3,i}], [P_{3,i}^T, P_{2,i}]]`` of the certificate
        ``V = xi^T P(alpha) xi`` with ``xi = (x, x_f)`` in the same coordinates.
    solver, status : str
        Solver name and the final ``problem.status``.
    compile_time, solve_time : float
        Seconds: one-time compilation of the LMI program that produced this
        design (shared by every solve of that program), and the solves at
        this ``epsilon`` (a retry at the larger margin and a fallback solver
        included); ``nan`` when read from a file without them (the design an
        FMU carries: :func:`without_timings`).
    lmi_margin : float
        ``-max`` eigenvalue over every LMI (6)-(7) at the returned point (> 0).
    lyapunov_margin : float
        Smallest eigenvalue over the ``P_i`` (> 0).
    n_lmis : int
        Number of LMIs (6)-(7) checked.
    nw : int
        Disturbance dimension of the plant it was designed for.
    plant : str
        Name of the plant (informative).
    model_digest : str
        :func:`model_digest` of the plant it was designed for (``""``: not recorded).
    """

    kind: str
    H: np.ndarray
    Af: np.ndarray
    Bf: np.ndarray
    Cf: np.ndarray
    Df: np.ndarray
    gamma: float
    epsilon: float
    multiplier: tuple[float, float]
    lyapunov: np.ndarray
    solver: str
    status: str
    compile_time: float
    solve_time: float
    lmi_margin: float
    lyapunov_margin: float
    n_lmis: int
    nw: int
    plant: str = ""
    model_digest: str = ""
    if TYPE_CHECKING:  # not a field: set in __post_init__ (a frozen class); declared for the type checker only
        _stack: MatrixStack = dataclasses.field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in (KIND_PD, KIND_ROBUST):
            raise ArgumentError(f"kind must be {KIND_PD!r} or {KIND_ROBUST!r}; found {abbreviate(self.kind, 30)}")
        arrays = {}
        for name in (*_FILTER_NAMES, "lyapunov"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.ndim != 3:
                raise DimensionError(f"{name} has shape {arr.shape}; expected (vertices, rows, cols)")
            if not np.all(np.isfinite(arr)):
                raise DimensionError(f"{name} holds non-finite values")
            arr.setflags(write=False)
            arrays[name] = arr
        nf, nx = arrays["H"].shape[0], arrays["H"].shape[1]
        ny, nz = arrays["Bf"].shape[2], arrays["Cf"].shape[1]
        n = arrays["lyapunov"].shape[0]
        expected = {
            "H": (nf, nx, nx),
            "Af": (nf, nx, nx),
            "Bf": (nf, nx, ny),
            "Cf": (nf, nz, nx),
            "Df": (nf, nz, ny),
            "lyapunov": (n, 2 * nx, 2 * nx),
        }
        for name, shape in expected.items():
            if arrays[name].shape != shape:
                raise DimensionError(f"{name} has shape {arrays[name].shape}; expected {shape}")
        want_nf = 1 if self.kind == KIND_ROBUST else n
        if nf != want_nf:
            raise DimensionError(
                f"a {self.kind} design needs {want_nf} set(s) of filter matrices; found {nf}"
            )
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "_stack", MatrixStack({n: arrays[n] for n in _FILTER_NAMES}))
        a, b = (float(v) for v in self.multiplier)
        object.__setattr__(self, "multiplier", (a, b))
        object.__setattr__(self, "gamma", float(self.gamma))
        object.__setattr__(self, "epsilon", float(self.epsilon))

    # -- dimensions -------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        """Number of vertices ``N`` of the plant's polytope."""
        return int(self.lyapunov.shape[0])

    @property
    def nx(self) -> int:
        return int(self.H.shape[1])

    @property
    def ny(self) -> int:
        return int(self.Bf.shape[2])

    @property
    def nz(self) -> int:
        return int(self.Cf.shape[1])

    def check_model(self, plant: PolytopicLPV, *, source: str = "design", plant_name: str = "") -> None:
        """Raise :class:`~lpvest.core.ModelFileError` unless this design fits
        ``plant``: same dimensions, and the same vertex matrices when the
        design recorded them (:func:`model_digest`).

        Parameters
        ----------
        plant : PolytopicLPV
            The plant the design is to filter (a model with general noise in its
            H-infinity setting, :func:`lpvest.systems.hinf_setting`); its
            ``n_vertices, nx, ny, nz, nw`` must equal the design's.
        source : str, default "design"
            What the design is (e.g. its file path): the start of the error message.
        plant_name : str, default ""
            The plant's name in the error message (``""``: ``plant.name``, or "this one").

        Raises
        ------
        ModelFileError
            A dimension differs, or the design recorded a :func:`model_digest` that is not the plant's.
        """
        got = {"n_vertices": plant.n_vertices, "nx": plant.nx, "ny": plant.ny, "nz": plant.nz, "nw": plant.nw}
        want = {"n_vertices": self.n_vertices, "nx": self.nx, "ny": self.ny, "nz": self.nz, "nw": self.nw}
        for key, value in want.items():
            if got[key] != value:
                raise ModelFileError(f"{source}: designed for a plant with {key} = {value}; this plant has {got[key]}")
        if self.model_digest and self.model_digest != model_digest(plant):
            raise ModelFileError(
                f"{source}: designed for another plant ({self.plant or 'unnamed'}, vertex digest "
                f"{self.model_digest[:12]}...) than {plant_name or getattr(plant, 'name', '') or 'this one'} "
                f"({model_digest(plant)[:12]}...); design it again with `lpvest design`"
            )

    @property
    def scheduled(self) -> bool:
        """True for a parameter-dependent filter (it needs ``alpha``)."""
        return self.kind == KIND_PD

    # -- evaluation -------------------------------------------------------------
    def matrices_at(self, alpha: object | None = None, *, check: bool = True) -> FilterMatrices:
        """The filter matrices at ``alpha`` (shape (N,), on the simplex; ``check=False``:
        a validated ``alpha``, not checked again).

        A robust design ignores ``alpha`` (it may be ``None``).

        Parameters
        ----------
        alpha : array_like, shape (N,), optional
            Scheduling parameter on the unit simplex; required for a parameter-dependent
            design, ignored by a robust one.
        check : bool, default True
            Validate ``alpha`` (shape, finite, on the simplex); ``False``: ``alpha`` is
            taken as an already validated ndarray.

        Returns
        -------
        FilterMatrices
            ``sum_i alpha_i (H_i, A_{f,i}, B_{f,i}, C_{f,i}, D_{f,i})`` (parameter-dependent),
            as fresh arrays, or the single set of a robust design (read-only views).

        Raises
        ------
        DimensionError
            ``alpha`` is ``None`` for a parameter-dependent design, or has the wrong shape.
        SchedulingRangeError
            ``alpha`` is not on the unit simplex (with ``check=True``).
        """
        if not self.scheduled:
            return FilterMatrices(*(getattr(self, n)[0] for n in _FILTER_NAMES))
        if alpha is None:
            raise DimensionError(f"a {self.kind} filter needs alpha of shape ({self.n_vertices},)")
        if check:
            alpha = as_vector(alpha, "alpha", self.n_vertices)
            check_simplex(alpha, "alpha")
        # check=False: the caller gives a validated ndarray (see above)
        return FilterMatrices(**self._stack.at(cast(np.ndarray, alpha)))

    # -- JSON -------------------------------------------------------------------
    def to_dict(self) -> dict[str, object]:
        """The JSON-able dictionary described in the module documentation.

        Returns
        -------
        dict
            Plain Python values (lists, floats, str); ``"epsilon"`` is ``None`` for
            ``epsilon = inf``.
        """
        return {
            "format": DESIGN_FORMAT,
            "version": DESIGN_FORMAT_VERSION,
            "kind": self.kind,
            "plant": self.plant,
            "n_vertices": self.n_vertices,
            "nx": self.nx,
            "ny": self.ny,
            "nz": self.nz,
            "nw": self.nw,
            "model_digest": self.model_digest,
            "gamma": self.gamma,
            "epsilon": None if math.isinf(self.epsilon) else self.epsilon,
            "multiplier": list(self.multiplier),
            "filter": {n: getattr(self, n).tolist() for n in _FILTER_NAMES},
            "lyapunov": self.lyapunov.tolist(),
            "solver": {
                "name": self.solver,
                "status": self.status,
                "compile_time": self.compile_time,
                "solve_time": self.solve_time,
            },
            "check": {
                "lmi_margin": self.lmi_margin,
                "lyapunov_margin": self.lyapunov_margin,
                "n_lmis": self.n_lmis,
            },
        }

    def to_json(self, path: str | Path | None = None) -> str:
        """The design as JSON text; also written to ``path`` when given.

        Parameters
        ----------
        path : str or Path, optional
            File to write (UTF-8, overwritten); by default nothing is written.

        Returns
        -------
        str
            The JSON text of :meth:`to_dict` (indented, ending with a newline).
        """
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"
        if path is not None:
            Path(path).write_text(text, encoding="utf-8")
        return text

    @classmethod
    def from_dict(cls, data: Mapping[str, object], *, source: str = "design") -> HinfDesign:
        """Inverse of :meth:`to_dict`; raises :class:`~lpvest.core.ModelFileError`
        naming ``source`` and the field when the data are malformed.

        Parameters
        ----------
        data : mapping
            The dictionary of the JSON format (``"format": "lpvest.hinf-design"``,
            ``"version": 1``); ``"plant"`` and ``"model_digest"`` may be missing.
        source : str, default "design"
            Where the data came from (e.g. a file path), for error messages.

        Returns
        -------
        HinfDesign
            The design; its dimensions agree with ``n_vertices, nx, ny, nz`` of ``data``.
        """

        def field(mapping: Mapping[str, object], key: str, where: str = "") -> Any:
            if not isinstance(mapping, Mapping) or key not in mapping:
                raise ModelFileError(f"{source}: missing field {where}{key!r}")
            return mapping[key]

        if not isinstance(data, Mapping) or data.get("format") != DESIGN_FORMAT:
            raise ModelFileError(f"{source}: not an lpvest H-infinity design (format != {DESIGN_FORMAT!r})")
        version = field(data, "version")
        if version != DESIGN_FORMAT_VERSION:
            raise ModelFileError(
                f"{source}: design format version {abbreviate(version, 30)}; this lpvest reads {DESIGN_FORMAT_VERSION}"
            )
        filt = field(data, "filter")
        solver = field(data, "solver")
        check = field(data, "check")
        eps = field(data, "epsilon")
        try:
            design = cls(
                kind=field(data, "kind"),
                H=np.array(field(filt, "H", "filter."), dtype=float),
                Af=np.array(field(filt, "Af", "filter."), dtype=float),
                Bf=np.array(field(filt, "Bf", "filter."), dtype=float),
                Cf=np.array(field(filt, "Cf", "filter."), dtype=float),
                Df=np.array(field(filt, "Df", "filter."), dtype=float),
                gamma=float(field(data, "gamma")),
                epsilon=math.inf if eps is None else float(eps),
                # a tuple of any length to mypy; __post_init__ unpacks it into (a, b)
                multiplier=tuple(float(v) for v in field(data, "multiplier")),  # type: ignore[arg-type]  # see above
                lyapunov=np.array(field(data, "lyapunov"), dtype=float),
                solver=str(field(solver, "name", "solver.")),
                status=str(field(solver, "status", "solver.")),
                compile_time=float(solver.get("compile_time", math.nan)),
                solve_time=float(solver.get("solve_time", math.nan)),
                lmi_margin=float(field(check, "lmi_margin", "check.")),
                lyapunov_margin=float(field(check, "lyapunov_margin", "check.")),
                n_lmis=int(field(check, "n_lmis", "check.")),
                nw=int(field(data, "nw")),
                plant=str(data.get("plant", "")),
                model_digest=str(data.get("model_digest", "")),
            )
        except ModelFileError:
            raise
        except (ValueError, TypeError) as exc:
            raise ModelFileError(f"{source}: {exc}") from exc
        for key in ("n_vertices", "nx", "ny", "nz"):
            if field(data, key) != getattr(design, key):
                raise ModelFileError(
                    f"{source}: {key} = {abbreviate(data[key], 30)} disagrees with the matrices "
                    f"({getattr(design, key)})"
                )
        return design

    @classmethod
    def from_json(cls, source: str | Path) -> HinfDesign:
        """Load a design from a JSON file path or from JSON text.

        Parameters
        ----------
        source : str or Path
            A :class:`~pathlib.Path`, a path string, or JSON text (a string whose first
            non-blank character is ``{``).

        Returns
        -------
        HinfDesign
            The design read by :meth:`from_dict`.

        Raises
        ------
        ModelFileError
            The file cannot be read, is not valid JSON, or is not a valid design.

        Examples
        --------
        >>> import lpvest
        >>> from lpvest.design import design_hinf
        >>> d = design_hinf(lpvest.load_system("peixoto-ex1").model(), epsilon=150.0)
        >>> HinfDesign.from_json(d.to_json()).gamma == d.gamma
        True
        """
        text: str
        name = "design"
        if isinstance(source, Path) or (isinstance(source, str) and not source.lstrip().startswith("{")):
            path = Path(source)
            name = str(path)
            try:
                text = path.read_text(encoding="utf-8")
            except OSError as exc:
                raise ModelFileError(f"{path}: cannot be read: {exc.strerror}") from exc
        else:
            text = str(source)
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelFileError(f"{name}: not valid JSON: {exc}") from exc
        return cls.from_dict(data, source=name)


def without_timings(text: str) -> str:
    """The JSON text of a design (:meth:`HinfDesign.to_json`) without the
    solver's compile and solve times, the only fields that differ between two
    solves of the same program: what an FMU carries, so that two builds give
    the same bytes. Text in another format is returned as is."""
    try:
        data = json.loads(text)
    except ValueError:
        return text
    if not isinstance(data, dict) or data.get("format") != DESIGN_FORMAT or not isinstance(data.get("solver"), dict):
        return text
    data["solver"] = {k: v for k, v in data["solver"].items() if k not in ("compile_time", "solve_time")}
    return json.dumps(data, indent=1, allow_nan=False) + "\n"
