"""Module MyMATHS of the Slave firmware (seed 000 section 3, "Módulo MyMATHS", table 15).

Integer maths for the balance controllers: ``abs`` of a signed int, and ``seno`` / ``coseno`` from
one look-up table of ``100 * sin`` for every whole degree 0..90. The values listed in table 15
(0->0, 1->1, 2->3, 3->5, 4->6, 5->8, 81->98, 82->99, 83->99, 89->99, 90->100) are *truncated*, not
rounded (100 * sin 2 deg = 3.49 -> 3, 100 * sin 4 deg = 6.98 -> 6), so the table is built by
truncation (docs/firmware.md, "MyMATHS"). Arguments of any sign and size are folded into 0..90 and
the sign is applied afterwards, as the manual asks; ``coseno(t) = seno(90 - t)``.
"""

from __future__ import annotations

import math

__all__ = ["SINE_TABLE", "abs", "seno", "coseno"]


def _build_table() -> tuple[int, ...]:
    # The tiny epsilon keeps exact values exact under truncation: sin(30 deg) is
    # 0.49999999999999994 in binary floating point and must give 50, not 49.
    return tuple(int(100.0 * math.sin(math.radians(d)) + 1e-9) for d in range(91))


SINE_TABLE: tuple[int, ...] = _build_table()
"""``SINE_TABLE[d] = trunc(100 * sin(d degrees))`` for d = 0..90 (table 15)."""


def abs(value: int) -> int:
    """MyMATHS ``abs``: modulus of a ``signed int``, returned as ``unsigned int``."""
    return -value if value < 0 else value


def seno(angle_deg: int) -> int:
    """MyMATHS ``seno`` (table 15): ``100 * sin(angle)`` as an int in -100..100, angle in whole
    degrees (any value: folded into 0..90 with the sign restored)."""
    a = angle_deg % 360                  # 0..359
    if a > 180:
        a -= 360                         # -179..180
    if a < 0:
        a = -a
        if a > 90:
            a = 180 - a
        return -SINE_TABLE[a]
    if a > 90:
        a = 180 - a
    return SINE_TABLE[a]


def coseno(angle_deg: int) -> int:
    """MyMATHS ``coseno``: ``100 * cos(angle)`` = ``seno(90 - angle)`` (the same table)."""
    return seno(90 - angle_deg)
