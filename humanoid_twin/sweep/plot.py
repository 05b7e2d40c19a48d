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
    if isinstance(v, str) and v.lower() in ("true", "false"):     # a CSV's true/false (an older True)
        return 1.0 if v.lower() == "true" else 0.0
    if isinstance(v, bool | int | float):
        return float(v)
    return math.nan


UNITS = {"_mm": "mm", "_deg": "deg", "_s": "s", "_n": "N"}
# cop_margin_min_mm when no foot pad touched the platform at some sample (scenarios.NO_SUPPORT_MARGIN_MM):
# not a distance, drawn as a marker under the axis instead of a point that would set its range
NO_SUPPORT = -1000.0


def _label(name: str) -> str:
    """An axis label with the unit its name ends with: ``cop_margin_min_mm`` -> ``... (mm)``."""
    for suffix, unit in UNITS.items():
        if name.endswith(suffix):
            return f"{name} ({unit})"
    return {"tilt": "tilt (deg)", "T": "T (s)", "motion": "motion (deg)"}.get(name, name)


def plot_sweep(rows: Sequence[dict[str, Any]], x: str, metric: str, path: Path,
               names: Sequence[str], title: str | None = None) -> None:
    """Write ``path`` (PNG): ``metric`` against parameter ``x``; one line per combination of the
    other parameters ``names`` (and seeds), each with its own marker and a small sideways offset
    so that identical lines stay visible; failed runs are gaps; a ``cop_margin_min_mm`` of -1000
    (no foot touching) is a red cross under the lowest value, not a point of the line."""
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
    numeric = sorted(v for v in xs_all if isinstance(v, int | float))
    steps = [b - a for a, b in zip(numeric, numeric[1:], strict=False) if b > a]
    spread = (1.0 if categorical else (min(steps) if steps else 1.0)) * 0.12
    n = len(lines)
    real = [m for pts in lines.values() for _, m in pts if not math.isnan(m) and m != NO_SUPPORT]
    floor = (min(real) - 0.1 * (max(real) - min(real) or 1.0)) if real else 0.0
    markers = "osD^v<>ph*"
    nosupport_drawn = False
    for i, (label, pts) in enumerate(lines.items()):
        off = (i - (n - 1) / 2) * spread / max(n - 1, 1) if n > 1 else 0.0
        xs = [(order.index(v) if categorical else v) + off for v, _ in pts]
        ys = [math.nan if m == NO_SUPPORT else m for _, m in pts]
        ax.plot(xs, ys, marker=markers[i % len(markers)], linestyle="-", alpha=0.85,
                label=", ".join(f"{n_}={v}" for n_, v in label) or metric)
        lost = [xx for xx, (_, m) in zip(xs, pts, strict=True) if m == NO_SUPPORT]
        if lost:
            ax.plot(lost, [floor] * len(lost), "x", color="red", markersize=9,
                    label=None if nosupport_drawn else "no foot touching (-1000)")
            nosupport_drawn = True
    if categorical:
        ax.set_xticks(range(len(order)), [str(v) for v in order])
    ax.set_xlabel(_label(x))
    ax.set_ylabel(_label(metric))
    ax.set_title(title or f"{metric} against {x}")
    ax.grid(True, alpha=0.3)
    if len(lines) > 1 or others or nosupport_drawn:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
