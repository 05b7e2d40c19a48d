"""The package type-checks: mypy on ``humanoid_twin`` with the settings of ``[tool.mypy]`` in
pyproject.toml (the bodies of unannotated functions too; an unneeded ``# type: ignore`` is an
error). The collaborators' types are named (``humanoid_twin/interfaces.py``, type-only imports),
so a call with the wrong object, or a renamed method, fails here before any run does.

Incremental: the cache is ``.mypy_cache`` in the repository (gitignored); about 35 s of CPU cold,
1-4 s warm.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys

import pytest
from helpers import REPO as ROOT

pytestmark = pytest.mark.slow       # over a minute cold on a busy 2-core machine: `-m "not slow"` skips it


def test_mypy_finds_no_error_in_the_package():
    if importlib.util.find_spec("mypy") is None:
        pytest.fail("mypy is not installed: pip install -e '.[test]'")
    r = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", str(ROOT / ".mypy_cache")],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    checked = re.search(r"no issues found in (\d+) source files", r.stdout)
    assert checked and int(checked[1]) > 50, r.stdout      # it read the whole package (pyproject's packages)
