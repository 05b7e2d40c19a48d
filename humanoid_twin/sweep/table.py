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


# columns whose values are whole numbers in every sweep; every other number is a float, so that
# two sweeps (tilt=10,20 and tilt=2.5) have one type per column and read as one dataset
INT_COLUMNS = frozenset({"seed", "can_frames", "serial_frames", "host_controller_calls", "perna"})
_FLOAT_SUFFIXES = ("_s", "_mm", "_deg", "_n")
_FLOAT_COLUMNS = frozenset({"rtf", "tilt", "T", "motion", "duration"})


def _column_type(pa: Any, name: str, values: list[Any]) -> Any:
    present = [v for v in values if v is not None]
    if name in INT_COLUMNS and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.int64()
    if present and all(isinstance(v, bool) for v in present):
        return pa.bool_()
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pa.float64()
    if not present and (name in _FLOAT_COLUMNS or name.endswith(_FLOAT_SUFFIXES)):
        return pa.float64()      # a column empty in this sweep (fell_at_s: nothing fell) keeps its type
    if not present and name in ("fell", "completed"):
        return pa.bool_()
    return pa.string()


def parquet_schema(rows: list[dict[str, Any]], columns: list[str]) -> Any:
    """The Parquet schema of a sweep table: one fixed type per column, never Arrow ``null`` (an
    empty column takes the type its name says), ints only for :data:`INT_COLUMNS`, other numbers
    as float64, text for the rest (docs/sweeps.md)."""
    pa = _pyarrow()
    fields = []
    for c in columns:
        kind = _column_type(pa, c, [r.get(c) for r in rows])
        fields.append(pa.field(c, kind))
        if kind == pa.float64():
            for r in rows:
                if isinstance(r.get(c), int):
                    r[c] = float(r[c])
        elif kind == pa.string():
            for r in rows:
                if r.get(c) is not None and not isinstance(r[c], str):
                    r[c] = str(r[c])
    return pa.schema(fields)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


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
            schema = parquet_schema(full, columns)
            table = pa.Table.from_pylist(full, schema=schema) if full else schema.empty_table()
            pq.write_table(table, tmp)
        else:
            with os.fdopen(fd, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(columns)
                for row in rows:
                    w.writerow([_csv_text(row.get(c)) for c in columns])
                f.flush()
                os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())      # like the other outputs (mkstemp makes 0600)
        os.replace(tmp, path.resolve())       # through a symlink: beside its target (same disk)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
