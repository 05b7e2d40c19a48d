"""Regenerate the parts of the docs that are generated from the code (a test fails when they drift).

    .venv/bin/python scripts/gen_docs.py           # rewrite them in place
    .venv/bin/python scripts/gen_docs.py --check   # exit 1 and name each block that differs

Each block sits between ``<!-- generated: NAME -->`` and ``<!-- end generated: NAME -->`` in a doc:

- ``summary-keys`` in docs/scenarios.md: the run summary's keys (``summary.SUMMARY_KEYS``).
- ``fault-kinds`` in docs/supervisor.md: the ``--fault`` kinds (``faults.KINDS``).
- ``parameters`` in docs/parameters.md: every named parameter (``params.registry()``).
- ``core-modules`` in docs/architecture.md: the compiled core and why each module is in it
  (``core_modules.CORE_MODULES``).

docs/fault_matrix.md is the output of ``scripts/fault_matrix.py --seed 0 --out docs/fault_matrix.md``
(48 runs; tests/project/test_docs.py checks its text and cells against the script, re-runs a sample of
its rows and compares).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _summary_keys() -> str:
    from humanoid_twin.summary import summary_keys_markdown

    return summary_keys_markdown()


def _fault_kinds() -> str:
    from humanoid_twin.faults import kinds_markdown

    return kinds_markdown()


def _parameters() -> str:
    from humanoid_twin.params import params_markdown

    return params_markdown()


def _core_modules() -> str:
    from humanoid_twin.core_modules import core_modules_markdown

    return core_modules_markdown()


BLOCKS: dict[str, tuple[Path, Callable[[], str]]] = {
    "summary-keys": (ROOT / "docs" / "scenarios.md", _summary_keys),
    "fault-kinds": (ROOT / "docs" / "supervisor.md", _fault_kinds),
    "parameters": (ROOT / "docs" / "parameters.md", _parameters),
    "core-modules": (ROOT / "docs" / "architecture.md", _core_modules),
}


def _pattern(name: str) -> re.Pattern[str]:
    n = re.escape(name)
    return re.compile(rf"(<!-- generated: {n} -->\n)(.*?)(<!-- end generated: {n} -->)", re.S)


def render(name: str) -> tuple[Path, str, str]:
    """(the doc, its text now, its text with block ``name`` regenerated)."""
    path, make = BLOCKS[name]
    text = path.read_text()
    pat = _pattern(name)
    if not pat.search(text):
        raise SystemExit(f"{path}: no block '{name}' (markers <!-- generated: {name} -->)")
    return path, text, pat.sub(lambda m: m.group(1) + make() + m.group(3), text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if a block drifted")
    args = ap.parse_args(argv)
    stale = []
    for name in BLOCKS:
        path, old, new = render(name)
        if old != new:
            stale.append(f"{path.relative_to(ROOT)}: {name}")
            if not args.check:
                path.write_text(new)
    for s in stale:
        print(("stale: " if args.check else "rewrote: ") + s, file=sys.stderr)
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    raise SystemExit(main())
