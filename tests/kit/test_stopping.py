"""Torque off on a stop is said to be confirmed for a servo when, and only when, that servo read it back.

A servo that read back torque off once has confirmed it: a later try's read of it that fails (a
reply held up on a busy computer) must not make the stop say it "did not confirm it", and a servo
is not asked again once it has answered. Every sequence of answers of three servos over the
driver's tries is checked (the emulated bus in real time: tests/kit/test_hardware.py)."""

from __future__ import annotations

import itertools

import pytest

from snakekit.hardware.bus import sdk
from snakekit.hardware.registers import TORQUE_ENABLE
from snakekit.hardware.stopping import StopMixin

OFF, ON, LOST = "off", "on", "lost"   # a read-back of torque enable: 0, 1, no valid reply


class Port:
    is_using = False

    def clearPort(self):  # noqa: N802 - the SDK's name
        pass


class PacketHandler:
    """The SDK's packet handler as the stop uses it, with each servo's read-backs scripted in turn."""

    def __init__(self, answers: dict[int, list[str]]):
        self.answers = {i: list(a) for i, a in answers.items()}
        self.log: list[tuple] = []

    def write1ByteTxOnly(self, port, target, address, value):  # noqa: N802
        assert (address, value) == (TORQUE_ENABLE, 0)
        self.log.append(("off", target))
        return sdk.COMM_SUCCESS

    def read1ByteTxRx(self, port, servo, address):  # noqa: N802
        assert address == TORQUE_ENABLE
        self.log.append(("read", servo))
        said = self.answers[servo].pop(0)
        if said == LOST:
            return 0, sdk.COMM_RX_TIMEOUT, 0
        return (0 if said == OFF else 1), sdk.COMM_SUCCESS, 0


class Arm(StopMixin):
    def __init__(self, ids, retries, answers):
        self.ids, self.retries = list(ids), retries
        self.port = Port()
        self.bus = type("Bus", (), {"ph": PacketHandler(answers)})()
        self.torque_enabled = True


RETRIES = 2
TRIES = RETRIES + 1
SEQUENCES = list(itertools.product((OFF, ON, LOST), repeat=TRIES))


@pytest.mark.parametrize("first", range(len(SEQUENCES)))
def test_a_servo_confirms_torque_off_once_it_read_it_back_in_any_try(first):
    """Servo 1 answers with each of the 27 sequences over three tries, beside servo 2 with every other
    sequence and servo 3 that never answers (unplugged)."""
    for second in SEQUENCES:
        answers = {1: SEQUENCES[first], 2: second, 3: (LOST,) * TRIES}
        arm = Arm([1, 2, 3], RETRIES, answers)
        still_on = arm._torque_off_safely()

        def reads_until_confirmed(seq):
            return seq.index(OFF) + 1 if OFF in seq else TRIES

        assert still_on == [i for i in (1, 2, 3) if OFF not in answers[i]]
        log = arm.bus.ph.log
        for i in (1, 2, 3):   # asked until it confirmed, then never again
            assert log.count(("read", i)) == reads_until_confirmed(answers[i]), (answers, log)
        # the first try's torque off is one broadcast; each later try's goes to the servos still unconfirmed,
        # and every read of a servo comes after a torque off sent to it in the same try
        assert log[0] == ("off", sdk.BROADCAST_ID)
        sent = set()
        for what, who in log:
            if what == "off":
                sent = set(arm.ids) if who == sdk.BROADCAST_ID else sent | {who}
            else:
                assert who in sent, log
        assert arm.torque_enabled is bool(still_on)


def test_the_stop_says_only_the_unconfirmed_servos():
    """Servo 2 confirms in the first try and its reads would fail after; servo 3 is unplugged."""
    arm = Arm([1, 2, 3, 4, 5], 3, {1: [OFF], 2: [OFF, LOST, LOST, LOST], 3: [LOST] * 4, 4: [ON, OFF], 5: [OFF]})
    arm.on_close, arm._planner = "torque_off", None
    arm.bus.hold = lambda: __import__("contextlib").nullcontext()
    said = arm.stop()
    assert said == ("Torque off was sent, but servo(s) 3 did not confirm it: they may still have torque on. "
                    "Switch the arm's power off before touching it.")
