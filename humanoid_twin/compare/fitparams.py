"""The parameters ``compare`` and ``calibrate`` take, through the project's parameter registry
(humanoid_twin/params.py: names, units, defaults, bounds; docs/parameters.md).

``expand_fit(fit, tie)``: the fitted unknowns, each a group of names sharing one value
(a glob in ``--fit`` gives one unknown per match; ``--tie`` one unknown for all its matches),
with the bounds and the default of its first name.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["ParamError", "Unknown", "expand_fit", "registry_or_error"]


class ParamError(ValueError):
    """A parameter that cannot be used (one line for the user, exit 2)."""


def registry_or_error() -> Any:
    """The registry of humanoid_twin/params.py."""
    try:
        from humanoid_twin.params import registry
    except ImportError:      # pragma: no cover - the registry is part of the package
        raise ParamError("this build has no parameter registry (humanoid_twin/params.py)") from None
    return registry()


def _wrap(fn: Any, *args: Any) -> Any:
    from humanoid_twin import params as P  # noqa: N812

    try:
        return fn(*args)
    except P.ParamError as exc:
        raise ParamError(str(exc)) from None


@dataclass(frozen=True)
class Unknown:
    """One fitted value: the ``names`` it sets (one, or several tied), its bounds and start."""

    names: tuple[str, ...]
    lo: float
    hi: float
    default: float

    @property
    def label(self) -> str:
        return self.names[0] if len(self.names) == 1 else "+".join(self.names)


def _split(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def _match(reg: Any, pattern: str) -> list[str]:
    names = _wrap(reg.match, pattern)
    if not names:
        raise ParamError(f"--fit/--tie {pattern!r}: matches no parameter (humanoid-twin params lists them)")
    return list(names)


def expand_fit(fit: str, tie: str = "", start: Mapping[str, float] | None = None) -> list[Unknown]:
    """The unknowns of ``--fit`` and ``--tie`` (comma-separated names or globs). ``start``: the
    values the fit starts from (``--params``/``--set``), else each parameter's default."""
    reg = registry_or_error()
    start = start or {}
    out: list[Unknown] = []
    seen: set[str] = set()

    def add(names: Iterable[str]) -> None:
        names = tuple(names)
        for n in names:
            if n in seen:
                raise ParamError(f"parameter {n} is named twice in --fit/--tie")
            seen.add(n)
        p = reg.get(names[0])
        out.append(Unknown(names, float(p.min), float(p.max), float(start.get(names[0], p.default))))

    for pattern in _split(fit):
        for name in _match(reg, pattern):
            add((name,))
    tied = [n for pattern in _split(tie) for n in _match(reg, pattern)]
    if tied:
        add(tied)
    if not out:
        raise ParamError("--fit names no parameter")
    return out
