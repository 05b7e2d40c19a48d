"""User code by reference: one rule set for scenarios, firmware laws and host controllers.

A plug-in is named by a *reference*, the same three ways for all three kinds (docs/scenarios.md,
"Your own scenario"; docs/controllers.md):

- ``FILE.py:NAME``: a Python file, imported under a name of its own (one module per resolved
  path and per process, whichever kind asks for it first);
- ``MODULE:NAME``: an importable module (the CLI makes the current directory importable first, as
  ``python -m`` does);
- ``NAME`` alone (no colon): the name of an entry point in the kind's group
  (:data:`SCENARIO_GROUP`, :data:`LAW_GROUP`, :data:`HOST_CONTROLLER_GROUP`), or a scenario's
  built-in name.

The reference splits at its *last* colon (a file's path may hold one); NAME may be dotted
(``module:Class.attr``). What goes wrong is one line naming the kind and the reference as given
(``law 'mylaw:Nope': mylaw has no 'Nope' ...``), raised as the caller's own error class; the CLI
prints it and exits 2 before anything is written. The import runs user code: any exception it
raises, ``SystemExit`` included, is that code's fault and becomes the one line (its message
bounded, :func:`~humanoid_twin.containment.describe`); a real Ctrl-C or SIGTERM and the twin's
own control flow pass through (:func:`~humanoid_twin.containment.user_fault`).
"""

from __future__ import annotations

import difflib
import hashlib
import importlib
import importlib.util
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from humanoid_twin.containment import attribute_path, describe, user_fault

__all__ = [
    "SCENARIO_GROUP",
    "LAW_GROUP",
    "HOST_CONTROLLER_GROUP",
    "FILE_MODULE_PREFIX",
    "Kind",
    "is_reference",
    "split_reference",
    "entry_point_names",
    "did_you_mean",
    "load_reference",
]

SCENARIO_GROUP = "humanoid_twin.scenarios"              # a package's scenarios, by name
LAW_GROUP = "humanoid_twin.laws"                        # a package's firmware laws
HOST_CONTROLLER_GROUP = "humanoid_twin.host_controllers"   # a package's PC-side step functions
# a FILE.py is imported as this prefix + 12 hex digits of its resolved path's SHA-256
FILE_MODULE_PREFIX = "humanoid_twin_user_"
SYNTAX = "FILE.py:NAME or MODULE:NAME"


@dataclass(frozen=True)
class Kind:
    """What a caller loads: ``what`` names it in messages (``"law"``), ``group`` its entry point
    group, ``error`` the exception class its messages are raised as, ``builtins`` the names it
    knows without an import (a scenario's registry; listed when a name is unknown), ``wanted`` what
    a module's objects of the kind look like (listed when NAME is missing), ``hint`` an extra word
    for a missing NAME (``hint(module, where, attr)``, or nothing)."""

    what: str
    group: str
    error: Callable[[str], BaseException]
    builtins: Callable[[], Iterable[str]] = tuple
    wanted: Callable[[Any], bool] | None = None
    hint: Callable[[Any, str, str], str] | None = None


def is_reference(ref: str) -> bool:
    """``FILE.py:NAME`` or ``MODULE:NAME`` (something to import), not a name."""
    return ":" in ref


def split_reference(ref: str) -> tuple[str, str]:
    """``FILE.py:NAME`` / ``MODULE:NAME`` -> ``(FILE.py or MODULE, NAME)``, split at the last colon
    (a file's path may hold one); ``("", ref)`` for a name."""
    where, _, attr = ref.rpartition(":")
    return where, attr


def entry_point_names(group: str) -> list[str]:
    """The names installed packages declare in the entry point group ``group``."""
    from importlib.metadata import entry_points

    return sorted(ep.name for ep in entry_points(group=group))


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """``"; did you mean X?"`` for a misspelt ``name`` among ``choices``, or nothing."""
    close = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]}?" if close else ""


def load_reference(ref: str, kind: Kind) -> Any:
    """The object ``ref`` names (the module docstring's rules), unchecked: the caller judges what
    it got. ``kind.error`` (one line naming ``kind.what`` and ``ref``) when it names nothing."""
    ref = str(ref).strip()
    if not is_reference(ref):
        return _entry_point(ref, kind)
    where, attr = split_reference(ref)
    if not where or not attr:
        raise kind.error(f"{kind.what} {ref!r}: expected {SYNTAX}")
    module = _import_where(ref, where, kind)
    try:
        return attribute_path(module, attr)
    except AttributeError:
        pass
    except BaseException as exc:        # noqa: BLE001 - a module's __getattr__ is user code too
        if not user_fault(exc):
            raise
        raise kind.error(f"{kind.what} {ref!r}: {where}.{attr} raised {describe(exc)}") from None
    raise kind.error(f"{kind.what} {ref!r}: {where} has no {attr!r}{_missing(module, where, attr, kind)}")


def _import_where(ref: str, where: str, kind: Kind) -> Any:
    """The module of a reference: a ``.py`` file (imported under a name of its own, once per
    process) or an importable module."""
    path = Path(where).expanduser().resolve() if where.endswith(".py") else None
    if path is not None and not path.is_file():
        raise kind.error(f"{kind.what} {ref!r}: no such file {where}")
    try:
        return importlib.import_module(where) if path is None else _import_file(path)
    except BaseException as exc:        # noqa: BLE001 - a user's module: any import failure
        if not user_fault(exc):
            raise
        raise kind.error(f"{kind.what} {ref!r}: cannot import {where}: {describe(exc)}") from None


def _import_file(path: Path) -> Any:
    name = FILE_MODULE_PREFIX + hashlib.sha256(str(path).encode()).hexdigest()[:12]
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def _entry_point(ref: str, kind: Kind) -> Any:
    from importlib.metadata import entry_points

    eps = [ep for ep in entry_points(group=kind.group) if ep.name == ref] if ref else []
    if not eps:
        known = [*kind.builtins(), *entry_point_names(kind.group)]
        builtins = ", ".join(kind.builtins())
        choose = f"choose from {builtins}; or " if builtins else ""
        raise kind.error(
            f"unknown {kind.what} {ref!r} ({choose}FILE.py:NAME, MODULE:NAME, or an entry point of "
            f"{kind.group!r}: {', '.join(entry_point_names(kind.group)) or 'none installed'})"
            f"{did_you_mean(ref, known)}")
    try:
        return eps[0].load()
    except BaseException as exc:        # noqa: BLE001 - a user's package: judged, not trusted
        if not user_fault(exc):
            raise
        raise kind.error(f"{kind.what} {ref!r}: cannot load its entry point: {describe(exc)}") from None


def _missing(module: Any, where: str, attr: str, kind: Kind) -> str:
    """What a module that lacks ``attr`` holds instead: the kind's own hint, else its public
    objects of the kind (and the closest to ``attr``)."""
    if kind.hint is not None:
        return kind.hint(module, where, attr)
    if kind.wanted is None:
        return ""
    found = [var for var, obj in vars(module).items() if not var.startswith("_") and kind.wanted(obj)]
    if not found:
        return ""
    more = " ..." if len(found) > 10 else ""
    return f" (it holds {', '.join(found[:10])}{more}){did_you_mean(attr, found)}"
