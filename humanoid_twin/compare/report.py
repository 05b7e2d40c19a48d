"""``calibrate --report F.html``: every signal before and after the fit, on the training and the
validation logs, in one self-contained HTML page (inline SVG, no script, nothing fetched).

Per log: a table of the RMS per signal group before and after, then one small plot per signal
that was compared: the log (black), the twin before the fit (grey) and after it (blue), on the
log's time. ``--report F.rrd`` writes the same as a rerun recording instead
(humanoid_twin/compare/overlay.py: ``before/LOG/...`` and ``after/LOG/...``).
"""

from __future__ import annotations

import html
import pathlib
from collections.abc import Sequence
from typing import Any

import numpy as np

from humanoid_twin.compare.signals import GROUP_UNITS, GROUPS, SIGNALS

__all__ = ["write_report"]

_W, _H, _POINTS = 360, 90, 400


def _poly(t: np.ndarray, v: np.ndarray, t0: float, t1: float, lo: float, hi: float, colour: str) -> str:
    if t.size == 0:
        return ""
    step = max(1, t.size // _POINTS)
    ts, vs = t[::step], v[::step]
    sx = (_W - 4) / max(t1 - t0, 1e-9)
    sy = (_H - 4) / max(hi - lo, 1e-9)
    pts = " ".join(f"{2 + (a - t0) * sx:.1f},{_H - 2 - (b - lo) * sy:.1f}"
                   for a, b in zip(ts, vs, strict=True))
    return f'<polyline fill="none" stroke="{colour}" stroke-width="1" points="{pts}"/>'


def _plot(name: str, before: tuple, after: tuple) -> str:
    t, tb, log = before
    t2, ta, _ = after
    arrays = [a for a in (tb, log, ta) if a.size]
    if not arrays:
        return ""
    lo = min(float(a.min()) for a in arrays)
    hi = max(float(a.max()) for a in arrays)
    if hi == lo:
        hi, lo = hi + 0.5, lo - 0.5
    t0 = float(min(t.min() if t.size else 0, t2.min() if t2.size else 0))
    t1 = float(max(t.max() if t.size else 1, t2.max() if t2.size else 1))
    svg = (f'<svg width="{_W}" height="{_H}" style="border:1px solid #ddd">'
           + _poly(t, log, t0, t1, lo, hi, "#000") + _poly(t, tb, t0, t1, lo, hi, "#aaa")
           + _poly(t2, ta, t0, t1, lo, hi, "#1f77b4") + "</svg>")
    return f'<div class="p"><div>{html.escape(name)} [{lo:g} .. {hi:g}]</div>{svg}</div>'


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f}"


def _section(title: str, before: Any, after: Any) -> str:
    rows = "".join(f"<tr><td>{g}</td><td>{GROUP_UNITS[g]}</td><td>{_fmt(before.rms[g])}</td>"
                   f"<td>{_fmt(after.rms[g])}</td></tr>" for g in GROUPS)
    plots = "".join(_plot(s.name, before.series[s.name], after.series[s.name]) for s in SIGNALS)
    return (f"<h2>{html.escape(title)}: {html.escape(before.log)}</h2>"
            f"<p>frames compared {after.frames_compared}, "
            f"missing in the twin {after.frames_missing['twin']}, "
            f"in the log {after.frames_missing['log']}</p>"
            "<table><tr><th>group</th><th>unit</th><th>RMS before</th><th>RMS after</th></tr>"
            f"{rows}</table><div>{plots}</div>")


def _fit_row(name: str, e: dict[str, Any]) -> str:
    ci = "-" if e["ci95"] is None else f"{e['ci95'][0]:.4g} .. {e['ci95'][1]:.4g}"
    ident = "yes" if e["identifiable"] else "no: " + html.escape(e.get("needs", ""))
    return (f"<tr><td>{html.escape(name)}</td><td>{e['start']:g}</td><td>{e['value']:g}</td>"
            f"<td>{ci}</td><td>{ident}</td></tr>")


def write_report(path: str | pathlib.Path, fitted: dict[str, Any], summary: dict[str, Any],
                 training: Sequence[tuple[Any, Any]], validation: Sequence[tuple[Any, Any]]) -> None:
    """The HTML report at ``path``: the fitted values, then each log's signals before and after."""
    rows = "".join(_fit_row(name, e) for name, e in fitted.items())
    head = ("<!doctype html><html><head><meta charset='utf-8'><title>humanoid-twin calibrate</title>"
            "<style>body{font-family:sans-serif}td,th{padding:2px 8px;border-bottom:1px solid #eee}"
            ".p{display:inline-block;margin:4px;font-size:11px}</style></head><body>"
            "<h1>humanoid-twin calibrate</h1><p>log: black; twin before the fit: grey; after: blue</p>")
    resid = "".join(f"<li>{k}: {_fmt(summary.get(k))}</li>" for k in
                    ("residual_before", "residual_after", "validation_before", "validation_after"))
    body = ("<table><tr><th>parameter</th><th>start</th><th>fitted</th><th>95 %</th>"
            f"<th>identifiable</th></tr>"
            f"{rows}</table><ul>{resid}<li>evaluations: {summary.get('evaluations')}</li></ul>")
    sections = "".join(_section("training", b, a) for b, a in training)
    sections += "".join(_section("validation", b, a) for b, a in validation)
    pathlib.Path(path).write_text(head + body + sections + "</body></html>\n", encoding="utf-8")
