"""Which core runs: the compiled one (C extension modules built from the firmware's own source
with its augmenting ``.pxd`` declarations) or the interpreted source (docs/architecture.md,
"The compiled core").

``HUMANOID_TWIN_PURE_PYTHON=1`` makes every ``humanoid_twin`` module load from its ``.py`` even
where a compiled module sits beside it (for debugging: breakpoints and tracebacks in the firmware
work there). The switch is read once, when the package is first imported.

In a source tree (an editable install) the package's import also compares each compiled module
with its ``.py`` and ``.pxd`` (:func:`stale_modules`, file times only: a few milliseconds): when
one is older, an edit has not been rebuilt and the compiled module would run the old code. The
whole package then loads from its source, as with ``HUMANOID_TWIN_PURE_PYTHON=1`` (a compiled
module cannot be swapped for its source alone: the others are built against its C types), and a
:class:`StaleCoreWarning` says so, once, in the CLI, a script or a notebook alike
(:func:`source_if_stale`).
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

from humanoid_twin.core_modules import CORE_MODULES, source_path

PURE_PYTHON_ENV = "HUMANOID_TWIN_PURE_PYTHON"
PACKAGE = "humanoid_twin"
# the module whose form tells which core runs: the clock drives every event of the twin
PROBE_MODULE = "humanoid_twin.clock"


def pure_python_requested() -> bool:
    """True when the environment asks for the interpreted source (``HUMANOID_TWIN_PURE_PYTHON``
    set to anything but empty or ``0``)."""
    return os.environ.get(PURE_PYTHON_ENV, "") not in ("", "0")


class _SourceFirstFinder:
    """A meta path finder that loads ``humanoid_twin.*`` modules from their ``.py`` source even
    when a compiled extension module of the same name is beside it."""

    @classmethod
    def find_spec(cls, name: str, path: Sequence[str] | None = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if not name.startswith(PACKAGE + ".") or path is None:
            return None
        leaf = name.rpartition(".")[2]
        for folder in path:
            source = Path(folder, leaf + ".py")
            if source.is_file():
                return importlib.util.spec_from_file_location(name, source)
        return None


def install_source_first() -> None:
    """Put :class:`_SourceFirstFinder` first on ``sys.meta_path`` (once)."""
    if not any(f is _SourceFirstFinder for f in sys.meta_path):
        sys.meta_path.insert(0, _SourceFirstFinder)


def is_compiled(module: ModuleType) -> bool:
    """True when ``module`` was loaded from a compiled extension module."""
    return isinstance(getattr(module, "__loader__", None), importlib.machinery.ExtensionFileLoader)


def core_kind() -> str:
    """``"compiled"`` when the core's modules run compiled, ``"python"`` when they run from
    their source (no compiled modules installed, or ``HUMANOID_TWIN_PURE_PYTHON=1``)."""
    import importlib

    return "compiled" if is_compiled(importlib.import_module(PROBE_MODULE)) else "python"


def stale_modules(pkg: Path | None = None) -> list[str]:
    """In a source tree (an editable install), the compiled modules (``core_modules.py``'s list)
    older than their ``.py`` or ``.pxd``: an edit not yet rebuilt (``python
    scripts/build_core.py``), which the compiled module would silently ignore (the package's
    import runs the source then: :func:`source_if_stale`). Empty for an installed wheel and for
    the interpreted source. ``pkg``: the package's folder (default: this package's)."""
    pkg = Path(__file__).resolve().parent if pkg is None else pkg
    if pure_python_requested() or not (pkg.parent / "setup.py").is_file():
        return []
    stale = []
    for name in sorted(CORE_MODULES):
        source = pkg.parent / source_path(name)
        built = [p for p in source.parent.glob(source.stem + ".*") if p.suffix in (".so", ".pyd")]
        if not built or not source.is_file():
            continue
        pxd = source.with_suffix(".pxd")
        newest_source = max(source.stat().st_mtime, pxd.stat().st_mtime if pxd.is_file() else 0.0)
        if newest_source > max(p.stat().st_mtime for p in built):
            stale.append(name)
    return stale


class StaleCoreWarning(UserWarning):
    """A compiled module is older than its source: the package runs from its source instead."""


def stale_message(stale: Sequence[str]) -> str:
    """The warning's text: which compiled modules are older than their source, what runs instead,
    and how to rebuild."""
    names = ", ".join(stale[:3]) + (f" and {len(stale) - 3} more" if len(stale) > 3 else "")
    return (f"humanoid-twin: the compiled core is older than its source ({names}): running the "
            f"source instead (slower); rebuild it with 'python scripts/build_core.py'")


def _caller_stacklevel() -> int:
    """The ``stacklevel`` of the first frame outside the import machinery and this package: the
    user's ``import`` line (a script's, a notebook cell's), which the warning then names."""
    frame, level = sys._getframe(1), 1
    pkg_dir = str(Path(__file__).resolve().parent)
    while frame is not None:
        where = frame.f_code.co_filename
        if "importlib" in where and "_bootstrap" in where:
            frame = frame.f_back  # type: ignore[assignment]  # warnings.warn skips these frames itself: not counted (a caller's frame; the loop stops at None)
            continue
        if not where.startswith(pkg_dir):
            return level
        frame, level = frame.f_back, level + 1  # type: ignore[assignment]  # a caller's frame; the loop stops at None
    return 1


def source_if_stale() -> list[str]:
    """At the package's import: when compiled modules are older than their source
    (:func:`stale_modules`), load every module from its source (:func:`install_source_first`)
    and warn (:class:`StaleCoreWarning`); the stale modules' names (empty: nothing done)."""
    stale = stale_modules()
    if stale:
        install_source_first()
        warnings.warn(stale_message(stale), StaleCoreWarning, stacklevel=_caller_stacklevel())
    return stale


def compiled_modules() -> list[str]:
    """The ``humanoid_twin`` modules loaded so far that run compiled."""
    return sorted(n for n, m in list(sys.modules.items())
                  if n.startswith(PACKAGE + ".") and m is not None and is_compiled(m))
