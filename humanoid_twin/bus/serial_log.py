"""The RS-232 traffic of a twin, byte for byte, in a text file, and its replay into a fresh twin.

Writing: :meth:`SerialLog.attach` taps the twin's cable (``SerialLink.add_tap``) and writes one
line per write in either direction, per host flush and per unplugged cable, in virtual time
(the format: docs/buses.md, "The serial log"; ``run``/``serve --serial-log FILE`` write one
through the rig). Replaying: :func:`replay` feeds the host's bytes at their instants into a fresh
twin built with the options the header records (seed, faults, laws, tilt ...) and compares the
twin's answers with the log, byte for byte and microsecond for microsecond::

    python -m humanoid_twin.bus.serial_log replay FILE     # exit 0: the twin answered as logged

Exit codes of the command: 0 the answers match, 1 they differ (the first difference on stderr),
2 the file is not a serial log (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from humanoid_twin.bus.serial_link import TAP_FLUSH, TAP_TO_DEVICE, TAP_TO_HOST, TAP_UNPLUG, SerialLink
from humanoid_twin.protocol.wire import BAUDRATE

MAGIC = "# humanoid-twin serial log 1"
_EVENTS = (TAP_TO_DEVICE, TAP_TO_HOST, TAP_FLUSH, TAP_UNPLUG)


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
    :meth:`humanoid_twin.rig.RigOptions.replay_meta` gives them (``seed`` at least), which
    :func:`replay` rebuilds the twin with; :meth:`note` adds to it later (a ``# meta`` line among
    the records; the later lines' keys join the header's).
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
        header records a default rig of the twin's seed (a twin with faults or laws: log it
        through :class:`~humanoid_twin.rig.Rig`, whose options the header then records)."""
        from humanoid_twin.rig import RigOptions

        return cls(path, twin.link, meta=RigOptions(seed=twin.seed, monitor=False).replay_meta())

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
        """Stop logging and close the file (idempotent; safe from a signal handler's finally)."""
        f, self._f = self._f, None
        if f is None:
            return
        try:
            self.link.remove_tap(self._on_event)
        except ValueError:
            pass
        f.close()

    def __enter__(self) -> SerialLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_log(path: str | Path) -> tuple[dict[str, Any], list[Record]]:
    """The header's meta and the records of a serial log; :class:`SerialLogError` if it is not one."""
    try:
        text = Path(path).read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise SerialLogError(f"{path}: cannot read it as a serial log ({exc})") from None
    lines = text.splitlines()
    if not lines or lines[0] != MAGIC:
        raise SerialLogError(f"{path}: not a serial log (its first line is not '{MAGIC}')")
    return _meta(path, lines), list(_records(path, lines))


def _meta(path: str | Path, lines: list[str]) -> dict[str, Any]:
    """Every ``# meta`` line's keys, in file order (the header's, then :meth:`SerialLog.note` s)."""
    meta: dict[str, Any] = {}
    for ln in lines:
        if ln.startswith("# meta "):
            try:
                more = json.loads(ln[len("# meta "):])
            except json.JSONDecodeError as exc:
                raise SerialLogError(f"{path}: its meta line is not JSON ({exc})") from None
            if isinstance(more, dict):
                meta.update(more)
    return meta


def _records(path: str | Path, lines: list[str]) -> Iterator[Record]:
    last = 0
    for no, ln in enumerate(lines, 1):
        if not ln or ln.startswith("#"):
            continue
        f = ln.split()
        try:
            t_us, event = int(f[0]), f[1]
            if event not in _EVENTS or t_us < last:
                raise ValueError("unknown event" if event not in _EVENTS else "time goes back")
            if event in (TAP_TO_DEVICE, TAP_TO_HOST):
                data = bytes(int(h, 16) for h in f[3:])
                if not data or any(len(h) != 2 for h in f[3:]):
                    raise ValueError("bytes are two hex digits each, at least one")
                rec = Record(t_us, event, data=data, end_us=int(f[2]))
            else:
                if len(f) != 3:
                    raise ValueError("a drop has one count")
                rec = Record(t_us, event, dropped=int(f[2]))
        except (ValueError, IndexError) as exc:
            raise SerialLogError(f"{path}:{no}: not a serial-log line ({exc}): {ln[:80]!r}") from None
        last = t_us
        yield rec


@dataclass
class ReplayResult:
    """What :func:`replay` found: the host bytes fed, the twin's answer bytes compared, and the
    first difference (None when the twin answered as logged)."""

    host_bytes: int
    twin_bytes: int
    difference: str | None


def replay(path: str | Path, seed: int | None = None) -> ReplayResult:
    """Feed the host->twin bytes of the log at their instants (the flushes and unplugs too) into a
    fresh twin and compare its twin->host writes with the log's. The twin is a
    :class:`~humanoid_twin.rig.Rig` of the options the log's meta records (those of
    :meth:`~humanoid_twin.rig.RigOptions.replay_meta`, and the tilt's start; ``seed`` given: that
    one instead).
    An unplug is a ``serve`` session's start or end, which also resets the Master's receiver
    (``bus/bridges.py``): the replay does both."""
    import dataclasses

    from humanoid_twin.rig import Rig, RigOptions

    meta, records = read_log(path)
    try:
        opts = RigOptions.from_replay_meta(meta)
    except ValueError as exc:
        raise SerialLogError(f"{path}: {exc}") from None
    if seed is not None:
        opts = dataclasses.replace(opts, seed=seed)
    answers: list[Record] = []

    def tap(event: str, t_us: int, data: bytes, n: int) -> None:
        if event == TAP_TO_HOST:
            answers.append(Record(t_us, event, data=data, end_us=n))

    try:
        rig = Rig(opts)
    except ValueError as exc:       # a law of the meta that cannot be loaded here (LawError)
        raise SerialLogError(f"{path}: cannot rebuild the twin it logged: {exc}") from None
    try:
        twin = rig.twin
        if "tilt_from_s" in meta:
            rig.start_tilt(float(meta["tilt_from_s"]))
        twin.link.add_tap(tap)
        host = 0
        for rec in records:
            if rec.event == TAP_TO_HOST:
                continue
            twin.advance_to(rec.t_us)
            if rec.event == TAP_TO_DEVICE:
                twin.link.host_write(rec.data)
                host += len(rec.data)
            elif rec.event == TAP_FLUSH:
                twin.link.host_reset_output()
            else:                # a serve client came or left: the cable and the Master's receiver
                twin.link.unplug()
                twin.master.reset_receiver()
        end = max((max(r.t_us, r.end_us) for r in records), default=0)
        twin.advance_to(end)
    finally:
        rig.close()
    logged = [r for r in records if r.event == TAP_TO_HOST]
    diff = None
    for i, (want, got) in enumerate(zip(logged, answers, strict=False)):
        if want != got:
            diff = f"twin->host write {i + 1}: the log has '{want.line()}', the twin sent '{got.line()}'"
            break
    else:
        if len(logged) != len(answers):
            i = min(len(logged), len(answers))
            extra = logged[i] if len(logged) > i else answers[i]
            who = "the log has" if len(logged) > i else "the twin sent"
            diff = (f"{len(logged)} twin->host writes in the log, {len(answers)} from the twin; "
                    f"the first unmatched: {who} '{extra.line()}'")
    return ReplayResult(host, sum(len(r.data) for r in answers), diff)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m humanoid_twin.bus.serial_log",
                                 description="Replay a serial log into a fresh twin and check its answers.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    rp = sub.add_parser("replay", help="feed the log's host bytes to a fresh twin; compare its answers")
    rp.add_argument("file", type=Path)
    rp.add_argument("--seed", type=int, help="the twin's seed (default: the log's)")
    args = ap.parse_args(argv)
    try:
        res = replay(args.file, seed=args.seed)
    except SerialLogError as exc:
        print(f"serial_log: error: {exc}", file=sys.stderr)
        return 2
    if res.difference is not None:
        print(f"serial_log: {args.file}: the twin's answers differ: {res.difference}", file=sys.stderr)
        return 1
    print(f"{args.file}: replayed {res.host_bytes} host bytes; the twin's {res.twin_bytes} answer bytes "
          "match the log")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
