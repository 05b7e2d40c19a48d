"""The lockstep virtual clock that drives the whole twin (like PX4 SITL lockstep).

Time is an integer number of microseconds. Every activity of the twin is an event on this
clock: the Master's 250 µs timer, each Slave's 20 ms PWM tick, the end of each CAN frame on
the wire, each serial byte after its 11 bit times. The plant (MuJoCo) is bound to this clock
(``Plant.bind_clock``) and steps itself lazily: its every read or write first runs the physics
steps due up to ``now_us`` in one ``mj_step(..., nstep=k)`` call. The result is the same as
stepping physics as events, without a Python call per physics step.

Events at the same instant run in the order they were scheduled (a sequence number breaks
ties), so the same inputs and seed give the same bytes and trajectories, run after run.
"""

from __future__ import annotations

import heapq
import time
from array import array
from collections.abc import Callable

try:        # Cython's pure-Python mode: True in the compiled core, where "cython" is the compiler's
    import cython
    _COMPILED = cython.compiled
except ImportError:         # interpreted, Cython not installed
    _COMPILED = False

US_PER_S = 1_000_000

Callback = Callable[[], None]

_QUEUE_START = 64          # the queue's first capacity (a booted twin holds ~10 events); doubles as needed


_heappush = heapq.heappush
_heappop = heapq.heappop


def _zeros(n: int) -> array:
    return array("q", bytes(8 * n))


class Clock:
    """Integer-microsecond discrete-event scheduler.

    The queue is a binary min-heap on (due time, sequence number). Every pending event has its
    own sequence number, so the order in which events run is fully determined by that pair,
    whatever the heap's layout; the heap has two layouts of that one order:
    - compiled (clock.pxd): parallel arrays, the due times, sequence numbers and periods as C
      ``long long`` memoryviews over ``array('q')`` and the callbacks in a list, sifted by
      :meth:`_push` and :meth:`_pop` on C integers;
    - interpreted: ``heapq`` on ``(due, seq, period, callback)`` tuples in ``_queue`` (C code
      in CPython: the arrays' sifting written in Python costs ~20 000 instructions an event
      there, heapq ~2 500).
    tests/twin/test_clock.py runs both layouts against each other. A periodic event
    (:meth:`call_every`) is one entry, pushed again with a new sequence number after its
    callback returns.
    """

    __slots__ = ("now_us", "events_run", "_until", "_seq", "_n", "_t", "_s", "_p", "_cb", "_queue")

    def __init__(self) -> None:
        self.now_us: int = 0
        self.events_run = 0
        self._until = -1          # the target of the run_until in progress (-1: none)
        self._seq = 0
        self._n = 0               # pending events: heap entries 0.._n-1
        self._t = _zeros(_QUEUE_START)                      # due times (us)
        self._s = _zeros(_QUEUE_START)                      # sequence numbers (ties: first scheduled first)
        self._p = _zeros(_QUEUE_START)                      # periods (us; 0: runs once)
        self._cb: list[Callback | None] = [None] * _QUEUE_START
        self._queue: list[tuple[int, int, int, Callback]] = []      # the interpreted layout

    @property
    def now_s(self) -> float:
        """Virtual time in seconds."""
        return self.now_us / US_PER_S

    @property
    def pending(self) -> int:
        """Events scheduled and not run yet (a periodic event counts once)."""
        return self._n + len(self._queue)      # one layout holds the events, the other is empty

    # -- the heap: the only methods that know its layout (the class doc) ---------------------
    def _first_due(self) -> int:
        """The due time of the earliest pending event, -1 when none is pending."""
        if _COMPILED:
            return self._t[0] if self._n else -1
        queue = self._queue
        return queue[0][0] if queue else -1

    def _run_first(self) -> None:
        """Take the earliest event off the queue and run it at its due time; a periodic one is
        pushed again, with a new sequence number, after its callback returns."""
        if _COMPILED:
            t = self._t[0]
            period = self._p[0]
            cb = self._cb[0]
            self._pop()
        else:
            t, _, period, cb = _heappop(self._queue)
        self.now_us = t
        cb()  # type: ignore[misc]  # a pending event's callback (None only in free slots)
        if period:
            self._push(t + period, period, cb)  # type: ignore[arg-type]  # as above

    def _grow(self) -> None:
        cap = 2 * len(self._cb)
        t, s, p = _zeros(cap), _zeros(cap), _zeros(cap)
        for i in range(self._n):
            t[i] = self._t[i]
            s[i] = self._s[i]
            p[i] = self._p[i]
        self._t, self._s, self._p = t, s, p
        self._cb.extend([None] * (cap - len(self._cb)))

    def _push(self, t_us: int, period_us: int, callback: Callback) -> int:
        """Add an event with the next sequence number (sift up from the end)."""
        self._seq = seq = self._seq + 1
        if not _COMPILED:
            _heappush(self._queue, (t_us, seq, period_us, callback))
            return 0
        i = self._n
        if i == len(self._cb):
            self._grow()
        self._n = i + 1
        T = self._t
        S = self._s
        P = self._p
        CB = self._cb
        while i > 0:
            up = (i - 1) >> 1
            tu = T[up]
            if tu < t_us or (tu == t_us and S[up] < seq):
                break
            T[i] = tu
            S[i] = S[up]
            P[i] = P[up]
            CB[i] = CB[up]
            i = up
        T[i] = t_us
        S[i] = seq
        P[i] = period_us
        CB[i] = callback
        return 0

    def _pop(self) -> None:
        """Remove the earliest event, entry 0 (the last entry sifts down from the top); the
        array layout only."""
        self._n = n = self._n - 1
        T = self._t
        S = self._s
        P = self._p
        CB = self._cb
        t = T[n]
        s = S[n]
        p = P[n]
        cb = CB[n]
        CB[n] = None
        if n == 0:
            return
        i = 0
        c = 1
        while c < n:
            tc = T[c]
            sc = S[c]
            if c + 1 < n:
                tr = T[c + 1]
                if tr < tc or (tr == tc and S[c + 1] < sc):
                    c += 1
                    tc = tr
                    sc = S[c]
            if t < tc or (t == tc and s < sc):
                break
            T[i] = tc
            S[i] = sc
            P[i] = P[c]
            CB[i] = CB[c]
            i = c
            c = 2 * i + 1
        T[i] = t
        S[i] = s
        P[i] = p
        CB[i] = cb

    # -- scheduling ---------------------------------------------------------------------------
    def schedule(self, t_us: int, callback: Callback) -> None:
        """Run ``callback`` at absolute virtual time ``t_us`` (not before ``now_us``)."""
        if t_us < self.now_us:
            raise ValueError(f"cannot schedule in the past: {t_us} < {self.now_us}")
        self._push(t_us, 0, callback)

    def after(self, delay_us: int, callback: Callback) -> None:
        """Run ``callback`` ``delay_us`` microseconds from now."""
        self.schedule(self.now_us + delay_us, callback)

    def call_every(self, period_us: int, callback: Callback, first_us: int | None = None) -> None:
        """Run ``callback`` every ``period_us``, first at ``first_us`` (default: one period from now).
        After each call the next one is scheduled (a new sequence number); a callback that raises
        is not called again."""
        if type(period_us) is not int or period_us <= 0:
            raise ValueError(f"period must be a positive int of microseconds, got {period_us!r}")
        due = self.now_us + period_us if first_us is None else first_us
        if due < self.now_us:
            raise ValueError(f"cannot schedule in the past: {due} < {self.now_us}")
        self._push(due, period_us, callback)

    def schedule_fast(self, t_us: int, callback: Callback) -> None:
        """:meth:`schedule` without the past check, for a hot path that knows ``t_us >= now_us``
        (the CAN wire's frame events)."""
        self._push(t_us, 0, callback)

    def next_due_us(self) -> int | None:
        """Virtual time of the earliest pending event (None when nothing is scheduled).

        The CAN wire's fast path: a decision that would be taken at ``t`` can be taken now when
        nothing is due before ``t`` (no event can run, and so no frame can be requested, in
        between)."""
        due = self._first_due()
        return due if due >= 0 else None

    def due_by(self, t_us: int) -> bool:
        """Whether an event is due at or before ``t_us`` (``next_due_us() <= t_us``, False when
        nothing is scheduled): the question the wire's and the boards' fast paths ask, typed
        for compiled callers (``cpdef bint``)."""
        due = self._first_due()
        return 0 <= due <= t_us

    def skip_to(self, t_us: int) -> bool:
        """Inside an event, move ``now_us`` on to ``t_us`` when that changes nothing: no event is
        due up to ``t_us`` and ``t_us`` is within the ``run_until`` in progress. The caller then
        does at once what an event at ``t_us`` would have done (the CAN wire's end of frame).
        Returns False, and moves nothing, otherwise."""
        if t_us > self._until or t_us < self.now_us:
            return False
        due = self._first_due()
        if 0 <= due <= t_us:
            return False
        self.now_us = t_us
        return True

    def run_until(self, t_us: int) -> None:
        """Run every event due at or before ``t_us``, then set ``now_us = t_us``."""
        n = 0
        outer = self._until
        self._until = t_us if t_us < outer or outer < 0 else outer
        try:
            while True:
                due = self._first_due()
                if due < 0 or due > t_us:
                    break
                self._run_first()
                n += 1
        finally:
            self._until = outer
        self.events_run += n
        if t_us > self.now_us:
            self.now_us = t_us

    def run_for(self, duration_us: int) -> None:
        """Advance virtual time by ``duration_us``."""
        self.run_until(self.now_us + duration_us)


class RealTimePacer:
    """Keeps virtual time in step with the wall clock (``serve``, ``run --viewer``): the one
    real-time pacer.

    ``pace()`` advances the clock to the virtual instant that corresponds to the elapsed wall
    time since ``start()``, at most ``max_step_us`` at a time, and returns how far behind real
    time the twin is (seconds, 0 when on time); ``wait()``, for code that runs inside a clock
    event, sleeps until wall time has caught up with the clock instead.
    """

    def __init__(self, clock: Clock, speed: float = 1.0) -> None:
        self.clock = clock
        self.speed = speed
        self._wall0 = time.monotonic()
        self._virt0 = clock.now_us

    def start(self) -> None:
        """Anchor virtual now to wall now."""
        self._wall0 = time.monotonic()
        self._virt0 = self.clock.now_us

    def target_us(self) -> int:
        """The virtual time that corresponds to wall now."""
        return self._virt0 + int((time.monotonic() - self._wall0) * self.speed * US_PER_S)

    def pace(self, max_step_us: int = 2_000, advance_to: Callable[[int], None] | None = None) -> float:
        """Advance virtual time toward wall time with ``advance_to`` (default: the clock's
        ``run_until``; the twin passes its own ``Twin.advance_to``); return the lag in seconds."""
        target = self.target_us()
        now = self.clock.now_us
        if target > now:
            (advance_to or self.clock.run_until)(min(target, now + max_step_us))
        return max(0.0, (target - self.clock.now_us) / US_PER_S)

    def wait(self) -> float:
        """Sleep until wall time catches up with the clock's now (for a caller inside a clock event,
        the live viewer: the twin runs faster than real time); return how long it slept (s)."""
        ahead = (self.clock.now_us - self._virt0) / (self.speed * US_PER_S) - (time.monotonic() - self._wall0)
        if ahead > 0:
            time.sleep(ahead)
            return ahead
        return 0.0
