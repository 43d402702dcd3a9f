"""The driver's options, checked before the port is opened: every bad value is a SnakekitError
that says what was wrong and what to use."""

from __future__ import annotations

import numbers
import os

from ..errors import ConfigurationError, InputTypeError
from ..model import SnakeSpec
from ..profile_planner import VELOCITY_UNIT
from .registers import velocity_limit_units

ON_CLOSE = ("torque_off", "hold")


def port_name(port) -> str:
    """The arm's serial port: ``port``, or else the ``SNAKEKIT_PORT`` environment variable (the
    container's ``hardware`` service sets it), or a ConfigurationError that says what to give."""
    port = os.environ.get("SNAKEKIT_PORT") if port is None else port
    if not port:
        raise ConfigurationError("the hardware backend needs the arm's serial port: make_robot('hardware', "
                                 "port='/dev/ttyUSB0') (macOS: '/dev/cu.usbserial-...', Windows: 'COM3', "
                                 "through snakekit bridge: 'socket://HOST:7800'), or SNAKEKIT_PORT set")
    return str(port)


def _whole(value, name: str, low: int, high: int | None = None) -> int:
    """``value`` as an int in ``low..high``, or a :class:`ConfigurationError` that says so."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputTypeError(f"{name} must be a whole number, got {value!r}")
    value = int(value)
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in {low}..{high}"
        raise ConfigurationError(f"{name} must be {bound}, got {value}")
    return value


def check_options(spec: SnakeSpec, ids, on_close, retries, profile_velocity, profile_acceleration, watchdog):
    """``(ids, retries, profile_velocity, profile_acceleration, watchdog)``, checked and normalised.

    The profile velocity may not exceed the joint speed limit (nor be 0: no profile, full speed).
    """
    if ids is None:
        ids = spec.servo_ids
    if isinstance(ids, (str, bytes)) or not hasattr(ids, "__iter__"):
        raise InputTypeError(f"ids must be {spec.n_joints} servo ids, base to tip, e.g. (1, 2, 3, 4, 5); got {ids!r}")
    ids = tuple(_whole(i, "each servo id", 0, 252) for i in ids)
    if len(ids) != spec.n_joints or len(set(ids)) != len(ids):
        raise ConfigurationError(f"ids must be {spec.n_joints} distinct servo ids, one a joint, got {ids}")
    if on_close not in ON_CLOSE:
        raise ConfigurationError(f"on_close must be one of {', '.join(map(repr, ON_CLOSE))}, got {on_close!r}")
    retries = _whole(retries, "retries", 0, 100)
    top = velocity_limit_units(spec)
    if isinstance(profile_velocity, numbers.Integral) and not isinstance(profile_velocity, bool) and (
            profile_velocity == 0 or profile_velocity > top):
        raise ConfigurationError(
            f"profile_velocity {profile_velocity} would let the servos move at "
            f"{'full speed (0 = no profile)' if profile_velocity == 0 else f'{profile_velocity * VELOCITY_UNIT:.2f} rad/s'}, "
            f"over the {spec.velocity_limit} rad/s joint speed limit; use 1..{top} (0.229 rev/min units)")
    profile_velocity = _whole(profile_velocity, "profile_velocity", 1, top)
    profile_acceleration = _whole(profile_acceleration, "profile_acceleration", 1, 32767)
    if not isinstance(watchdog, numbers.Real) or not (watchdog == 0 or 0.02 <= watchdog <= 2.54):
        raise ConfigurationError(f"watchdog must be 0 (off) or 0.02..2.54 s, got {watchdog!r}")
    return ids, retries, profile_velocity, profile_acceleration, float(watchdog)
