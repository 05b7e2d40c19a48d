"""The RS-232 traffic of a twin, byte for byte, in a text file: the serial log's format.

Writing: :class:`SerialLog` (or :meth:`SerialLog.attach`) taps the twin's cable
(``SerialLink.add_tap``) and writes one line per write in either direction, per host flush and
per unplugged cable, in virtual time (the format: docs/buses.md, "The serial log";
``run``/``serve --serial-log FILE`` write one through the rig). Reading: :func:`iter_log` streams
a log's lines, each checked against the format and against the lines before it (a log is data
from anywhere: times that go back, an ``end_us`` its bytes contradict, a flush of bytes that were
not waiting are :class:`SerialLogError` with the line number); :func:`scan_log` checks a whole
log in one pass, :func:`read_log` reads one into memory.

A run log, as the CAN log (``recording/can_log.py``) is: both are written beside the recording
by the rig. The bus keeps only the tap the log is written from (``bus/serial_link.py``). The
replay of a log into a fresh twin is above the rig it builds: humanoid_twin/replay.py
(``humanoid-twin replay FILE``; ``python -m humanoid_twin.bus.serial_log replay FILE``, the older
spelling, is an alias of that command).
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from humanoid_twin.bus.serial_link import TAP_FLUSH, TAP_TO_DEVICE, TAP_TO_HOST, TAP_UNPLUG, SerialLink
from humanoid_twin.clock import US_PER_S, Clock
from humanoid_twin.limits import MAX_RUN_S
from humanoid_twin.protocol.wire import BAUDRATE, BYTESIZE, PARITY, STOPBITS

MAGIC = "# humanoid-twin serial log 1"
_EVENTS = (TAP_TO_DEVICE, TAP_TO_HOST, TAP_FLUSH, TAP_UNPLUG)
LINE_PREFIX = "# line "
META_PREFIX = "# meta "
END_KEY = "end_us"          # the meta's key of the instant the log was closed (SerialLog.close)
# the longest run a log may describe: one simulated day (humanoid_twin/limits.py)
MAX_LOG_S = MAX_RUN_S
MAX_LOG_US = MAX_LOG_S * US_PER_S
# the longest line read (characters): a write of ~20 000 bytes, far more than any client's
MAX_LINE_CHARS = 1 << 16


@dataclass(frozen=True)
class Record:
    """One line of a serial log: ``event`` at ``t_us``; a write's ``data`` and the stop-bit time
    of its last byte ``end_us``, or a drop's byte count ``dropped``."""

    t_us: int
    event: str
    data: bytes = b""
    end_us: int = 0
    dropped: int = 0

    def line(self) -> str:
        if self.event in (TAP_TO_DEVICE, TAP_TO_HOST):
            return f"{self.t_us} {self.event} {self.end_us} {self.data.hex(' ')}"
        return f"{self.t_us} {self.event} {self.dropped}"


def max_bytes_per_s(link_bits_per_byte: int = 11, baudrate: int = BAUDRATE) -> int:
    """The most a serial log grows per simulated second (bytes): the line full both ways in the
    protocol's 6-byte frames (one write each; 11 bits a byte, seed 002 slide 7), each the
    longest line of this format (11-digit times, a simulated day) and its newline. At 8E1,
    115200 baud: 2 x 1745.5 lines of 52 bytes."""
    from humanoid_twin.protocol.rs232 import FRAME_LEN

    longest = Record(10**11 - 1, TAP_TO_DEVICE, data=bytes(FRAME_LEN), end_us=10**11 - 1).line()
    lines_per_s = 2 * baudrate / (link_bits_per_byte * FRAME_LEN)
    return math.ceil(lines_per_s * (len(longest) + 1))


class SerialLogError(ValueError):
    """A file that is not a serial log (or a line that breaks its format)."""


class SerialLog:
    """Writes every event of ``link`` to ``path`` (text, one line per event, flushed per line).

    ``meta`` goes into the header as JSON: the options of the twin, as
    :meth:`humanoid_twin.rig.RigOptions.replay_meta` gives them (``seed`` at least), which the
    replay (humanoid_twin/replay.py) rebuilds the twin with; :meth:`note` adds to it later (a
    ``# meta`` line among the records; the later lines' keys join the header's).
    """

    def __init__(self, path: str | Path, link: SerialLink, meta: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.link = link
        self.records = 0
        f = open(self.path, "w", encoding="ascii", buffering=1)  # noqa: SIM115
        settings = f"{link.baudrate} {link.bytesize}{link.parity}{link.stopbits}"
        try:
            f.write(f"{MAGIC}\n# line {settings}; times in virtual microseconds since the twin started\n"
                    f"# meta {json.dumps(meta or {}, sort_keys=True)}\n"
                    "# t_us event end_us bytes(hex) | t_us flush|unplug bytes_dropped\n")
        except BaseException:
            f.close()
            raise
        self._f: IO[str] | None = f
        link.add_tap(self._on_event)

    @classmethod
    def attach(cls, twin: Any, path: str | Path) -> SerialLog:
        """Log the RS-232 cable of ``twin`` (a :class:`~humanoid_twin.twin.Twin`) into ``path``; the
        header records the twin's seed, as a default rig's does (a twin with faults or laws: log
        it through :class:`~humanoid_twin.rig.Rig`, whose options the header then records)."""
        return cls(path, twin.link, meta={"seed": twin.seed})

    def note(self, meta: dict[str, Any]) -> None:
        """Add ``meta`` to the header's meta, from now (e.g. when the platform's tilt starts)."""
        if self._f is not None:
            self._f.write(f"# meta {json.dumps(meta, sort_keys=True)}\n")

    def _on_event(self, event: str, t_us: int, data: bytes, n: int) -> None:
        if self._f is None:
            return
        if event in (TAP_TO_DEVICE, TAP_TO_HOST):
            rec = Record(t_us, event, data=data, end_us=n)
        else:
            rec = Record(t_us, event, dropped=n)
        self._f.write(rec.line() + "\n")
        self.records += 1

    def close(self) -> None:
        """Stop logging, note the instant it stopped (``# meta {"end_us": T}``: a replay runs the
        twin to there, the run's end, not only to its last byte) and close the file (idempotent;
        safe from a signal handler's finally)."""
        f = self._f
        if f is None:
            return
        try:
            self.note({END_KEY: self.link.clock.now_us})
        finally:
            self._f = None
            try:
                self.link.remove_tap(self._on_event)
            except ValueError:
                pass
            f.close()

    def __enter__(self) -> SerialLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class LogInfo:
    """What :func:`scan_log` found in a whole, consistent log: the ``meta`` (every ``# meta``
    line's keys), the number of ``records``, and ``end_us``, the last instant a line names (a
    write's last stop bit included; the log's close, :data:`END_KEY`, when it says it)."""

    meta: dict[str, Any] = field(default_factory=dict)
    records: int = 0
    end_us: int = 0


class _Checker:
    """The lines of a log against each other: a link of the log's line settings, with nothing at
    either end, is given each record at its instant and must log it back the same (the same
    ``end_us`` by the cable's own burst rule; a flush of exactly the bytes that had not started).
    The counts of an ``unplug`` are not checked: they include answers the host had not read yet,
    which the log does not say."""

    def __init__(self, settings: tuple[int, int, str, int]) -> None:
        baud, bytesize, parity, stopbits = settings
        self.clock = Clock()
        self.link = SerialLink(self.clock, baud, bytesize=bytesize, parity=parity, stopbits=stopbits)
        self.seen: list[tuple[str, int]] = []
        self.link.add_tap(lambda event, t_us, data, n: self.seen.append((event, n)))

    def check(self, rec: Record) -> str | None:
        """Why ``rec`` contradicts the lines before it (None: it does not)."""
        self.clock.run_until(rec.t_us)
        self.seen.clear()
        link = self.link
        if rec.event == TAP_TO_DEVICE:
            link.host_write(rec.data)
        elif rec.event == TAP_TO_HOST:
            link.device_write(rec.data)
            link.host_read_available()          # the host's side keeps nothing
        elif rec.event == TAP_FLUSH:
            dropped = link.host_reset_output()
            if dropped != rec.dropped:
                return (f"a flush of {rec.dropped} bytes, but {dropped} of the host's bytes had not "
                        "started then")
            return None
        else:
            link.unplug()
            return None
        end_us = self.seen[-1][1]
        if end_us != rec.end_us:
            n = len(rec.data)
            return (f"end_us {rec.end_us} contradicts its {n} byte{'s' * (n != 1)} written at {rec.t_us}: "
                    f"the last stop bit is at {end_us}")
        return None


def _settings(text: str) -> tuple[int, int, str, int] | None:
    """``115200 8E1`` (a ``# line`` header's first words) -> (baud, bytesize, parity, stopbits)."""
    words = text.split(";")[0].split()
    if len(words) != 2 or not words[0].isdigit() or len(words[1]) != 3:
        return None
    size, parity, stop = tuple(words[1])
    if not size.isdigit() or not stop.isdigit():
        return None
    return int(words[0]), int(size), parity, int(stop)


def line_settings(path: str | Path) -> tuple[int, int, str, int]:
    """The line a log was written on (its ``# line`` header), or the protocol's when it has none."""
    for no, ln in _lines(path):
        if ln.startswith(LINE_PREFIX):
            found = _settings(ln[len(LINE_PREFIX):])
            if found is None:
                raise SerialLogError(f"{path}:{no}: a '# line' header that is not 'BAUD 8E1': {ln[:80]!r}")
            return found
        if ln and not ln.startswith("#"):
            break
    return BAUDRATE, BYTESIZE, PARITY, STOPBITS


def _open(path: str | Path) -> IO[str]:
    """The log opened for reading; :class:`SerialLogError` (one line) when it cannot be: missing,
    unreadable, a directory, or not a regular file (a pipe or a device: the replay reads a log
    twice, once to check it whole, then to feed it)."""
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            what = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
            raise SerialLogError(f"{path}: {what}, not a serial log")
        return open(path, encoding="ascii", newline="\n")  # noqa: SIM115 - the caller closes it
    except OSError as exc:
        raise SerialLogError(f"{path}: cannot read it: {exc.strerror or exc}") from None


def _lines(path: str | Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of each line, without its end; the first must be :data:`MAGIC`.
    A line longer than :data:`MAX_LINE_CHARS`, or one that is not ASCII: :class:`SerialLogError`."""
    with _open(path) as f:
        no = 0
        while True:
            no += 1
            try:
                ln = f.readline(MAX_LINE_CHARS + 1)
            except UnicodeDecodeError:
                raise SerialLogError(f"{path}:{no}: not text (a byte that is not ASCII)") from None
            except OSError as exc:
                raise SerialLogError(f"{path}: cannot read it: {exc.strerror or exc}") from None
            if not ln:
                if no == 1:
                    raise SerialLogError(f"{path}: empty, not a serial log")
                return
            if len(ln) > MAX_LINE_CHARS:
                raise SerialLogError(f"{path}:{no}: a line longer than {MAX_LINE_CHARS} characters")
            ln = ln.rstrip("\n").rstrip("\r")
            if no == 1 and ln != MAGIC:
                raise SerialLogError(f"{path}: not a serial log (its first line is not '{MAGIC}')")
            yield no, ln


def _meta_line(path: str | Path, no: int, text: str) -> dict[str, Any]:
    try:
        more = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise SerialLogError(f"{path}:{no}: its meta line is not JSON ({exc})") from None
    if not isinstance(more, dict):
        raise SerialLogError(f"{path}:{no}: its meta line is not a JSON object")
    return more


def _record(f: list[str]) -> Record:
    if len(f) < 3:
        raise ValueError("too few fields")
    if not all(w.isdigit() and w.isascii() for w in (f[0], f[2])):
        raise ValueError("times and counts are non-negative integers")
    t_us, event = int(f[0]), f[1]
    if event not in _EVENTS:
        raise ValueError("unknown event")
    if event in (TAP_TO_DEVICE, TAP_TO_HOST):
        hexes = f[3:]
        if not hexes or any(len(h) != 2 for h in hexes):
            raise ValueError("bytes are two hex digits each, at least one")
        return Record(t_us, event, data=bytes.fromhex("".join(hexes)), end_us=int(f[2]))
    if len(f) != 3:
        raise ValueError("a drop has one count")
    return Record(t_us, event, dropped=int(f[2]))


def iter_log(path: str | Path) -> Iterator[tuple[int, Record | dict[str, Any]]]:
    """``(line number, record or meta)`` for each event line and each ``# meta`` line, in file
    order, streamed. Each line is checked as it comes: its format, its times (never back, within
    :data:`MAX_LOG_S`), and against the lines before it (:class:`_Checker`); the first that fails
    is :class:`SerialLogError` naming its line."""
    settings = line_settings(path)
    try:
        checker = _Checker(settings)
    except ValueError as exc:           # a line the cable cannot be (a baud rate of 0, 9 data bits ...)
        raise SerialLogError(f"{path}: its '# line' header names a line a cable cannot have: {exc}") from None
    last = 0
    closed: int | None = None          # the instant the log was closed (END_KEY), once read
    for no, ln in _lines(path):
        if ln.startswith(META_PREFIX):
            meta = _meta_line(path, no, ln[len(META_PREFIX):])
            if END_KEY in meta:
                closed = _end(path, no, meta[END_KEY], last)
            yield no, meta
            continue
        if not ln or ln.startswith("#"):
            continue
        try:
            rec = _record(ln.split())
            why = None
            if max(rec.t_us, rec.end_us) > MAX_LOG_US:
                why = f"a time beyond {MAX_LOG_S} s (one simulated day, the longest run)"
            elif closed is not None:
                why = f"a line after the log was closed (at {closed})"
            elif rec.t_us < last:
                why = f"time goes back ({rec.t_us} after {last})"
            else:
                why = checker.check(rec)
        except ValueError as exc:
            raise SerialLogError(f"{path}:{no}: not a serial-log line ({exc}): {ln[:80]!r}") from None
        if why is not None:
            raise SerialLogError(f"{path}:{no}: the line contradicts the log: {why}: {ln[:80]!r}")
        last = rec.t_us
        yield no, rec


def _end(path: str | Path, no: int, value: Any, last: int) -> int:
    """The meta's :data:`END_KEY` (line ``no``): an instant at or after the last line's (``last``),
    within :data:`MAX_LOG_S`."""
    if type(value) is not int or not last <= value <= MAX_LOG_US:
        raise SerialLogError(f"{path}:{no}: the meta's {END_KEY} must be an instant {last}..{MAX_LOG_US} "
                             f"(the last line's to one simulated day), got {value!r:.40}")
    return value


def merge_meta(path: str | Path, meta: dict[str, Any], no: int, more: dict[str, Any]) -> None:
    """Add a ``# meta`` line's keys (line ``no``) to ``meta``; a key it gives again with another
    value contradicts the log (:class:`SerialLogError`)."""
    for key, value in more.items():
        if key in meta and meta[key] != value:
            raise SerialLogError(f"{path}:{no}: the meta line gives {key} again, {value!r:.80} after "
                                 f"{meta[key]!r:.80}")
        meta[key] = value


def scan_log(path: str | Path) -> LogInfo:
    """Check a whole log (:func:`iter_log`) in one pass without keeping its records."""
    info = LogInfo()
    for no, item in iter_log(path):
        if isinstance(item, dict):
            merge_meta(path, info.meta, no, item)
            info.end_us = max(info.end_us, item.get(END_KEY, 0))
        else:
            info.records += 1
            info.end_us = max(info.end_us, item.t_us, item.end_us)
    return info


def read_log(path: str | Path) -> tuple[dict[str, Any], list[Record]]:
    """The meta and the records of a serial log, checked (:func:`iter_log`); :class:`SerialLogError`
    if it is not one."""
    meta: dict[str, Any] = {}
    records: list[Record] = []
    for no, item in iter_log(path):
        if isinstance(item, dict):
            merge_meta(path, meta, no, item)
        else:
            records.append(item)
    return meta, records
