"""The test route the README offers: one file runs in one process at once (no pytest-xdist workers
to start), the fast subset (``-m "not slow"``) comes before the whole suite, and CI (``.ci/run``)
runs the whole suite on one worker per core, with the README's own command."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys

from helpers import REPO


def _pytest_commands(text: str) -> list[str]:
    """Every ``pytest`` invocation of a text, from ``python -m pytest`` to the end of its line."""
    return [m.group(0).strip() for m in re.finditer(r"\S*python3? -m pytest[^\n`]*", text)]


def test_one_file_runs_in_one_process_without_workers():
    # a user's `python -m pytest tests/FILE.py`, nothing else on the line: no worker is started
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "tests/project/test_core.py::test_pure_python_switch_reads_only_set_values"],
                       cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "passed" in r.stdout
    assert not re.search(r"created: \d+/\d+ workers|\[gw\d+\]|bringing up nodes", r.stdout), r.stdout[-2000:]


def test_the_readme_offers_the_fast_subset_first_then_what_ci_runs():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    quick = readme[readme.index("## Quick start"):readme.index("\n## ", readme.index("## Quick start") + 1)]
    commands = _pytest_commands(quick)
    assert len(commands) == 2, commands
    fast, whole = (shlex.split(c) for c in commands)
    assert "-m" in fast[3:] and fast[fast.index("-m", 3) + 1] == "not slow", fast
    assert "not slow" not in whole, whole
    ci = _pytest_commands((REPO / ".ci" / "run").read_text(encoding="utf-8"))
    assert [shlex.split(c) for c in ci] == [whole], "the README's whole-suite command is .ci/run's"
    for argv in (fast, whole):
        assert argv[argv.index("-n") + 1] == "auto" and argv[argv.index("--dist") + 1] == "loadfile", argv
        # files in collection order, the longest first (tests/conftest.py), not by number of tests
        assert "--no-loadscope-reorder" in argv, argv


def test_the_longest_files_named_first_exist():
    from conftest import LONGEST_FIRST

    assert len(set(LONGEST_FIRST)) == len(LONGEST_FIRST)
    for name in LONGEST_FIRST:
        assert (REPO / "tests" / name).is_file(), name
