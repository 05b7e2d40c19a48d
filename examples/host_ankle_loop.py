"""A PC-side balance loop: the host reads both feet's force sensors over the serial link and
turns both ankles (foot front joints) together to keep the mean CoP on the feet's centres.

Run it on a tilting platform with the firmware laws off (docs/controllers.md):

    humanoid-twin run stand --control none --tilt 20 --host-controller examples.host_ankle_loop:step

(from the repository root; or ``--host-controller host_ankle_loop:step`` from examples/). Without
``--host-controller`` the robot falls from about 13 deg of tilt; with it, it stands. The same
``step`` drives the real robot: only the serial port changes (docs/host.md).

Both legs get the *same* ankle command (the host sees both feet): no leader/follower split is
needed, unlike two boards each closing a loop on its own foot (docs/balance.md 2.2).
"""

from __future__ import annotations

import math

from humanoid_twin.controllers import HostContext

GAIN_DEG_PER_MM = 0.005      # ankle pitch change per call per mm of mean CoP error
LEGS = (1, 2)                # SCU 1 right leg, SCU 2 left leg (foot lateral, foot front, knee)


def step(ctx: HostContext) -> None:
    """Called every --host-period-ms (default 20 ms) of simulated time."""
    host = ctx.host
    pitch = ctx.state.setdefault("pitch_deg", 0.0)
    ys = []
    for scu in LEGS:
        r = host.readspecial(scu)                 # 4 force readings, table 12 order
        if r.error:
            return                                # a lost frame: try again next call
        cop = host.calccop(r.special)             # (x, y) mm in the foot frame, NaN unloaded
        if not math.isnan(cop[1]):
            ys.append(float(cop[1]))
    if not ys:
        return
    cop_y = sum(ys) / len(ys)                     # mm, forward positive
    # CoP forward of the centre: the mass is too far forward: ankle pitch + (toes down) moves
    # the shanks, and the mass, back
    pitch += GAIN_DEG_PER_MM * cop_y
    ctx.state["pitch_deg"] = pitch
    for scu in LEGS:
        host.applyjoint(scu, 0, host.servo_command(scu, [0.0, pitch, 0.0]))
