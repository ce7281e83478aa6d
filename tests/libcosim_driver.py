"""libcosim as a second, independent importer of the FMUs, for the tests.

libcosim keeps an FMU's library loaded for good, so every run is in a
subprocess.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Mapping
from pathlib import Path

from fmpy import read_model_description


def load_and_step(paths: Mapping[str, Path], *, rounds: int = 2, steps: int = 5) -> dict[str, bool]:
    """Load each FMU in libcosim, one execution after another in one process,
    ``rounds`` times over (the same FMU instantiated again after its execution
    ended), each with its own sample time (its default experiment's step), and
    take ``steps`` steps.

    Returns ``"round:name" -> True`` when the steps succeeded and every real
    output is finite afterwards (False otherwise).
    """
    names = sorted(paths)
    step_sizes = {n: float(read_model_description(str(paths[n])).defaultExperiment.stepSize) for n in names}
    code = textwrap.dedent(f"""
        import json, math
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimSlave import CosimLocalSlave
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimLogging import log_output_level, CosimLogLevel
        log_output_level(CosimLogLevel.ERROR)
        paths = {json.dumps({n: str(paths[n]) for n in names})}
        steps = {json.dumps(step_sizes)}
        out = {{}}
        for round_ in range({rounds}):
            for name, path in paths.items():
                ex = CosimExecution.from_step_size(step_size=int(round(steps[name] * 1e9)))
                i = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name=name))
                refs = [v.reference for v in ex.slave_variables(i) if v.causality == 2]  # outputs
                obs = CosimObserver.create_last_value()
                ex.add_observer(obs)
                ok = ex.step({steps})
                values = obs.last_real_values(i, refs) if refs else []
                out[f"{{round_}}:{{name}}"] = bool(ok) and all(math.isfinite(v) for v in values)
                del ex
        print("RESULT" + json.dumps(out))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))[len("RESULT"):])
