"""The host side: the 2006 MATLAB toolbox of the PC (seed 000 section 4), in Python over pyserial.

The same code drives a real serial port, a pty, a TCP socket (``socket://HOST:PORT``) or the
in-process twin (``twin://NAME``): only the URL given to :func:`initcom` (or
:class:`HumanoidClient`) changes. docs/host.md has the MATLAB -> Python table.

- drivers (table 20): :func:`initcom`, :func:`killcom`, :func:`calibcom`, :func:`readcanstat`,
  :func:`readjoint`, :func:`readspecial`, :func:`applyjoint`, :func:`applycontrol`,
  :class:`HumanoidClient`;
- one unit (table 21): :func:`predict_trajectory`, :func:`sample_traj`, :func:`sample_traj3`;
- planners (tables 22-23): :func:`flexao`, :func:`inclinar`, :func:`levantar_perna`;
- execution (tables 24-26): :func:`exe_traj`, :func:`recycle`, :func:`controller`,
  :func:`controller_off`, :func:`adaptate`, :func:`correct`, :func:`limit`, :func:`power_on`;
- forces (table 27): :func:`calccop`, :func:`cop_acquire`, :func:`cop_graphs`, :func:`cop_realtime`;
- time base: :func:`now`, :func:`sleep`.
"""

from humanoid_twin.host.cop import CopData, calccop, cop_acquire, cop_graphs, cop_realtime, sensor_loads
from humanoid_twin.host.drivers import (
    ERROR_TEXT,
    ApplyResult,
    BadFrame,
    CalibResult,
    CanStatResult,
    CanStatus,
    CommError,
    ErrorCode,
    HumanoidClient,
    InvalidRequest,
    PortError,
    ReadJointResult,
    ReadSpecialResult,
    SupervisorRefused,
    SupervisorResult,
    Timeout,
    applycontrol,
    applyjoint,
    calibcom,
    estop,
    initcom,
    killcom,
    readcanstat,
    readjoint,
    readspecial,
    readsupervisor,
    reset,
)
from humanoid_twin.host.motion import (
    TrajData,
    controller,
    controller_off,
    exe_traj,
    power_on,
    recycle,
    servo_command,
)
from humanoid_twin.host.planners import GAINS, LEG_SCUS, flexao, inclinar, levantar_perna
from humanoid_twin.host.tables import RobotTables, adaptate, correct, default_tables, limit, load_tables
from humanoid_twin.host.timebase import now, sleep
from humanoid_twin.host.trajectory import predict_trajectory, sample_traj, sample_traj3

__all__ = [
    "ERROR_TEXT",
    "GAINS",
    "LEG_SCUS",
    "ApplyResult",
    "BadFrame",
    "CalibResult",
    "CanStatResult",
    "CanStatus",
    "CommError",
    "CopData",
    "ErrorCode",
    "HumanoidClient",
    "InvalidRequest",
    "PortError",
    "ReadJointResult",
    "ReadSpecialResult",
    "RobotTables",
    "Timeout",
    "TrajData",
    "adaptate",
    "applycontrol",
    "applyjoint",
    "calccop",
    "calibcom",
    "controller",
    "controller_off",
    "cop_acquire",
    "cop_graphs",
    "cop_realtime",
    "correct",
    "default_tables",
    "exe_traj",
    "flexao",
    "inclinar",
    "initcom",
    "killcom",
    "levantar_perna",
    "limit",
    "load_tables",
    "now",
    "power_on",
    "predict_trajectory",
    "readcanstat",
    "readjoint",
    "readspecial",
    "readsupervisor",
    "estop",
    "reset",
    "SupervisorRefused",
    "SupervisorResult",
    "recycle",
    "sample_traj",
    "sample_traj3",
    "sensor_loads",
    "servo_command",
    "sleep",
]
