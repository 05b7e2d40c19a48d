"""The RS-232 cable: byte timing (11 bits at 115200), full duplex, twin:// through pyserial,
virtual timeouts, noise, and the pty / TCP bridges with real pyserial clients. No mocks."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
import serial

import humanoid_twin.bus  # noqa: F401  (registers twin://)
from humanoid_twin.bus import PtyBridge, SerialLink, TcpBridge, register_link, unregister_link
from humanoid_twin.clock import Clock, RealTimePacer


def stop_bit_us(n: int, baud: int = 115200) -> int:
    """ceil(n * 11e6 / baud), the rule, computed with integers."""
    return -(-n * 11_000_000 // baud)


def echo_link(clock: Clock) -> tuple[SerialLink, list[tuple[int, int]]]:
    """A link whose device side (a tiny test device on the real link) echoes every byte."""
    link = SerialLink(clock)
    seen: list[tuple[int, int]] = []

    def device_rx(b: int) -> None:
        seen.append((clock.now_us, b))
        link.device_write(bytes([b]))

    link.set_device_rx(device_rx)
    return link, seen


def test_byte_timing_eleven_bits_at_115200():
    clock = Clock()
    link, seen = echo_link(clock)
    clock.run_until(1000)
    link.host_write(b"\xff\x08\x00\x00\x46\x4e")         # a 6-byte request
    clock.run_until(5000)
    assert [t - 1000 for t, _ in seen] == [stop_bit_us(n) for n in range(1, 7)]
    assert [t - 1000 for t, _ in seen] == [96, 191, 287, 382, 478, 573]    # 6*11/115200 s = 572.9 us
    assert bytes(b for _, b in seen) == b"\xff\x08\x00\x00\x46\x4e"
    assert link.bytes_to_device == 6 and link.bytes_to_host == 6


def test_bytes_queue_behind_a_busy_line_and_directions_are_independent():
    clock = Clock()
    link = SerialLink(clock)
    got: list[int] = []
    link.set_device_rx(lambda b: got.append(clock.now_us))
    link.host_write(b"abc")
    clock.run_until(50)                                # line still busy with byte 1
    link.host_write(b"def")                            # queues behind: one burst of 6
    link.device_write(b"xyz")                          # the other direction starts at once
    clock.run_until(10_000)
    assert got == [stop_bit_us(n) for n in range(1, 7)]
    # host side: bytes become readable at their stop bits, starting at t=50
    link.device_write(b"")                             # nothing: no effect
    assert link.host_read_available() == b"xyz"
    clock2 = Clock()
    link2 = SerialLink(clock2)
    link2.device_write(b"xyz")
    clock2.run_until(stop_bit_us(2) - 1)
    assert link2.host_read_available() == b"x"
    assert link2.next_host_byte_us() == stop_bit_us(2)
    clock2.run_until(stop_bit_us(3))
    assert link2.host_read_available() == b"yz"
    # a new burst starts when the line was idle
    clock2.run_until(10_000)
    link2.device_write(b"q")
    assert link2.next_host_byte_us() == 10_000 + 96


def test_other_baudrates_and_bad_input():
    clock = Clock()
    link = SerialLink(clock, baudrate=9600)
    got = []
    link.set_device_rx(lambda b: got.append(clock.now_us))
    link.host_write(bytearray(b"ab"))
    clock.run_until(100_000)
    assert got == [-(-11_000_000 // 9600), -(-22_000_000 // 9600)]    # 1146, 2292 us
    with pytest.raises(TypeError, match="bytes"):
        link.host_write("text")                         # type: ignore[arg-type]
    with pytest.raises(ValueError, match="baudrate"):
        SerialLink(clock, baudrate=0)
    with pytest.raises(ValueError, match="parity"):
        SerialLink(clock, parity="X")
    assert SerialLink(clock, parity="N").bits_per_byte == 10


def test_noise_flips_bits_deterministically():
    def run(seed: int) -> bytes:
        clock = Clock()
        link, seen = echo_link(clock)
        link.set_noise(0.2, seed=seed)
        link.host_write(bytes(range(200)))
        clock.run_until(100_000)
        return link.host_read_available(), link.bytes_corrupted

    (a, na), (b, nb), (c, _) = run(1), run(1), run(2)
    assert a == b and na == nb and a != c
    wrong = [x ^ y for x, y in zip(a, bytes(range(200)), strict=True) if x != y]
    assert 40 <= na <= 120 and 0 < len(wrong) <= na          # corrupted in either direction
    assert all(bin(w).count("1") <= 2 for w in wrong)         # one bit per pass, two passes
    with pytest.raises(ValueError, match="probability"):
        SerialLink(Clock()).set_noise(1.5)


# -- twin:// ----------------------------------------------------------------------------------------
@pytest.fixture
def echo_url():
    clock = Clock()
    link, seen = echo_link(clock)
    register_link("echo-test", link, clock.run_until)
    yield clock, link, seen
    unregister_link("echo-test")


def test_twin_url_reads_advance_virtual_time(echo_url):
    clock, link, seen = echo_url
    ser = serial.serial_for_url("twin://echo-test", baudrate=115200, parity="E", timeout=0.5)
    try:
        t0 = clock.now_us
        assert ser.write(b"\xfa\xf9\xf8\xf7\xf6\xf5") == 6
        assert ser.in_waiting == 0
        assert ser.read(6) == b"\xfa\xf9\xf8\xf7\xf6\xf5"
        # the last echoed byte leaves the device when the 6th request byte arrived (573 us)
        # and queues behind the echoes before it: its stop bit is 96 + 573 us after t0
        assert clock.now_us - t0 == stop_bit_us(1) + stop_bit_us(6)
        assert ser.virtual_time_s() == clock.now_us / 1e6
        ser.sleep(0.01)
        assert clock.now_us - t0 == stop_bit_us(1) + stop_bit_us(6) + 10_000
    finally:
        ser.close()


def test_host_byte_us_and_a_read_advances_once_to_its_last_byte():
    """A twin:// read of n bytes already on their way advances the twin once, to the stop bit of
    the n-th (SerialLink.host_byte_us), and ends at the instant byte-by-byte advancing would."""
    clock = Clock()
    link = SerialLink(clock)
    assert link.host_byte_us(1) is None
    link.device_write(b"abcdef")
    assert [link.host_byte_us(n) for n in (1, 4, 6, 9)] == [stop_bit_us(n) for n in (1, 4, 6, 6)]
    targets: list[int] = []

    def advance(t: int) -> None:
        targets.append(t)
        clock.run_until(t)

    register_link("read-once", link, advance)
    try:
        with serial.serial_for_url("twin://read-once", baudrate=115200, parity="E", timeout=1.0) as port:
            assert port.read(4) == b"abcd"
            assert targets == [stop_bit_us(4)] and clock.now_us == stop_bit_us(4)
            assert port.read(2) == b"ef" and targets[-1] == clock.now_us == stop_bit_us(6)
    finally:
        unregister_link("read-once")


def test_twin_url_virtual_timeout_returns_short(echo_url):
    clock, link, seen = echo_url
    ser = serial.serial_for_url("twin://echo-test", baudrate=115200, parity="E", timeout=0.5)
    try:
        ser.write(b"abc")
        wall = time.perf_counter()
        t0 = clock.now_us
        assert ser.read(10) == b"abc"
        assert clock.now_us - t0 == 500_000                # exactly the virtual timeout
        assert time.perf_counter() - wall < 2.0            # and not 0.5 s of wall time per se
        ser.timeout = 0
        ser.write(b"d")
        assert ser.read(1) == b""                           # non-blocking: nothing yet
        ser.sleep(0.001)
        assert ser.in_waiting == 1
        ser.reset_input_buffer()
        assert ser.in_waiting == 0
        ser.write(b"0123456789")
        ser.sleep(0.0002)             # 200 us: bytes 1-2 sent, byte 3 shifting out (191..287 us)
        ser.reset_output_buffer()     # the byte being shifted completes, the rest never leaves
        ser.sleep(0.01)
        assert bytes(b for _, b in seen[-4:]) == b"d012"
    finally:
        ser.close()


def test_twin_url_errors(echo_url):
    with pytest.raises(serial.SerialException, match="no twin link registered"):
        serial.serial_for_url("twin://nobody", baudrate=115200, parity="E")
    ser = serial.serial_for_url("twin://echo-test", baudrate=115200, parity="E")
    try:
        with pytest.raises(serial.SerialException, match="already open"):
            serial.serial_for_url("twin://echo-test", baudrate=115200, parity="E")
        ser.baudrate = 9600
        with pytest.raises(serial.SerialException, match="115200"):
            ser.write(b"x")
        ser.baudrate = 115200
        ser.write(b"x")
    finally:
        ser.close()
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("twin://echo-test?speed=2", baudrate=115200, parity="E")
    ser = serial.serial_for_url("twin://echo-test", baudrate=115200, parity="E")   # reopen works
    ser.close()
    with pytest.raises(ValueError, match="name"):
        register_link("a/b", SerialLink(Clock()), lambda t: None)


# -- bridges ------------------------------------------------------------------------------------------
CLIENT = r"""
import sys, serial
s = serial.Serial(sys.argv[1], 115200, parity=serial.PARITY_EVEN, timeout=4)
s.write(bytes.fromhex(sys.argv[2]))
print(s.read(len(sys.argv[2]) // 2).hex(), flush=True)
s.close()
"""


def paced_loop(clock: Clock, bridge, done, wall_limit: float = 8.0) -> None:
    pacer = RealTimePacer(clock)
    pacer.start()
    t_end = time.monotonic() + wall_limit
    while not done() and time.monotonic() < t_end:
        bridge.poll()
        pacer.pace()
        bridge.poll()
        time.sleep(0.0005)


def test_pty_bridge_with_a_pyserial_client_in_a_subprocess():
    clock = Clock()
    link, seen = echo_link(clock)
    payload = "ff08000046" + "4e" + "00ff"
    with PtyBridge(link) as bridge:
        assert bridge.port_name.startswith("/dev/")
        proc = subprocess.Popen([sys.executable, "-c", CLIENT, bridge.port_name, payload],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            paced_loop(clock, bridge, lambda: proc.poll() is not None)
            out, err = proc.communicate(timeout=5)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert proc.returncode == 0, err
    assert out.strip() == payload
    assert bytes(b for _, b in seen) == bytes.fromhex(payload)
    # each byte reached the device at least one character time (95.5 us) after the previous one
    times = [t for t, _ in seen]
    assert all(b - a >= 95 for a, b in zip(times, times[1:], strict=False))
    assert bridge.bytes_in == 8 and bridge.bytes_out == 8


def test_tcp_bridge_with_pyserial_socket_url():
    clock = Clock()
    link, seen = echo_link(clock)
    with TcpBridge(link) as bridge:
        assert bridge.port_name.startswith("socket://127.0.0.1:")
        client = serial.serial_for_url(bridge.port_name, timeout=0)
        got = bytearray()
        try:
            client.write(b"\xfa\x01\x02\x03")
            paced_loop(clock, bridge, lambda: (got.extend(client.read(64)), len(got) >= 4)[1], 5.0)
        finally:
            client.close()
        assert bytes(got) == b"\xfa\x01\x02\x03"
        assert bridge.clients_served == 1
        # the client hung up: the bridge serves the next one
        paced_loop(clock, bridge, lambda: not bridge.connected, 2.0)
        assert not bridge.connected
        client2 = serial.serial_for_url(bridge.port_name, timeout=0)
        got2 = bytearray()
        try:
            client2.write(b"\x55")
            paced_loop(clock, bridge, lambda: (got2.extend(client2.read(64)), len(got2) >= 1)[1], 5.0)
        finally:
            client2.close()
        assert bytes(got2) == b"\x55" and bridge.clients_served == 2
