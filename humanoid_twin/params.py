"""The robot's numbers as named parameters (docs/parameters.md).

Every physical and electrical number a user may change (a servo's gain and gear train, a
potentiometer's mounting offset, a force sensor's scale and zero, the floor's friction, a body's
mass, the boards' clock, the IMU's bias) has a dotted name, a unit, a default, bounds and one line
of doc naming its source. The defaults are the values the twin uses today, read where they are
written once: the packaged MJCF (through MuJoCo's ``MjSpec``, ``plant/model_params.py``) or the
one constant that holds them in the code (``cycles.DEFAULT_PIC_MHZ``); a gain, an offset or a
bias added to today's number has the identity as its default (1 or 0). With every parameter at
its default the twin is exactly today's.

    from humanoid_twin.params import registry, load_params_file, non_defaults, params_digest

    reg = registry()
    reg.get("servo.r_knee.kp").default            # 46.2614 (N.m/rad, from humanoid.xml)
    values = reg.check({"servo.*_knee.kp": 40.0})  # the glob expanded: both knees
    Twin(seed=0, params=values)                    # the twin with them (Plant, Rig the same)

A params file is TOML: top-level keys are parameter names (quoted, or TOML's dotted keys),
values numbers; ``--set NAME=VALUE`` on the command line comes after the file.
"""

from __future__ import annotations

import difflib
import fnmatch
import functools
import hashlib
import json
import math
import numbers
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Param", "Registry", "ParamError", "registry", "load_params_file", "parse_set", "non_defaults",
           "params_digest", "merge", "params_markdown", "GLOB_CHARS"]

GLOB_CHARS = "*?["          # a name with one of these is a glob (fnmatch) over the names


class ParamError(ValueError):
    """A parameter name, value or file that cannot be used: one line for the user (exit 2)."""


@dataclass(frozen=True)
class Param:
    """One named parameter: ``name``, ``unit``, ``default``, bounds ``min`` .. ``max`` (inclusive)
    and ``doc`` (one line, with its source). ``kind`` and ``target`` say what it sets: the kind
    (``servo.kp``, ``pot.offset_deg``, ``fsr.gain`` ...) and the model's element (a joint, a site,
    a body; empty for a global one)."""

    name: str
    unit: str
    default: float
    min: float
    max: float
    doc: str
    kind: str = ""
    target: str = ""

    def as_dict(self) -> dict[str, Any]:
        """The public fields (``params --json``)."""
        return {"default": self.default, "unit": self.unit, "min": self.min, "max": self.max, "doc": self.doc}


class Registry:
    """Every parameter by name, in a stable order (``registry()`` builds it once)."""

    def __init__(self, params: Iterable[Param]) -> None:
        self._params: dict[str, Param] = {}
        for p in params:
            if p.name in self._params:
                raise ValueError(f"parameter {p.name} registered twice")
            if not p.min <= p.default <= p.max:
                raise ValueError(f"parameter {p.name}: default {p.default} outside {p.min}..{p.max}")
            self._params[p.name] = p

    def names(self) -> list[str]:
        """Every name, in the registry's order (servos, pots, force sensors, floor, bodies, boards)."""
        return list(self._params)

    def __iter__(self) -> Any:
        return iter(self._params.values())

    def __len__(self) -> int:
        return len(self._params)

    def __contains__(self, name: object) -> bool:
        return name in self._params

    def get(self, name: str) -> Param:
        """The parameter ``name``; :class:`ParamError` naming the closest names otherwise."""
        p = self._params.get(name)
        if p is None:
            raise ParamError(self._unknown(name))
        return p

    def _unknown(self, name: str) -> str:
        close = difflib.get_close_matches(str(name), self._params, n=3, cutoff=0.6)
        hint = f"; did you mean {', '.join(close)}?" if close else "; humanoid-twin params lists them"
        return f"unknown parameter {name!r}{hint}"

    def match(self, pattern: str) -> list[str]:
        """The names ``pattern`` matches (a glob: ``*``, ``?``, ``[...]``; a plain name matches
        itself), in registry order; :class:`ParamError` when it matches none."""
        if not isinstance(pattern, str) or not pattern:
            raise ParamError(f"a parameter name must be a non-empty text, got {pattern!r}")
        if not any(c in pattern for c in GLOB_CHARS):
            self.get(pattern)
            return [pattern]
        found = [n for n in self._params if fnmatch.fnmatchcase(n, pattern)]
        if not found:
            raise ParamError(f"{pattern!r} matches no parameter (humanoid-twin params lists them)")
        return found

    def check(self, values: Mapping[str, Any]) -> dict[str, float]:
        """``values`` (names or globs -> numbers) checked and expanded: each glob gives every
        name it matches (a later key overrides an earlier one), each value a finite number within
        the parameter's bounds. Returns name -> float, in the given order;
        :class:`ParamError` (one line) on the first bad name or value."""
        out: dict[str, float] = {}
        for key, value in values.items():
            names = self.match(key)
            v = _number(value, key)
            for name in names:
                p = self._params[name]
                if not p.min <= v <= p.max:
                    unit = "" if p.unit == "1" else f" {p.unit}"     # "1": a plain ratio, no unit to say
                    raise ParamError(f"{name} = {value!r} is outside its bounds {p.min:g}..{p.max:g}{unit}")
                out.pop(name, None)
                out[name] = v
        return out

    def non_defaults(self, values: Mapping[str, float]) -> dict[str, float]:
        """The entries of ``values`` (checked names) that differ from their default, sorted by name."""
        return {n: float(v) for n, v in sorted(values.items()) if float(v) != self._params[n].default}


def _number(value: Any, name: str) -> float:
    """``value`` as a finite float (a number, or a number's text); :class:`ParamError` otherwise."""
    if isinstance(value, bool):
        raise ParamError(f"{name}: {value!r} is not a number")
    if isinstance(value, str):
        try:
            v = float(value.strip())
        except ValueError:
            raise ParamError(f"{name}: {value!r} is not a number") from None
    elif isinstance(value, numbers.Real):
        v = float(value)
    else:
        raise ParamError(f"{name}: {value!r} is not a number")
    if not math.isfinite(v):
        raise ParamError(f"{name}: {value!r} is not a finite number")
    return v


@functools.cache
def registry() -> Registry:
    """The registry of the packaged model and the firmware's constants (built once per process)."""
    from humanoid_twin.cycles import DEFAULT_PIC_MHZ, PIC_MHZ_MAX, PIC_MHZ_MIN
    from humanoid_twin.plant.model_params import plant_params

    params = list(plant_params())
    params.append(Param("pic_mhz", "MHz", DEFAULT_PIC_MHZ, PIC_MHZ_MIN, PIC_MHZ_MAX,
                        "the Slave boards' PIC18F258 clock (today's --pic-mhz; the cycle table: "
                        "docs/firmware.md); datasheet DS41159: 40 MHz at most", kind="pic_mhz"))
    return Registry(params)


def parse_set(text: str) -> tuple[str, float]:
    """``"NAME=VALUE"`` (``--set``) -> ``(NAME, VALUE)``; NAME may be a glob (checked later, by
    :meth:`Registry.check`); :class:`ParamError` when it is not ``NAME=NUMBER``."""
    name, eq, value = str(text).partition("=")
    name = name.strip()
    if not eq or not name or not value.strip():
        raise ParamError(f"--set {text!r}: expected NAME=VALUE (e.g. servo.r_knee.kp=40)")
    return name, _number(value, name)


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """TOML's tables and dotted keys (``[servo.r_knee]`` / ``servo.r_knee.kp = 40``) as dotted names."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out


def load_params_file(path: str | Path) -> dict[str, float]:
    """The parameters of a TOML file (``--params FILE.toml``), checked (:meth:`Registry.check`:
    globs expanded); :class:`ParamError` naming the file when it is missing, not TOML, or holds
    a bad name or value."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ParamError(f"params file {path}: no such file") from None
    except IsADirectoryError:
        raise ParamError(f"params file {path}: is a directory") from None
    except OSError as exc:
        raise ParamError(f"params file {path}: cannot read it: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParamError(f"params file {path}: not TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ParamError(f"params file {path}: not TOML: not UTF-8 text") from None
    try:
        return registry().check(_flatten(data))
    except ParamError as exc:
        raise ParamError(f"params file {path}: {exc}") from None


def merge(files: Iterable[str | Path] = (), sets: Iterable[str] = ()) -> dict[str, float]:
    """What ``--params FILE`` (each in turn) then ``--set NAME=VALUE`` (each in turn) give: the
    checked values, a later one overriding an earlier one."""
    values: dict[str, float] = {}
    for f in files:
        for name, v in load_params_file(f).items():
            values.pop(name, None)
            values[name] = v
    reg = registry()
    for text in sets:
        name, v = parse_set(text)
        for n, x in reg.check({name: v}).items():
            values.pop(n, None)
            values[n] = x
    return values


def non_defaults(values: Mapping[str, Any]) -> dict[str, float]:
    """The values (names or globs, checked) that differ from their defaults, sorted by name: what
    every output records (the summary's ``params``, the logs' headers)."""
    reg = registry()
    return reg.non_defaults(reg.check(values))


def params_digest(values: Mapping[str, Any]) -> str:
    """A short fingerprint (16 hex digits of SHA-256) of the non-default values: two runs with
    the same digest ran with the same numbers (every default: the digest of ``{}``)."""
    canon = json.dumps(non_defaults(values), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canon.encode()).hexdigest()[:16]


def params_markdown() -> str:
    """docs/parameters.md's table of every parameter (scripts/gen_docs.py)."""
    lines = ["| name | unit | default | min | max | what, and its source |", "|---|---|---|---|---|---|"]
    for p in registry():
        lines.append(f"| `{p.name}` | {p.unit or '1'} | {p.default:.6g} | {p.min:.6g} | {p.max:.6g} "
                     f"| {p.doc} |")
    return "\n".join(lines) + "\n"
