"""A build cache of FMUs: each built on demand into a folder and reused while it
is up to date.

An FMU is up to date when its *fingerprint* is the one recorded in
``manifest.json`` at build time and the file's SHA-256 is unchanged. The
fingerprint hashes everything the FMU is made from, as its manifest records it
(the code it carries, the model file, the build plan, the design file,
pythonfmu and the compiler), plus the solver versions when a design is solved
at build time. Any change rebuilds; nothing is guessed from time stamps.

:class:`FmuCache` holds the mechanism; a subclass says which FMUs exist
(:class:`~lpvest.experiments.ExperimentFmus`: the paper experiments').

Examples
--------
>>> from lpvest.fmi import plan_system
>>> plans, _ = plan_system("sridhar-ltv")
>>> digest = fingerprint(plans[0])          # what the FMU is made from
>>> len(digest), digest == fingerprint(plan_system("sridhar-ltv")[0][0])
(64, True)
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import shutil
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from ..core._errors import LpvestError
from ..core._paths import user_cache_dir

if TYPE_CHECKING:
    from ._build import FmuPlan

__all__ = ["FmuCache", "FmuCacheError", "fingerprint", "default_cache_dir", "CACHE_FORMAT"]

#: The format tag of ``manifest.json``.
CACHE_FORMAT = "lpvest-fmu-cache/2"


class FmuCacheError(LpvestError, RuntimeError):
    """An FMU of a cache could not be built or is unknown."""


# ---------------------------------------------------------------------------
# fingerprints
# ---------------------------------------------------------------------------
@cache
def _solver_versions() -> str:
    from importlib.metadata import PackageNotFoundError, version

    out = []
    for name in ("numpy", "scipy", "cvxpy", "clarabel"):
        try:
            out.append(f"{name}={version(name)}")
        except PackageNotFoundError:
            out.append(f"{name}=none")
    return ";".join(out)


def fingerprint(plan: FmuPlan, backend: str = "pythonfmu") -> str:
    """SHA-256 of everything an FMU of ``plan`` (a :class:`~lpvest.fmi.FmuPlan`)
    is made from: the inputs its manifest records (:func:`lpvest.fmi._build.manifest_inputs`:
    plan, model file, carried code, design file, pythonfmu, compiler; for the
    native backend :func:`lpvest.fmi.native._build.native_manifest_inputs`: plan,
    model file, the C runtime, zig and its flags), and for a design solved at
    build time the versions of the solver stack."""
    from ._build import backend_of, manifest_inputs

    if backend_of(plan, backend) == "native":
        from .native._build import native_manifest_inputs

        inputs = native_manifest_inputs(plan)
        if plan.design is not None:
            inputs["design_file_sha256"] = hashlib.sha256(Path(plan.design).read_bytes()).hexdigest()
    else:
        inputs = manifest_inputs(plan)
    if plan.estimator is not None and plan.estimator.design and plan.design is None:
        inputs["solvers"] = _solver_versions()
    return hashlib.sha256((CACHE_FORMAT + json.dumps(inputs, sort_keys=True)).encode()).hexdigest()


def _file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def default_cache_dir() -> Path:
    """``$LPVEST_FMU_CACHE``, else ``$XDG_CACHE_HOME/lpvest/fmus`` (``~/.cache/lpvest/fmus``)."""
    env = os.environ.get("LPVEST_FMU_CACHE")
    if env:
        return Path(env)
    return user_cache_dir("fmus")


# ---------------------------------------------------------------------------
# the cache
# ---------------------------------------------------------------------------
class FmuCache:
    """FMUs in a cache folder, built when missing or stale.

    A subclass says which FMUs exist: :meth:`plan` gives the
    :class:`~lpvest.fmi.FmuPlan` of an identifier, :meth:`known` whether
    an identifier is one of them
    (:class:`~lpvest.experiments.ExperimentFmus`: the paper experiments').

    ``fmus["PeixotoEx1Plant"]`` (or :meth:`path`) returns the FMU's path,
    building and validating it first when it is missing or out of date.
    :attr:`built` and :attr:`reused` list what happened. :meth:`resolved`
    gives a copy for other processes (it pickles) that serves the FMUs
    checked here and builds nothing.

    Parameters
    ----------
    directory : str or Path
        The cache folder (created when needed): ``<identifier>.fmu`` files and
        ``manifest.json``.
    progress : callable, optional
        Called with a message before each build (the CLI prints it).
    backend : str, default "pythonfmu"
        The FMU backend (:data:`lpvest.fmi._build.BACKENDS`); ``"native"``
        builds every discrete-time role as C (the others stay pythonfmu FMUs).

    Raises
    ------
    ArgumentError
        ``backend`` is not one of :data:`lpvest.fmi._build.BACKENDS`.
    """

    def __init__(self, directory: str | Path, *, progress: Callable[[str], None] | None = None,
                 backend: str = "pythonfmu") -> None:
        from ._build import check_backend

        self.directory = Path(directory)
        self.progress = progress
        self.backend = check_backend(backend)
        self.built: list[str] = []
        self.reused: list[str] = []
        self.build_time = 0.0
        self._checked: dict[str, Path] = {}
        self._lock = threading.Lock()
        #: only the checked FMUs are served (a copy made by :meth:`resolved`)
        self._fixed = False

    def __getstate__(self) -> dict[str, object]:
        state = dict(self.__dict__)
        del state["_lock"]
        state["progress"] = None  # a callback of this process
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    # -- manifest -------------------------------------------------------------
    @property
    def manifest_path(self) -> Path:
        return self.directory / "manifest.json"

    def _manifest(self) -> dict[str, Any]:
        try:
            data = json.loads(self.manifest_path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            return {}
        if not isinstance(data, dict) or data.get("format") != CACHE_FORMAT:
            return {}
        fmus = data.get("fmus", {})
        return fmus if isinstance(fmus, dict) else {}

    def _record(self, identifier: str, entry: dict[str, object]) -> None:
        fmus = self._manifest()
        fmus[identifier] = entry
        self.directory.mkdir(parents=True, exist_ok=True)
        tmp = self.manifest_path.with_suffix(f".json.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"format": CACHE_FORMAT, "fmus": fmus}, indent=1, sort_keys=True) + "\n",
                       encoding="utf-8")
        tmp.replace(self.manifest_path)

    # -- what exists ----------------------------------------------------------
    def plan(self, identifier: str) -> FmuPlan:
        """The :class:`~lpvest.fmi.FmuPlan` of ``identifier``.

        A subclass implements it; here it raises ``NotImplementedError``.

        Parameters
        ----------
        identifier : str
            An FMU of this cache (:meth:`known`).

        Returns
        -------
        FmuPlan
            What the FMU is built from.
        """
        raise NotImplementedError

    def known(self, identifier: str) -> bool:
        """Whether ``identifier`` names an FMU of this cache.

        A subclass implements it; here it raises ``NotImplementedError``.

        Parameters
        ----------
        identifier : str
            An FMU identifier (``PeixotoEx1Plant``).

        Returns
        -------
        bool
            True when :meth:`plan` can plan it.
        """
        raise NotImplementedError

    # -- access ---------------------------------------------------------------
    def path(self, identifier: str) -> Path:
        """The FMU's path; built (and validated) first when missing or stale.

        Parameters
        ----------
        identifier : str
            An FMU of this cache.

        Returns
        -------
        Path
            ``directory/<identifier>.fmu``, up to date.

        Raises
        ------
        FmuCacheError
            The FMU was not resolved for this copy (:meth:`resolved`), or the
            built FMU fails validation.
        """
        with self._lock:
            if identifier in self._checked:
                return self._checked[identifier]
            if self._fixed:
                raise FmuCacheError(f"{identifier} was not resolved for this process (resolved: "
                                    f"{', '.join(self._checked) or 'none'}): declare it with the experiment")
            plan = self.plan(identifier)
            want = fingerprint(plan, self.backend)
            if not self._up_to_date(identifier, want):
                self._build(plan, want, self.directory / f"{identifier}.fmu")
            self._checked[identifier] = self.directory / f"{identifier}.fmu"
            return self._checked[identifier]

    def _up_to_date(self, identifier: str, want: str) -> bool:
        """Whether the FMU file is the one recorded with the fingerprint ``want`` (then it counts as reused)."""
        target = self.directory / f"{identifier}.fmu"
        known = self._manifest().get(identifier, {})
        if target.is_file() and known.get("fingerprint") == want and known.get("sha256") == _file_digest(target):
            self.reused.append(identifier)
            return True
        return False

    def stale(self, identifiers: Iterable[str]) -> list[str]:
        """Which of ``identifiers`` need a build; the others are checked (as :meth:`path` does).

        With :meth:`build_file` (in other processes) and :meth:`record`
        (here), the stale FMUs can be built side by side.

        Parameters
        ----------
        identifiers : iterable of str
            FMUs of this cache.

        Returns
        -------
        list of str
            The missing or out-of-date ones, in the given order.
        """
        out = []
        with self._lock:
            for identifier in dict.fromkeys(identifiers):
                if identifier in self._checked:
                    continue
                if self._up_to_date(identifier, fingerprint(self.plan(identifier), self.backend)):
                    self._checked[identifier] = self.directory / f"{identifier}.fmu"
                else:
                    out.append(identifier)
        return out

    def build_file(self, identifier: str) -> dict[str, Any]:
        """Build and validate one FMU into the cache folder and record nothing
        (another process may :meth:`record` it); safe side by side for different FMUs.

        Parameters
        ----------
        identifier : str
            An FMU of this cache.

        Returns
        -------
        dict
            The manifest entry for :meth:`record` (``fingerprint``, ``sha256``,
            ``built``) and ``seconds``, the build's time.

        Raises
        ------
        FmuCacheError
            The built FMU fails validation.
        """
        from ._build import backend_of, build_fmu, validate_fmus

        plan = self.plan(identifier)
        want = fingerprint(plan, self.backend)
        t = time.perf_counter()
        path = build_fmu(plan, self.directory, backend=backend_of(plan, self.backend))
        (check,) = validate_fmus([path])
        if not check.ok:
            raise FmuCacheError(f"{identifier}: the built FMU fails validation: " + "; ".join(check.problems))
        return {"fingerprint": want, "sha256": _file_digest(path), "built": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "seconds": time.perf_counter() - t}

    def record(self, identifier: str, entry: Mapping[str, Any]) -> Path:
        """Record an FMU that :meth:`build_file` built (in this or another process).

        Parameters
        ----------
        identifier : str
            The FMU.
        entry : mapping
            What :meth:`build_file` returned.

        Returns
        -------
        Path
            The FMU's path, now checked.
        """
        with self._lock:
            self._record(identifier, {k: entry[k] for k in ("fingerprint", "sha256", "built")})
            self.built.append(identifier)
            self.build_time += float(entry["seconds"])
            self._checked[identifier] = self.directory / f"{identifier}.fmu"
            return self._checked[identifier]

    __getitem__ = path

    def paths(self, identifiers: Iterable[str]) -> dict[str, Path]:
        """The paths of several FMUs, each as :meth:`path` gives it.

        Parameters
        ----------
        identifiers : iterable of str
            FMUs of this cache.

        Returns
        -------
        dict of str to Path
            Each identifier's FMU, up to date, in the given order.
        """
        return {i: self.path(i) for i in identifiers}

    def resolved(self, identifiers: Iterable[str]) -> Self:
        """A copy that serves ``identifiers``, built or checked here first, and
        nothing else: what another process (a Dask worker) gets, so that no two
        processes build into one folder. It pickles (without :attr:`progress`).

        Parameters
        ----------
        identifiers : iterable of str
            The FMUs the other process may use.

        Returns
        -------
        FmuCache
            Of the same class; its :meth:`path` raises
            :class:`FmuCacheError` for any other identifier.
        """
        paths = self.paths(identifiers)
        view = copy.copy(self)
        view.__setstate__({**self.__getstate__(), "_checked": paths, "_fixed": True, "built": [], "reused": [],
                           "build_time": 0.0})
        return view

    def _build(self, plan: FmuPlan, want: str, target: Path) -> None:
        from ._build import backend_of

        if self.progress is not None:
            backend = backend_of(plan, self.backend)
            self.progress(f"building {plan.identifier} into {self.directory}" + (
                f" ({backend})" if self.backend != "pythonfmu" else ""))
        entry = self.build_file(plan.identifier)
        assert entry["fingerprint"] == want
        self._record(plan.identifier, {k: entry[k] for k in ("fingerprint", "sha256", "built")})
        self.build_time += entry["seconds"]
        self.built.append(plan.identifier)

    def adopt(self, paths: Mapping[str, str | Path]) -> None:
        """Take FMUs built from the current code elsewhere (e.g. a test
        session's FMU set) into the cache: copied and recorded as up to date.
        Identifiers this cache does not know are ignored.

        Parameters
        ----------
        paths : mapping of str to str or Path
            FMU files by identifier. They are not rebuilt nor compared with the
            current plan: the caller vouches that they were built from it.
            Identifiers already checked here are left alone.
        """
        with self._lock:
            for identifier, src in paths.items():
                if not self.known(identifier) or identifier in self._checked:
                    continue
                plan = self.plan(identifier)
                target = self.directory / f"{identifier}.fmu"
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, target)
                self._record(identifier, {"fingerprint": fingerprint(plan, self.backend),
                                          "sha256": _file_digest(target), "built": "adopted from " + str(src)})

    def summary(self) -> str:
        """One line: how many FMUs were built and reused, and where.

        Returns
        -------
        str
            E.g. ``"FMU cache <directory>: built 2 (3.1 s), reused 5 up-to-date"``.
        """
        parts = []
        if self.built:
            parts.append(f"built {len(self.built)} ({self.build_time:.1f} s)")
        if self.reused:
            parts.append(f"reused {len(self.reused)} up-to-date")
        backend = "" if self.backend == "pythonfmu" else f" ({self.backend} backend)"
        return f"FMU cache {self.directory}{backend}: " + (", ".join(parts) if parts else "nothing used yet")
