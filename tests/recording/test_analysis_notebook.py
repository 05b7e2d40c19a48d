"""examples/read_recording.ipynb runs top to bottom (the `analysis` extra: rerun's dataframe API,
pandas, python-can + the DBC) on a short recorded flexao."""

from __future__ import annotations

import pytest
from helpers import REPO

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

NOTEBOOK = REPO / "examples" / "read_recording.ipynb"


def test_read_recording_notebook_executes(tmp_path):
    # imported here, not at collection (jupyter's client costs a quarter second to import)
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(nb, timeout=180, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    assert (tmp_path / "flexao.rrd").is_file() and (tmp_path / "flexao.asc").is_file()
    last = "".join(o.get("text", "") for o in nb.cells[-1].outputs)
    assert "samples" in last and "CAN frames" in last, last
