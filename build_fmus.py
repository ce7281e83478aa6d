#!/usr/bin/env python3
"""Build every lpvest FMU, validate each, print a table (same as ``lpvest build``).

    python build_fmus.py [--out DIR] [--model FILE.toml ...] [--backend pythonfmu|native]

Default: every example system in ``models/`` into ``fmu-build/`` (ignored by
git). ``--model FILE.toml`` builds the plant, scheduler, source and every
applicable filter of your own model file instead. Any validation problem
(``fmpy.validation.validate_fmu``) makes the exit status non-zero.
``--backend native`` builds every discrete-time role as C (no Python needed
in the host; docs/fmus.md says which backend to choose).
"""

import sys

from lpvest.cli import main

if __name__ == "__main__":
    sys.exit(main(["build", *sys.argv[1:]]))
