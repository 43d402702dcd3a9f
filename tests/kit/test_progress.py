"""Runs that take a while say how far they are."""

import io

import numpy as np

import snakekit
from snakekit.progress import TextProgress


def test_a_real_time_run_reports_its_progress(capsys):
    move = snakekit.joint_trajectory(np.zeros(5), [0.2, 0, 0, 0, 0], 0.3)
    with snakekit.make_robot("sim", realtime=True) as robot:
        robot.run(move, progress=True)
    err = capsys.readouterr().err
    assert err.startswith("\rrunning on the sim robot:")
    assert err.endswith(f"{0.8:.1f} / 0.8 s robot time (100 %)\n")  # 0.3 s moving + 0.5 s settling


def test_a_fast_or_short_run_is_quiet(capsys):
    move = snakekit.joint_trajectory(np.zeros(5), [0.2, 0, 0, 0, 0], 0.3)
    with snakekit.make_robot("sim") as robot:
        robot.run(move)
    with snakekit.make_robot("sim", realtime=True) as robot:
        robot.run(move)  # 0.8 s: below the 3 s that earns a progress line
    assert capsys.readouterr().err == ""


def test_an_interrupted_run_shows_where_it_stopped():
    out = io.StringIO()
    bar = TextProgress(50.0, "Task 2", stream=out, every=0.0)
    bar.update(20.0)
    bar.close(complete=False)
    assert out.getvalue().endswith("Task 2:  20.0 / 50.0 s robot time (40 %)\n")
