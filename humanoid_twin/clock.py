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
from collections.abc import Callable

US_PER_S = 1_000_000

_heappush = heapq.heappush

Callback = Callable[[], None]


class Clock:
    """Integer-microsecond discrete-event scheduler."""

    __slots__ = ("now_us", "_queue", "_seq", "events_run", "_until")

    def __init__(self) -> None:
        self.now_us: int = 0
        self._queue: list[tuple[int, int, Callback]] = []
        self._seq = 0
        self.events_run = 0
        self._until = -1          # the target of the run_until in progress (-1: none)

    @property
    def now_s(self) -> float:
        """Virtual time in seconds."""
        return self.now_us / US_PER_S

    def schedule(self, t_us: int, callback: Callback) -> None:
        """Run ``callback`` at absolute virtual time ``t_us`` (not before ``now_us``)."""
        if t_us < self.now_us:
            raise ValueError(f"cannot schedule in the past: {t_us} < {self.now_us}")
        self._seq = seq = self._seq + 1
        _heappush(self._queue, (t_us, seq, callback))

    def after(self, delay_us: int, callback: Callback) -> None:
        """Run ``callback`` ``delay_us`` microseconds from now."""
        self.schedule(self.now_us + delay_us, callback)

    def call_every(self, period_us: int, callback: Callback, first_us: int | None = None) -> None:
        """Run ``callback`` every ``period_us``, first at ``first_us`` (default: one period from now)."""
        if period_us <= 0:
            raise ValueError("period must be positive")
        due = self.now_us + period_us if first_us is None else first_us
        queue = self._queue

        def tick() -> None:
            nonlocal due
            callback()
            due += period_us
            # self.schedule, inlined (due > now: no past check needed)
            self._seq = seq = self._seq + 1
            _heappush(queue, (due, seq, tick))

        self.schedule(due, tick)

    def schedule_fast(self, t_us: int, callback: Callback) -> None:
        """:meth:`schedule` without the past check, for a hot path that knows ``t_us >= now_us``
        (the CAN wire's frame events)."""
        self._seq = seq = self._seq + 1
        _heappush(self._queue, (t_us, seq, callback))

    def next_due_us(self) -> int | None:
        """Virtual time of the earliest pending event (None when nothing is scheduled).

        The CAN wire's fast path: a decision that would be taken at ``t`` can be taken now when
        nothing is due before ``t`` (no event can run, and so no frame can be requested, in
        between)."""
        queue = self._queue
        return queue[0][0] if queue else None

    def due_by(self, t_us: int) -> bool:
        """Whether an event is due at or before ``t_us`` (``next_due_us() <= t_us``, False when
        nothing is scheduled): the question the wire's and the boards' fast paths ask, typed
        for compiled callers (``cpdef bint``)."""
        queue = self._queue
        return bool(queue) and queue[0][0] <= t_us

    def skip_to(self, t_us: int) -> bool:
        """Inside an event, move ``now_us`` on to ``t_us`` when that changes nothing: no event is
        due up to ``t_us`` and ``t_us`` is within the ``run_until`` in progress. The caller then
        does at once what an event at ``t_us`` would have done (the CAN wire's end of frame).
        Returns False, and moves nothing, otherwise."""
        queue = self._queue
        if t_us > self._until or (queue and queue[0][0] <= t_us) or t_us < self.now_us:
            return False
        self.now_us = t_us
        return True

    def run_until(self, t_us: int) -> None:
        """Run every event due at or before ``t_us``, then set ``now_us = t_us``."""
        queue = self._queue
        pop = heapq.heappop
        n = 0
        outer = self._until
        self._until = t_us if t_us < outer or outer < 0 else outer
        try:
            while queue and queue[0][0] <= t_us:
                t, _, cb = pop(queue)
                self.now_us = t
                cb()
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
