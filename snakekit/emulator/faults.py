"""What can go wrong on the emulated bus, as one frozen value.

>>> Faults(drop=0.1, seed=1).describe()
'drop 10% of instruction packets'
"""

from __future__ import annotations

from dataclasses import dataclass

from ..validate import MAX_DURATION, number

#: The latest a delayed reply may come [s]: far past the SDK's timeout, and the driver's.
MAX_DELAY_TIME = 10.0


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
            number(getattr(self, name), f"Faults.{name}", at_least=0, at_most=1,
                   hint="It is a probability (0.1 = 10 % of packets)")
        number(self.delay_time, "Faults.delay_time", "s", at_least=0, at_most=MAX_DELAY_TIME,
               hint="It is how late a delayed reply arrives (the SDK gives up after ~34 ms)")
        number(self.overload_after, "Faults.overload_after", "s", at_least=0, at_most=MAX_DURATION,
               hint="It is how long after the faults are set the overload alert comes")
        if self.count is not None:
            number(self.count, "Faults.count", at_least=0, integer=True, hint="It is how many packet faults are "
                   "injected before they stop (None: never stop)")
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
