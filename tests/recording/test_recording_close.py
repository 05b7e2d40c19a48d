"""The recorder's close path under real signals, exceptions and a long run (real rerun files).

Children are started with default signal dispositions (SIGINT and SIGTERM reset in the child), so
the tests do not depend on how pytest itself was started (a background job ignores SIGINT).
"""

from __future__ import annotations

import signal
import subprocess
import sys

import numpy as np
import pytest
from helpers import default_signals

from humanoid_twin import recording
from humanoid_twin.recording import read_rrd_scalars, verify_rrd
from humanoid_twin.twin import Twin

_PRELUDE = (
    "import os, signal, sys\n"
    "from humanoid_twin.twin import Twin\n"
    "from humanoid_twin.recording import Recorder\n"
    "twin = Twin(seed=0)\n"
    "rec = Recorder(sys.argv[1], twin, chunk_s=0.5)\n"
)
_LOOP = (
    "twin.run_for(0.3)\n"
    "print('ready', flush=True)\n"
    "while True:\n"
    "    twin.run_for(0.1)\n"
)
# SIGTERM as a program (the CLI) handles it: close in the handler, at whatever point it lands
_TERM_CLOSES = "signal.signal(signal.SIGTERM, lambda s, f: (rec.close(), os._exit(143)))\n"
# SIGTERM turned into SystemExit: the finally/atexit path closes
_TERM_EXITS = "signal.signal(signal.SIGTERM, lambda s, f: sys.exit(143))\n"


def _run_and_signal(path, setup: str, sig: int) -> subprocess.CompletedProcess:
    proc = subprocess.Popen([sys.executable, "-c", _PRELUDE + setup + _LOOP, str(path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_signals)
    try:
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.parametrize("setup,sig,code", [
    ("", signal.SIGINT, -signal.SIGINT),          # KeyboardInterrupt -> atexit closes, dies of SIGINT
    (_TERM_CLOSES, signal.SIGTERM, 143),          # close() called from the handler
    (_TERM_EXITS, signal.SIGTERM, 143),           # SystemExit -> atexit closes
], ids=["sigint", "sigterm-handler-closes", "sigterm-systemexit"])
def test_signal_leaves_a_file_rerun_verifies(tmp_path, setup, sig, code):
    path = tmp_path / "sig.rrd"
    r = _run_and_signal(path, setup, sig)
    assert r.returncode == code, r.stderr[-2000:]
    verify_rrd(path)                                  # `rerun rrd verify`
    t, _ = read_rrd_scalars(path, "robot/trunk_tilt_deg")
    assert len(t) >= 16 and np.all(np.diff(t) == pytest.approx(0.02))   # every row up to the stop


def test_exception_inside_the_run_leaves_a_file_rerun_verifies(tmp_path):
    path = tmp_path / "exc.rrd"

    def boom() -> None:
        raise RuntimeError("boom")

    with (pytest.raises(RuntimeError, match="boom"), Twin(seed=0) as twin,
          recording.Recorder(path, twin, chunk_s=0.5)):
        twin.clock.schedule(730_000, boom)
        twin.run_for(2.0)
    verify_rrd(path)
    t, _ = read_rrd_scalars(path, "robot/trunk_tilt_deg")
    assert t[-1] == pytest.approx(0.72)


def test_close_is_idempotent_and_sampling_after_close_is_ignored(tmp_path):
    path = tmp_path / "c.rrd"
    with Twin(seed=0) as twin:
        rec = recording.Recorder(path, twin)
        twin.run_for(0.1)
        rec.close()
        rec.close()
        n = rec.samples
        twin.run_for(0.1)
        assert rec.samples == n and rec.closed
    verify_rrd(path)


def test_supervisor_hook_records_mode_and_events(tmp_path):
    """``Recorder.log_event`` and the ``supervisor/mode`` column, on sim_time."""
    from humanoid_twin.recording import read_rrd_rows

    path = tmp_path / "sup.rrd"
    with Twin(seed=0) as twin, recording.Recorder(path, twin) as rec:
        twin.run_for(0.2)
        rec.log_event(twin.clock.now_us, "operator note", "WARN")
        twin.run_for(0.1)
    verify_rrd(path)
    t, v = read_rrd_scalars(path, "supervisor/mode")
    assert len(t) == rec.samples and v.shape[1] == 2
    assert read_rrd_rows(path)["supervisor/events"] == 1
    with pytest.raises(ValueError):
        rec.log_event(0, "x", "LOUD")


def test_recording_is_compacted_at_close(tmp_path):
    """Sent in 0.2 s batches, the closed file holds one chunk per entity (rerun's own
    ``rrd optimize``); without compaction, one per batch."""
    from collections import Counter

    from humanoid_twin.recording.readback import _chunks

    def chunks_per_entity(path) -> Counter:
        return Counter(c.entity_path for c in _chunks(path) if not c.is_static)

    sizes = {}
    for compact in (False, True):
        path = tmp_path / f"c{compact}.rrd"
        with Twin(seed=0) as twin, recording.Recorder(path, twin, chunk_s=0.2, compact=compact) as rec:
            twin.run_for(1.0)
        verify_rrd(path)
        per = chunks_per_entity(path)
        assert max(per.values()) == (1 if compact else 6), per.most_common(3)
        sizes[compact] = path.stat().st_size
        assert (rec.size_before_compaction is not None) == compact
    assert sizes[True] < sizes[False]


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_memory_stays_flat_over_a_long_recording(tmp_path):
    """60 simulated seconds sent in 0.5 s batches (4x the default's chunks, to make growth
    visible): RSS after the first 15 s stays within 3 MB (rerun's in-memory footer index grew
    ~0.5 MB per simulated second here before the file was streamed without it)."""
    path = tmp_path / "long.rrd"
    with Twin(seed=0) as twin, recording.Recorder(path, twin, chunk_s=0.5) as rec:
        twin.run_for(15.0)
        base = _rss_mb()
        peak = base
        for _ in range(9):
            twin.run_for(5.0)
            peak = max(peak, _rss_mb())
    assert peak - base < 3.0, (base, peak)
    verify_rrd(path)
    assert rec.samples == 3001


def test_a_short_run_keeps_the_footer_a_long_or_open_one_is_compacted(tmp_path):
    """`run` decides before the boot: a run of at most SHORT_RECORDING_S simulated seconds is
    written with rerun's own footer (no rewrite at close), a longer or open-ended one streams
    without it and is compacted. Either way the file verifies."""
    from humanoid_twin.recording import SHORT_RECORDING_S, compact_for
    from humanoid_twin.scenarios import RunOptions, run

    assert not compact_for(30.0) and not compact_for(SHORT_RECORDING_S)
    assert compact_for(SHORT_RECORDING_S + 1) and compact_for(None)
    path = tmp_path / "short.rrd"
    run(RunOptions(scenario="stand", duration=3.0, out=path, progress=False))
    verify_rrd(path)
