"""Sweeps: a grid of runs on this machine's cores or on a Ray cluster, into one table (docs/sweeps.md).

The API behind ``humanoid-twin sweep`` and ``scripts/balance_study.py``:

- :func:`grid` expands ``{name: [values]}`` x seeds into :class:`Point` s (one run each);
- :class:`RunCli` runs one point as ``humanoid-twin run ... --json`` in a subprocess (a crash or a
  hang is that point's ``error``, never the end of the sweep) and returns its table row;
- :func:`run_sweep` runs the points with a task (:class:`RunCli` or any picklable
  ``task(point) -> summary dict``) on the ``local`` backend (a process pool) or on ``ray``, skips
  the points already in ``out`` and rewrites ``out`` atomically as runs finish.
"""

from __future__ import annotations

from humanoid_twin.sweep.engine import Point, RunCli, SweepError, grid, run_sweep, typed_value
from humanoid_twin.sweep.table import read_table, write_table

__all__ = ["Point", "RunCli", "SweepError", "grid", "run_sweep", "typed_value", "read_table", "write_table"]
