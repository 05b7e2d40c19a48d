"""The build of the compiled core (docs/architecture.md, "The compiled core").

The per-event path (the clock, the CAN wire, the RS-232 link, the Master's and the Slaves'
firmware, the protocol codecs) is plain Python: the ``.py`` files are the firmware as the manual
names it. Beside some of them an augmenting ``.pxd`` file declares C types for the same source
(Cython's "pure Python mode"), and this build compiles those modules to C extension modules.

Where Cython or a C compiler is missing the extensions are skipped (``optional=True``): the package
installs and runs the same source interpreted, only slower. ``HUMANOID_TWIN_NO_COMPILE=1`` skips
the build on purpose; ``HUMANOID_TWIN_PURE_PYTHON=1`` at run time ignores compiled modules that are
present (``humanoid_twin/core.py``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent


def core_modules() -> list[str]:
    """Every module of the package with an augmenting ``.pxd`` beside its ``.py``: the compiled core."""
    pkg = HERE / "humanoid_twin"
    return sorted(
        ".".join(p.relative_to(HERE).with_suffix("").parts)
        for p in pkg.rglob("*.pxd")
        if p.with_suffix(".py").exists()
    )


COMPILER_DIRECTIVES = {
    "annotation_typing": False,   # the .py's hints are for readers; the C types are in the .pxd
    "binding": True,              # compiled functions keep their signatures and docstrings
    "embedsignature": True,
    "boundscheck": False,
    "wraparound": True,
    "initializedcheck": False,
    "cdivision": False,           # Python's // and % on the PIC's integers (floor, not C's)
}


def ext_modules(prefixes: tuple[str, ...] = ("humanoid_twin",)) -> list[Extension]:
    """The core's extension modules (those whose name starts with one of ``prefixes``)."""
    if os.environ.get("HUMANOID_TWIN_NO_COMPILE"):
        return []
    try:
        from Cython.Build import cythonize
    except ImportError:
        print("humanoid-twin: Cython is not installed: the core stays interpreted", file=sys.stderr)
        return []
    # -g0: no debug symbols (a third of the build's time, most of the wheel's size)
    exts = [Extension(name, [str(Path(*name.split(".")).with_suffix(".py"))], optional=True,
                      extra_compile_args=["-g0"])
            for name in core_modules() if name.startswith(prefixes)]
    return cythonize(
        exts,
        nthreads=os.cpu_count() or 1,
        language_level=3,
        quiet=True,
        compiler_directives=COMPILER_DIRECTIVES,
    )


if __name__ == "__main__":          # setuptools' build backend runs this file as __main__
    # the C files compile in parallel, one per core
    setup(ext_modules=ext_modules(), options={"build_ext": {"parallel": os.cpu_count() or 1}})
