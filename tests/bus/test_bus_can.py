"""The CAN wire: frame length, virtual-time timing, arbitration, slide 23 filters, TX buffers,
abort, error confinement and bus-off recovery, fault injection, other python-can interfaces,
python-can tools on the channel and python-can log files. Real python-can, no mocks."""

from __future__ import annotations

import os
import random

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_twin.bus import (
    BUS_OFF,
    ERROR_ACTIVE,
    ERROR_PASSIVE,
    CanError,
    CanNetwork,
    frame_bits,
    max_frame_bits,
)
from humanoid_twin.clock import Clock

try:  # the slide 23 masks/filters from the protocol package
    from humanoid_twin.protocol.canframes import master_filters, slave_filters
except ImportError:  # pragma: no cover - protocol package not there yet
    def master_filters() -> list[dict]:
        return [{"can_id": 0b00000000000, "can_mask": 0b00001111100},
                {"can_id": 0b00000000100, "can_mask": 0b00001111100}]

    def slave_filters() -> list[dict]:
        return [{"can_id": 0b00000000000, "can_mask": 0b11110000100},
                {"can_id": 0b00000000100, "can_mask": 0b11110000100}]


# -- an independent reference for the frame length -----------------------------------------------
def ref_stuffed_frame(arbitration_id: int, data: bytes) -> str:
    """SOF..CRC of a CAN 2.0A data frame as transmitted (with stuff bits), written independently:
    CRC by polynomial long division over Python ints, stuffing by looking back at the output."""
    n = len(data)
    body = "0" + format(arbitration_id, "011b") + "000" + format(n, "04b")
    body += "".join(format(b, "08b") for b in data)
    rem = int(body, 2) << 15                    # M(x) * x^15 mod G(x), G = x^15 + 0x4599
    gen = (1 << 15) | 0x4599
    while rem.bit_length() > 15:
        rem ^= gen << (rem.bit_length() - 16)
    crc = format(rem, "015b")
    # the CRC makes the whole bit sequence a multiple of G(x)
    whole = int(body + crc, 2)
    while whole.bit_length() > 15:
        whole ^= gen << (whole.bit_length() - 16)
    assert whole == 0
    out = ""
    for bit in body + crc:
        out += bit
        if len(out) >= 5 and out[-5:] in ("00000", "11111"):
            out += "1" if bit == "0" else "0"
    return out


def ref_frame_bits(arbitration_id: int, data: bytes) -> int:
    # + CRC delimiter, ACK slot, ACK delimiter, EOF (7), intermission (3)
    return len(ref_stuffed_frame(arbitration_id, data)) + 1 + 1 + 1 + 7 + 3


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 0x7FF), st.binary(min_size=0, max_size=8))
def test_frame_bits_matches_independent_reference(arbitration_id, data):
    stuffed = ref_stuffed_frame(arbitration_id, data)
    assert "000000" not in stuffed and "111111" not in stuffed   # the receiver's stuff rule holds
    assert frame_bits(arbitration_id, data) == ref_frame_bits(arbitration_id, data)
    assert frame_bits(arbitration_id, bytearray(data)) == ref_frame_bits(arbitration_id, data)


def test_frame_bits_known_frames_and_bounds():
    # ID 0 with no data: SOF, ID, RTR, IDE, r0 and DLC are 19 dominant bits, the CRC of all
    # zeros is 0: 34 dominant bits -> a recessive stuff bit after every 5 -> 6 stuff bits
    assert ref_stuffed_frame(0, b"") == ("00000" "1") * 6 + "0000"
    assert frame_bits(0, b"") == 34 + 6 + 13 == 53
    # a stuff bit counts in the next run: ID 0x78 = 00001111000: SOF+0000 [1] 1111 [0] 000 000...
    assert ref_stuffed_frame(0x78, b"")[:16] == "00000" "1" "1111" "0" "0000" "1"
    # all-recessive data: 0x7FF with 8 x 0xFF
    assert frame_bits(0x7FF, b"\xff" * 8) == ref_frame_bits(0x7FF, b"\xff" * 8)
    rnd = random.Random(3)
    for n in range(9):
        for _ in range(200):
            bits = frame_bits(rnd.randrange(0x800), bytes(rnd.randrange(256) for _ in range(n)))
            assert 47 + 8 * n <= bits <= max_frame_bits(n)
    assert max_frame_bits(8) == 135          # 111 + 24 (Davis et al. 2007)
    # Tindell's 0..19 stuff bit bound for 8 bytes is too small: this frame has 20 stuff bits
    assert frame_bits(0x2F, bytes.fromhex("3c3c3c3c3c3c3c3c")) == 111 + 20
    assert ref_frame_bits(0x2F, bytes.fromhex("3c3c3c3c3c3c3c3c")) == 131


def test_frame_bits_rejects_bad_frames():
    with pytest.raises(ValueError, match="0..0x7FF"):
        frame_bits(0x800, b"")
    with pytest.raises(ValueError, match="at most 8"):
        frame_bits(1, bytes(9))


# -- helpers -------------------------------------------------------------------------------------
def std(arbitration_id: int, data: bytes = bytes(8)) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)


def act_id(dst: int, index: int) -> int:       # Master -> Slave actuation (slide 18)
    return (0 << 7) | (dst << 3) | (index << 2) | 0b00


def sens_id(src: int, index: int) -> int:      # Slave -> Master sensors
    return (src << 7) | (0 << 3) | (index << 2) | 0b01


class Recorder:
    """A node's RX interrupt that notes (virtual time, id, data)."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.got: list[tuple[int, int, bytes]] = []

    def __call__(self, msg: can.Message) -> None:
        assert msg.timestamp == self.clock.now_us / 1e6
        self.got.append((self.clock.now_us, msg.arbitration_id, bytes(msg.data)))


def make_net(interface: str = "humanoid_twin", n_slaves: int = 2):
    clock = Clock()
    net = CanNetwork(clock, interface=interface)
    rec = {"master": Recorder(clock)}
    nodes = {"master": net.attach("master", master_filters(), rec["master"])}
    for a in range(1, n_slaves + 1):
        rec[a] = Recorder(clock)
        nodes[a] = net.attach(f"slave{a}", slave_filters(), rec[a])
    return clock, net, nodes, rec


# -- timing ----------------------------------------------------------------------------------------
def test_frame_timing_in_virtual_time():
    clock, net, nodes, rec = make_net()
    m1, m2 = std(act_id(1, 0), bytes(range(8))), std(act_id(1, 1), b"\xff" * 8)
    b1, b2 = frame_bits(m1.arbitration_id, m1.data), frame_bits(m2.arbitration_id, m2.data)
    clock.run_until(1000)
    assert nodes["master"].send(m1) and nodes["master"].send(m2)
    clock.run_until(5000)
    # the frame is valid at the end of its EOF: start + bits - 3 (IFS) bit times of 1 us;
    # the second one starts after the first one's intermission
    assert [(t, i) for t, i, _ in rec[1].got] == [
        (1000 + b1 - 3, m1.arbitration_id), (1000 + b1 + b2 - 3, m2.arbitration_id)]
    assert rec[1].got == rec[2].got            # every slave hears the Master (slide 23 filters)
    assert rec["master"].got == []
    assert net.frames_sent == 2 and net.frames_by_node["master"] == 2
    assert net.busy_us == b1 + b2
    assert net.bus_load == pytest.approx((b1 + b2) / 5000)


def test_send_at_requests_for_a_later_instant_only_when_nothing_is_due_before():
    """A Slave answers 20 us after an actuation packet: CanController.send_at(msg, t) requests the
    frame for that instant without a clock event, and is refused when an event is due first."""
    clock, net, nodes, rec = make_net()
    clock.run_until(1000)
    slave = nodes[1]
    msg = slave.load_tx(None, sens_id(1, 0), bytes(range(8)))
    clock.schedule(1010, lambda: None)
    with pytest.raises(ValueError, match="due before"):
        slave.send_at(msg, 1020)
    assert slave.pending == 0
    assert slave.send_at(msg, 1005)                   # nothing due up to 1005
    clock.run_until(2000)
    bits = frame_bits(msg.arbitration_id, bytes(range(8)))
    assert [(t, i) for t, i, _ in rec["master"].got] == [(1005 + bits - 3, msg.arbitration_id)]


def test_clock_due_by_is_next_due_at_or_before():
    """Clock.due_by(t) (the fast paths' typed question) is next_due_us() <= t, False when empty."""
    clock = Clock()
    assert clock.next_due_us() is None and not clock.due_by(0) and not clock.due_by(10**12)
    clock.schedule(50, lambda: None)
    clock.schedule(30, lambda: None)
    assert clock.next_due_us() == 30
    assert [clock.due_by(t) for t in (29, 30, 31)] == [False, True, True]
    clock.run_until(40)
    assert clock.next_due_us() == 50 and not clock.due_by(49) and clock.due_by(50)


def test_twin_bus_deliver_is_its_port_and_counts_skips_there():
    """The wire's per-frame path is each TwinBus's RxPort (compiled with the wire): deliver takes
    the route kept for the ID after the first frame; rx_skipped is counted on the port."""
    from humanoid_twin.bus.twin_bus import RxPort, TwinBus

    got: list[tuple[str, int]] = []
    tx = TwinBus("port-test")
    a = TwinBus("port-test", rx_callback=lambda m: got.append(("a", m.arbitration_id)), rx_ids=[0x10])
    b = TwinBus("port-test", rx_callback=lambda m: got.append(("b", m.arbitration_id)))
    try:
        assert isinstance(tx.port, RxPort) and tx.port.bus is tx
        for arb in (0x10, 0x11, 0x10, 0x11):
            tx.deliver(can.Message(arbitration_id=arb, data=b"", is_extended_id=False))
        assert got == [("a", 0x10), ("b", 0x10), ("b", 0x11), ("a", 0x10), ("b", 0x10), ("b", 0x11)]
        assert a.rx_skipped == a.port.rx_skipped == 2 and b.rx_skipped == 0
        assert [i for i, r in enumerate(tx.port.routes) if r is not None] == [0x10, 0x11]
        b.set_muted(True)                              # the routes are rebuilt without b
        assert all(r is None for r in tx.port.routes)
        tx.deliver(can.Message(arbitration_id=0x10, data=b"", is_extended_id=False))
        assert got[-1] == ("a", 0x10) and len(got) == 7
    finally:
        for bus in (tx, a, b):
            bus.shutdown()


def test_clock_skip_to_only_over_nothing_and_within_the_run():
    """Clock.skip_to (the wire handles a frame's end at once): inside an event, now moves on only
    when no event is due up to the target and the target is within the run_until in progress."""
    clock = Clock()
    seen: list[tuple[str, int, bool]] = []

    def first() -> None:
        seen.append(("skip over the event at 50", clock.now_us, clock.skip_to(60)))
        seen.append(("skip to 40", clock.now_us, clock.skip_to(40)))
        seen.append(("back to 30", clock.now_us, clock.skip_to(30)))

    clock.schedule(10, first)
    clock.schedule(50, lambda: seen.append(("event", clock.now_us, True)))
    assert not clock.skip_to(5)                       # outside a run
    clock.run_until(45)
    clock.schedule(80, lambda: seen.append(("beyond the run", clock.now_us, clock.skip_to(200))))
    clock.run_until(100)
    assert seen == [("skip over the event at 50", 10, False), ("skip to 40", 10, True),
                    ("back to 30", 40, False), ("event", 50, True), ("beyond the run", 80, False)]
    assert clock.now_us == 100


def test_load_tx_checks_the_frame_once():
    clock, net, nodes, _ = make_net()
    with pytest.raises(CanError, match="0..0x7FF"):
        nodes[1].load_tx(None, 0x800, b"")
    with pytest.raises(CanError, match="0..8 data bytes"):
        nodes[1].load_tx(None, 0x100, bytes(9))


def test_a_reloaded_frame_takes_the_wire_for_its_own_length():
    """load_tx keeps a reloaded frame's length for the same ID and payload (the same bytes, or
    equal ones) and measures it again otherwise: each frame ends on the wire after its own bits
    (a zero payload needs stuff bits, 0x55 none)."""
    clock = Clock()
    net = CanNetwork(clock)
    got = []
    a = net.attach("a", None, lambda m: None)
    net.attach("b", None, lambda m: got.append(clock.now_us))
    msg = None
    zeros = bytes(8)
    for arb, payload in [(0x100, zeros), (0x100, zeros), (0x100, bytes(bytearray(8))),
                         (0x100, b"\x55" * 8), (0x101, b"\x55" * 8), (0x100, zeros)]:
        msg = a.load_tx(msg, arb, payload)
        assert msg.bits == frame_bits(arb, payload)
        start = clock.now_us
        a.send(msg)
        clock.run_until(start + 1000)
        assert got[-1] - start == frame_bits(arb, payload) - 3
    assert len(got) == 6 and frame_bits(0x100, zeros) != frame_bits(0x100, b"\x55" * 8)


def test_bitrate_scales_frame_time():
    clock = Clock()
    net = CanNetwork(clock, bitrate=125_000)     # 8 us per bit
    got = []
    a = net.attach("a", None, lambda m: None)
    net.attach("b", None, lambda m: got.append(clock.now_us))
    a.send(std(0x123, b"\x01\x02"))
    clock.run_until(10_000)
    assert got == [8 * (frame_bits(0x123, b"\x01\x02") - 3)]
    with pytest.raises(ValueError, match="bitrate"):
        CanNetwork(clock, bitrate=2_000_000)


def test_arbitration_lowest_id_wins_at_the_same_instant():
    clock, net, nodes, rec = make_net(n_slaves=3)
    # three slaves answer at the same instant; slave 3 requests first, slave 1 last
    for a in (3, 2, 1):
        clock.schedule(2000, lambda a=a: nodes[a].send(std(sens_id(a, 0), bytes([a]) * 8)))
    clock.run_until(3000)
    ids = [i for _, i, _ in rec["master"].got]
    assert ids == [sens_id(1, 0), sens_id(2, 0), sens_id(3, 0)]   # lower address = priority
    times = [t for t, _, _ in rec["master"].got]
    b = [frame_bits(sens_id(a, 0), bytes([a]) * 8) for a in (1, 2, 3)]
    assert times == [2000 + b[0] - 3, 2000 + b[0] + b[1] - 3, 2000 + b[0] + b[1] + b[2] - 3]


def test_waiting_frames_arbitrate_when_the_wire_frees():
    clock, net, nodes, rec = make_net(n_slaves=3)
    nodes[3].send(std(sens_id(3, 0)))            # on the wire at t=0
    clock.run_until(10)
    nodes[2].send(std(sens_id(2, 1)))            # waits
    clock.run_until(20)
    nodes[1].send(std(sens_id(1, 1)))            # waits, requested later but lower ID
    clock.run_until(2000)
    assert [i for _, i, _ in rec["master"].got] == [sens_id(3, 0), sens_id(1, 1), sens_id(2, 1)]
    b3 = frame_bits(sens_id(3, 0), bytes(8))
    assert rec["master"].got[1][0] == b3 + frame_bits(sens_id(1, 1), bytes(8)) - 3


# -- filters, buffers, abort -------------------------------------------------------------------------
def test_slide23_filters_route_frames():
    clock, net, nodes, rec = make_net(n_slaves=2)
    nodes["master"].send(std(act_id(2, 1)))
    clock.run_until(500)
    nodes[2].send(std(sens_id(2, 1)))
    clock.run_until(1000)
    nodes[1].send(std((1 << 7) | (2 << 3) | 0b01))   # slave -> slave: nobody takes it
    clock.run_until(1500)
    assert [i for _, i, _ in rec[1].got] == [act_id(2, 1)]      # slaves take every Master frame
    assert [i for _, i, _ in rec[2].got] == [act_id(2, 1)]
    assert [i for _, i, _ in rec["master"].got] == [sens_id(2, 1)]
    assert net.frames_sent == 3                   # the unreceived frame still used the wire


def test_rx_ids_hand_over_only_those_frames_and_count_the_others():
    clock = Clock()
    net = CanNetwork(clock)
    got: list[int] = []
    master = net.attach("master", master_filters(), None)
    mine = act_id(2, 0), act_id(2, 1)
    slave = net.attach("slave2", slave_filters(), lambda m: got.append(m.arbitration_id), rx_ids=mine)
    for i, ident in enumerate((act_id(1, 0), act_id(2, 0), act_id(3, 1), act_id(2, 1), act_id(1, 0))):
        clock.run_until(500 * (i + 1))
        assert master.send(std(ident))
    clock.run_until(5000)
    assert got == [act_id(2, 0), act_id(2, 1)]     # the interrupt runs for its own two IDs only
    assert slave.rx_skipped == 3                   # the three others: let in and counted
    net.force_bus_off("slave2")                    # a bus-off node takes nothing, counts nothing
    master.send(std(act_id(1, 0)))
    clock.run_until(6000)
    assert slave.rx_skipped == 3 and len(got) == 2


def test_three_tx_buffers_fourth_request_refused():
    clock, net, nodes, rec = make_net(n_slaves=1)
    s = nodes[1]
    assert [s.send(std(sens_id(1, i % 2))) for i in range(4)] == [True, True, True, False]
    assert s.tx_refused == 1 and s.pending == 3
    clock.run_until(1000)
    assert len(rec["master"].got) == 3 and s.pending == 0
    assert s.send(std(sens_id(1, 0)))


def test_abort_drops_pending_frames_not_the_one_on_the_wire():
    clock, net, nodes, rec = make_net(n_slaves=2)
    nodes[1].send(std(sens_id(1, 0)))             # starts at 0
    nodes[2].send(std(sens_id(2, 0)))             # pending behind it
    clock.run_until(50)
    assert nodes[1].abort() == 0                  # its frame is already on the wire
    assert nodes[2].abort() == 1
    clock.run_until(1000)
    assert [i for _, i, _ in rec["master"].got] == [sens_id(1, 0)]
    assert nodes[2].tx_aborted == 1 and nodes[2].pending == 0


def test_invalid_frames_are_refused_with_a_clear_error():
    clock, net, nodes, _ = make_net(n_slaves=1)
    with pytest.raises(CanError, match="is_extended_id=False"):
        nodes[1].send(can.Message(arbitration_id=0x81, data=b"\x00"))      # python-can default: 29 bit
    with pytest.raises(CanError, match="standard"):
        nodes[1].send(can.Message(arbitration_id=0x81, is_remote_frame=True, is_extended_id=False))
    with pytest.raises(CanError, match="dlc"):
        nodes[1].send(can.Message(arbitration_id=0x81, data=b"\x00", dlc=8, is_extended_id=False))
    with pytest.raises(ValueError, match="already attached"):
        net.attach("slave1", None, lambda m: None)
    with pytest.raises(ValueError, match="can_mask"):
        net.attach("x", [{"can_id": 1}], lambda m: None)
    with pytest.raises(ValueError, match="unknown python-can interface"):
        CanNetwork(clock, interface="no-such-bus")
    with pytest.raises(ValueError, match="already belongs"):
        CanNetwork(clock, channel=net.channel)
    assert nodes[1].pending == 0


# -- error confinement ------------------------------------------------------------------------------
def test_error_states_bus_off_and_recovery():
    clock, net, nodes, rec = make_net(n_slaves=2)
    m, s1, s2 = nodes["master"], nodes[1], nodes[2]
    errors = can.BufferedReader()
    net.add_listener(errors)
    net.set_faults(corrupt_prob=1.0, seed=1)      # every frame is destroyed by an error frame
    m.send(std(act_id(1, 0)))
    states = []
    for _ in range(40):
        clock.run_for(200)                         # ~one retransmission per 130 us
        states.append((m.tec, m.state))
    t_err = []
    while (e := errors.get_message(0)) is not None:
        assert e.is_error_frame
        t_err.append(round(e.timestamp * 1e6))
    # an error frame takes frame_bits + 7 bits; error-passive (from the 16th error) adds the
    # 8-bit suspend transmission before each retransmission
    bits = frame_bits(act_id(1, 0), bytes(8))
    gaps = [b - a for a, b in zip(t_err, t_err[1:], strict=False)]
    assert gaps == [bits + 7] * 15 + [bits + 7 + 8] * 16
    # TEC +8 per error: passive past 127 (16 errors), bus-off past 255 (32 errors)
    assert (128, ERROR_PASSIVE) in states and (120, ERROR_ACTIVE) in states
    assert m.state == BUS_OFF and m.tx_errors == 32 and net.error_frames == 32
    assert s1.rec == 32 and s2.rec == 32 and s1.state == ERROR_ACTIVE
    assert rec[1].got == [] and m.pending == 0     # nobody received; TX buffers cleared
    assert not m.send(std(act_id(1, 0)))          # bus-off: no transmission
    # a bus-off node receives nothing either
    net.set_faults(0.0, 0.0)
    s1.send(std(sens_id(1, 0)))
    clock.run_for(1000)
    assert rec["master"].got == []
    assert s2.rec == 31 and s1.rec == 32           # successful frame: receivers REC -1
    # recovery: 128 x 11 recessive bits after canClearStatus; the wire is idle meanwhile
    t0 = clock.now_us
    m.clear_status()
    assert m.recovering and m.state == BUS_OFF
    clock.run_until(t0 + 128 * 11 - 1)
    assert m.state == BUS_OFF
    clock.run_until(t0 + 128 * 11)
    assert (m.state, m.tec, m.rec, m.recovering) == (ERROR_ACTIVE, 0, 0, False)
    assert m.send(std(act_id(1, 0)))
    clock.run_for(500)
    assert [i for _, i, _ in rec[1].got] == [act_id(1, 0)]


def test_recovery_is_slower_on_a_busy_wire_and_force_bus_off():
    clock, net, nodes, rec = make_net(n_slaves=2)
    net.force_bus_off("slave2")
    s2 = nodes[2]
    assert s2.state == BUS_OFF and s2.error_state_code == 2
    s2.clear_status()
    t0 = clock.now_us
    # the Master keeps the wire busy: a frame every 250 us, each giving one run of recessive bits
    clock.call_every(250, lambda: nodes["master"].send(std(act_id(1, 0))), first_us=t0)
    while s2.recovering:
        clock.run_for(50)
    busy_time = clock.now_us - t0
    assert busy_time > 128 * 11 + 250
    n_frames_seen = len(rec[1].got)
    # each 250 us slot holds the frame's 11 trailing recessive bits plus ~130 idle bits: ~12 runs
    assert 8 <= n_frames_seen <= 14
    clock.run_for(1000)
    assert len(rec[2].got) >= 3                    # back on the bus, receiving


def test_clear_status_resets_counters_when_not_bus_off():
    clock, net, nodes, _ = make_net(n_slaves=1)
    net.set_faults(corrupt_prob=1.0, seed=0)
    nodes[1].send(std(sens_id(1, 0)))
    clock.run_for(130 * 3)
    assert nodes[1].tec == 24 and nodes["master"].rec == 3
    nodes[1].clear_status()
    assert nodes[1].tec == 0 and nodes[1].state == ERROR_ACTIVE


def test_fault_injection_is_deterministic_per_seed():
    def run(seed: int) -> tuple:
        clock, net, nodes, rec = make_net(n_slaves=1)
        net.set_faults(drop_prob=0.2, corrupt_prob=0.1, seed=seed)
        clock.call_every(250, lambda: nodes["master"].send(std(act_id(1, 0))), first_us=0)
        clock.run_until(50_000)
        return tuple(rec[1].got), net.frames_dropped, net.error_frames, nodes["master"].tec

    a, b, c = run(7), run(7), run(8)
    assert a == b and a != c
    got, dropped, errors, tec = a
    assert 200 > len(got) > 100 and dropped > 20 and errors > 5


def test_silenced_node_stops_transmitting_but_still_receives():
    clock, net, nodes, rec = make_net(n_slaves=2)
    net.silence("slave1")
    nodes[1].send(std(sens_id(1, 0)))
    nodes[2].send(std(sens_id(2, 0)))
    nodes["master"].send(std(act_id(1, 0)))
    clock.run_until(2000)
    assert [i for _, i, _ in rec["master"].got] == [sens_id(2, 0)]
    assert [i for _, i, _ in rec[1].got] == [act_id(1, 0)]
    assert nodes[1].pending == 1                   # stuck in its TX buffer
    net.silence("slave1", False)
    clock.run_until(3000)
    assert [i for _, i, _ in rec["master"].got] == [sens_id(2, 0), sens_id(1, 0)]


# -- other interfaces, tools, logs ---------------------------------------------------------------
def _exchange(interface: str) -> dict:
    clock = Clock()
    net = CanNetwork(clock, interface=interface)
    rec = {k: Recorder(clock) for k in ("master", 1, 2)}
    nodes = {"master": net.attach("master", master_filters(), rec["master"])}

    def slave_answer(a: int):
        def on_rx(msg: can.Message) -> None:
            rec[a](msg)
            if (msg.arbitration_id >> 3) & 0xF == a:
                nodes[a].abort()
                nodes[a].send(std(sens_id(a, (msg.arbitration_id >> 2) & 1), bytes([a, 0xFF]) * 4))
        return on_rx

    for a in (1, 2):
        nodes[a] = net.attach(f"slave{a}", slave_filters(), slave_answer(a))
    master = nodes["master"]
    for k, (a, idx) in enumerate([(1, 0), (1, 1), (2, 0), (2, 1)]):
        clock.schedule(250 * k, lambda a=a, idx=idx: master.send(std(act_id(a, idx), bytes([a, idx]) * 4)))
    clock.run_until(2000)
    net.shutdown()
    return {k: v.got for k, v in rec.items()}


def test_virtual_interface_gives_the_same_delivery_times():
    twin = _exchange("humanoid_twin")
    virt = _exchange("virtual")
    assert twin == virt
    assert len(twin["master"]) == 4 and len(twin[1]) == 4


@pytest.mark.skipif(not os.path.exists("/sys/class/net/vcan0"),
                    reason="no vcan0 here (ip link add dev vcan0 type vcan; ip link set up vcan0)")
def test_socketcan_interface_gives_the_same_delivery_times():  # pragma: no cover - needs vcan0
    clock, net, nodes, rec = make_net("socketcan", n_slaves=1)
    nodes["master"].send(std(act_id(1, 0)))
    clock.run_until(1000)
    net.shutdown()
    assert rec[1].got == [(frame_bits(act_id(1, 0), bytes(8)) - 3, act_id(1, 0), bytes(8))]


def test_python_can_tool_joins_the_channel():
    clock, net, nodes, rec = make_net(n_slaves=1)
    tool = can.Bus(interface="humanoid_twin", channel=net.channel)            # everything
    picky = can.Bus(interface="humanoid_twin", channel=net.channel,
                    can_filters=[{"can_id": sens_id(1, 0), "can_mask": 0x7FF}])
    try:
        nodes["master"].send(std(act_id(1, 0)))
        clock.run_until(300)
        nodes[1].send(std(sens_id(1, 0)))
        clock.run_until(600)
        seen = [tool.recv(timeout=0), tool.recv(timeout=0), tool.recv(timeout=0)]
        assert [m.arbitration_id for m in seen[:2]] == [act_id(1, 0), sens_id(1, 0)] and seen[2] is None
        assert seen[0].timestamp == (frame_bits(act_id(1, 0), bytes(8)) - 3) / 1e6
        assert seen[0].channel == net.channel
        assert picky.recv(timeout=0).arbitration_id == sens_id(1, 0) and picky.recv(timeout=0) is None
        # a frame the tool sends goes through the wire in virtual time, like a node's
        t0 = clock.now_us
        tool.send(std(act_id(1, 1), b"\x42"))
        assert rec[1].got[-1][1] == act_id(1, 0)                            # not delivered yet
        clock.run_for(200)
        assert rec[1].got[-1] == (t0 + frame_bits(act_id(1, 1), b"\x42") - 3, act_id(1, 1), b"\x42")
    finally:
        tool.shutdown()
        picky.shutdown()
    with pytest.raises(can.CanOperationError):
        tool.send(std(1))


def test_python_can_sees_messages_and_the_nodes_the_wires_frames():
    """The wire carries its own frame record between its nodes (load_tx's Frame, python-can's
    attribute names); a listener, a tool's recv() and a tool's rx_callback get can.Message
    objects with the same id, bytes, virtual timestamp and channel."""
    from humanoid_twin.bus.frames import Frame
    from humanoid_twin.bus.twin_bus import TwinBus

    class Sink(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            got.append(("listener", msg))

    clock, net, nodes, rec = make_net(n_slaves=1)
    got: list[tuple[str, object]] = []
    net.add_listener(Sink())
    net.attach("isr", None, lambda m: got.append(("isr", m)))
    tool = TwinBus(net.channel, rx_callback=lambda m: got.append(("tool", m)))
    reader = can.Bus(interface="humanoid_twin", channel=net.channel)
    try:
        frame = nodes[1].load_tx(None, sens_id(1, 1), b"\x10\x20\x30")
        assert nodes[1].send(frame)
        clock.run_until(500)
        got.append(("recv", reader.recv(timeout=0)))
        t = (frame_bits(sens_id(1, 1), b"\x10\x20\x30") - 3) / 1e6
        kinds = {k: type(m) for k, m in got}
        assert kinds == {"isr": Frame, "listener": can.Message, "tool": can.Message, "recv": can.Message}
        assert dict(got)["isr"] is frame
        for _, m in got:
            assert (m.arbitration_id, bytes(m.data), m.dlc, m.timestamp, m.channel, m.is_extended_id) == (
                sens_id(1, 1), b"\x10\x20\x30", 3, t, net.channel, False)
    finally:
        tool.shutdown()
        reader.shutdown()


def test_standalone_channel_without_network_delivers_immediately():
    a = can.Bus(interface="humanoid_twin", channel="standalone-test")
    b = can.Bus(interface="humanoid_twin", channel="standalone-test",
                can_filters=[{"can_id": 0x100, "can_mask": 0x700}])
    try:
        a.send(std(0x123, b"\x01"))
        a.send(std(0x223, b"\x02"))
        assert b.recv(timeout=0).data == b"\x01" and b.recv(timeout=0) is None
        assert a.recv(timeout=0) is None                  # no own messages by default
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.parametrize("suffix", [".asc", ".log"])
def test_logger_writes_virtual_timestamps(tmp_path, suffix):
    clock, net, nodes, rec = make_net(n_slaves=1)
    path = tmp_path / f"trace{suffix}"
    logger = can.Logger(str(path))
    net.add_listener(logger)
    buffered = can.BufferedReader()
    net.add_listener(buffered)
    for k in range(4):
        clock.schedule(250 * k, lambda k=k: nodes["master"].send(std(act_id(1, k % 2), bytes([k]) * 8)))
        clock.schedule(250 * k + 200, lambda k=k: nodes[1].send(std(sens_id(1, k % 2), bytes([k]) * 8)))
    clock.run_until(1200)
    logger.stop()
    live = []
    while (m := buffered.get_message(0)) is not None:
        live.append(m)
    assert len(live) == 8 and [m.timestamp for m in live] == sorted(m.timestamp for m in live)
    assert live[0].timestamp == (frame_bits(act_id(1, 0), bytes(8)) - 3) / 1e6
    assert {m.channel for m in live} == {net.channel}
    back = list(can.LogReader(str(path)))
    assert [(m.arbitration_id, bytes(m.data)) for m in back] == [
        (m.arbitration_id, bytes(m.data)) for m in live]
    t_live = [m.timestamp for m in live]
    t_back = [m.timestamp for m in back]
    if suffix == ".asc":           # ASC stores times relative to the first frame
        t_live = [t - t_live[0] for t in t_live]
    assert t_back == pytest.approx(t_live, abs=1e-6)
