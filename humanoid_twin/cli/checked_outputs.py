"""The outputs of ``run``, ``serve`` and ``replay``: each checked as the command line checks an
output (one line, exit 2, before anything is written), the free space of every disk checked
against what the command writes there, then written under temporary names and renamed at the end
(humanoid_twin/outputs.py): a failed command never replaces an existing file."""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path
from typing import Any

from humanoid_twin.cli.messages import one_line
from humanoid_twin.cli.options import cannot_write_in, usage_error
from humanoid_twin.outputs import NAME_MAX, Outputs

MIN_FREE_BYTES = 8 * 2**20  # a run's outputs need at least this much free disk besides their own size

# What a run writes, per simulated second, measured on stand and flexao (docs/scenarios.md,
# "Disk space"): the recording streams 186-215 kB/s (220 000 bound); the CAN wire carries 3 800
# frames/s (4 000 bound) and each python-can format costs (bytes per frame, measured x 1.25):
RRD_BYTES_PER_S = 220_000
CAN_FRAMES_PER_S = 4_000
CAN_LOG_BYTES_PER_FRAME = {".asc": 78, ".blf": 7, ".csv": 44, ".log": 52, ".trc": 92, ".txt": 150,
                           ".db": 41}
CAN_LOG_BYTES_PER_FRAME_OTHER = 150     # a format not measured (.mf4 ...): the largest
CAN_LOG_BYTES_PER_FRAME_GZ = 8          # any format + .gz (measured .asc.gz: 3.2)


def check_writable(path: Path, what: str) -> Path:
    """``path`` may be written by a run (one line, exit 2 otherwise); returns the file it names
    (through symbolic links: :func:`humanoid_twin.containment.output_target`, which also refuses
    a FIFO or a device)."""
    from humanoid_twin.containment import OutputPathError, output_target

    try:
        target = output_target(path, what)
    except OutputPathError as exc:
        raise usage_error(str(exc)) from None
    parent = target.parent
    if not parent.is_dir():
        raise usage_error(f"{what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK) or (target.exists() and not os.access(target, os.W_OK)):
        raise usage_error(f"{what} {path} is not writable")
    why = cannot_write_in(parent)
    if why is not None:
        raise usage_error(f"{what} {path}: cannot write in {parent}: {why}")
    if len(os.fsencode(target.name)) > NAME_MAX:
        raise usage_error(f"{what}: the file name is longer than {NAME_MAX} bytes")
    return target


def output_bytes(kind: str, path: Path, expected_s: float) -> int:
    """What a run of ``expected_s`` simulated seconds writes to ``path`` at most (bytes): a
    recording (``kind`` "out"), twice over when it is compacted at the end (the compaction writes
    a copy before it replaces the file), or a CAN log in its format."""
    if kind == "out":
        from humanoid_twin.recording import compact_for

        return round(expected_s * RRD_BYTES_PER_S * (2 if compact_for(expected_s) else 1))
    if kind == "serial_log":
        from humanoid_twin.recording.serial_log import max_bytes_per_s

        return round(expected_s * max_bytes_per_s())     # measured flexao: 18 400 bytes/s
    suffix = path.suffix.lower()
    if suffix == ".gz":
        per_frame = CAN_LOG_BYTES_PER_FRAME_GZ
    else:
        per_frame = CAN_LOG_BYTES_PER_FRAME.get(suffix, CAN_LOG_BYTES_PER_FRAME_OTHER)
    return round(expected_s * CAN_FRAMES_PER_S * per_frame)


class CheckedOutputs(Outputs):
    """The command's files, written under temporary names next to their final ones and renamed at
    the end (humanoid_twin/outputs.py): a failed run never replaces an existing file. Each temporary
    file is created up front (an unwritable place is found before the run: exit 2), once the free
    space of every disk has been checked against what the run will write there
    (:func:`output_bytes`)."""

    def check_space(self, wanted: dict[str, tuple[Path, str]], expected_s: float) -> None:
        """Every disk has room for what the run writes on it, plus :data:`MIN_FREE_BYTES` (an
        open-ended run, ``serve``: ``expected_s`` 0, that margin only)."""
        need: dict[int, list] = {}
        for key, (path, what) in wanted.items():
            parent = check_writable(path, what).parent
            dev = os.stat(parent).st_dev
            entry = need.setdefault(dev, [parent, 0, []])
            entry[1] += output_bytes(key, path, expected_s)
            entry[2].append(f"{what} {path}")
        for parent, total, whats in need.values():
            free = shutil.disk_usage(parent).free
            if free < total + MIN_FREE_BYTES:
                raise usage_error(
                    f"{' and '.join(whats)}: a {expected_s:g} s run writes about "
                    f"{(total + MIN_FREE_BYTES) / 2**20:.0f} MB there, only {free / 2**20:.0f} MB free "
                    "(docs/scenarios.md, \"Disk space\")")

    def open_all(self, out: Path | None, args: argparse.Namespace, expected_s: float) -> dict[str, Any]:
        """The outputs of a ``run`` or ``serve`` (the recording ``out``, ``args``' ``--can-log`` and
        ``--serial-log``): their disks' space checked (:meth:`check_space`), each created under its
        temporary name. Returns the :class:`~humanoid_twin.rig.RigOptions` output fields: the
        temporary names, and the CAN log's final name (``can_log_name``, its header)."""
        finals = {"out": out, "can_log": args.can_log, "serial_log": args.serial_log}
        wanted = {k: (p, what) for (k, p), what in zip(finals.items(), ("--out", "--can-log", "--serial-log"),
                                                      strict=True) if p is not None}
        self.check_space(wanted, expected_s)
        files: dict[str, Any] = {k: self.add(k, *wanted[k]) if k in wanted else None for k in finals}
        files["can_log_name"] = None if args.can_log is None else args.can_log.name
        return files

    def add(self, key: str, path: Path, what: str) -> Path:  # type: ignore[override]
        """As :meth:`Outputs.add`, checked first as the CLI checks an output (one line, exit 2)."""
        check_writable(path.expanduser(), what)
        try:
            return super().add(key, path)
        except OSError as exc:
            self.discard()
            raise usage_error(f"{what} {path}: cannot write there: {exc.strerror or exc}") from None

    def write_failed(self, exc: BaseException) -> str:
        """The line of a full disk (or a file-size limit) met while writing: nothing is replaced."""
        return (f"humanoid-twin: error: cannot write the outputs: {one_line(self.final_names(str(exc)))}; "
                "no file replaced\n")

    def kept(self) -> str:
        """``; recorded so far: FILE ...`` after a signal (the files committed whole), or ``""``."""
        kept = " ".join(str(p) for p in self.final.values())
        return f"; recorded so far: {kept}" if kept else ""
