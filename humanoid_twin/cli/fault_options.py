"""``--fault SPEC`` and ``--host-link S``, the fault options ``run`` and ``serve`` share.

The kinds and their arguments come from ``humanoid_twin.faults.KINDS``; a SPEC that
``faults.parse_fault`` refuses (a ``ValueError``, one line) becomes argparse's usage error
(exit 2, nothing written).
"""

from __future__ import annotations

import argparse

from humanoid_twin.cli.argtypes import positive_seconds
from humanoid_twin.faults import KINDS, FaultSpec, FaultSpecError, parse_fault
from humanoid_twin.master.supervisor import SupervisorConfig

__all__ = ["add_fault_options", "fault_spec", "supervisor_config"]


def fault_spec(text: str) -> FaultSpec:
    """An argparse type: ``text`` parsed by :func:`~humanoid_twin.faults.parse_fault`."""
    try:
        return parse_fault(text)
    except FaultSpecError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_fault_options(p: argparse.ArgumentParser) -> None:
    """``--fault SPEC`` (repeatable) and ``--host-link S`` on an argparse (sub)parser."""
    p.add_argument("--fault", type=fault_spec, action="append", default=[], metavar="SPEC",
                   help="inject a fault, KIND[:ARG][@T0[-T1]] (repeatable; seeded by --seed): "
                   + ", ".join(f"{k.name}:{k.arg}" for k in KINDS.values()) + " (docs/supervisor.md)")
    p.add_argument("--host-link", type=positive_seconds, metavar="S",
                   help="supervisor: latch host_link when no valid host frame arrives for S seconds "
                   "while ready (default: off)")


def supervisor_config(args: argparse.Namespace) -> SupervisorConfig | None:
    """The :class:`~humanoid_twin.master.supervisor.SupervisorConfig` the CLI options ask for."""
    if getattr(args, "host_link", None) is None:
        return None
    return SupervisorConfig(host_link_ms=max(1, round(args.host_link * 1000)))
