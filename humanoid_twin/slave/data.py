"""Module DATA of the Slave firmware (seed 000 section 3, tables 12-14).

``calcCoP``: the centre of pressure of a foot from its four force sensors and their table 12
coordinates, in integer arithmetic. ``jacobianMatrix``: the Jacobian of the leg's mass centre with
respect to (foot lateral, foot front, knee), from the table 13 constants and the MyMATHS sine
table, in integers. The derivation is in docs/firmware.md ("DATA").

Frames and units (docs/firmware.md):
- foot frame: x to the robot's right, y forward, z up, origin at the foot centre; sensor
  coordinates ``hardware.FORCE_SENSOR_XY_MM`` held here in tenths of a millimetre;
- the CoP is returned in whole millimetres;
- the Jacobian is in micrometres per radian; the angles enter in whole degrees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from humanoid_twin.hardware import COP_MIN_LOAD, FORCE_SENSOR_XY_MM, LINK_COM_MM, LINK_LENGTH_MM, LINK_MASS_KG
from humanoid_twin.slave.mymaths import coseno, seno

__all__ = [
    "SENSOR_X_TENTHS",
    "SENSOR_Y_TENTHS",
    "COP_MIN_LOAD",
    "LEG_A_TENTHS",
    "LEG_B_TENTHS",
    "calcCoP",
    "jacobianMatrix",
    "mass_centre_mm",
    "divround",
]

# Table 12 in tenths of a millimetre (integers; order FL, FR, RL, RR).
SENSOR_X_TENTHS: tuple[int, ...] = tuple(round(10 * x) for x, _ in FORCE_SENSOR_XY_MM)
SENSOR_Y_TENTHS: tuple[int, ...] = tuple(round(10 * y) for _, y in FORCE_SENSOR_XY_MM)

# Table 13, as the mass centre of the two leg links seen from the ankle (foot as the base).
# The lower link (M1) goes from the ankle to the knee, its CoM R = 47 mm below the knee, i.e.
# h = L - R = 48 mm above the ankle; the upper link (M2) from the knee to the hip, its CoM 48 mm
# above the knee. With m = M1 + M2:  A = (M1 h + M2 L) / m,  B = M2 h / m  (both 0.45 kg:
# A = 71.5 mm, B = 24 mm).
_M1 = _M2 = LINK_MASS_KG
_H = LINK_LENGTH_MM - LINK_COM_MM
LEG_A_MM: float = (_M1 * _H + _M2 * LINK_LENGTH_MM) / (_M1 + _M2)
LEG_B_MM: float = _M2 * _H / (_M1 + _M2)
LEG_A_TENTHS: int = round(10 * LEG_A_MM)
LEG_B_TENTHS: int = round(10 * LEG_B_MM)


def divround(n: int, d: int) -> int:
    """Integer ``n / d`` rounded to the nearest, halves away from zero (``d > 0``)."""
    if n >= 0:
        return (2 * n + d) // (2 * d)
    return -((-2 * n + d) // (2 * d))


def calcCoP(forces: Sequence[int]) -> tuple[int, int, bool]:
    """``calcCoP`` (table 14): centre of pressure ``(x_mm, y_mm, loaded)`` of a foot from its
    four 7-bit force values (table 12 order: front-left, front-right, rear-left, rear-right).

    ``CoP = sum(F_i * p_i) / sum(F_i)`` with the table 12 coordinates in tenths of a millimetre,
    rounded to whole millimetres. ``loaded`` is False (and the CoP is the foot centre, (0, 0))
    when the four forces add up to less than :data:`COP_MIN_LOAD`.
    """
    f0, f1, f2, f3 = forces
    total = f0 + f1 + f2 + f3
    if total < COP_MIN_LOAD:
        return 0, 0, False
    x0, x1, x2, x3 = SENSOR_X_TENTHS
    y0, y1, y2, y3 = SENSOR_Y_TENTHS
    den = 10 * total
    x = divround(f0 * x0 + f1 * x1 + f2 * x2 + f3 * x3, den)
    y = divround(f0 * y0 + f1 * y1 + f2 * y2 + f3 * y3, den)
    return x, y, True


def _cdiv100(n: int) -> int:
    """``n / 100`` truncated toward zero, as C integer division does."""
    return n // 100 if n >= 0 else -(-n // 100)


def jacobianMatrix(
    q0: int, q1: int, q2: int, signs: Sequence[int] = (1, 1, 1)
) -> tuple[tuple[int, int, int], tuple[int, int, int], tuple[int, int, int]]:
    """``jacobianMatrix`` (table 14): ``J[r][j] = d p_r / d q_j`` of the leg's mass centre
    ``p = (x lateral, y forward, z up)`` in the foot frame, in micrometres per radian, with
    respect to the servo angles ``q0`` foot lateral, ``q1`` foot front, ``q2`` knee (whole
    degrees, the servo frame).

    ``signs`` maps the servo angles onto the kinematic angles of docs/firmware.md (roll about
    +y, pitch and knee about +x, leg relative to the foot): ``a = s0 q0, b = s1 q1, c = s2 q2``;
    column ``j`` is multiplied by ``s_j`` accordingly. With ``Z = A cos b + B cos(b+c)`` and
    ``Y = -(A sin b + B sin(b+c))``::

        J = [[ Z cos a,   Y sin a,  -B sin(b+c) sin a],
             [ 0,        -Z,        -B cos(b+c)      ],
             [-Z sin a,   Y cos a,  -B sin(b+c) cos a]]

    Sines and cosines come from the MyMATHS table (x100); products of two table values are
    divided by 100 with C truncation.
    """
    s0, s1, s2 = signs
    a = s0 * q0
    b = s1 * q1
    bc = b + s2 * q2
    sa = seno(a)
    ca = coseno(a)
    sb = seno(b)
    cb = coseno(b)
    sbc = seno(bc)
    cbc = coseno(bc)
    A = LEG_A_TENTHS
    B = LEG_B_TENTHS
    z = A * cb + B * cbc          # micrometres (tenths of mm x 100)
    y = -(A * sb + B * sbc)
    bs = B * sbc
    bcz = B * cbc
    j11 = _cdiv100(z * ca)
    j12 = _cdiv100(y * sa)
    j13 = _cdiv100(-bs * sa)
    j31 = _cdiv100(-z * sa)
    j32 = _cdiv100(y * ca)
    j33 = _cdiv100(-bs * ca)
    return (
        (s0 * j11, s1 * j12, s2 * j13),
        (0, -s1 * z, -s2 * bcz),
        (s0 * j31, s1 * j32, s2 * j33),
    )


def mass_centre_mm(a_deg: float, b_deg: float, c_deg: float) -> tuple[float, float, float]:
    """The leg mass centre ``(x, y, z)`` in mm in the foot frame (origin at the ankle) for the
    *kinematic* angles ``a`` roll, ``b`` pitch, ``c`` knee, in float degrees: the function that
    :func:`jacobianMatrix` differentiates (docs/firmware.md)."""
    a = math.radians(a_deg)
    b = math.radians(b_deg)
    bc = b + math.radians(c_deg)
    z = LEG_A_MM * math.cos(b) + LEG_B_MM * math.cos(bc)
    y = -(LEG_A_MM * math.sin(b) + LEG_B_MM * math.sin(bc))
    return z * math.sin(a), y, z * math.cos(a)
