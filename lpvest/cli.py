"""The ``lpvest`` command line.

::

    lpvest systems                          the example systems, one line each
    lpvest systems show NAME|FILE.toml      dimensions, matrices, scheduling map
    lpvest simulate NAME|FILE.toml          simulate one model: CSV, plot, summary
    lpvest reproduce NAME|all --out DIR [--backend native] [--quiet]
                                            reproduce paper examples through FMUs (all: + DIR/report.md)
    lpvest regress [--update] [--quiet]     FMU co-simulations against tests/data/reference
    lpvest build [--out DIR] [--model FILE.toml ...] [--kinds ROLES] [--design [ROLE=]FILE.json]
                 [--backend pythonfmu|native]
                                            build and validate the FMUs (native: C, no Python needed)
    lpvest design NAME|FILE.toml [--kind pd|robust] [--epsilon E|--search] [--solver S] --out FILE.json
                                            design an H-infinity filter, write it as JSON
    lpvest cosim FILE.toml [--out DIR] [--fmus DIR]    co-simulate FMUs described in a file: CSV, plot, summary
    lpvest cosim FILE.toml --ssp OUT.ssp [--worker-threads N|none]
                                            write that system as an SSP file instead
    lpvest sweep SPEC.toml [--out DIR] [--workers N | --scheduler ADDRESS] [--fmus DIR]
                                            a co-simulation (or experiment) over seeds and parameters, on Dask
    lpvest validate FMU...                  validate FMUs (fmpy.validation)

Errors in the user's input print one line (``lpvest: error: ...``) and exit
with status 2; no traceback (``lpvest --debug ...`` shows it). Every
subcommand has a description and examples in ``lpvest COMMAND --help``.
"""

from __future__ import annotations

import argparse
import atexit
import dataclasses
import difflib
import json
import os
import re
import signal
import sys
import time
import warnings
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from .core._errors import ArgumentError, LpvestError, OutputError, abbreviate, one_line, shorten
from .core._interrupt import abandoned_calls, exit_status, handling_signals

__all__ = ["main", "describe_model"]


def _parse_params(items: Sequence[str] | None) -> dict[str, float]:
    out = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ArgumentError(f"--param {abbreviate(item)}: expected NAME=VALUE")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ArgumentError(f"--param {abbreviate(item)}: {abbreviate(value, 30)} is not a number") from None
    return out


def _out_dir(path: str | Path, option: str = "--out") -> Path:
    """The output folder, created and writable, before any slow work; one line
    naming the option (and the part of the path in the way) if it cannot be.
    Every command that writes uses it."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if isinstance(exc, FileExistsError | NotADirectoryError):
            blocker = next((p for p in (out, *out.parents) if p.exists() and not p.is_dir()), out)
            reason = f"{shorten(str(blocker), 60)} is a file, not a folder"
        else:  # e.g. "permission denied", as the check below says it
            reason = str(exc.strerror or exc)
            reason = reason[:1].lower() + reason[1:]
        raise OutputError(f"{option} {shorten(str(out), 60)}: cannot create the output folder ({reason})"
                          ) from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {shorten(str(out), 60)}: cannot write in the output folder (permission denied)")
    return out


def _out_file(path: str, option: str, kind: str, is_kind: Callable[[Path], bool]) -> Path:
    """An output file: its folder as :func:`_out_dir`, not a folder itself, and
    either new or a file of the ``kind`` the command writes (``is_kind``): a
    command replaces its own earlier output, never another file given by mistake."""
    out = Path(path)
    if out.is_dir():
        raise OutputError(f"{option} {shorten(str(out), 60)}: is a folder; expected a file name")
    if out.exists() and not is_kind(out):
        raise OutputError(f"{option} {shorten(str(out), 60)}: exists and is not {kind} (only one is replaced); "
                          "remove it or choose another name")
    _out_dir(out.parent if str(out.parent) else ".", option)
    return out


def _is_design_file(path: Path) -> bool:
    """A design as ``lpvest design`` writes it (JSON with the design format's name)."""
    from .design._result import DESIGN_FORMAT

    try:
        if path.stat().st_size > 2**26:  # 64 MiB: far beyond any design
            return False
        data = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(data, dict) and data.get("format") == DESIGN_FORMAT


def _is_ssp_file(path: Path) -> bool:
    """An SSP archive (a zip holding SystemStructure.ssd)."""
    try:
        with zipfile.ZipFile(path) as z:
            return "SystemStructure.ssd" in z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def _number(text: str) -> float:
    """A number option (``--epsilon``): any float, ``inf`` and ``-inf`` included,
    never nan."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, found {abbreviate(text, 30)}") from None
    if value != value:
        raise argparse.ArgumentTypeError(f"expected a number (inf and -inf allowed), found {text}")
    return value


def _workers(text: str) -> int:
    """``--workers``: 0 (this process) or a number of worker processes."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected 0 (run in this process) or a number of worker processes, "
                                         f"found {abbreviate(text, 30)}")
    return value


def _worker_threads(text: str) -> int | None:
    """``--worker-threads``: 0 (libcosim steps the FMUs in its calling thread),
    a number of threads, or ``none`` (not declared: libcosim's default pool)."""
    from .cosim._ssp import MAX_WORKER_THREADS

    if text.strip().lower() == "none":
        return None
    value = int(text) if text.strip().isdigit() else -1
    if not 0 <= value <= MAX_WORKER_THREADS:
        raise argparse.ArgumentTypeError(f"expected 0 (the calling thread), a number of threads, or none; found "
                                         f"{abbreviate(text, 30)}")
    return value


def _echo(message: str) -> None:
    """A progress line on stderr (plain lines: readable in a redirected log)."""
    print(message, file=sys.stderr, flush=True)


def _seed(text: str) -> int:
    """``--seed``: a non-negative integer (numpy's seeds)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, found {abbreviate(text, 30)}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, found {value}")
    return value


def _steps(text: str) -> int:
    """``--steps``: 2 .. MAX_STEPS samples."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of samples, found {abbreviate(text, 30)}") from None
    if not 2 <= value <= MAX_STEPS:
        raise argparse.ArgumentTypeError(f"expected 2 to {MAX_STEPS:,} samples, found {value}")
    return value


#: The most samples ``lpvest simulate`` writes (every one goes into the CSV and the plot).
MAX_STEPS = 1_000_000


def describe_model(key: str, model: object) -> str:
    """A human-readable description: type, dimensions, matrices, maps (the
    model's own ``describe``)."""
    describe = getattr(model, "describe", None)
    if describe is None:  # pragma: no cover - every model class has one
        return f"  model {key}: {type(model).__name__}"
    return "\n".join(describe(key))


def _model_summary(model: object) -> str:
    from .systems._modelfile import MODEL_TYPES

    for name, cls in MODEL_TYPES.items():
        if isinstance(model, cls):
            return name
    return type(model).__name__  # pragma: no cover


def cmd_systems(args: argparse.Namespace) -> int:
    from .systems._catalog import example_systems
    from .systems._modelfile import load_system

    if not args.words:
        entries = example_systems()
        width = max(len(e.name) for e in entries)
        for e in entries:
            system = load_system(e.path)
            models = ", ".join(f"{k} ({_model_summary(m)})" for k, m in system.models.items())
            print(f"{e.name:<{width}}  {e.title}  [models: {models}]")
        return 0
    words = list(args.words)
    if words[0] == "show":  # `lpvest systems show NAME` and `lpvest systems NAME` are the same
        words = words[1:]
    if len(words) == 2 and difflib.get_close_matches(words[0], ["show"], cutoff=0.6):  # `systems shwo NAME`
        raise ArgumentError(f"systems: {abbreviate(words[0], 30)} is not a word of `lpvest systems` (did you mean "
                            f"`lpvest systems show {shorten(words[1], 60)}`?)")
    if len(words) > 1:
        raise ArgumentError(f"systems: expected one example name or model file, found {len(words)}: "
                            f"{shorten(' '.join(words), 60)} (one system at a time)")
    if not words:
        raise ArgumentError("systems: expected one example name or model file, e.g. `lpvest systems show "
                            "peixoto-ex1` (or nothing, to list the examples)")
    system = load_system(words[0], parameters=_parse_params(args.param))
    keys = [args.model] if args.model else list(system.models)
    chosen = {key: system.model(key) for key in keys}  # a wrong --model fails before anything is printed
    print(f"{system.name}: {system.title}")
    if system.source:
        print(f"  source: {system.source}")
    if system.path:
        print(f"  file: {system.path}")
    if system.description:
        for line in system.description.strip().splitlines():
            print(f"  {line}")
    if system.parameters:
        ranges = system.parameter_ranges
        print("  parameters: " + ", ".join(f"{k} = {v:g}" + (f" in {ranges[k].text()}" if k in ranges else "")
                                           for k, v in system.parameters.items()))
    if system.scheduling is not None:
        s = system.scheduling
        box = ", ".join(f"{n} in [{lo:g}, {hi:g}]" for n, lo, hi in zip(s.names, s.lower, s.upper, strict=True))
        print(f"  scheduling: {box}")
    for key, model in chosen.items():
        print(describe_model(key, model))
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from .experiments._simulate import simulate_system
    from .systems._modelfile import load_system

    system = load_system(args.target, parameters=_parse_params(args.param))
    sim = simulate_system(system, args.model, steps=args.steps, schedule=args.schedule, seed=args.seed)
    out = _out_dir(args.out)
    stem = f"{system.name}-{sim.model}"
    csv = sim.write_csv(out / f"{stem}.csv")
    png = sim.plot(out / f"{stem}.png")
    print(f"simulated {system.name} / {sim.model}: {args.steps} samples")
    for name, col in sim.columns.items():
        if name == sim.time_name:
            continue
        print(f"  {name:<10} min {np.min(col):>11.4g}  max {np.max(col):>11.4g}  rms {np.sqrt(np.mean(col**2)):>11.4g}")
    print(f"wrote {csv}\nwrote {png}")
    return 0


def _backend_argument(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--backend", choices=("pythonfmu", "native"), default="pythonfmu",
                   help=f"{what}: pythonfmu (default; runs in a host's Python) or native (C, no Python needed: "
                        "every discrete-time role; the LTV plant and the B-spline observer stay pythonfmu)")


def cmd_reproduce(args: argparse.Namespace) -> int:
    from .experiments import registry
    from .experiments._fmus import ExperimentFmus
    from .experiments._reproduce import ReproduceInterrupted, reproduce, reproduce_all

    experiments = registry()
    names = list(dict.fromkeys(args.names))  # in the order given, each once
    if not names or names == ["list"]:
        if not experiments:
            print("no experiments are registered")
        for exp in experiments.values():
            print(f"{exp.name:<28} {exp.title}")
        return 0
    for word in ("all", "list"):
        if word in names and len(names) > 1:
            raise ArgumentError(f"'{word}' stands alone (lpvest reproduce {word}), not among experiment names")
    unknown = [n for n in names if n != "all" and n not in experiments]
    if unknown:
        raise ArgumentError(f"no experiment {abbreviate(unknown[0], 30)} (known: {', '.join(experiments) or 'none'}; "
                            "or all, list)")
    cache = _out_dir(args.fmus, "--fmus") if args.fmus else None  # a file there: said now, not after a build
    out = _out_dir(args.out)
    default = "fmu-cache" if args.backend == "pythonfmu" else f"fmu-cache-{args.backend}"
    fmus = ExperimentFmus(cache or out / default, progress=None if args.quiet else _echo, backend=args.backend)

    def echo(text: str) -> None:
        print(text, flush=True)

    t = time.perf_counter()
    try:
        if names == ["all"]:
            runs = reproduce_all(out, fmus=fmus, reduced=args.quick, echo=echo, workers=args.workers,
                                 backend=args.backend, progress=False if args.quiet else None)
        else:
            runs = reproduce(names, out, fmus=fmus, reduced=args.quick, echo=echo, workers=args.workers,
                             backend=args.backend, progress=False if args.quiet else None)
    except ReproduceInterrupted as exc:  # what finished, what the cache kept, how to go on: one line
        print(f"lpvest: interrupted ({exc.name}): {exc}", file=sys.stderr)
        return exit_status(exc)
    seconds = time.perf_counter() - t
    print(fmus.summary())
    if len(runs) > 1:
        print("\nexperiment                    time  FMU vs library")
        for r in runs:
            verdict = "-" if r.result.fmu is None else r.result.fmu.headline().split(": ", 1)[1]
            print(f"{r.name:<28} {r.seconds:>5.1f} s  {verdict}")
    print(f"{len(runs)} experiment(s) in {seconds:.1f} s")
    bad = [r.name for r in runs if not r.ok]
    if bad:
        print(f"FMU results disagree with the library in: {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0


def cmd_regress(args: argparse.Namespace) -> int:
    from .experiments._fmus import as_experiment_fmus
    from .experiments._references import RegressInterrupted, regress

    if args.update and args.dir:  # the folder the references go to, checked before any FMU is built
        _out_dir(args.dir, "--dir")
    fmus = as_experiment_fmus(_out_dir(args.fmus, "--fmus") if args.fmus else None)
    if not args.quiet:
        fmus.progress = lambda msg: print(msg, file=sys.stderr, flush=True)
    try:
        return regress(args.names, update=args.update, directory=args.dir, fmus=fmus)
    except RegressInterrupted as exc:  # what was rewritten or compared, how to go on: one line
        print(f"lpvest: interrupted ({exc.name}): {exc}", file=sys.stderr)
        return exit_status(exc)


def _design_args(items: Sequence[str] | None) -> dict[str, Path]:
    """``--design [ROLE=]FILE`` -> {role: file}; the role defaults to the design's kind
    (parameter-dependent -> HinfPD, robust -> HinfRobust)."""
    from .design._result import KIND_PD, HinfDesign

    out: dict[str, Path] = {}
    for item in items or ():
        role, sep, file = item.partition("=")
        if not sep:
            file, role = item, ""
        if not file.strip():
            raise ArgumentError(f"--design {abbreviate(item, 40)}: expected [ROLE=]FILE.json, found no file name"
                                + (f" after {role}=" if role else ""))
        path = Path(file)
        if not role:
            role = "HinfPD" if HinfDesign.from_json(path).kind == KIND_PD else "HinfRobust"
        if role in out:
            raise LpvestError(f"--design: two designs for {role}")
        out[role] = path
    return out


def cmd_build(args: argparse.Namespace) -> int:
    import warnings

    from .design._program import check_solver
    from .fmi._build import BuildWarning, build_fmus, format_table, known_roles

    designs = _design_args(args.design)  # the arguments first: a mistake there creates no folder
    out = _out_dir(args.out)
    sources = args.model or None
    if designs and (not sources or len(sources) != 1):
        raise LpvestError("--design needs exactly one --model: the model file (or example) the design is for")
    roles = None
    if args.kinds:
        roles = [r.strip() for item in args.kinds for r in item.split(",") if r.strip()]
        unknown = [r for r in roles if r not in known_roles()]
        if unknown:
            raise ArgumentError(f"--kinds: no role {abbreviate(unknown[0], 30)} (roles: {', '.join(known_roles())})")
    options: dict[str, object] = {}
    if args.epsilon is not None:
        options["epsilon"] = args.epsilon
    if args.solver is not None:
        options["solver"] = check_solver(args.solver)
    with warnings.catch_warnings(record=True) as caught:  # what the FMUs lack: printed as notes below
        warnings.simplefilter("always", BuildWarning)
        results, notes = build_fmus(sources, out, roles=roles, designs=designs, design_options=options,
                                    progress=None if args.quiet else _echo, backend=args.backend,
                                    bar=not args.quiet)
    for w in caught:
        if issubclass(w.category, BuildWarning):
            notes.append(str(w.message))
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    print(format_table([r.validation for r in results]))
    for note in notes:
        print(f"note: {note}")
    bad = [r for r in results if not r.validation.ok]
    print(f"{len(results)} FMU(s) in {out}" + (f"; {len(bad)} failed validation" if bad else ", all valid"))
    if not results:
        raise LpvestError("nothing to build" + (f" (no FMU has a role in --kinds {', '.join(roles)})" if roles else ""))
    return 1 if bad else 0


def cmd_design(args: argparse.Namespace) -> int:
    from .design._program import check_solver, design_hinf
    from .design._result import KIND_PD, KIND_ROBUST
    from .design._search import search_epsilon
    from .systems._affine import AffineLPV
    from .systems._modelfile import load_system
    from .systems._polytopic import PolytopicLPV

    system = load_system(args.target, parameters=_parse_params(args.param))
    model = system.model(args.model)
    if not isinstance(model, PolytopicLPV | AffineLPV):
        raise LpvestError(f"{system.name}: model {args.model or system.default!r} is {type(model).__name__}; "
                          "an H-infinity design needs a polytopic plant or an affine model with general noise")
    kind = {"pd": KIND_PD, "robust": KIND_ROBUST}[args.kind]
    check_solver(args.solver)
    # before the solve: an unwritable place, or another file in the way, fails now, not after it
    out = _out_file(args.out, "--out", "an lpvest design (JSON)", _is_design_file)
    t = time.perf_counter()
    if args.epsilon is not None:
        design = design_hinf(model, epsilon=args.epsilon, kind=kind, solver=args.solver)
    else:
        design = search_epsilon(model, kind=kind, solver=args.solver, progress=not args.quiet).design
    seconds = time.perf_counter() - t
    params = _parse_params(args.param)
    # the design names the system (and the parameters) it was made for
    label = system.name + (f" ({', '.join(f'{k} = {v:g}' for k, v in params.items())})" if params else "")
    design = dataclasses.replace(design, plant=label)
    design.to_json(out)
    eps = "inf" if design.epsilon == float("inf") else f"{design.epsilon:.6g}"
    print(f"{system.name}: {kind} H-infinity filter, gamma = {design.gamma:.6g} at epsilon = {eps} "
          f"({design.solver}, {seconds:.1f} s; LMI margin {design.lmi_margin:.3g}, "
          f"Lyapunov margin {design.lyapunov_margin:.3g})")
    print(f"wrote {out}")
    return 0


def cmd_cosim(args: argparse.Namespace) -> int:
    from .cosim._cosimfile import load_cosim

    threads = getattr(args, "worker_threads", 0)  # absent: not given
    if hasattr(args, "worker_threads") and not args.ssp:
        raise ArgumentError("--worker-threads sets the threads libcosim steps the FMUs of an SSP file on: "
                                "give it with --ssp")
    spec = load_cosim(args.file, fmu_dir=args.fmus)
    if args.ssp:
        path = spec.to_ssp(_out_file(args.ssp, "--ssp", "an SSP file", _is_ssp_file), worker_threads=threads)
        how = ("on libcosim's default thread pool" if threads is None
               else "in libcosim's calling thread" if threads == 0 else f"on {threads} libcosim threads")
        print(f"wrote {path}: {len(spec.components)} components, {len(spec.connections)} connections, "
              f"step {spec.step_size:g}, t = {spec.start_time:g} .. {spec.stop_time:g}, FMUs stepped {how}")
        print("note: fmpy's simulate_ssp and libcosim step all components in parallel (Jacobi): each connection "
              "adds a one-step delay where an output feeds through from an input (see lpvest.cosim)")
        return 0
    out = _out_dir(args.out)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = spec.run(progress=False if args.quiet else None)
    for w in caught:  # e.g. a component discarded a step: the run stopped there
        print(f"lpvest: warning: {' '.join(str(w.message).split())}", file=sys.stderr)
    stem = spec.path.stem
    print(result.summary())
    print(f"wrote {result.write_csv(out / f'{stem}.csv')}")
    if not args.no_plot:
        print(f"wrote {result.plot(out / f'{stem}.png')}")
    return 0


def _check_fmu_file(path: Path) -> None:
    """One line when ``path`` is not an FMU at all (a zip archive with a
    modelDescription.xml); fmpy's validation judges the rest."""
    shown = shorten(str(path), 80)
    try:
        if not path.is_file():
            raise ArgumentError(f"{shown}: no such file" if not path.exists() else f"{shown}: not a file")
        with zipfile.ZipFile(path) as z:
            if "modelDescription.xml" not in z.namelist():
                raise ArgumentError(f"{shown}: not an FMU (the archive has no modelDescription.xml)")
    except (zipfile.BadZipFile, EOFError):
        raise ArgumentError(f"{shown}: not an FMU (not a zip archive)") from None
    except OSError as exc:
        raise ArgumentError(f"{shown}: cannot be read ({exc.strerror or exc})") from None


def cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import SweepInterrupted, experiment_studies, run_sweep

    if args.list:
        for st in experiment_studies().values():
            axes = ", ".join([*st.axes, *(["seeds"] if st.seeded else [])])
            print(f"{st.name:<22} {st.title}\n{'':<22} axes: {axes or '-'}; metrics: {', '.join(st.metrics)}")
        return 0
    if args.spec is None:
        raise LpvestError("give a sweep file (SPEC.toml; see examples/sweep_kalman.toml), or --list")
    if args.scheduler is not None and args.workers is not None:
        raise LpvestError("--workers starts a local cluster; --scheduler uses an existing one: give one of them")
    out = _out_dir(Path(args.out) if args.out else Path("out") / f"sweep-{Path(args.spec).stem}")
    try:
        res = run_sweep(args.spec, out, scheduler=args.scheduler, workers=args.workers, fmus=args.fmus,
                        ship_fmus=not args.shared_fmus, overwrite=args.overwrite, retry_failed=args.retry_failed,
                        progress=False if args.no_progress or args.quiet else None, plot=not args.no_plot)
    except SweepInterrupted as exc:
        print(f"lpvest: {exc}", file=sys.stderr)
        return exit_status(exc)
    print(res.report())
    return 1 if res.failures else 0


def cmd_validate(args: argparse.Namespace) -> int:
    from .fmi._build import format_table, validate_fmus

    for name in args.fmus:
        _check_fmu_file(Path(name))
    results = validate_fmus(args.fmus)
    print(format_table(results))
    return 0 if all(r.ok for r in results) else 1


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (and status 2), and
    for which ``-1e300``, ``-.5`` and ``-inf`` are numbers (argparse's own test,
    ``-1`` and ``-1.5`` only, took the others for options: "expected one
    argument")."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        # an unknown option before the command: say so, not "arguments are required: COMMAND"
        words = list(sys.argv[1:] if args is None else args)
        first = words[0].split("=", 1)[0] if words else ""
        if self.prog == "lpvest" and first.startswith("-") and first not in self._option_string_actions:
            self.error(f"unrecognized option {abbreviate(words[0], 30)} before the command (a command's options "
                       "go after it)")
        return super().parse_known_args(args, namespace)

    def parse_args(self, args: Any = None, namespace: Any = None) -> Any:
        # what argparse calls "unrecognized arguments: --stpes 10 (see lpvest --help)" is the
        # command's mistake: said by the command, naming the word, with the nearest option
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            command = self._command_parser(parsed)
            command.error(_unrecognized(command, extras[0]))
        return parsed

    def _command_parser(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The parser of the command ``parsed`` names (this one if none)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen: argparse.ArgumentParser = action.choices.get(getattr(parsed, action.dest, ""), self)
                return chosen
        return self

    def error(self, message: str) -> NoReturn:
        text = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {shorten(text, 240)} (see {self.prog} --help)\n")


def _unrecognized(parser: argparse.ArgumentParser, word: str) -> str:
    """An argument ``parser`` does not take, said as what it is (an option, or
    a word too many), with the nearest option of the command when one is near."""
    if not word.startswith("-") or _NEGATIVE_NUMBER.match(word):
        return f"unexpected argument {abbreviate(word, 30)} ({parser.prog} takes no more)"
    name = word.split("=", 1)[0]
    options = {o[2:]: o for o in parser._option_string_actions if o.startswith("--")}
    near = difflib.get_close_matches(name.lstrip("-"), options, n=1, cutoff=0.75)  # a typo, not any option
    return f"unrecognized option {abbreviate(name, 30)}" + (f" (did you mean {options[near[0]]}?)" if near else "")


#: What argparse should take for a negative number (not an option).
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE)


#: Description and examples of each subcommand, for ``lpvest COMMAND --help``
#: (a subcommand that sets its own in ``add_parser`` keeps them).
HELP: dict[str, tuple[str, str]] = {
    "systems": (
        "List the example systems (models/*.toml), or show one system in detail: its models, dimensions, "
        "matrices and scheduling map. A model file of your own is checked the same way.",
        "lpvest systems\n  lpvest systems show peixoto-ex2 --param rho=10\n  lpvest systems peixoto-ex1\n"
        "  lpvest systems show my_plant.toml --model plant"),
    "simulate": (
        "Simulate one model of an example system or a model file with default signals (a scheduling sinusoid "
        "spanning 90 % of the box, the model's own noise, seeded) and write a CSV, a plot and a summary.",
        "lpvest simulate cox-toth-ex1 --model io --schedule \"0.5 + 0.3*sin(k)\" --out out/sim\n"
        "  lpvest simulate peixoto-ex2 --param rho=10 --steps 200\n"
        "  lpvest simulate my_plant.toml --schedule \"sin(0.1*k)\" --schedule \"0.5\"   # two scheduling components"),
    "reproduce": (
        "Reproduce a paper example through FMUs (built into OUT/fmu-cache or reused): tables in the terminal, "
        "figures and results.json in OUT/NAME; 'all' runs every example and writes OUT/report.md.",
        "lpvest reproduce list\n  lpvest reproduce peixoto-fig1 --out out\n  lpvest reproduce all --out out --quick\n"
        "  lpvest reproduce all --out out --workers 0   # in this process, one experiment after another\n"
        "  lpvest reproduce all --out out-native --backend native"),
    "regress": (
        "Co-simulate the FMUs of each paper example briefly and compare with the stored regression references "
        "(tests/data/reference); --update rewrites them after a deliberate change.",
        "lpvest regress\n  lpvest regress peixoto-fig1\n  lpvest regress --update"),
    "build": (
        "Build the FMUs of every example system (or of the given model files) and validate them with fmpy. "
        "An H-infinity filter FMU carries a design: the one given with --design, the one stored with an example "
        "system (models/designs), or one solved at build time.",
        "lpvest build\n  lpvest build --out my-fmus --model my_plant.toml\n"
        "  lpvest build --model my_plant.toml --kinds Plant,HinfPD --design pd.json\n"
        "  lpvest build --backend native --out fmu-native"),
    "design": (
        "Design an H-infinity filter by LMIs (Peixoto et al. Theorem 1, or Corollary 1 with --kind robust) and "
        "write it as JSON, for `lpvest build --design`; the best epsilon unless --epsilon is given.",
        "lpvest design peixoto-ex1 --out pd.json\n"
        "  lpvest design peixoto-ex2 --param rho=11 --kind robust --epsilon 150 --out robust.json"),
    "cosim": (
        "Co-simulate FMUs described in a TOML file (format: lpvest/cosim/_cosimfile.py, examples/*.toml): CSV, plot "
        "and summary; or write the system as an SSP file.",
        "lpvest cosim examples/peixoto_ex1_hinf.toml --out out/cosim\n"
        "  lpvest cosim examples/cox_toth_kalman.toml --fmus my-fmus/\n"
        "  lpvest cosim examples/peixoto_ex1_hinf.toml --ssp system.ssp"),
    "sweep": (
        "Run a co-simulation file, or the Monte Carlo part of a paper experiment, over seeds and parameters "
        "on Dask (a local cluster, one worker per core, or --scheduler ADDRESS): one co-simulation per task, "
        "seeds from numpy's SeedSequence by task index, a Parquet summary and Zarr trajectories written as "
        "tasks finish, a figure per metric; a rerun resumes; a failing task is recorded with its message. "
        "Format: lpvest/sweep/_sweepfile.py; needs the extra lpvest[sweep].",
        "lpvest sweep examples/sweep_kalman.toml --out out/sweep-kalman\n"
        "  lpvest sweep examples/sweep_kalman.toml --scheduler tcp://10.0.0.5:8786\n"
        "  lpvest sweep --list"),
    "validate": (
        "Validate FMUs with fmpy.validation; the exit status is 1 if any FMU has a problem.",
        "lpvest validate fmu-build/*.fmu"),
}


def _describe_subcommands(sub: argparse._SubParsersAction) -> None:
    """Description, examples and ``--debug`` for every subcommand."""
    for name, p in sub.choices.items():
        description, examples = HELP.get(name, (None, None))
        p.formatter_class = argparse.RawDescriptionHelpFormatter
        if p.description is None and description is not None:
            p.description = description
        if p.epilog is None and examples is not None:
            p.epilog = "examples:\n  " + examples
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show the traceback of an error")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="lpvest", description="Estimation for LPV and LTV systems.",
                     epilog="lpvest COMMAND --help describes each command, with examples.")
    parser.add_argument("--version", action="version", version=f"lpvest {_version()}")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("systems", help="list the example systems, or show one")
    p.add_argument("words", nargs="*", metavar="[show] NAME|FILE.toml",
                   help="an example name or a model file to show in detail (default: list the examples)")
    p.add_argument("--model", help="show only this model of the system")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter")
    p.set_defaults(func=cmd_systems)

    p = sub.add_parser("simulate", help="simulate one model and write CSV and a plot")
    p.add_argument("target", help="example name or model file (.toml)")
    p.add_argument("--model", help="model of the system (default: the file's default)")
    p.add_argument("--steps", type=_steps, default=100, help="number of samples (default 100)")
    p.add_argument("--schedule", action="append", metavar="FORMULA",
                   help="scheduling as a formula of the step k, e.g. '0.5*sin(0.25*k)'; once per scheduling "
                        "component (default: a sinusoid spanning 90%% of the box)")
    p.add_argument("--seed", type=_seed, default=0, help="noise seed, a non-negative integer (default 0)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter")
    p.add_argument("--out", default="out/simulate", help="output folder (default out/simulate)")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("reproduce", help="reproduce a paper example through FMUs (list them with 'list')")
    p.add_argument("names", nargs="*", metavar="NAME",
                   help="experiment names (run in this order, side by side with --workers), 'all' (every one; "
                        "also writes OUT/report.md), or 'list' (the default)")
    p.add_argument("--out", default="out", help="output folder (default out); each experiment gets a subfolder")
    p.add_argument("--fmus", metavar="DIR",
                   help="FMU cache folder (default OUT/fmu-cache): built when missing or out of date, else reused")
    p.add_argument("--quick", action="store_true",
                   help="reduced configuration: 200 Monte Carlo runs, 5 noise seeds, Example 2 at rho = 1, 11, 21")
    p.add_argument("--workers", type=_workers, metavar="N",
                   help="run the experiments (and Example 2's values of rho) side by side on N Dask worker "
                        "processes (default: one per core); 0: one after another in this process. The numbers "
                        "are the same either way")
    _backend_argument(p, "the FMUs' backend; native FMUs go to OUT/fmu-cache-native by default")
    p.add_argument("--quiet", action="store_true",
                   help="no FMU build lines or progress bars (tables, results and errors only)")
    p.set_defaults(func=cmd_reproduce)

    from .experiments._references import add_arguments as regress_arguments

    p = sub.add_parser("regress", help="compare the FMU co-simulations with the stored regression references "
                                       "(--update rewrites them)")
    regress_arguments(p)
    p.set_defaults(func=cmd_regress)

    p = sub.add_parser("build", help="build the FMUs of every example system (or of --model files) and validate them")
    p.add_argument("--out", default="fmu-build", help="output folder (default fmu-build)")
    p.add_argument("--model", action="append", metavar="FILE.toml",
                   help="build the FMUs of this model file (or example name) instead; repeatable")
    p.add_argument("--kinds", action="append", metavar="ROLE[,ROLE...]",
                   help="build only these roles (Plant, Scheduler, Source, Kalman, TruncatedKalman, HinfPD, "
                        "HinfRobust, BSplineObserver)")
    p.add_argument("--design", action="append", metavar="[ROLE=]FILE.json",
                   help="carry this design (from `lpvest design`) in the H-infinity filter FMU instead of "
                        "solving one; the role follows the design's kind unless given; needs one --model")
    p.add_argument("--epsilon", type=_number, metavar="E",
                   help="H-infinity filters designed at build time: design at this epsilon instead of searching "
                        "the best one")
    p.add_argument("--solver", metavar="NAME",
                   help="H-infinity filters designed at build time: cvxpy solver, or AUTO (default)")
    _backend_argument(p, "the FMU backend")
    p.add_argument("--quiet", action="store_true", help="no progress lines or bars (results and errors only)")
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("design", help="design an H-infinity filter (LMIs) and write it as JSON for `lpvest build "
                                      "--design`")
    p.add_argument("target", help="example name or model file (.toml) with a polytopic model")
    p.add_argument("--model", help="model of the system (default: the file's default)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter")
    p.add_argument("--kind", choices=["pd", "robust"], default="pd",
                   help="pd: gain-scheduled (Theorem 1, default); robust: constant (Corollary 1)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--epsilon", type=_number, help="design at this epsilon (any real number, inf allowed)")
    group.add_argument("--search", action="store_true", help="search the best epsilon over the real line (default)")
    p.add_argument("--solver", default="AUTO",
                   help="cvxpy solver, or AUTO (default): Clarabel for small LMI programs, SCS for large ones")
    p.add_argument("--out", required=True, metavar="DESIGN.json", help="the design file to write")
    p.add_argument("--quiet", action="store_true", help="no progress lines or bars (results and errors only)")
    p.set_defaults(func=cmd_design)

    p = sub.add_parser("cosim", help="co-simulate FMUs described in a TOML file; CSV, plot, summary (or --ssp)")
    p.add_argument("file", metavar="FILE.toml", help="co-simulation description (see examples/*.toml)")
    p.add_argument("--out", default="out/cosim", help="output folder (default out/cosim)")
    p.add_argument("--fmus", metavar="DIR",
                   help="folder of the FMUs named in the file (default: the file's fmu_dir, else fmu-build)")
    p.add_argument("--ssp", metavar="OUT.ssp", help="write the system as an SSP file (FMUs included) and stop")
    p.add_argument("--worker-threads", type=_worker_threads, default=argparse.SUPPRESS, metavar="N",
                   help="with --ssp: the threads libcosim steps the FMUs on (numWorkerThreads); 0, the default: "
                        "its calling thread, fastest for lpvest's FMUs; none: not declared, libcosim's own pool")
    p.add_argument("--no-plot", action="store_true", help="write the CSV only")
    p.add_argument("--quiet", action="store_true", help="no progress lines or bars (results and errors only)")
    p.set_defaults(func=cmd_cosim)

    p = sub.add_parser("sweep", help="run a co-simulation (or an experiment's Monte Carlo) over seeds and parameters "
                                     "on Dask: Parquet summary, Zarr trajectories, a figure per metric; resumable")
    p.add_argument("spec", nargs="?", metavar="SPEC.toml", help="sweep file (see examples/sweep_kalman.toml)")
    p.add_argument("--out", help="output folder (default out/sweep-<SPEC>); a rerun of the same spec resumes there")
    p.add_argument("--workers", type=_workers, metavar="N",
                   help="worker processes of the local Dask cluster (default: one per core; 0: run in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tcp://10.0.0.5:8786; its workers need lpvest)")
    p.add_argument("--fmus", metavar="DIR", help="folder of the co-simulation's FMUs (default: the files' fmu_dir), "
                                                 "or the FMU cache of an experiment")
    p.add_argument("--shared-fmus", action="store_true",
                   help="workers read the FMUs from their paths (a shared file system) instead of receiving them")
    p.add_argument("--overwrite", action="store_true", help="replace the results of a different sweep in --out")
    p.add_argument("--retry-failed", action="store_true", help="run the failed tasks of an earlier run again")
    p.add_argument("--no-plot", action="store_true", help="no figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--list", action="store_true", help="list the experiments that can be swept")
    p.add_argument("--quiet", action="store_true", help="no progress lines or bars (results and errors only)")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("validate", help="validate FMUs with fmpy (exit status 1 on any problem)")
    p.add_argument("fmus", nargs="+", metavar="FMU", help="FMU files")
    p.set_defaults(func=cmd_validate)
    _describe_subcommands(sub)
    return parser


def _version() -> str:
    from ._version import __version__

    return __version__


def run(argv: Sequence[str] | None = None) -> int:
    """:func:`main` for the console script: after an interruption that left a
    native solve running, the process leaves at once with the status (see
    :func:`lpvest.core.abandoned_calls`), after the functions registered with
    :mod:`atexit` (which remove the temporary folders: the status bridges, the
    native runtime, the unpacked FMUs of a co-simulation), as the interpreter's
    exit would have run them before its shutdown."""
    status = main(argv)
    if abandoned_calls():
        # a second Ctrl-C or SIGTERM from here on leaves at once, skipping what is
        # left of the clean-ups, never through the interpreter's shutdown
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, lambda *_: os._exit(status))
        # the atexit functions, as the interpreter's exit runs them (while the
        # solver's thread still runs); then not its shutdown, which can abort
        # with the solver running
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        with handling_signals():  # Ctrl-C and SIGTERM raise Interrupted (exit 130, 143)
            return int(args.func(args))
    except BrokenPipeError:  # e.g. `lpvest systems show X | head`: the reader left
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (LpvestError, OSError) as exc:  # the user's input, or a file the system refuses
        if debug:
            import traceback

            traceback.print_exc()
        print(f"lpvest: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        name = getattr(exc, "name", "SIGINT")
        kept = _KEPT.get(args.command)
        print(f"lpvest: interrupted ({name})" + (f": {kept(args)}" if kept else ""), file=sys.stderr)
        return exit_status(exc)


#: What an interrupted command leaves behind and how to go on, one line.
_KEPT: dict[str, Callable[[argparse.Namespace], str]] = {
    "design": lambda a: "nothing was written (an interrupted solve is never a design); run the same command "
                        "again to design anew",
    "build": lambda a: f"the FMUs and designs finished so far are in {a.out} (designs in {a.out}/.designs), the "
                       "interrupted one was not kept; run the same command again to resume (it reuses those "
                       "designs)",
    "cosim": lambda a: f"the co-simulation stopped, no result was written to {a.out}; run the same command again",
    "sweep": lambda a: "the tasks finished so far are written; run the same sweep again to resume",
    "reproduce": lambda a: "the FMUs built so far are kept in the FMU cache; run the same command again: it "
                           "reuses them and the finished experiments and runs the others",
    "regress": lambda a: "nothing was written; run the same command again",
    "simulate": lambda a: "run the same command again",
    "systems": lambda a: "nothing was written",
    "validate": lambda a: "nothing was written",
}


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run())
