"""Foreign FMUs for the tests: small FMI 2.0 co-simulation FMUs written in C
(``tests/data/foreign/``), not made by lpvest or pythonfmu, compiled here with
the system's C compiler against the FMI 2.0 headers that fmpy ships
(``fmpy/c-code``) and zipped with their model description.

- ``AllTypes``: a parameter, an input and an output of every FMI 2.0 type
  (Real, Integer, Enumeration, Boolean, String), value references overlapping
  across types;
- ``Limited``: counts whole time units and returns fmi2Discard from the step
  that reaches its parameter ``last`` (as the Reference FMU ``Stair`` does at
  the end of its validity).
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

SOURCES = Path(__file__).resolve().parent / "data" / "foreign"

#: The foreign FMUs: model identifier -> source stem in tests/data/foreign.
MODELS = {"AllTypes": "all_types", "Limited": "limited"}


def compiler() -> str | None:
    """The C compiler the build uses (``cc``, else ``gcc``), or ``None``."""
    return shutil.which("cc") or shutil.which("gcc")


def build_foreign_fmu(identifier: str, out: Path) -> Path:
    """Compile the model ``identifier`` into ``out/<identifier>.fmu``.

    Warnings are errors (``-Wall -Wextra -Werror``, C99): the sources are
    part of the test suite.
    """
    import fmpy

    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) to build the foreign test FMUs")
    stem = MODELS[identifier]
    work = out / f"{identifier}-build"
    work.mkdir(parents=True, exist_ok=True)
    library = work / f"{identifier}.so"
    headers = Path(fmpy.__file__).resolve().parent / "c-code"
    subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-shared", "-fPIC", f"-I{headers}",
                    f"-I{SOURCES}", "-o", str(library), str(SOURCES / f"{stem}.c")],
                   check=True, capture_output=True, text=True)
    fmu = out / f"{identifier}.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(SOURCES / f"{stem}.xml", "modelDescription.xml")
        z.write(library, f"binaries/linux64/{identifier}.so")
    return fmu
