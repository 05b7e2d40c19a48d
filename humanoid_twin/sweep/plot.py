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
    _check_metric(rows, metric)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    others = _varied(rows, x, names)
    lines = _lines(rows, x, metric, others)
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    axis = _XAxis([v for pts in lines.values() for v, _ in pts], len(lines))
    nosupport_drawn = _draw_lines(ax, lines, axis, metric)
    if axis.categorical:
        ax.set_xticks(range(len(axis.order)), [str(v) for v in axis.order])
    ax.set_xlabel(_label(x))
    ax.set_ylabel(_label(metric))
    ax.set_title(title or f"{metric} against {x}")
    ax.grid(True, alpha=0.3)
    if len(lines) > 1 or others or nosupport_drawn:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _check_metric(rows: Sequence[dict[str, Any]], metric: str) -> None:
    """``metric`` is a column of the rows (:class:`SweepError` naming the columns otherwise)."""
    if rows and not any(metric in r for r in rows):
        keys = sorted({k for r in rows for k in r})
        raise SweepError(f"--metric {metric!r} is not a column of the sweep (columns: {' '.join(keys)})")


def _varied(rows: Sequence[dict[str, Any]], x: str, names: Sequence[str]) -> list[str]:
    """The parameters (``names`` and ``seed``) besides ``x`` that take more than one value: one
    line per combination of them."""
    return [n for n in dict.fromkeys((*names, "seed")) if n != x and len({str(r.get(n)) for r in rows}) > 1]


def _lines(rows: Sequence[dict[str, Any]], x: str, metric: str, others: list[str]
           ) -> dict[tuple, list[tuple[Any, float]]]:
    """The plot's lines: the rows grouped by their values of ``others`` (the label), each a list of
    (x value, metric) in the rows' order."""
    lines: dict[tuple, list[tuple[Any, float]]] = {}
    for r in rows:
        label = tuple((n, r.get(n)) for n in others)
        lines.setdefault(label, []).append((typed_value(r.get(x)), _number(r.get(metric))))
    return lines


class _XAxis:
    """Where the points of the lines go along x: numbers where every x value is one (else the
    values in their first order, as categories), each line shifted sideways by its own small
    offset (a fraction of the smallest step between values)."""

    def __init__(self, xs_all: list[Any], n_lines: int) -> None:
        self.categorical = not all(isinstance(v, int | float) for v in xs_all)
        self.order = list(dict.fromkeys(xs_all))
        numeric = sorted(v for v in xs_all if isinstance(v, int | float))
        steps = [b - a for a, b in zip(numeric, numeric[1:], strict=False) if b > a]
        self.spread = (1.0 if self.categorical else (min(steps) if steps else 1.0)) * 0.12
        self.n = n_lines

    def positions(self, i: int, pts: list[tuple[Any, float]]) -> list[float]:
        """The x positions of line ``i``'s points."""
        n = self.n
        off = (i - (n - 1) / 2) * self.spread / max(n - 1, 1) if n > 1 else 0.0
        return [(self.order.index(v) if self.categorical else v) + off for v, _ in pts]


def _floor(lines: dict[tuple, list[tuple[Any, float]]]) -> float:
    """Where the no-support crosses go: a tenth of the values' range under the lowest value."""
    real = [m for pts in lines.values() for _, m in pts if not math.isnan(m) and m != NO_SUPPORT]
    return (min(real) - 0.1 * (max(real) - min(real) or 1.0)) if real else 0.0


def _draw_lines(ax: Any, lines: dict[tuple, list[tuple[Any, float]]], axis: _XAxis, metric: str) -> bool:
    """Each line with its own marker, its no-support points as red crosses under the lowest value;
    whether any cross was drawn (it has a legend entry)."""
    floor = _floor(lines)
    markers = "osD^v<>ph*"
    nosupport_drawn = False
    for i, (label, pts) in enumerate(lines.items()):
        xs = axis.positions(i, pts)
        ys = [math.nan if m == NO_SUPPORT else m for _, m in pts]
        ax.plot(xs, ys, marker=markers[i % len(markers)], linestyle="-", alpha=0.85,
                label=", ".join(f"{n_}={v}" for n_, v in label) or metric)
        lost = [xx for xx, (_, m) in zip(xs, pts, strict=True) if m == NO_SUPPORT]
        if lost:
            ax.plot(lost, [floor] * len(lost), "x", color="red", markersize=9,
                    label=None if nosupport_drawn else "no foot touching (-1000)")
            nosupport_drawn = True
    return nosupport_drawn
