"""The rig (humanoid_twin/rig.py): one assembly, closed in reverse, on error too."""

from __future__ import annotations

from pathlib import Path

import pytest
from serial import SerialException

from humanoid_twin.recording.can_log import CanLogError
from humanoid_twin.recording.readback import read_rrd_rows, verify_rrd
from humanoid_twin.rig import Rig, RigOptions
from humanoid_twin.twin import Twin


def test_a_failed_assembly_closes_what_it_had_opened(tmp_path: Path) -> None:
    """The CAN log (assembled after the recording) cannot be written: the recording is closed
    (a valid file) and the twin is closed (its port cannot be opened any more)."""
    twins: list[Twin] = []
    out = tmp_path / "x.rrd"
    with pytest.raises(CanLogError, match="unknown format '.nope'"):
        Rig(RigOptions(out=out, can_log=tmp_path / "x.nope"), on_twin=twins.append)
    verify_rrd(out)
    with pytest.raises(SerialException, match="no twin link registered"):
        twins[0].open_port()


def test_an_error_in_the_run_closes_the_outputs_and_the_twin(tmp_path: Path) -> None:
    out, log = tmp_path / "x.rrd", tmp_path / "x.asc"
    failed = pytest.raises(RuntimeError, match="the experiment failed")
    with failed, Rig(RigOptions(out=out, can_log=log)) as rig:
        rig.boot()
        raise RuntimeError("the experiment failed")
    verify_rrd(out)
    assert read_rrd_rows(out)["robot/trunk_tilt_deg"] > 100        # the boot, recorded
    assert log.read_text().rstrip().endswith("End TriggerBlock")    # the .asc log is complete
    with pytest.raises(SerialException, match="no twin link registered"):
        rig.twin.open_port()
