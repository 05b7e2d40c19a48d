"""A sweep's named parameters (docs/parameters.md, docs/sweeps.md): which ``--param`` names are
the robot's parameters or a scenario's fields (given to each run as ``--set NAME=VALUE``), and
domain randomisation, ``--randomize NAME=uniform(A,B)|normal(MU,SIGMA) --samples N``: seeded
draws, one value per name and sample (a glob sets every match to that value), each within the
parameter's bounds (a normal draw beyond them is clipped to them), written in the rows.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from humanoid_twin.sweep.table import SweepError

__all__ = ["is_set_name", "run_arg", "Randomize", "parse_randomize", "draw_samples", "RANDOMIZE_SEED",
           "SIGNIFICANT_DIGITS"]

SCENARIO_PREFIX = "scenario."
RANDOMIZE_SEED = 20061      # the draws' seed: the same samples every time (a sweep resumes)
SIGNIFICANT_DIGITS = 6      # a drawn value is kept to 6 significant digits (the table's text is exact)
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_DIST = re.compile(rf"^\s*(uniform|normal)\(\s*({_NUMBER})\s*,\s*({_NUMBER})\s*\)\s*$")


def is_set_name(name: str) -> bool:
    """A ``--param`` name that a run takes as ``--set NAME=VALUE``: a scenario's field
    (``scenario.FIELD``), or a named parameter (a dotted name or glob, or ``pic_mhz``)."""
    if name.startswith(SCENARIO_PREFIX) or "." in name or any(c in name for c in "*?["):
        return True
    from humanoid_twin.params import registry

    return name in registry()


def flag(name: str) -> str:
    """The ``run`` flag of a parameter column: its name with ``-`` for ``_`` (``pic_mhz`` ->
    ``--pic-mhz``, as argparse names the option's ``dest``)."""
    return "--" + name.replace("_", "-")


def run_arg(name: str, value: Any) -> str:
    """The ``run`` argument that sets ``--param`` ``name`` to ``value``: ``--set NAME=V`` for a
    named parameter or a scenario's field, else the run option's own flag."""
    return f"--set={name}={value}" if is_set_name(name) else f"{flag(name)}={value}"


@dataclass(frozen=True)
class Randomize:
    """One ``--randomize NAME=DIST(A,B)``: ``kind`` uniform (A..B) or normal (mean A, sd B)."""

    name: str
    kind: str
    a: float
    b: float
    lo: float           # the bounds of the parameter (of every match of a glob: the tightest)
    hi: float


def parse_randomize(specs: Sequence[str]) -> list[Randomize]:
    """``--randomize`` texts, checked against the registry: :class:`SweepError` (one line) for a
    malformed one, a name given twice, an unknown name or a glob that matches nothing, a uniform
    range outside the parameter's bounds or backwards, a normal with sd <= 0."""
    from humanoid_twin.params import ParamError, registry

    reg = registry()
    out: list[Randomize] = []
    for spec in specs:
        name, eq, dist = spec.partition("=")
        name = name.strip()
        m = _DIST.match(dist)
        if not eq or not name or m is None:
            raise SweepError(f"--randomize {spec!r}: expected NAME=uniform(A,B) or NAME=normal(MU,SIGMA)")
        if any(r.name == name for r in out):
            raise SweepError(f"--randomize {name} given twice")
        try:
            matches = [reg.get(n) for n in reg.match(name)]
        except ParamError as exc:
            raise SweepError(f"--randomize: {exc}") from None
        kind, a, b = m.group(1), float(m.group(2)), float(m.group(3))
        lo, hi = max(p.min for p in matches), min(p.max for p in matches)
        _check_distribution(spec, name, kind, a, b, lo, hi)
        out.append(Randomize(name, kind, a, b, lo, hi))
    return out


def _check_distribution(spec: str, name: str, kind: str, a: float, b: float, lo: float, hi: float) -> None:
    """A uniform(A,B) forwards and within the bounds ``lo``..``hi``; a normal(MU,SIGMA) with SIGMA
    > 0 and its mean within them (:class:`SweepError` naming ``spec``)."""
    if kind == "uniform":
        if not a < b:
            raise SweepError(f"--randomize {spec!r}: uniform(A,B) needs A < B")
        if a < lo or b > hi:
            raise SweepError(f"--randomize {spec!r}: outside the bounds of {name}, {lo:g}..{hi:g}")
        return
    if not b > 0:
        raise SweepError(f"--randomize {spec!r}: normal(MU,SIGMA) needs SIGMA > 0")
    if not lo <= a <= hi:
        raise SweepError(f"--randomize {spec!r}: the mean is outside the bounds of {name}, "
                         f"{lo:g}..{hi:g}")


def draw_samples(randomized: Sequence[Randomize], samples: int, seed: int = RANDOMIZE_SEED
                 ) -> list[tuple[tuple[str, float], ...]]:
    """``samples`` draws of every randomised parameter (in the given order), seeded: sample k is
    the same whatever the sweep's other options; each value rounded to
    :data:`SIGNIFICANT_DIGITS` and clipped to the parameter's bounds."""
    import numpy as np

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(samples):
        row = []
        for r in randomized:
            x = rng.uniform(r.a, r.b) if r.kind == "uniform" else rng.normal(r.a, r.b)
            x = min(max(float(f"{x:.{SIGNIFICANT_DIGITS}g}"), r.lo), r.hi)
            row.append((r.name, x))
        out.append(tuple(row))
    return out
