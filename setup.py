"""The build of the compiled core (docs/architecture.md, "The compiled core").

The per-event path (the clock, the CAN wire, the RS-232 link, the Master's and the Slaves'
firmware, the protocol codecs) is plain Python: the ``.py`` files are the firmware as the manual
names it. Beside each of them an augmenting ``.pxd`` file declares C types for the same source
(Cython's "pure Python mode"), and this build compiles the modules that
``humanoid_twin/core_modules.py`` names (the one list of the compiled core) to C extension
modules. Cython's generated C goes to ``build/cython/`` (``C_BUILD_DIR``), never beside the
sources; the extension modules go where Python imports them (the source tree, for an editable
install).

Where Cython or a C compiler is missing the extensions are skipped, all of them (``OptionalCore``):
the package installs and runs the same source interpreted, only slower. ``HUMANOID_TWIN_NO_COMPILE=1`` skips
the build on purpose; ``HUMANOID_TWIN_PURE_PYTHON=1`` at run time ignores compiled modules that are
present (``humanoid_twin/core.py``).
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = Path(__file__).resolve().parent

# Cython's generated C, one file per module (build/cython/humanoid_twin/...): relative to the
# project's folder, where setuptools' build runs (and scripts/build_core.py changes to)
C_BUILD_DIR = "build/cython"


def _core_list() -> ModuleType:
    """``humanoid_twin/core_modules.py``, loaded by its path: importing the package would import
    its dependencies, which an isolated build environment does not have."""
    spec = importlib.util.spec_from_file_location("_humanoid_twin_core_modules",
                                                  HERE / "humanoid_twin" / "core_modules.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


COMPILER_DIRECTIVES = {
    "annotation_typing": False,   # the .py's hints are for readers; the C types are in the .pxd
    "binding": True,              # compiled functions keep their signatures and docstrings
    "embedsignature": True,
    "boundscheck": False,
    "wraparound": True,
    "initializedcheck": False,
    "cdivision": False,           # Python's // and % on the PIC's integers (floor, not C's)
}


# scripts/build_core.py --debug: Cython's checks on (an index out of range, an unset memoryview,
# a C integer overflow raise instead of reading or computing garbage) and C debug symbols (gdb)
DEBUG_DIRECTIVES = {"boundscheck": True, "initializedcheck": True, "overflowcheck": True}
DEBUG_COMPILE_ARGS = ["-g", "-O0"]


def core_extensions(prefixes: tuple[str, ...] = ("humanoid_twin",), debug: bool = False) -> list[Extension]:
    """One extension module per module of the core list whose name starts with one of
    ``prefixes``, built from its ``.py`` (Cython finds the ``.pxd`` beside it)."""
    # -g0: no debug symbols (a third of the build's time, most of the wheel's size)
    args = DEBUG_COMPILE_ARGS if debug else ["-g0"]
    core = _core_list()
    return [Extension(name, [core.source_path(name)], extra_compile_args=args)
            for name in core.CORE_MODULES if name.startswith(prefixes)]


def ext_modules(prefixes: tuple[str, ...] = ("humanoid_twin",), jobs: int | None = None,
                debug: bool = False, annotate: bool = False) -> list[Extension]:
    """The core's extension modules (those whose name starts with one of ``prefixes``), their C
    generated into ``C_BUILD_DIR`` by ``jobs`` Cython processes (default: one per core).
    ``debug``: with Cython's run-time checks and C debug symbols (its C in ``C_BUILD_DIR-debug``,
    so that each folder's C matches its directives); ``annotate``: the C of every module
    named written again, with an HTML page beside it (``cython -a``: each line's C, the lines
    that call into Python in yellow)."""
    if os.environ.get("HUMANOID_TWIN_NO_COMPILE"):
        return []
    try:
        from Cython.Build import cythonize
    except ImportError:
        print("humanoid-twin: Cython is not installed: the core stays interpreted", file=sys.stderr)
        return []
    return cythonize(
        core_extensions(prefixes, debug),
        build_dir=C_BUILD_DIR + ("-debug" if debug else ""),
        nthreads=jobs or os.cpu_count() or 1,
        language_level=3,
        quiet=True,
        annotate=annotate,
        force=annotate,         # an up-to-date module's C is not written again, nor its page
        compiler_directives={**COMPILER_DIRECTIVES, **(DEBUG_DIRECTIVES if debug else {})},
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
