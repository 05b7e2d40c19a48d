"""The build of the compiled core (docs/architecture.md, "The compiled core").

The per-event path (the clock, the CAN wire, the RS-232 link, the Master's and the Slaves'
firmware, the protocol codecs) is plain Python: the ``.py`` files are the firmware as the manual
names it. Beside some of them an augmenting ``.pxd`` file declares C types for the same source
(Cython's "pure Python mode"), and this build compiles those modules to C extension modules.

Where Cython or a C compiler is missing the extensions are skipped, all of them (``OptionalCore``):
the package installs and runs the same source interpreted, only slower. ``HUMANOID_TWIN_NO_COMPILE=1`` skips
the build on purpose; ``HUMANOID_TWIN_PURE_PYTHON=1`` at run time ignores compiled modules that are
present (``humanoid_twin/core.py``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

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
    exts = [Extension(name, [str(Path(*name.split(".")).with_suffix(".py"))],
                      extra_compile_args=["-g0"])
            for name in core_modules() if name.startswith(prefixes)]
    return cythonize(
        exts,
        nthreads=os.cpu_count() or 1,
        language_level=3,
        quiet=True,
        compiler_directives=COMPILER_DIRECTIVES,
    )


class OptionalCore(build_ext):
    """Compiles the core where a C compiler works; where it does not, builds none of it (all or
    nothing: a compiled module takes the C types of the modules it cimports, so half a core would
    not import) and the package runs its source interpreted."""

    def build_extensions(self) -> None:
        try:
            super().build_extensions()
        except Exception as exc:  # noqa: BLE001 - any compiler or linker failure
            for ext in self.extensions:
                Path(self.get_ext_fullpath(ext.name)).unlink(missing_ok=True)
            first = (str(exc).splitlines() or [type(exc).__name__])[0][:200]
            print(f"humanoid-twin: the compiled core was not built ({first}); the package runs its "
                  "source interpreted", file=sys.stderr)


if __name__ == "__main__":          # setuptools' build backend runs this file as __main__
    # the C files compile in parallel, one per core
    setup(ext_modules=ext_modules(), cmdclass={"build_ext": OptionalCore},
          options={"build_ext": {"parallel": os.cpu_count() or 1}})
