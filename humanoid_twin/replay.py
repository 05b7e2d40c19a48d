"""A serial log replayed into a fresh twin, its answers checked: ``humanoid-twin replay FILE``.

The log (recording/serial_log.py, docs/buses.md "The serial log") is the input of a session and what
the host saw. :func:`replay` builds the :class:`~humanoid_twin.rig.Rig` its meta describes
(:meth:`~humanoid_twin.rig.RigOptions.from_replay_meta`), feeds the host's bytes, flushes and
unplugs at their instants and compares every answer of the twin with the log's, byte for byte
and microsecond for microsecond; on request it records the replay as a run does (``out``,
``can_log``).

A log is data (it may come from anywhere), so before anything runs or is written
(:func:`check_log`) the whole file is read and checked: its lines against the format and each
other (recording/serial_log.iter_log: times, lengths, one simulated day at most), and its meta's
values (:func:`check_meta`). A replay imports no code a log names: a firmware law the meta
names is the package's own built-in class, or the class the caller gives (``--law``) under the
same name; otherwise :class:`ReplayError`. The CAN wire is rebuilt in-process only (a log never
opens a system's CAN interface): a log of a ``socketcan`` run replays with
``can_interface="humanoid_twin"`` given (the answers do not depend on the interface: the wire's
timing is the twin's).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from humanoid_twin.clock import US_PER_S
from humanoid_twin.controllers import law_reference
from humanoid_twin.protocol.wire import BAUDRATE, BYTESIZE, PARITY, STOPBITS
from humanoid_twin.recording.serial_log import (
    MAX_LOG_S,
    TAP_FLUSH,
    TAP_TO_DEVICE,
    TAP_TO_HOST,
    LogInfo,
    Record,
    SerialLogError,
    iter_log,
    line_settings,
    scan_log,
)
from humanoid_twin.rig import Rig, RigOptions
from humanoid_twin.seeds import SEED_MAX

__all__ = ["ReplayError", "ReplayTimeoutError", "ReplayResult", "WALL_CHECK_US", "REPLAY_CAN_INTERFACES",
           "check_log", "check_meta", "replay", "replay_options"]

# the CAN wires a replay builds: in-process ones (python-can's "virtual" bus is in-process too)
REPLAY_CAN_INTERFACES = ("humanoid_twin", "virtual")


class ReplayError(ValueError):
    """The log cannot be replayed here (not a serial log, records that contradict each other, a
    meta that cannot rebuild the twin, a law it names that the caller did not give): one line."""


class ReplayTimeoutError(RuntimeError):
    """The replay took more wall time than it was given (``wall_timeout``); its outputs are
    closed, not complete."""


# the replay advances the twin at most this far at a time (virtual us) between two looks at the
# wall clock: a long silence in a log is many steps (the same run: serve's loop steps 1 ms)
WALL_CHECK_US = 100_000


@dataclass
class ReplayResult:
    """What :func:`replay` found: the host bytes fed, the twin's answer bytes, the twin->host
    writes of the log and of the twin, the first difference (None when the twin answered as
    logged), and the simulated seconds replayed."""

    host_bytes: int
    twin_bytes: int
    logged_writes: int
    twin_writes: int
    difference: str | None
    end_s: float

    def as_dict(self) -> dict[str, Any]:
        """The result as ``replay --json`` prints it."""
        return {"match": self.difference is None, **dataclasses.asdict(self)}


def _number(meta: dict[str, Any], key: str, lo: float, hi: float) -> None:
    value = meta[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or not lo <= value <= hi:
        raise ReplayError(f"its meta's {key} must be a number {lo:g}..{hi:g}, got {value!r}")


def check_meta(meta: dict[str, Any]) -> None:
    """The values of a log's meta, each a value :meth:`RigOptions.replay_meta` could have written
    (the limits are the run's own: ``--seed``, ``--tilt``, ``--pic-mhz``, ``--fault``, the CAN
    wire); :class:`ReplayError` naming the first that is not. Keys it does not know are left to
    :meth:`RigOptions.from_replay_meta`."""
    _check_rig_values(meta)
    _check_faults(meta)
    sup = meta.get("supervisor")
    if sup is not None and not isinstance(sup, dict):
        raise ReplayError(f"its meta's supervisor must be an object of thresholds, got {sup!r:.80}")
    laws = meta.get("laws", [])
    if not isinstance(laws, list) or not all(_is_law_pair(pair) for pair in laws):
        raise ReplayError(f"its meta's laws must be [control type, \"module:Class\"] pairs, got {laws!r:.80}")


def _check_rig_values(meta: dict[str, Any]) -> None:
    """The meta's seed, platform tilt, PIC clock and CAN channel."""
    from humanoid_twin.cycles import check_pic_mhz
    from humanoid_twin.plant.plant import TILT_MAX_DEG

    seed = meta.get("seed", 0)
    if type(seed) is not int or not 0 <= seed <= SEED_MAX:
        raise ReplayError(f"its meta's seed must be an integer 0..{SEED_MAX}, got {seed!r}")
    if "tilt" in meta:
        _number(meta, "tilt", -TILT_MAX_DEG, TILT_MAX_DEG)
    if "tilt_from_s" in meta:
        _number(meta, "tilt_from_s", 0, MAX_LOG_S)
    if "pic_mhz" in meta:
        try:
            check_pic_mhz(meta["pic_mhz"])
        except ValueError as exc:
            raise ReplayError(f"its meta's pic_mhz: {exc}") from None
    channel = meta.get("can_channel")
    if channel is not None and (not isinstance(channel, str) or not channel.isprintable()
                                or len(channel) > 64):
        raise ReplayError(f"its meta's can_channel must be a name (text), got {channel!r:.80}")


def _check_faults(meta: dict[str, Any]) -> None:
    """The meta's faults: ``--fault`` texts that compose (as a run checks them)."""
    from humanoid_twin.fault_compose import check_composition
    from humanoid_twin.faults import FaultSpecError, parse_fault

    faults = meta.get("faults", [])
    if not isinstance(faults, list) or not all(isinstance(f, str) for f in faults):
        raise ReplayError(f"its meta's faults must be a list of --fault texts, got {faults!r:.80}")
    try:
        check_composition([parse_fault(text) for text in faults])
    except FaultSpecError as exc:
        raise ReplayError(f"its meta's faults: {exc}") from None


def _is_law_pair(pair: Any) -> bool:
    """``[control type, "module:Class"]``: the type by its number or its name."""
    from humanoid_twin.slave.laws import CONTROL_TYPES

    return (isinstance(pair, list) and len(pair) == 2 and isinstance(pair[1], str)
            and (type(pair[0]) is int and pair[0] in CONTROL_TYPES.values()
                 or isinstance(pair[0], str) and pair[0] in CONTROL_TYPES))


def _control_type(ctype: int | str) -> int:
    from humanoid_twin.slave.laws import CONTROL_TYPES

    return CONTROL_TYPES[ctype] if isinstance(ctype, str) else int(ctype)


def _type_name(ctype: int) -> str:
    from humanoid_twin.slave.laws import CONTROL_TYPES

    return next(name for name, value in CONTROL_TYPES.items() if value == ctype)


def _resolve_laws(logged: Iterable[tuple[int | str, Any]],
                  given: Iterable[tuple[int | str, Any]]) -> tuple[tuple[int, Any], ...]:
    """The law classes of the replay: each law the log names (``module:Class``) is a built-in
    class of that name (no import), or the class the caller gave for that control type under
    that name; a law given and not logged would build another twin than the logged one."""
    from humanoid_twin.slave.laws import BUILTIN_LAWS

    builtin = {law_reference(cls): cls for cls in BUILTIN_LAWS.values()}
    offered = {_control_type(ctype): law for ctype, law in given}
    out: list[tuple[int, Any]] = []
    for ctype, ref in logged:
        ctype = _control_type(ctype)
        law = offered.pop(ctype, None)
        if law is not None and law_reference(law) == ref:
            out.append((ctype, law))
        elif law is None and ref in builtin:
            out.append((ctype, builtin[ref]))
        else:
            mine = "" if law is None else f" (--law {_type_name(ctype)}={law_reference(law)} is another)"
            raise ReplayError(f"the log names the law {ref!r:.120} for {_type_name(ctype)}{mine}: a replay "
                              f"imports no code a log names; to run it, name it: --law {_type_name(ctype)}="
                              f"{ref:.120}")
    if offered:
        ctype, law = next(iter(offered.items()))
        raise ReplayError(f"--law {_type_name(ctype)}={law_reference(law)}: the log records no law for "
                          f"{_type_name(ctype)}; the twin it logged ran the built-in one")
    return tuple(out)


def check_log(path: str | Path) -> LogInfo:
    """The whole log checked (its lines, its line settings, its meta's values), before anything
    runs or is written; :class:`ReplayError` with the reason (and the line) otherwise."""
    try:
        info = scan_log(path)
        settings = line_settings(path)
    except SerialLogError as exc:
        raise ReplayError(str(exc)) from None
    twin_line = (BAUDRATE, BYTESIZE, PARITY, STOPBITS)
    if settings != twin_line:
        raise ReplayError(f"{path}: logged on a {settings[0]} {''.join(map(str, settings[1:]))} line; the "
                          f"twin's is {BAUDRATE} {BYTESIZE}{PARITY}{STOPBITS}")
    try:
        check_meta(info.meta)
    except ReplayError as exc:
        raise ReplayError(f"{path}: {exc}") from None
    return info


def replay_options(path: str | Path, info: LogInfo, *, seed: int | None = None,
                   laws: Iterable[tuple[int | str, Any]] = (),
                   can_interface: str | None = None) -> RigOptions:
    """The :class:`RigOptions` of the twin ``info``'s meta describes (``seed``, ``can_interface``:
    these instead; ``laws``: the classes the caller names, :func:`_resolve_laws`), with no output
    and no monitor; :class:`ReplayError` when the meta cannot rebuild it here."""
    try:
        opts = RigOptions.from_replay_meta(info.meta)
        opts = dataclasses.replace(opts, laws=_resolve_laws(opts.laws, laws))
    except ValueError as exc:           # ReplayError too: the message gets the file's name
        raise ReplayError(f"{path}: {exc}") from None
    interface = can_interface or opts.can_interface
    if interface not in REPLAY_CAN_INTERFACES:
        raise ReplayError(f"{path}: logged on the CAN interface {opts.can_interface!r:.40} (channel "
                          f"{opts.can_channel!r:.40}): a replay opens no system CAN interface a log names; "
                          "replay it on the twin's own wire: --can-interface humanoid_twin")
    channel = opts.can_channel if interface == opts.can_interface else None
    opts = dataclasses.replace(opts, can_interface=interface, can_channel=channel)
    if seed is not None:
        opts = dataclasses.replace(opts, seed=seed)
    return opts


class _Comparison:
    """The twin's twin->host writes against the log's, in order, as they come (constant memory:
    an answer missing or one too many is found once the replay is past its instant)."""

    def __init__(self) -> None:
        self.want: deque[tuple[int, Record]] = deque()     # (line number, logged write)
        self.got: deque[Record] = deque()
        self.logged = self.sent = self.twin_bytes = 0
        self.difference: str | None = None

    def tap(self, event: str, t_us: int, data: bytes, n: int) -> None:
        if event == TAP_TO_HOST:
            self.sent += 1
            self.twin_bytes += len(data)
            if self.difference is None:
                self.got.append(Record(t_us, event, data=data, end_us=n))

    def expect(self, no: int, rec: Record) -> None:
        self.logged += 1
        if self.difference is None:
            self.want.append((no, rec))

    def match(self, now_us: int, read_us: int) -> None:
        """Pair the writes so far; a logged write older than ``now_us`` with no twin write left to
        pair, or a twin write older than ``read_us`` (the log's last line read) with no logged
        one, is a difference."""
        want, got = self.want, self.got
        while self.difference is None and want and got:
            no, w = want.popleft()
            g = got.popleft()
            if w != g:
                self._differ(f"line {no}, twin->host write {self.logged - len(want)}: the log has "
                             f"'{w.line()}', the twin sent '{g.line()}'")
        if self.difference is None and want and want[0][1].t_us < now_us:
            no, w = want[0]
            self._differ(f"line {no}, twin->host write {self.logged - len(want) + 1}: the log has "
                         f"'{w.line()}', the twin sent nothing then")
        elif self.difference is None and got and got[0].t_us < read_us:
            self._differ(f"twin->host write {self.sent - len(got) + 1}: the twin sent '{got[0].line()}', "
                         "the log has no write then")

    def finish(self) -> None:
        if self.difference is None and (self.want or self.got):
            self._differ(f"{self.logged} twin->host writes in the log, {self.sent} from the twin; the first "
                         "unmatched: " + (f"the log has '{self.want[0][1].line()}' (line {self.want[0][0]})"
                                          if self.want else f"the twin sent '{self.got[0].line()}'"))

    def _differ(self, text: str) -> None:
        self.difference = text
        self.want.clear()
        self.got.clear()


def replay(path: str | Path, seed: int | None = None, *, laws: Iterable[tuple[int | str, Any]] = (),
           can_interface: str | None = None, out: Path | None = None, can_log: Path | None = None,
           can_log_name: str | None = None, info: LogInfo | None = None,
           wall_timeout: float | None = None) -> ReplayResult:
    """Feed the host->twin bytes of the log at their instants (the flushes and unplugs too) into
    the twin its meta describes (:func:`replay_options`) and compare its twin->host writes with
    the log's. ``out`` / ``can_log``: record the replay (a rerun recording, a CAN log) as a run
    does; ``info``: the log already checked (:func:`check_log`), else it is checked here;
    ``wall_timeout``: at most that many wall seconds (:class:`ReplayTimeoutError` beyond, the
    outputs closed). :class:`ReplayError` when the log cannot be replayed (nothing has run then).

    An unplug is a ``serve`` session's start or end, which also resets the Master's receiver
    (``bus/bridges.py``): the replay does both. A host line at the instant the twin is at is fed
    at once: the host wrote it before the events of that instant ran (the first request at 0,
    before a fault that starts at 0). Without outputs the replay stops at the first difference."""
    from humanoid_twin.controllers import LawError

    info = check_log(path) if info is None else info
    opts = replay_options(path, info, seed=seed, laws=laws, can_interface=can_interface)
    recording = out is not None or can_log is not None
    opts = dataclasses.replace(opts, out=out, can_log=can_log, can_log_name=can_log_name, monitor=recording)
    try:
        rig = Rig(opts, expected_s=info.end_us / US_PER_S)
    except LawError as exc:      # the caller's law cannot be made for every board
        raise ReplayError(f"{path}: {exc}") from None
    cmp = _Comparison()
    host = 0
    deadline = None if wall_timeout is None else time.monotonic() + wall_timeout

    def advance(t_us: int) -> None:
        while twin.clock.now_us < t_us:
            if deadline is not None and time.monotonic() > deadline:
                raise ReplayTimeoutError(f"the replay took more than {wall_timeout:g} wall seconds: stopped "
                                         f"at t={twin.now_s:.3f} s simulated")
            twin.advance_to(min(t_us, twin.clock.now_us + WALL_CHECK_US))

    try:
        twin = rig.twin
        if "tilt_from_s" in info.meta:
            rig.start_tilt(float(info.meta["tilt_from_s"]))
        twin.link.add_tap(cmp.tap)
        for no, rec in iter_log(path):
            if isinstance(rec, dict):
                continue
            if rec.event == TAP_TO_HOST:
                cmp.expect(no, rec)
            else:
                advance(rec.t_us)
                if rec.event == TAP_TO_DEVICE:
                    twin.link.host_write(rec.data)
                    host += len(rec.data)
                elif rec.event == TAP_FLUSH:
                    twin.link.host_reset_output()
                else:                # a serve client came or left: the cable and the Master's receiver
                    twin.link.unplug()
                    twin.the_master().reset_receiver()
            cmp.match(twin.clock.now_us, rec.t_us)
            if cmp.difference is not None and not recording:
                break
        else:
            advance(info.end_us)
            cmp.match(twin.clock.now_us, info.end_us)
            cmp.finish()
    except SerialLogError as exc:       # the file changed since it was checked
        raise ReplayError(str(exc)) from None
    finally:
        rig.close()
    return ReplayResult(host, cmp.twin_bytes, cmp.logged, cmp.sent, cmp.difference, rig.twin.now_s)
