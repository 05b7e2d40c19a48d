"""The clock's event queue: events run in (due time, order scheduled) order, in both of the
queue's layouts (humanoid_twin/clock.py: C arrays in the compiled core, heapq interpreted).

The order is what makes a run repeatable byte for byte (tests/golden/test_golden.py); here it is
checked against a plain reference scheduler on random schedules, with ties, events scheduled
from inside events, periodic events and more pending events than the queue's first capacity.
"""

from __future__ import annotations

import random

import pytest

from humanoid_twin import clock as clock_module
from humanoid_twin.clock import Clock
from humanoid_twin.core import is_compiled


class Reference:
    """The order the clock promises, written the plainest way: the earliest (due, seq) first."""

    def __init__(self) -> None:
        self.now_us = 0
        self.seq = 0
        self.pending: list[list] = []

    def schedule(self, t_us: int, cb, period: int = 0) -> None:
        self.seq += 1
        self.pending.append([t_us, self.seq, period, cb])

    def call_every(self, period: int, cb, first_us: int) -> None:
        self.schedule(first_us, cb, period)

    def run_until(self, t_us: int) -> None:
        while self.pending:
            entry = min(self.pending, key=lambda e: (e[0], e[1]))
            if entry[0] > t_us:
                break
            self.pending.remove(entry)
            self.now_us, _, period, cb = entry
            cb()
            if period:
                self.schedule(self.now_us + period, cb, period)
        self.now_us = max(self.now_us, t_us)


def scripted_run(sched, seed: int) -> list[tuple[int, str]]:
    """Drive ``sched`` (a Clock or the Reference) through a seeded random script; return what ran, when."""
    rng = random.Random(seed)
    log: list[tuple[int, str]] = []

    def event(name: str, depth: int):
        def cb() -> None:
            log.append((sched.now_us, name))
            if depth < 2 and rng.random() < 0.3:          # an event that schedules more events
                for k in range(rng.randrange(1, 4)):
                    t = sched.now_us + rng.choice((0, 0, 1, 7, 250))
                    sched.schedule(t, event(f"{name}.{k}", depth + 1))
        return cb

    for i in range(300):                                   # > the queue's first capacity (64)
        sched.schedule(rng.randrange(0, 5_000, 5), event(f"e{i}", 0))
    for i in range(6):
        period = rng.choice((250, 1000, 20_000 // 8))
        sched.call_every(period, event(f"p{i}", 2), first_us=rng.randrange(0, 2000, 250))
    for t in range(0, 12_000, 1_300):
        sched.run_until(t)
    return log


@pytest.mark.parametrize("seed", range(5))
def test_events_run_in_due_then_scheduled_order(seed):
    """The clock (whichever core runs) and the reference run the same events at the same times in
    the same order, ties included."""
    got = scripted_run(Clock(), seed)
    want = scripted_run(Reference(), seed)
    assert len(got) > 400
    assert got == want


@pytest.mark.skipif(is_compiled(clock_module), reason="the compiled core has the array layout only")
@pytest.mark.parametrize("seed", range(3))
def test_both_layouts_give_the_same_order(monkeypatch, seed):
    """Interpreted, the array layout the compiled core uses (run in Python) and heapq give the
    same run, event for event."""
    heap = scripted_run(Clock(), seed)
    monkeypatch.setattr(clock_module, "_COMPILED", True)
    arrays = scripted_run(Clock(), seed)
    assert arrays == heap


def test_a_periodic_event_that_raises_is_not_called_again():
    clock = Clock()
    calls = []

    def tick() -> None:
        calls.append(clock.now_us)
        if len(calls) == 3:
            raise RuntimeError("boom")

    clock.call_every(100, tick, first_us=0)
    with pytest.raises(RuntimeError):
        clock.run_until(1_000)
    clock.run_until(2_000)
    assert calls == [0, 100, 200]
    assert clock.pending == 0


def test_scheduling_in_the_past_is_refused():
    clock = Clock()
    clock.run_until(500)
    with pytest.raises(ValueError, match="past"):
        clock.schedule(499, lambda: None)
    with pytest.raises(ValueError, match="past"):
        clock.call_every(10, lambda: None, first_us=10)
    with pytest.raises(ValueError, match="positive"):
        clock.call_every(0, lambda: None)
    assert clock.pending == 0 and clock.next_due_us() is None
