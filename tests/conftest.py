"""Shared fixtures: a twin and a booted twin (the one boot sequence, ``scenarios.boot``).

Tests that attach an observer (a monitor, a CAN log, faults, supervisor listeners) before the
boot build their twin themselves and call :func:`humanoid_twin.scenarios.boot` on it.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from humanoid_twin.scenarios import boot
from humanoid_twin.twin import Twin


@pytest.fixture
def twin() -> Iterator[Twin]:
    """A fresh twin, seed 0, not booted (Slaves with PWM off); closed after the test."""
    tw = Twin(seed=0)
    yield tw
    tw.close()


@pytest.fixture
def booted_twin(twin: Twin) -> tuple[Twin, Any]:
    """``(twin, H)``: the seed-0 twin after :func:`~humanoid_twin.scenarios.boot` (PWM on,
    every Slave calibrated) and the host end ``H`` of its RS-232 link."""
    return twin, boot(twin)
