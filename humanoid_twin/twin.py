"""The whole twin in one object: plant, buses, Master, 8 Slaves, on one lockstep clock.

    twin = Twin(seed=0)
    port = twin.open_port()          # pyserial Serial on "twin://<name>", same API as a real port
    port.write(frame); port.read(6)  # reading advances virtual time (lockstep)

The same host code drives a real robot: only the pyserial URL changes.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping
from pathlib import Path

import serial

from humanoid_twin.bus.network import CanNetwork
from humanoid_twin.bus.protocol_twin import register_link, unregister_link
from humanoid_twin.bus.serial_link import SerialLink
from humanoid_twin.clock import US_PER_S, Clock, RealTimePacer
from humanoid_twin.cycles import DEFAULT_PIC_MHZ
from humanoid_twin.hardware import PWM_PERIOD_US
from humanoid_twin.master.master import Master
from humanoid_twin.master.pic import TIMER_PERIOD_US
from humanoid_twin.master.supervisor import SupervisorConfig
from humanoid_twin.plant import Plant
from humanoid_twin.protocol.wire import LINE_SETTINGS, N_SCU, SCUS
from humanoid_twin.seeds import STREAM_PHASES, derive_seed
from humanoid_twin.signals import check as check_signal
from humanoid_twin.slave.slave import Slave

_names = itertools.count()


class Twin:
    """Plant + Master + 8 Slaves + CAN + RS-232 on one virtual clock."""

    def __init__(
        self,
        *,
        seed: int = 0,
        model_path: str | Path | None = None,
        can_interface: str = "humanoid_twin",
        can_channel: str | None = None,
        name: str | None = None,
        supervisor: SupervisorConfig | None = None,
        pic_mhz: float = DEFAULT_PIC_MHZ,
        params: Mapping[str, float] | None = None,
        master: bool = True,
        phases_us: Mapping[int, int] | None = None,
    ) -> None:
        self.seed = seed
        self.clock = Clock()
        # physics time is the clock's: the plant steps itself before any read or write. ``params``
        # (humanoid_twin/params.py): the plant takes the model's and the sensors' (checked there)
        self.plant = Plant(model_path, seed=seed, clock=self.clock, params=params)
        # the Slaves' clock (the Master's: DEFAULT_PIC_MHZ, docs/firmware.md): the parameter
        # pic_mhz when given, else the argument
        self.pic_mhz = pic_mhz = self.plant.params.get("pic_mhz", pic_mhz)
        # the non-default parameters this twin runs with (what every output records)
        self.params: dict[str, float] = dict(sorted(
            {**self.plant.params, **({"pic_mhz": pic_mhz} if pic_mhz != DEFAULT_PIC_MHZ else {})}.items()))
        self.network = CanNetwork(self.clock, interface=can_interface, channel=can_channel)
        self.link = SerialLink(self.clock)
        # ``master=False``: no Master board on the wire; something else stands in for it (a CAN
        # log's player: humanoid_twin/compare/, ``humanoid-twin compare``)
        self.master: Master | None = (Master(self.clock, self.network, self.link, supervisor)
                                      if master else None)
        # Slave PWM periods are not synchronised on the robot: each board starts its 20 ms
        # period at its own phase, drawn from the seed (docs/firmware.md); ``phases_us`` (SCU ->
        # us) sets some or all of them instead (a robot's, read from its CAN log: ``compare``)
        self.phases_us: dict[int, int] = seed_phases(seed)
        for scu, p in (phases_us or {}).items():
            if scu not in self.phases_us:
                raise ValueError(f"phases_us: no Slave {scu!r} (the SCUs are {SCUS[0]}..{SCUS[-1]})")
            self.phases_us[scu] = int(p) % PWM_PERIOD_US
        self.slaves: dict[int, Slave] = {
            scu: Slave(scu, self.clock, self.plant, self.network, phase_us=self.phases_us[scu],
                       pic_mhz=pic_mhz)
            for scu in SCUS
        }
        self.name = name or f"twin{next(_names)}"
        self.url = f"twin://{self.name}"
        register_link(self.name, self.link, self.advance_to)
        self._closed = False

    # -- time ---------------------------------------------------------------------------
    @property
    def now_s(self) -> float:
        """Virtual time in seconds."""
        return self.clock.now_us / US_PER_S

    def advance_to(self, t_us: int) -> None:
        """Run every board and bus up to virtual time ``t_us``, then bring the physics there.

        The one way to move the whole twin in time (the serial port's lockstep reads, ``run``,
        ``serve``); the plant also runs its due physics itself before any read or write. A
        signal that user code swallowed is raised again here (humanoid_twin/signals.check).
        """
        check_signal()
        self.clock.run_until(t_us)
        self.plant.advance_to(t_us)

    def the_master(self) -> Master:
        """The Master board; ``RuntimeError`` for a twin built with ``master=False`` (a CAN log's
        player stands in for it). What a rig, a recording or a summary reads the Master through."""
        if self.master is None:
            raise RuntimeError("this twin has no Master board (built with master=False)")
        return self.master

    def run_for(self, seconds: float) -> None:
        """Advance the whole twin by ``seconds`` of virtual time."""
        self.advance_to(self.clock.now_us + round(seconds * US_PER_S))

    def run_realtime_step(self, pacer: RealTimePacer, max_step_us: int = 1_000) -> float:
        """Advance toward wall time by at most ``max_step_us`` (the ``serve`` loop); returns the lag in s."""
        return pacer.pace(max_step_us, advance_to=self.advance_to)

    def every(self, period_us: int, callback: Callable[[], None], first_us: int | None = None) -> None:
        """Call ``callback`` periodically in virtual time (recording, supervisors, tilt profiles)."""
        self.clock.call_every(period_us, callback, first_us)

    # -- host side ----------------------------------------------------------------------
    def open_port(self, timeout: float = 0.2) -> serial.Serial:
        """Open the host end of the RS-232 link, as pyserial sees a real port (115200 8E1)."""
        return serial.serial_for_url(self.url, timeout=timeout, **LINE_SETTINGS)

    def close(self) -> None:
        """Detach the link from the URL registry and shut the CAN buses down."""
        if self._closed:
            return
        self._closed = True
        unregister_link(self.name)
        self.network.shutdown()

    def __enter__(self) -> Twin:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _phases(seed: int) -> list[int]:
    """Deterministic per-seed PWM phase of each Slave, in microseconds within one period, on the
    Master's timer grid (250 us)."""
    import random

    rng = random.Random(derive_seed(seed, STREAM_PHASES))
    return [rng.randrange(0, PWM_PERIOD_US, TIMER_PERIOD_US) for _ in range(N_SCU)]


def seed_phases(seed: int) -> dict[int, int]:
    """The PWM phase (us) each Slave of a twin of ``seed`` starts at, SCU -> us (``Twin.phases_us``
    when no ``phases_us`` is given)."""
    return dict(zip(SCUS, _phases(seed), strict=True))
