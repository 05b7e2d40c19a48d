"""CAN traffic of the twin in python-can's standard log formats, and a DBC decoder for them.

``CanLog(path, network)`` opens a python-can writer (``can.Logger``: the format follows the
suffix, ``.asc .blf .csv .log .trc .db .mf4``, optionally ``.gz``; ``.txt``, which python-can
writes but cannot read, is refused) and attaches it to the
twin's :class:`~humanoid_twin.bus.CanNetwork` with ``network.add_listener``: every frame that
completed on the wire is written with its *virtual* timestamp (seconds of simulated time).
Errors (unknown suffix, a format whose optional dependency is missing, an unwritable path) are
raised by the constructor, i.e. before the run starts.

Read back: :func:`read_can_log` (python-can's ``can.LogReader``) and :func:`decode_can_log`
(cantools with the project's DBC, ``humanoid_twin.protocol.canframes.load_dbc``).

python-can's ASC and BLF writers store times relative to their first event; ``CanLog`` writes a
first event at virtual time 0 (an ASC comment line / a BLF marker) so that every format holds
the twin's virtual times as they are.
"""

from __future__ import annotations

import json
import pathlib
import threading
import time
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any, NamedTuple

import can

from humanoid_twin import signals
from humanoid_twin.protocol import canframes

if TYPE_CHECKING:
    import cantools.database

    from humanoid_twin.bus.network import CanNetwork

__all__ = [
    "CanLog",
    "CanLogError",
    "DecodedFrame",
    "check_log_path",
    "read_can_log",
    "decode_can_log",
    "convert_can_log",
    "log_suffix",
]


SQLITE_DRAIN_S = 60.0      # at most this long for python-can's SQLite writer to write its queue


class CanLogError(ValueError):
    """A CAN log that cannot be written or read in the requested format."""


def log_suffix(path: str | pathlib.Path) -> str:
    """The python-can format suffix of ``path`` (``.asc`` for ``run.asc`` and ``run.asc.gz``)."""
    p = pathlib.PurePath(path)
    suffixes = [s.lower() for s in p.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        return suffixes[-2] if len(suffixes) >= 2 else ""
    return suffixes[-1] if suffixes else ""


def _writer_suffixes() -> list[str]:
    from can.io import logger as _logger

    return sorted(_logger.MESSAGE_WRITERS)


def _reader_suffixes() -> list[str]:
    from can.io import player as _player

    return sorted(_player.MESSAGE_READERS)


def check_log_path(path: str | pathlib.Path) -> str:
    """Check, without creating anything, that a CAN log can be written at ``path``: a format
    python-can writes (by suffix, optionally ``.gz``), its optional dependency installed, an
    existing directory. Returns the format suffix (``.asc``). :class:`CanLogError` (a
    ``ValueError``) or ``FileNotFoundError``/``IsADirectoryError`` (``OSError``) otherwise."""
    p = pathlib.Path(path)
    suffix = log_suffix(p)
    known = _writer_suffixes()
    if suffix not in known:
        raise CanLogError(
            f"CAN log {str(p)!r}: unknown format {suffix or '(no suffix)'!r}; "
            f"python-can writes {', '.join(known)} (optionally + .gz)"
        )
    if suffix not in _reader_suffixes():
        readable = sorted(set(known) & set(_reader_suffixes()))
        raise CanLogError(
            f"CAN log {str(p)!r}: python-can writes {suffix!r} but cannot read it back; "
            f"use one of {', '.join(readable)}"
        )
    if suffix == ".mf4":
        try:
            import asammdf  # noqa: F401
        except ImportError:
            raise CanLogError(
                f"CAN log {str(p)!r}: format '.mf4' needs the asammdf package (pip install python-can[mf4])"
            ) from None
    if p.is_dir():
        raise IsADirectoryError(f"CAN log {str(p)!r} is a directory")
    if not p.parent.is_dir():
        raise FileNotFoundError(
            f"cannot write the CAN log {str(p)!r}: directory {str(p.parent)!r} does not exist"
        )
    return suffix


class _Tap(can.Listener):
    """The listener the network sees: forwards to the writer while the log is open, and to
    nothing once it is closed (the network may outlive the log)."""

    __slots__ = ("sink", "count")

    def __init__(self, sink: can.Listener) -> None:
        self.sink = sink
        self.count = 0

    def on_message_received(self, msg: can.Message) -> None:
        self.count += 1
        self.sink.on_message_received(msg)


class _Null(can.Listener):
    def on_message_received(self, msg: can.Message) -> None:
        pass


_NULL = _Null()


class CanLog:
    """Write every CAN frame of ``network`` to ``path`` (python-can format chosen by suffix).

    Use as a context manager or call :meth:`close`; closing is idempotent and leaves a file
    that ``can.LogReader`` reads back. Timestamps are virtual (simulated seconds since the
    twin's clock started).
    """

    def __init__(self, path: str | pathlib.Path, network: CanNetwork, name: str | None = None,
                 params: Mapping[str, float] | None = None) -> None:
        self.path = pathlib.Path(path)
        suffix = check_log_path(self.path)
        if not hasattr(network, "add_listener"):
            raise TypeError(f"CanLog needs a CanNetwork with add_listener(), got {type(network).__name__}")
        try:
            writer = can.Logger(self.path)
        except NotImplementedError as exc:  # e.g. .mf4 without asammdf
            raise CanLogError(f"CAN log {str(self.path)!r}: format {suffix!r} unavailable: {exc}") from exc
        except OSError as exc:
            raise OSError(
                exc.errno, f"cannot write the CAN log {str(self.path)!r}: {exc.strerror or exc}"
            ) from exc
        if isinstance(writer, (can.ASCWriter, can.BLFWriter)):
            # These writers store times relative to their first event: anchor that at virtual
            # time 0 so the file holds the twin's virtual times, not "since the first frame".
            writer.log_event("humanoid-twin: timestamps are virtual seconds of the twin's clock", 0.0)
            if params:      # the named parameters that differ from their defaults (docs/parameters.md)
                writer.log_event(f"humanoid-twin params: {json.dumps(dict(params), sort_keys=True)}", 0.0)
        if isinstance(writer, can.TRCWriter):
            # its header names the file by its absolute path: the file's own name instead (``name``:
            # the final one, when ``path`` is a temporary file renamed at the end)
            writer.filepath = pathlib.PurePath(name or self.path.name).name
        self._writer = writer
        self._thread_error: BaseException | None = None
        self._hook: Any = None
        if isinstance(writer, can.SqliteWriter):
            self._watch_writer_thread(writer)
        self._tap = _Tap(writer)
        self._closed = False
        self.network = network
        network.add_listener(self._tap)

    def _watch_writer_thread(self, writer: can.SqliteWriter) -> None:
        """python-can's SQLite writer writes in a thread of its own, where a failure (a full
        disk, a file-size limit) would only print that thread's traceback: it is caught here and
        :meth:`close` raises it as the ``OSError`` every other format raises (issue 24)."""
        previous = threading.excepthook
        thread = writer._writer_thread

        def hook(args: Any) -> None:
            if args.thread is thread:
                self._thread_error = args.exc_value
                return
            previous(args)

        self._hook = (hook, previous)
        threading.excepthook = hook

    @property
    def frames(self) -> int:
        """Frames written so far."""
        return self._tap.count

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran."""
        return self._closed

    def close(self) -> None:
        """Detach from the network (if it supports it), flush and close the file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._tap.sink = _NULL
        remove = getattr(self.network, "remove_listener", None)
        if remove is not None:
            try:
                remove(self._tap)
            except (ValueError, KeyError):
                pass
        writer = self._writer
        with signals.deferred():       # the file is complete before a signal is delivered
            if isinstance(writer, can.SqliteWriter):
                self._close_sqlite(writer)
            else:
                writer.stop()

    def _close_sqlite(self, writer: can.SqliteWriter) -> None:
        # python-can's SQLite writer thread leaves at stop() with frames still queued when it
        # was behind (it checks its stop flag after each batch): let it drain first
        thread = writer._writer_thread
        deadline = time.monotonic() + SQLITE_DRAIN_S
        while not writer.buffer.empty() and thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.01)
        try:
            writer.stop()
        finally:
            if self._hook is not None and threading.excepthook is self._hook[0]:
                threading.excepthook = self._hook[1]
        err = self._thread_error
        if err is not None or writer.num_frames != self._tap.count:
            why = "stopped" if err is None else f"{type(err).__name__}: {' '.join(str(err).split())[:200]}"
            raise OSError(f"cannot write the CAN log {str(self.path)!r}: python-can's SQLite writer "
                          f"failed ({why}); {writer.num_frames} of {self._tap.count} frames written")

    def __enter__(self) -> CanLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"CanLog({str(self.path)!r}, {state}, frames={self.frames})"


# --- read back ---------------------------------------------------------------------------


def read_can_log(path: str | pathlib.Path) -> list[can.Message]:
    """All frames of a CAN log written by :class:`CanLog` (python-can ``can.LogReader``)."""
    p = pathlib.Path(path)
    suffix = log_suffix(p)
    if suffix not in _reader_suffixes():
        raise CanLogError(
            f"CAN log {str(p)!r}: python-can cannot read {suffix or '(no suffix)'!r}; "
            f"it reads {', '.join(_reader_suffixes())}"
        )
    if not p.is_file():
        raise FileNotFoundError(f"CAN log {str(p)!r} does not exist")
    # ASC: the default relative timestamps are the virtual times (CanLog anchors the file at 0)
    with can.LogReader(p) as reader:
        return list(reader)


def convert_can_log(src: str | pathlib.Path, dst: str | pathlib.Path) -> int:
    """Convert a CAN log to another python-can format (by suffix) keeping the twin's virtual times:
    python-can's own ``can.logconvert`` writes ASC and BLF times relative to the first frame (every
    time shifted by it); this anchors them at 0, as :class:`CanLog` does. Returns the frames
    written; :class:`CanLogError` for a format that cannot be read or written."""
    frames = read_can_log(src)
    dst = pathlib.Path(dst)
    check_log_path(dst)
    writer = can.Logger(dst)
    try:
        if isinstance(writer, (can.ASCWriter, can.BLFWriter)):
            writer.log_event("humanoid-twin: timestamps are virtual seconds of the twin's clock", 0.0)
        if isinstance(writer, can.TRCWriter):
            writer.filepath = dst.name
        for msg in frames:
            writer.on_message_received(msg)
    finally:
        writer.stop()
    return len(frames)


class DecodedFrame(NamedTuple):
    """One CAN frame decoded with the project's DBC."""

    timestamp: float            # virtual seconds
    arbitration_id: int
    src: int                    # source address (0 = Master, 1..8 = SCU)
    dst: int                    # destination address
    index: int  # type: ignore[assignment]  # packet index 0/1 (the field, not tuple.index)
    op: int                     # 0 actuation (Master -> Slave), 1 sensors (Slave -> Master)
    name: str                   # DBC message name, e.g. "Actuation1_S3"
    signals: dict[str, Any]     # DBC signal values


def decode_can_log(
    path: str | pathlib.Path, db: cantools.database.Database | None = None
) -> Iterator[DecodedFrame]:
    """Decode a CAN log with the DBC (default: ``canframes.load_dbc()``). A frame whose ID is
    not in the DBC raises :class:`CanLogError` naming it (the twin sends no such frames)."""
    if db is None:
        db = canframes.load_dbc()
    for msg in read_can_log(path):
        try:
            m = db.get_message_by_frame_id(msg.arbitration_id)
        except KeyError:
            raise CanLogError(
                f"CAN log {str(path)!r}: frame ID 0x{msg.arbitration_id:03X} at t={msg.timestamp:.6f} s "
                "is not in the project's DBC"
            ) from None
        src, dst, index, op = canframes.split_id(msg.arbitration_id)
        yield DecodedFrame(
            msg.timestamp, msg.arbitration_id, src, dst, index, op, m.name,
            m.decode(bytes(msg.data), decode_choices=False),  # type: ignore[arg-type]  # a single-frame message decodes to a dict
        )
