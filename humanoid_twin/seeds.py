"""How a run's one ``--seed`` gives each of its random streams a seed of its own.

The twin draws from several independent streams (the Slaves' PWM phases, the CAN wire's faults,
the serial link's noise); each is seeded from the run's seed and a stream number, so one seed
fixes every stream. The plant spawns its own streams from the
run's seed (``numpy.random.SeedSequence``).
"""

from __future__ import annotations

__all__ = ["SEED_MAX", "STREAM_PHASES", "STREAM_SERIAL_NOISE", "derive_seed"]

SEED_MAX = 2**32 - 1        # a run's seed is 0..2**32-1 (numpy's range): --seed, a serial log's meta

_STRIDE = 7919               # a prime: seed s's streams are far from seed s + 1's

STREAM_SERIAL_NOISE = 1      # faults.py: serial-noise
STREAM_PHASES = 17           # twin.py: the Slaves' PWM phases
# faults.py: the CAN wire's drop/corrupt stream is re-seeded at each change, stream = the change's number


def derive_seed(seed: int, stream: int) -> int:
    """The seed of random stream ``stream`` of a run seeded with ``seed``."""
    return seed * _STRIDE + stream
