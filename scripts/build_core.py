#!/usr/bin/env python3
"""Rebuild the compiled core in place: only what changed since the last build.

For a developer editing the core (an editable install loads the compiled modules from the source
tree): the modules humanoid_twin/core_modules.py names, with the same Cython directives as ``pip
install -e .`` (setup.py), only those whose name starts with one of the given prefixes. Cython's C goes to
build/cython/ (build/cython-debug/ for --debug), the compiled modules beside their sources.

    python scripts/build_core.py                          # every core module
    python scripts/build_core.py humanoid_twin.slave      # one package
    python scripts/build_core.py humanoid_twin.slave.servo --annotate   # build/cython/**/servo.html
    python scripts/build_core.py --debug                  # Cython's checks on, C debug symbols

A --debug build runs slower: rebuild without --debug when done (the switch rebuilds every module
named, whatever changed).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# which kind of build ("debug" or "release") the compiled modules in the tree are now
LAST_KIND = REPO / "build" / "core-build-kind"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("prefixes", nargs="*", default=["humanoid_twin"], help="module name prefixes")
    ap.add_argument("-j", "--jobs", type=int, default=2,
                    help="parallel Cython and compiler jobs (default 2)")
    ap.add_argument("--debug", action="store_true",
                    help="boundscheck, initializedcheck and overflowcheck on; -g -O0")
    ap.add_argument("--annotate", action="store_true",
                    help="the named modules' C written again with an HTML page beside it (cython -a): "
                         "each line's C, Python calls in yellow")
    args = ap.parse_args()
    if args.jobs < 1:
        print(f"build_core.py: --jobs must be at least 1, not {args.jobs}", file=sys.stderr)
        return 2
    os.chdir(REPO)
    sys.path.insert(0, str(REPO))
    from setuptools import setup

    import setup as build  # setup.py: only defines the build when imported

    exts = build.ext_modules(tuple(args.prefixes), jobs=args.jobs, debug=args.debug,
                             annotate=args.annotate)
    if not exts:
        print("no core module matches", args.prefixes, file=sys.stderr)
        return 2
    kind = "debug" if args.debug else "release"
    # the other kind's modules are newer than this kind's C: setuptools would keep them
    switch = LAST_KIND.is_file() and LAST_KIND.read_text().strip() != kind
    tag = "-".join(p.replace(".", "_") for p in args.prefixes) + ("-debug" if args.debug else "")
    setup(name="humanoid-twin-core", ext_modules=exts, script_name="setup.py",
          script_args=["build_ext", "--inplace", "-j", str(args.jobs), "--build-temp", f"build/temp-{tag}",
                       *(["--force"] if switch else [])])
    LAST_KIND.parent.mkdir(exist_ok=True)
    LAST_KIND.write_text(kind + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
