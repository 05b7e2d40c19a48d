"""The sweep table: CSV (standard library) or Parquet (pyarrow, the ``parquet`` extra), written
atomically (a temporary file in the same folder, then a rename), so an existing table is never left
half-written."""

from __future__ import annotations

import csv
import json
import os
import tempfile
from pathlib import Path
from typing import Any

FORMATS = (".csv", ".parquet")


class SweepError(Exception):
    """Bad sweep input (one line for the user; the CLI exits 2)."""


def table_format(path: Path) -> str:
    """``csv`` or ``parquet`` from the suffix of ``path``; :class:`SweepError` otherwise."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise SweepError(f"--out {path}: a sweep table ends in .csv or .parquet")
    if suffix == ".parquet":
        _pyarrow()
    return suffix[1:]


def _pyarrow() -> Any:
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise SweepError("Parquet output needs pyarrow: pip install 'humanoid-twin[parquet]' "
                         "(or write a .csv)") from None
    return pyarrow


def cell(value: Any) -> Any:
    """A summary value as a table cell: lists and dicts as JSON text, the rest as it is."""
    if isinstance(value, list | tuple | dict):
        return json.dumps(value, sort_keys=True)
    return value


def read_table(path: Path) -> list[dict[str, Any]]:
    """The rows of an existing sweep table (CSV cells as text, Parquet cells typed)."""
    if table_format(path) == "parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pylist()
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _csv_text(value: Any) -> str:
    return "" if value is None else str(value)


def write_table(path: Path, rows: list[dict[str, Any]], columns: list[str]) -> None:
    """Write ``rows`` (missing cells empty) to ``path`` atomically."""
    fmt = table_format(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.resolve().parent)
    try:
        if fmt == "parquet":
            os.close(fd)
            pa = _pyarrow()
            import pyarrow.parquet as pq

            full = [{c: row.get(c) for c in columns} for row in rows]
            table = pa.Table.from_pylist(full) if full else pa.table({c: [] for c in columns})
            pq.write_table(table, tmp)
        else:
            with os.fdopen(fd, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(columns)
                for row in rows:
                    w.writerow([_csv_text(row.get(c)) for c in columns])
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path.resolve())   # through a symlink: beside its target (same disk)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
