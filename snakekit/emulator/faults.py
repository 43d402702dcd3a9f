"""What can go wrong on the emulated bus, as one frozen value.

>>> Faults(drop=0.1, seed=1).describe()
'drop 10% of instruction packets'
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ConfigurationError


@dataclass(frozen=True)
class Faults:
    """Faults the emulator injects. Change them at run time with ``emulator.faults = ...``.

    Attributes:
        drop: probability that an instruction packet is lost (no servo sees it, no reply).
        corrupt: probability that a status packet arrives with one byte flipped (bad CRC).
        delay: probability that the replies to an instruction arrive late.
        delay_time: how late a delayed reply is [s] (the SDK gives up after ~34 ms).
        missing: servo ids that are not on the bus (unplugged: never answer).
        overload: servo ids that report an overload alert (Hardware Error Status bit 5;
            torque goes off) ``overload_after`` seconds after these faults are set.
        overload_after: delay before the overload [s].
        count: stop injecting drops, corruptions and delays after this many (None: never).
        seed: random seed, so a run of faults can be repeated.
    """

    drop: float = 0.0
    corrupt: float = 0.0
    delay: float = 0.0
    delay_time: float = 0.1
    missing: tuple[int, ...] = ()
    overload: tuple[int, ...] = ()
    overload_after: float = 0.0
    count: int | None = None
    seed: int = 0

    def __post_init__(self):
        for name in ("drop", "corrupt", "delay"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ConfigurationError(f"Faults.{name} is a probability in [0, 1], got {v}")
        if self.delay_time < 0 or self.overload_after < 0:
            raise ConfigurationError("Faults.delay_time and Faults.overload_after are durations >= 0 s")
        object.__setattr__(self, "missing", tuple(int(i) for i in self.missing))
        object.__setattr__(self, "overload", tuple(int(i) for i in self.overload))

    def describe(self) -> str:
        """One line for a person."""
        parts = []
        if self.drop:
            parts.append(f"drop {self.drop:.0%} of instruction packets")
        if self.corrupt:
            parts.append(f"corrupt {self.corrupt:.0%} of status packets")
        if self.delay:
            parts.append(f"delay {self.delay:.0%} of replies by {1000 * self.delay_time:.0f} ms")
        if self.missing:
            parts.append("servo(s) " + ", ".join(map(str, self.missing)) + " missing")
        if self.overload:
            parts.append("overload on servo(s) " + ", ".join(map(str, self.overload))
                         + (f" after {self.overload_after:g} s" if self.overload_after else ""))
        if self.count is not None and parts:
            parts.append(f"at most {self.count} packet faults")
        return "; ".join(parts) or "no faults"


NO_FAULTS = Faults()
