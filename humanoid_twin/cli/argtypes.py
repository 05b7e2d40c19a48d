"""Checked number types for argparse, shared by ``run``, ``serve``, ``sweep`` and ``--fault``'s options.

Each is ``type=`` for ``add_argument``: a value that does not parse or is out of range becomes
argparse's own one-line usage error (exit 2, nothing written).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TypeVar

N = TypeVar("N", int, float)


def checked(kind: type[N], what: str, ok: Callable[[N], bool], must: str) -> Callable[[str], N]:
    """An argparse type: ``kind(text)`` ("not WHAT: ..." when it does not parse), finite, and
    ``ok(value)`` ("MUST, got ..." otherwise)."""

    def parse(text: str) -> N:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not {what}: {text!r}") from None
        if not (math.isfinite(value) and ok(value)):
            raise argparse.ArgumentTypeError(f"{must}, got {text!r}")
        return value

    return parse


positive_seconds = checked(float, "a number of seconds", lambda v: v > 0,
                           "must be a positive number of seconds")
non_negative_seconds = checked(float, "a number of seconds", lambda v: v >= 0,
                               "must be a number of seconds >= 0")
degrees_90 = checked(float, "a number of degrees", lambda v: abs(v) <= 90,
                     "must be within -90..90 degrees")
# a finite number of degrees, its range checked later by the one check of what it sets (--tilt:
# the platform's TILT_MAX_DEG, cli/options.check_rig_inputs): one range quoted, never two
degrees = checked(float, "a number of degrees", lambda v: True, "must be a finite number of degrees")
# a wall-clock limit: positive and finite, at most 10**7 s (~116 days; the interval timer's range)
wall_seconds = checked(float, "a number of seconds", lambda v: 0 < v <= 1e7,
                       "must be a number of seconds, 0 < S <= 10000000")
tcp_port = checked(int, "a port number", lambda v: 0 <= v <= 65535, "a TCP port is 0..65535")
count = checked(int, "a whole number", lambda v: v >= 1, "must be at least 1")
speed_factor = checked(float, "a speed factor", lambda v: 0.01 <= v <= 100,
                       "must be 0.01..100 (times real time)")
