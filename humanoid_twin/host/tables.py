"""The host's robot tables and the three functions that use them (seed 000 table 26).

``adaptate`` (leg angle -> servo angle: ``position * signal + offset``), ``correct`` (+ ``calib``,
the drift of belts and shafts) and ``limit`` (clip to ``lim_min`` .. ``lim_max``, the structure's
limits inside the servos' -90..90). The five 8 x 3 tables live in ONE editable file,
``humanoid_twin/host/robot_tables.json`` (with notes); :func:`load_tables` reads and checks it.

Angles: ``position`` holds the 3 servos of one SCU, degrees. ``adaptate``'s input is the leg
angle of the planners (joint frame of the MuJoCo model, 0 = vertical posture); its output and
everything after it is in the servo frame (what ``applyjoint`` sends).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import numpy as np

from humanoid_twin.hardware import N_SERVOS
from humanoid_twin.protocol.wire import N_SCU, POS_LIMIT_DEG, check_scu

__all__ = [
    "TABLES_PATH",
    "TABLE_NAMES",
    "RobotTables",
    "TablesError",
    "load_tables",
    "default_tables",
    "adaptate",
    "correct",
    "limit",
    "servo_to_leg",
]

# package data, read with importlib.resources (works from a wheel, an editable install, a checkout)
TABLES_PATH: Traversable = resources.files(__package__) / "robot_tables.json"
TABLE_NAMES = ("signal", "offset", "calib", "lim_min", "lim_max")


class TablesError(ValueError):
    """The robot tables file is missing, malformed or inconsistent."""


@dataclass(frozen=True)
class RobotTables:
    """The tables of seed 000 table 26, each an (8, 3) float array, row ``scu - 1``."""

    signal: np.ndarray
    offset: np.ndarray
    calib: np.ndarray
    lim_min: np.ndarray
    lim_max: np.ndarray
    force_calib_load: float
    path: str = ""


def _table(doc: dict[str, Any], name: str, path: Path) -> np.ndarray:
    try:
        entry = doc[name]
        values = entry["values"] if isinstance(entry, dict) else entry
        arr = np.array(values, dtype=float)
    except KeyError:
        raise TablesError(f"{path}: table {name!r} is missing (needs {{'values': 8 x 3}})") from None
    except (TypeError, ValueError) as exc:
        raise TablesError(f"{path}: table {name!r} is not a numeric 8 x 3 array: {exc}") from None
    if arr.shape != (N_SCU, N_SERVOS):
        raise TablesError(f"{path}: table {name!r} must be {N_SCU} x {N_SERVOS}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise TablesError(f"{path}: table {name!r} has non-finite values")
    arr.setflags(write=False)
    return arr


def load_tables(path: str | Path | None = None) -> RobotTables:
    """Read and check the robot tables (default: the package's ``robot_tables.json``).

    Checks: every table 8 x 3 and finite; ``signal`` only +1/-1; ``lim_min <= lim_max``, both
    within -90..90. Raises :class:`TablesError` naming the file and the problem.
    """
    p: Traversable | Path = TABLES_PATH if path is None else Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise TablesError(f"cannot read robot tables {p}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise TablesError(f"{p} is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise TablesError(f"{p}: expected a JSON object with the tables {TABLE_NAMES}")
    t = {name: _table(doc, name, p) for name in TABLE_NAMES}  # type: ignore[arg-type]  # a Path or the package's resource: both read_text
    if not np.all(np.abs(t["signal"]) == 1):
        raise TablesError(f"{p}: signal must be +1 or -1 everywhere, got {t['signal'].tolist()}")
    bad = np.argwhere(t["lim_min"] > t["lim_max"])
    if bad.size:
        scu, servo = bad[0]
        raise TablesError(f"{p}: lim_min > lim_max for SCU {scu + 1} servo {servo + 1}")
    for name in ("lim_min", "lim_max"):
        if np.any(np.abs(t[name]) > POS_LIMIT_DEG):
            raise TablesError(f"{p}: {name} must lie within -{POS_LIMIT_DEG}..{POS_LIMIT_DEG} degrees")
    entry = doc.get("force_calib_load", {"value": 0.0})
    try:
        load = float(entry["value"] if isinstance(entry, dict) else entry)
    except (KeyError, TypeError, ValueError):
        raise TablesError(f"{p}: force_calib_load must be a number (7-bit counts)") from None
    if not math.isfinite(load) or load < 0:
        raise TablesError(f"{p}: force_calib_load must be >= 0, got {load}")
    return RobotTables(**t, force_calib_load=load, path=str(p))


_DEFAULT: list[RobotTables] = []


def default_tables(reload: bool = False) -> RobotTables:
    """The package's tables, read once and cached (``reload=True`` re-reads the file)."""
    if reload or not _DEFAULT:
        _DEFAULT[:] = [load_tables()]
    return _DEFAULT[0]


def _row(scuid: Any) -> int:
    return check_scu(scuid, "scuid") - 1


def _position(position: Any) -> np.ndarray:
    arr = np.asarray(position, dtype=float)
    if arr.shape != (N_SERVOS,):
        raise ValueError(f"position must hold the {N_SERVOS} servos of one SCU, got shape {arr.shape}")
    if np.any(np.isnan(arr)):
        raise ValueError(f"position has NaN: {arr.tolist()}")
    return arr


def adaptate(scuid: int, position: Any, tables: RobotTables | None = None) -> np.ndarray:
    """``pos_final = adaptate(scuid, position)`` (seed 000 table 26): leg angles (0 = vertical
    posture) -> servo angles of SCU ``scuid``: ``position * signal + offset``."""
    t = tables or default_tables()
    r = _row(scuid)
    return _position(position) * t.signal[r] + t.offset[r]


def correct(scuid: int, position: Any, tables: RobotTables | None = None) -> np.ndarray:
    """``position_final = correct(scuid, position)`` (table 26): servo angles + ``calib`` (the drift
    of the servo's belt and shaft)."""
    t = tables or default_tables()
    r = _row(scuid)
    return _position(position) + t.calib[r]


def limit(scuid: int, position: Any, tables: RobotTables | None = None) -> np.ndarray:
    """``position_final = limit(scuid, position)`` (table 26): servo angles clipped to
    ``lim_min`` .. ``lim_max`` (the structure's limits, within the servos' -90..90)."""
    t = tables or default_tables()
    r = _row(scuid)
    return np.clip(_position(position), t.lim_min[r], t.lim_max[r])


def servo_to_leg(scuid: int, position: Any, tables: RobotTables | None = None) -> np.ndarray:
    """Inverse of ``correct(adaptate(..))``: measured servo angles -> leg angles (NaN passes
    through, for missing samples)."""
    t = tables or default_tables()
    r = _row(scuid)
    arr = np.asarray(position, dtype=float)
    if arr.shape[:1] != (N_SERVOS,):
        raise ValueError(f"position must hold the {N_SERVOS} servos of one SCU first, got shape {arr.shape}")
    sig = t.signal[r].reshape((N_SERVOS,) + (1,) * (arr.ndim - 1))
    off = (t.offset[r] + t.calib[r]).reshape(sig.shape)
    return (arr - off) * sig
