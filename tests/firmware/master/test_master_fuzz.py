"""The Master's serial receiver under arbitrary bytes (hypothesis, fast): no exception, a bounded
receive buffer, and after any garbage and the 2 ms break-off gap a clean request gets exactly its
own answer. Real Clock, SerialLink, CanNetwork and Master; nothing mocked."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_twin.bus.network import CanNetwork
from humanoid_twin.bus.serial_link import SerialLink
from humanoid_twin.clock import Clock
from humanoid_twin.master import Master
from humanoid_twin.master.usart import FRAME_GAP_US, PROCESS_US
from humanoid_twin.protocol.rs232 import FRAME_LEN, PARAM_TEST, TEST_MESSAGE, Op, encode_request

TEST_REQUEST = encode_request(Op.MASTER, 0, PARAM_TEST)
BYTE_US = math.ceil(11 * 1_000_000 / 115_200)

# garbage rich in 0xFF (start of frame) and in valid-looking frames, so that resync paths run
_garbage = st.lists(
    st.one_of(st.binary(min_size=1, max_size=12), st.just(b"\xff"), st.just(bytes.fromhex("FF045A5A04")),
              st.just(TEST_REQUEST)),
    max_size=30,
).map(b"".join)


class _Rig:
    def __init__(self) -> None:
        self.clock = Clock()
        self.net = CanNetwork(self.clock)
        self.link = SerialLink(self.clock)
        self.master = Master(self.clock, self.net, self.link)


_RIG = _Rig()     # one Master for every example: state left by earlier garbage is part of the test


@settings(max_examples=300, deadline=None, derandomize=True)
@given(garbage=_garbage)
def test_any_garbage_then_the_gap_then_a_clean_request_is_answered_exactly(garbage):
    rig = _RIG
    rig.link.host_write(garbage)
    # the garbage's own line time, its answers, then more than the break-off gap
    rig.clock.run_for(len(garbage) * BYTE_US + 2 * (6 * BYTE_US + PROCESS_US) * (1 + len(garbage) // 6)
                      + FRAME_GAP_US + 1_000)
    rig.link.host_read_available()
    assert 0 <= rig.master.usart.rx_len <= FRAME_LEN
    rig.link.host_write(TEST_REQUEST)
    rig.clock.run_for(12 * BYTE_US + PROCESS_US + 200)
    assert rig.link.host_read_available() == TEST_MESSAGE
