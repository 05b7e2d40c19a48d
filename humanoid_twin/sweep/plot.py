"""``sweep --plot``: one metric against one parameter, one line per value of the other parameters."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from humanoid_twin.sweep.engine import typed_value
from humanoid_twin.sweep.table import SweepError


def _number(value: Any) -> float:
    v = typed_value(value)
    if v == "True":
        return 1.0
    if v == "False":
        return 0.0
    if isinstance(v, bool | int | float):
        return float(v)
    return math.nan


def plot_sweep(rows: Sequence[dict[str, Any]], x: str, metric: str, path: Path,
               names: Sequence[str]) -> None:
    """Write ``path`` (PNG): ``metric`` against parameter ``x``; one line per combination of the
    other parameters ``names`` (and seeds); failed runs are gaps."""
    if rows and not any(metric in r for r in rows):
        keys = sorted({k for r in rows for k in r})
        raise SweepError(f"--metric {metric!r} is not a column of the sweep (columns: {' '.join(keys)})")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    others = [n for n in dict.fromkeys((*names, "seed")) if n != x and len({str(r.get(n)) for r in rows}) > 1]
    lines: dict[tuple, list[tuple[Any, float]]] = {}
    for r in rows:
        label = tuple((n, r.get(n)) for n in others)
        lines.setdefault(label, []).append((typed_value(r.get(x)), _number(r.get(metric))))
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    xs_all = [v for pts in lines.values() for v, _ in pts]
    categorical = not all(isinstance(v, int | float) for v in xs_all)
    order = list(dict.fromkeys(xs_all))
    for label, pts in lines.items():
        xs = [order.index(v) if categorical else v for v, _ in pts]
        ax.plot(xs, [m for _, m in pts], "o-",
                label=", ".join(f"{n}={v}" for n, v in label) or metric)
    if categorical:
        ax.set_xticks(range(len(order)), [str(v) for v in order])
    ax.set_xlabel(x)
    ax.set_ylabel(metric)
    ax.grid(True, alpha=0.3)
    if len(lines) > 1 or others:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
