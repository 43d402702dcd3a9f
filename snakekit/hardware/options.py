"""The driver's options, checked before the port is opened: every bad value is a SnakekitError
that says what was wrong and what to use."""

from __future__ import annotations

import numbers
import os

from ..errors import ConfigurationError, InputTypeError
from ..model import SnakeSpec
from ..profile_planner import check_profile
from ..validate import number, quote
from .bus import SUPPORTED_BAUD_RATES

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
        raise InputTypeError(f"{name} must be a whole number, got {quote(value)}")
    value = int(value)
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in {low}..{high}"
        raise ConfigurationError(f"{name} must be {bound}, got {value}")
    return value


def check_options(spec: SnakeSpec, ids, on_close, retries, profile_velocity, profile_acceleration, watchdog):
    """``(ids, retries, profile_velocity, profile_acceleration, watchdog)``, checked and normalised.

    The profile velocity may not exceed the joint speed limit (nor be 0: no profile, full speed):
    :func:`snakekit.profile_planner.check_profile`, which the simulator uses too.
    """
    if ids is None:
        ids = spec.servo_ids
    if isinstance(ids, (str, bytes)) or not hasattr(ids, "__iter__"):
        raise InputTypeError(f"ids must be {spec.n_joints} servo ids, base to tip, e.g. (1, 2, 3, 4, 5); got {quote(ids)}")
    ids = tuple(_whole(i, "each servo id", 0, 252) for i in ids)
    if len(ids) != spec.n_joints or len(set(ids)) != len(ids):
        raise ConfigurationError(f"ids must be {spec.n_joints} distinct servo ids, one a joint, got {quote(ids)}")
    if not isinstance(on_close, str) or on_close not in ON_CLOSE:
        raise ConfigurationError(f"on_close must be one of {', '.join(map(repr, ON_CLOSE))}, got {quote(on_close)}")
    retries = _whole(retries, "retries", 0, 100)
    profile_velocity, profile_acceleration = check_profile(profile_velocity, profile_acceleration, spec)
    if isinstance(watchdog, bool) or not isinstance(watchdog, numbers.Real) or not (
            watchdog == 0 or 0.02 <= watchdog <= 2.54):
        raise ConfigurationError(f"watchdog must be 0 (off) or 0.02..2.54 s, got {quote(watchdog)}")
    return ids, retries, profile_velocity, profile_acceleration, float(watchdog)


def check_baudrate(baudrate) -> int:
    """``baudrate`` [baud] as an int, or an error naming the rates to use."""
    return number(baudrate, "baudrate", "baud", at_least=1, integer=True,
                  hint=f"Use {SUPPORTED_BAUD_RATES}, the rate set in the servos' Baud Rate register (the kit's "
                  "arm: 4000000)")
