"""Package discovery for setuptools (metadata is in pyproject.toml).

The example model files live in the top-level ``models/`` folder and are
installed as the data package ``lpvest._models``; the FMU slave scripts in
``fmus/`` are installed as ``lpvest._fmus`` (``lpvest build`` needs them).
"""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["lpvest", "lpvest.*"]), "lpvest._models", "lpvest._models.designs",
              "lpvest._fmus"],
    package_dir={"lpvest._models": "models", "lpvest._models.designs": "models/designs", "lpvest._fmus": "fmus"},
)
