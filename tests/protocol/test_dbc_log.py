"""The DBC reads a real run's CAN log (issue 11): the foot force signals are named FL/FR/RL/RR
(seed 000 table 12 order) and the Slave's supervisor flags (docs/supervisor.md) decode by name."""

from __future__ import annotations

import subprocess
import sys

import can
import pytest

from humanoid_twin.protocol import canframes as cf


@pytest.mark.slow       # a CLI run in a subprocess
def test_a_runs_can_log_decodes_with_named_forces_and_can_state(tmp_path):
    log = tmp_path / "stand.asc"
    # SCU 1's controller is forced bus-off at 3.0 s: it recovers at its next tick and says so in
    # Sensors 1 SFlags bits 1-0 (the supervisor then latches safe: exit code 3)
    r = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "run", "stand", "--duration", "3.1",
                        "--no-record", "--no-progress", "--can-log", str(log), "--fault", "bus-off:1@3.0"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 3, r.stderr
    db = cf.load_dbc()
    sen1, sen2 = cf.SENSOR_IDS[1]
    forces, states = [], set()
    for msg in can.ASCReader(str(log)):
        if msg.arbitration_id == sen2 and 2.9 < msg.timestamp < 3.0:     # booted, standing
            sig = db.decode_message(msg.arbitration_id, msg.data)
            forces.append([sig[name] for name in ("FL", "FR", "RL", "RR")])
        elif msg.arbitration_id == sen1:
            sig = db.decode_message(msg.arbitration_id, msg.data)
            states.add((str(sig["CanState"]), sig["Watchdog"]))
    assert forces and all(90 <= f <= 170 for row in forces for f in row), forces  # 128: calibration load
    assert ("error-active", 0) in states and ("bus-off", 0) in states, states
