"""The threads that keep the arm's timing run under SCHED_FIFO where the system allows it
(snakekit.host.realtime): the goals' loop on a bus, the watchdog's keep-alive and the emulated
servos' responder; never the simulator's loop, never a process they start, and in the grader's
sandbox only up to the kit's priority, with a bound on a real-time thread that never waits."""

import os
import subprocess
import sys
import threading

import numpy as np
import pytest

import snakekit
from snakekit import host
from snakekit.emulator import make_emulated_robot

pytestmark = pytest.mark.skipif(not hasattr(os, "SCHED_FIFO"), reason="SCHED_FIFO is Linux's")
ROOT = os.geteuid() == 0


def policy(tid: int = 0) -> tuple[int, int]:
    """(policy without the reset-on-fork flag, priority) of a thread (0: the calling one)."""
    return os.sched_getscheduler(tid) & ~os.SCHED_RESET_ON_FORK, os.sched_getparam(tid).sched_priority


@pytest.mark.skipif(not ROOT, reason="raising a thread to SCHED_FIFO needs root or RLIMIT_RTPRIO")
def test_the_block_runs_under_fifo_at_the_kits_priority_and_its_children_and_after_do_not():
    before = policy()
    assert before == (os.SCHED_OTHER, 0)
    with host.realtime() as raised:
        assert raised is True
        assert policy() == (os.SCHED_FIFO, host.REALTIME_PRIORITY)
        other = []
        t = threading.Thread(target=lambda: other.append(policy()))
        t.start()
        t.join()
        child = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0))"],
                               capture_output=True, text=True, check=True).stdout.strip()
    assert other == [(os.SCHED_OTHER, 0)]  # a thread it starts: the process's own policy
    assert child == str(os.SCHED_OTHER)  # a process it starts does not inherit SCHED_FIFO
    assert policy() == before


def test_without_the_right_nothing_changes(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with host.realtime() as raised:
        assert raised is False and policy() == (os.SCHED_OTHER, 0)
    monkeypatch.delattr(os, "sched_setscheduler")  # not Linux
    with host.realtime() as raised:
        assert raised is False


@pytest.mark.skipif(not ROOT, reason="raising a thread to SCHED_FIFO needs root or RLIMIT_RTPRIO")
def test_a_run_on_the_emulated_bus_keeps_its_timing_under_fifo_and_the_simulator_does_not():
    seen = []
    with make_emulated_robot(motion="profile") as robot:
        responder = robot.emulator._thread.native_id
        assert policy(responder) == (os.SCHED_FIFO, host.REALTIME_PRIORITY)
        robot.on_record = lambda t, q, v: seen.append(policy())
        q = robot.read().positions
        robot.run(snakekit.Trajectory(np.array([0.0, 0.2]), np.vstack([q, q + 0.02])), settle=0.05)
        assert seen and set(seen) == {(os.SCHED_FIFO, host.REALTIME_PRIORITY)}
        assert policy() == (os.SCHED_OTHER, 0)  # back when the run ends
        keepalive = getattr(robot, "_keepalive", None)
        if keepalive is not None:
            assert policy(keepalive._thread.native_id) == (os.SCHED_FIFO, host.REALTIME_PRIORITY)
    seen.clear()
    with snakekit.make_robot("sim", realtime=True) as sim:  # paced by the wall clock, as in the lessons
        sim.on_record = lambda t, q, v: seen.append(policy())
        q = sim.read().positions
        sim.run(snakekit.Trajectory(np.array([0.0, 0.2]), np.vstack([q, q + 0.02])), settle=0.05)
    assert seen and set(seen) == {(os.SCHED_OTHER, 0)}
