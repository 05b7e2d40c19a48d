"""How injected faults compose (issue 24; docs/supervisor.md, "Faults that overlap").

At each instant the faults in effect are the *active set*: every ``--fault`` whose interval
``[T0, T1)`` holds that instant (no T1: to the end; a push: 100 ms). What the twin gets is a
function of the active set, recomputed at every start and every end, so the end of one fault
never switches off another of the same kind:

=====================  ==========================================================================
kind                   in effect while several are active
=====================  ==========================================================================
``can-drop``           P = 1 - prod(1 - P_i): independent losses (one alone: its P exactly)
``can-corrupt``        the same, for the error frames
``serial-noise``       the same, per byte
``silent``             a node is silent while any silence of it is active
``bus-off``            each forces its node off every 8 ms until its own T1 (they add up)
``deadline``           the Slave is late until the last active end of that Slave
``force-noise``        the largest COUNTS active
``force-stuck``        a foot stays frozen while any freeze of it is active (frozen at the first)
``servo-stuck``        the same, per servo
``push``               the forces add up
=====================  ==========================================================================

How a kind combines is its :class:`~humanoid_twin.faults.FaultKind`'s (``combine``, ``targeted``,
``lasts_us``, in ``faults.KINDS``); the table says what the built-in kinds do.

A combination the CAN wire cannot carry, a drop and a corruption whose probabilities add up to
more than 1 at some instant (a frame is lost *or* destroyed, never both), is refused before the
run (:func:`check_composition`: :class:`FaultSpecError`, exit 2 from the
CLI).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

from humanoid_twin.clock import US_PER_S

__all__ = ["KINDS", "FaultSpecError", "combine_probability", "active_at", "check_composition", "effective",
           "target_of"]

# The fault kinds by name: each a :class:`~humanoid_twin.faults.FaultKind` (``faults.register``
# adds one). Held here, below faults.py, because the composition reads each kind's ``combine``,
# ``targeted`` and ``lasts_us``; faults.py fills it and names it ``faults.KINDS``.
KINDS: dict[str, Any] = {}


class FaultSpecError(ValueError):
    """A ``--fault`` SPEC that cannot be used, alone or with the others (the message is one line)."""


def _kind(name: str) -> Any:
    return KINDS[name]


def combine_probability(ps: Sequence[float]) -> float:
    """``1 - prod(1 - p)``: the chance that at least one of independent events happens. One
    probability is returned as it is (bit for bit: a single fault behaves as it always did)."""
    if not ps:
        return 0.0
    if len(ps) == 1:
        return float(ps[0])
    return 1.0 - math.prod(1.0 - p for p in ps)


def target_of(spec: Any) -> Any:
    """What a fault acts on, among faults of its kind: the node, the SCU, (SCU, servo), or None
    (the whole wire, the serial link, every sensor, the trunk)."""
    return spec.arg if _kind(spec.kind).targeted else None


def _end_s(spec: Any) -> float:
    if spec.t1_s is not None:
        return spec.t1_s
    lasts_us = _kind(spec.kind).lasts_us
    if lasts_us is not None:
        return spec.t0_s + lasts_us / US_PER_S
    return math.inf


def active_at(specs: Iterable[Any], t_s: float) -> list[Any]:
    """The specs whose interval holds ``t_s`` (simulated seconds)."""
    return [s for s in specs if s.t0_s <= t_s < _end_s(s)]


def effective(kind: str, active: Iterable[Any], target: Any = None) -> Any:
    """What the twin gets for ``kind`` (on ``target``) while ``active`` are the active specs: a
    probability, the COUNTS, the total force, or whether the node / foot / servo is affected."""
    mine = [s.arg for s in active if s.kind == kind and target_of(s) == target]
    return _kind(kind).combine(mine)


def check_composition(specs: Sequence[Any]) -> None:
    """Refuse a set of faults the twin cannot combine: at some instant the CAN drop and
    corruption probabilities (each combined over its active faults) add up to more than 1.
    Raises :class:`FaultSpecError` (one line) naming the faults."""
    can = [s for s in specs if s.kind in ("can-drop", "can-corrupt")]
    for t in sorted({s.t0_s for s in can}):
        active = active_at(can, t)
        drop, corrupt = effective("can-drop", active), effective("can-corrupt", active)
        if drop + corrupt > 1.0:
            names = " ".join(f"--fault {s.text}" for s in active)
            raise FaultSpecError(
                f"{names}: from t={t:g} s a CAN frame would be lost with P {drop:.3g} and destroyed "
                f"with P {corrupt:.3g}, more than 1 in all (a frame is lost or destroyed, not both)")
