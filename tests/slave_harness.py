"""An lpvest FMU slave run in this process, from a resources folder written without bundling.

A built FMU runs the private copy of lpvest it carries, so a change to ``lpvest/fmi/_slave.py``
(a fix, or a mutant of ``./dev mutate``) reaches a built FMU only after a rebuild. Here the role
script's class is imported from this lpvest (``lpvest._fmus``) and instantiated as pythonfmu
would, against a folder holding what the builder writes into ``resources/`` (the spec, the model
file, the design) with the factory named by its plain module name: the same slave, without the
bundle, the zip and the binary. The FMI calls are the slave's Python methods, the ones
pythonfmu's binary calls.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import sys
from pathlib import Path
from typing import Any

from lpvest.fmi._build import design_text, manifest_inputs_version, plan_system, scripts_dir
from lpvest.fmi._parameters import SPEC_FILE, SPEC_FORMAT
from lpvest.fmi._state import decode_state, encode_state

#: pythonfmu's status values (Fmi2Status): ok, warning, discard, error, fatal
OK, WARNING, ERROR = 0, 1, 3


def write_resources(system: str, role: str, folder: Path) -> Path:
    """The resources folder of ``<system><role>``, as the builder writes it (no bundle)."""
    plans, _ = plan_system(system)
    plan = next(p for p in plans if p.role == role)
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(plan.system_path, folder / "model.toml")
    spec: dict[str, Any] = {
        "format": SPEC_FORMAT, "identifier": plan.identifier, "role": plan.role,
        "description": plan.description, "lpvest_version": manifest_inputs_version(), "package": "lpvest",
        "system": plan.system_name, "model_file": "model.toml", "model_key": plan.model_key,
        "model_parameters": list(plan.model_parameters), "sample_time": plan.step_size,
    }
    if plan.estimator is not None:
        spec["estimator"] = plan.estimator.to_json() | {"factory": plan.estimator.factory}
        if plan.estimator.design:
            design, origin = design_text(plan, None)
            if isinstance(design, str):
                (folder / "design.json").write_text(design, encoding="utf-8")
                spec["design_format"] = "text"
            else:
                (folder / "design.json").write_bytes(design)
            spec["design_file"], spec["design_origin"] = "design.json", origin
    (folder / SPEC_FILE).write_text(json.dumps(spec, indent=2) + "\n")
    (folder / "script.txt").write_text(plan.script)
    return folder


def _script(name: str) -> Any:
    """The role script ``fmus/<name>`` as a module (loaded once)."""
    key = f"_lpvest_harness_{name.removesuffix('.py')}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, scripts_dir() / name)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[key] = module
    return sys.modules[key]


class Slave:
    """One slave instance: FMI variables by name, the log kept (status, message)."""

    def __init__(self, resources: Path, name: str = "instance") -> None:
        module = _script((resources / "script.txt").read_text())
        cls = next(c for c in vars(module).values()
                   if isinstance(c, type) and c.__module__ == module.__name__ and c.__name__.startswith("Lpvest"))
        self.slave = cls(instance_name=name, resources=str(resources))
        self.vr = {v.name: vr for vr, v in self.slave.vars.items()}

    # -- the log ----------------------------------------------------------------------
    def take_log(self) -> list[tuple[int, str]]:
        """The messages since the last call, as ``(status, text)``."""
        out = [(int(m.status), m.msg) for m in self.slave.log_queue]
        self.slave.log_queue.clear()
        return out

    def errors(self) -> list[str]:
        return [text for status, text in self.take_log() if status >= ERROR]

    # -- FMI calls ----------------------------------------------------------------------
    def initialize(self, start_time: float = 0.0, **params: Any) -> list[str]:
        """setup, enter, set ``params``, exit; the error messages."""
        self.slave.setup_experiment(start_time)
        self.slave.enter_initialization_mode()
        for name, value in params.items():
            self.set(name, value)
        self.slave.exit_initialization_mode()
        return self.errors()

    def set(self, name: str, value: Any) -> None:
        vr = [self.vr[name]]
        kind = type(self.slave.vars[vr[0]]).__name__
        getattr(self.slave, f"set_{kind.lower()}")(vr, [value])

    def set_reals(self, values: dict[str, float]) -> None:
        self.slave.set_real([self.vr[n] for n in values], list(values.values()))

    def get(self, *names: str) -> list[Any]:
        vrs = [self.vr[n] for n in names]
        kinds = {type(self.slave.vars[v]).__name__ for v in vrs}
        assert len(kinds) == 1
        return getattr(self.slave, f"get_{kinds.pop().lower()}")(vrs)

    def step(self, t: float, h: float) -> bool:
        return self.slave.do_step(t, h)

    def get_state(self) -> bytes:
        return self.slave._fmu_state_to_bytes(self.slave._get_fmu_state())

    def set_state(self, state: bytes) -> None:
        self.slave._set_fmu_state(self.slave._fmu_state_from_bytes(state))


def edit_state(state: bytes, **changes: Any) -> bytes:
    """A serialized state with some entries replaced (as a host could hand one back)."""
    snap = decode_state(state)
    snap.update(changes)
    return encode_state(snap)
