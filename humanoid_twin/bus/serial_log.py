"""``python -m humanoid_twin.bus.serial_log replay FILE [options]``: the older spelling of
``humanoid-twin replay FILE [options]`` (docs/buses.md, "Replay"), kept for the scripts that use
it. The serial log itself (its format, writer and reader) is a run log beside the recording:
humanoid_twin/recording/serial_log.py. This module imports nothing of the package: the process
becomes the command.
"""

from __future__ import annotations

import os
import sys

__all__: list[str] = []


def _alias(argv: list[str]) -> None:
    if not argv or argv[0] != "replay":
        sys.stderr.write("usage: python -m humanoid_twin.bus.serial_log replay FILE [options] "
                         "(the same as: humanoid-twin replay FILE [options])\n")
        raise SystemExit(2)
    sys.stdout.flush()
    os.execv(sys.executable, [sys.executable, "-m", "humanoid_twin.cli.main", *argv])


if __name__ == "__main__":
    _alias(sys.argv[1:])
