"""A run's output files, written under temporary names beside their final ones and renamed at the
end: a run that failed never replaces an existing file (the CLI's ``run`` and ``serve``,
``humanoid_twin.open`` from Python: docs/scenarios.md, "Outputs")."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["NAME_MAX", "Outputs", "temp_name"]

NAME_MAX = 255              # bytes in a file name (Linux, macOS)


def temp_name(path: Path) -> Path:
    """The temporary name a run writes ``path`` under (beside it, renamed at the end): the
    suffixes kept at the end (the format follows them), and never longer than a file name may be
    (a valid 252-character name still gets a valid temporary one)."""
    name = f".partial-{os.getpid()}-{path.name}"
    if len(os.fsencode(name)) <= NAME_MAX:
        return path.with_name(name)
    import hashlib

    suffixes = path.suffixes[-2:] if path.suffix.lower() == ".gz" else path.suffixes[-1:]
    keep = "".join(suffixes)[-40:]
    digest = hashlib.sha256(os.fsencode(path.name)).hexdigest()[:16]
    return path.with_name(f".partial-{os.getpid()}-{digest}{keep}")


class Outputs:
    """A run's files by key (``"out"``, ``"can_log"``, ``"serial_log"``): :meth:`add` creates each
    under its temporary name, :meth:`commit` renames them to their final names, :meth:`discard`
    removes what was not committed. Each step is done whole before a signal is let through
    (humanoid_twin/signals.py)."""

    def __init__(self) -> None:
        self.final: dict[str, Path] = {}
        self.temp: dict[str, Path] = {}

    def add(self, key: str, path: Path) -> Path:
        """Create ``path``'s temporary file (``OSError`` when that place cannot be written);
        returns its name."""
        from humanoid_twin import signals

        path = path.expanduser()
        tmp = temp_name(path)
        with signals.deferred():     # created and registered together: no stray file after a signal
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
            self.final[key], self.temp[key] = path, tmp
        return tmp

    def commit(self) -> None:
        from humanoid_twin import signals

        with signals.deferred():     # every rename done before a signal is delivered
            for key, tmp in list(self.temp.items()):
                if tmp.exists():
                    os.replace(tmp, self.final[key])
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
