"""A run's output files, written under temporary names beside their final ones and renamed at the
end: a run that failed never replaces an existing file (the CLI's ``run``, ``serve`` and ``replay``,
``humanoid_twin.open`` from Python: docs/scenarios.md, "Outputs"). An output that names a link is
written to the link's target (the link stays); one that names a FIFO or a device is refused
(:func:`humanoid_twin.containment.output_target`)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["NAME_MAX", "PARTIAL_PREFIX", "Outputs", "temp_name", "remove_stale_partials"]

NAME_MAX = 255              # bytes in a file name (Linux, macOS)
PARTIAL_PREFIX = ".partial-"     # a run's temporary outputs: .partial-PID-NAME beside NAME


def temp_name(path: Path, pid: int | None = None) -> Path:
    """The temporary name a run (process ``pid``, default this one) writes ``path`` under (beside
    it, renamed at the end): the suffixes kept at the end (the format follows them), and never
    longer than a file name may be (a valid 252-character name still gets a valid temporary one)."""
    pid = os.getpid() if pid is None else pid
    name = f"{PARTIAL_PREFIX}{pid}-{path.name}"
    if len(os.fsencode(name)) <= NAME_MAX:
        return path.with_name(name)
    import hashlib

    suffixes = path.suffixes[-2:] if path.suffix.lower() == ".gz" else path.suffixes[-1:]
    keep = "".join(suffixes)[-40:]
    digest = hashlib.sha256(os.fsencode(path.name)).hexdigest()[:16]
    return path.with_name(f"{PARTIAL_PREFIX}{pid}-{digest}{keep}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:             # another user's process: alive
        return True
    return True


def remove_stale_partials(path: Path) -> list[Path]:
    """Remove the temporary files of ``path`` left by runs whose process is gone (a process ended
    at once, where no ``finally`` runs: ``os._exit`` in user code, SIGKILL, a power cut; issue
    36); returns them. A file of a process still alive is left alone."""
    removed: list[Path] = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return removed
    for entry in entries:
        pid_text = entry.name[len(PARTIAL_PREFIX):].partition("-")[0]
        if not entry.name.startswith(PARTIAL_PREFIX) or not pid_text.isdigit():
            continue
        pid = int(pid_text)
        if pid == os.getpid() or entry.name != temp_name(path, pid).name or _alive(pid):
            continue
        with contextlib.suppress(OSError):
            os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


class Outputs:
    """A run's files by key (``"out"``, ``"can_log"``, ``"serial_log"``): :meth:`add` creates each
    under its temporary name, :meth:`commit` renames them to their final names, :meth:`discard`
    removes what was not committed. Each step is done whole before a signal is let through
    (humanoid_twin/signals.py)."""

    def __init__(self) -> None:
        self.final: dict[str, Path] = {}       # as the user named them (messages, the summary)
        self.target: dict[str, Path] = {}      # the files they name (through symbolic links)
        self.temp: dict[str, Path] = {}

    def add(self, key: str, path: Path) -> Path:
        """Create the temporary file of output ``key`` (``path``) beside the file ``path`` names (a
        symbolic link is followed: its target is replaced at the end, the link stays), once the
        temporary files that dead runs left for it are removed; returns its name. ``OSError`` when
        that place cannot be written; ``OutputPathError`` (a ``ValueError``) for a FIFO or a device."""
        from humanoid_twin import signals
        from humanoid_twin.containment import output_target

        path = path.expanduser()
        target = output_target(path, key)
        tmp = temp_name(target)
        remove_stale_partials(target)
        with signals.deferred():     # created and registered together: no stray file after a signal
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            self.final[key], self.target[key], self.temp[key] = path, target, tmp
        return tmp

    def commit(self) -> None:
        from humanoid_twin import signals

        with signals.deferred():     # every rename done before a signal is delivered
            for key, tmp in list(self.temp.items()):
                if tmp.exists():
                    os.replace(tmp, self.target[key])
                del self.temp[key]

    def discard(self) -> None:
        from humanoid_twin import signals

        with signals.deferred():
            for tmp in self.temp.values():
                with contextlib.suppress(OSError):
                    tmp.unlink()
            self.temp.clear()

    def final_names(self, text: str) -> str:
        """``text`` with each temporary name replaced by its final one (error messages)."""
        for key, tmp in self.temp.items():
            text = text.replace(str(tmp), str(self.final[key]))
        return text
