"""Hold the twin against its robot: compare a robot's CAN log with the twin (``compare``), and
fit the twin's parameters to logs (``calibrate``). docs/calibration.md."""

from humanoid_twin.compare.core import CompareOptions, CompareResult, compare_log
from humanoid_twin.compare.robot_log import RobotLog, RobotLogError, read_robot_log

__all__ = ["CompareOptions", "CompareResult", "RobotLog", "RobotLogError", "compare_log", "read_robot_log"]
