#!/usr/bin/env python3
"""Rebuild the compiled core in place, for a developer editing it (an editable install loads the
compiled modules from the source tree): the same modules and Cython directives as ``pip install
-e .`` (setup.py), only those whose name starts with one of the given prefixes, and only what
changed since the last build.

    python scripts/build_core.py                          # every core module
    python scripts/build_core.py humanoid_twin.slave      # one package
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("prefixes", nargs="*", default=["humanoid_twin"], help="module name prefixes")
    ap.add_argument("-j", "--jobs", type=int, default=2, help="parallel compiler jobs (default 2)")
    args = ap.parse_args()
    os.chdir(REPO)
    sys.path.insert(0, str(REPO))
    from setuptools import setup

    import setup as build  # setup.py: only defines the build when imported

    exts = build.ext_modules(tuple(args.prefixes))
    if not exts:
        print("no core module matches", args.prefixes, file=sys.stderr)
        return 2
    tag = "-".join(p.replace(".", "_") for p in args.prefixes)
    setup(name="humanoid-twin-core", ext_modules=exts, script_name="setup.py",
          script_args=["build_ext", "--inplace", "-j", str(args.jobs), "--build-temp", f"build/temp-{tag}"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
