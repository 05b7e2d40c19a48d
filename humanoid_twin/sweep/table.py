"""The sweep table: CSV (standard library) or Parquet (pyarrow, the ``parquet`` extra), written
atomically (a temporary file in the same folder, then a rename), so an existing table is never left
half-written."""

from __future__ import annotations

import csv
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


def cells(summary: dict[str, Any]) -> dict[str, Any]:
    """A run's summary as the cells of its row: a dict one column per key (``task_load_max_slaves``),
    a list the words of the run's own table (``humanoid_twin.summary.table_cells``)."""
    from humanoid_twin.summary import table_cells

    return table_cells(summary)


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
_INT_PREFIXES = ("deadline_misses_",)
_FLOAT_SUFFIXES = ("_s", "_mm", "_deg", "_n")
_FLOAT_PREFIXES = ("task_load_max_",)
_FLOAT_COLUMNS = frozenset({"rtf", "tilt", "T", "motion", "duration"})
BOOL_COLUMNS = frozenset({"fell", "booted", "completed", "recording_compacted"})
KINDS = ("int", "float", "bool", "string")


def column_kind(name: str) -> str | None:
    """The kind (``int``, ``float``, ``bool``) a column's name says, None when it says none (text,
    or what its values are)."""
    if name in INT_COLUMNS or name.startswith(_INT_PREFIXES):
        return "int"
    if name in BOOL_COLUMNS:
        return "bool"
    if name in _FLOAT_COLUMNS or name.endswith(_FLOAT_SUFFIXES) or name.startswith(_FLOAT_PREFIXES):
        return "float"
    return None


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _column_type(pa: Any, name: str, values: list[Any], kind: str | None = None) -> Any:
    arrow = {"int": pa.int64(), "float": pa.float64(), "bool": pa.bool_(), "string": pa.string()}
    if kind is not None:         # a parameter's kind, from its option (docs/sweeps.md)
        return arrow[kind]
    present = [v for v in values if v is not None]
    if not present:              # a column empty in this sweep (fell_at_s: nothing fell) keeps its type
        return arrow[column_kind(name) or "string"]
    if column_kind(name) == "int" and all(_is_int(v) for v in present):
        return pa.int64()
    if all(isinstance(v, bool) for v in present):
        return pa.bool_()
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pa.float64()
    return pa.string()


def _as_kind(value: Any, kind: Any, pa: Any) -> Any:
    if value is None:
        return None
    if kind == pa.float64():
        return float(value)
    if kind == pa.int64():
        return int(value)
    if kind == pa.bool_():
        return value if isinstance(value, bool) else str(value).lower() in ("true", "yes", "1")
    return value if isinstance(value, str) else str(value)


def parquet_schema(rows: list[dict[str, Any]], columns: list[str],
                   kinds: dict[str, str] | None = None) -> Any:
    """The Parquet schema of a sweep table: one fixed type per column, never Arrow ``null`` (an
    empty column takes the type its name says), ``kinds`` (column -> ``int``, ``float``, ``bool``,
    ``string``: a parameter's, from its option) first, ints only for :data:`INT_COLUMNS`, other
    numbers as float64, text for the rest (docs/sweeps.md). The cells of ``rows`` are converted
    to their column's type in place."""
    pa = _pyarrow()
    kinds = kinds or {}
    fields = []
    for c in columns:
        kind = _column_type(pa, c, [r.get(c) for r in rows], kinds.get(c))
        fields.append(pa.field(c, kind))
        for r in rows:
            r[c] = _as_kind(r.get(c), kind, pa)
    return pa.schema(fields)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _csv_text(value: Any) -> str:
    """A cell as CSV text: empty for none, ``true``/``false`` as ``run --json`` spells them (pandas,
    polars, DuckDB and pyarrow read them back as booleans), numbers and text as they are."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def write_table(path: Path, rows: list[dict[str, Any]], columns: list[str],
                kinds: dict[str, str] | None = None) -> None:
    """Write ``rows`` (missing cells empty) to ``path`` atomically; ``kinds``: the Parquet type of
    some columns (:func:`parquet_schema`)."""
    fmt = table_format(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.resolve().parent)
    try:
        if fmt == "parquet":
            os.close(fd)
            pa = _pyarrow()
            import pyarrow.parquet as pq

            full = [{c: row.get(c) for c in columns} for row in rows]
            schema = parquet_schema(full, columns, kinds)
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
