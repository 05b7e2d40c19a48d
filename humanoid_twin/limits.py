"""Bounds that several rooms of the package share, each written once.

``MAX_RUN_S``: one simulated day, the longest a run may last. A run's ``--duration`` and a user
scenario's ``motion_s`` (``scenarios.MAX_DURATION_S``), a fault's T0 and T1
(``faults.MAX_FAULT_S``) and the times a serial log may hold (``MAX_LOG_S``: its replay is bounded
as the run was; a far-future event would run on for ever) are all this one number.
"""

from __future__ import annotations

__all__ = ["MAX_RUN_S"]

MAX_RUN_S = 86_400     # one simulated day (s)
