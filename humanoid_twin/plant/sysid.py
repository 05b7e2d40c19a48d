"""MuJoCo's system-identification toolbox (``mujoco.sysid``), reached through the plant.

MuJoCo lives in ``plant/`` only (tests/project/test_layers.py): ``calibrate`` (humanoid_twin/compare/
calibrate.py) takes the toolbox from here. It is installed by the ``mujoco[sysid]`` extra, this
project's ``calibrate`` extra (docs/calibration.md says what of it the fit uses, and why not the
rest).
"""

from __future__ import annotations

from typing import Any

__all__ = ["SysidMissingError", "toolbox"]


class SysidMissingError(ImportError):
    """``mujoco.sysid`` (or scipy, which it needs) is not installed."""


def toolbox() -> Any:
    """The ``mujoco.sysid`` module; :class:`SysidMissingError` when the extra is not installed."""
    try:
        import scipy  # noqa: F401
        from mujoco import sysid
    except ImportError as exc:
        raise SysidMissingError("calibrate needs MuJoCo's sysid toolbox: "
                                f"pip install 'humanoid-twin[calibrate]' ({exc})") from None
    return sysid
