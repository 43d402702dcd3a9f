"""A student's mistakes get a SnakekitError that says what was wrong and what to do.

Each test gives the library one of the bad inputs a new user tried, and checks the message a
user sees, and that the error is in snakekit's tree (so ``except SnakekitError`` catches it,
and generic ``except ValueError`` / ``except OSError`` code keeps working).
"""

import errno
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import snakekit
from snakekit import SPEC, Trajectory
from snakekit.robot import Run
from snakekit.trajectory import joint_trajectory, side_sweep


def raises(kind, text):
    """pytest.raises for ``kind`` whose message holds ``text`` (plain text, not a regex)."""
    class _Ctx:
        def __enter__(self):
            self.cm = pytest.raises(kind)
            self.info = self.cm.__enter__()
            return self.info

        def __exit__(self, *exc):
            out = self.cm.__exit__(*exc)
            assert isinstance(self.info.value, snakekit.SnakekitError)
            assert text in str(self.info.value), f"{text!r} not in {str(self.info.value)!r}"
            return out
    return _Ctx()


# --- inverse kinematics ----------------------------------------------------------------------


def test_ik_with_max_iter_zero_is_refused_not_solved():
    # before: the start pose came back as a "solution" (it puts the tool at (0.3315, 0), not on the target)
    with raises(snakekit.ConfigurationError, "max_iter must be a whole number from 1 to 10000, got 0. It is how many solver"):
        snakekit.inverse_kinematics([0.25, 0.10], max_iter=0)
    with raises(snakekit.ConfigurationError, "restarts must be a whole number from 0 to 1000, got -1"):
        snakekit.inverse_kinematics([0.25, 0.10], restarts=-1)


def test_ik_target_far_beyond_reach_is_unreachable_without_overflow():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # before: overflow warnings flooded, then a ShapeError about q
        with raises(snakekit.UnreachableTargetError,
                    "target (1e+300, 1e+300) m is out of reach: it is 1.414e+300 m from joint 1 and the arm reaches "
                    "0.3315 m. The closest tool point found is (0.2344, 0.2344) m") as e:
            snakekit.inverse_kinematics([1e300, 1e300])
        pose, q = snakekit.closest_reachable_point([1e300, 1e300])
    # the arm stretched towards 45 degrees: reach * (cos 45, sin 45)
    np.testing.assert_allclose(e.value.closest, [SPEC.reach / np.sqrt(2)] * 2, atol=1e-6)
    np.testing.assert_allclose(pose[:2], [SPEC.reach / np.sqrt(2)] * 2, atol=1e-6)
    assert e.value.target == (1e300, 1e300)


@pytest.mark.parametrize("tol", [0, float("nan"), -1e-6])
def test_ik_tolerance_must_be_a_positive_distance(tol):
    # before: "out of reach", with the target itself as the closest point
    with raises(snakekit.ConfigurationError, f"tol must be a finite number >= 1e-12 [m], got {tol!r}. "
                "It is how close the tool must come to the target"):
        snakekit.inverse_kinematics([0.25, 0.10], tol=tol)


def test_ik_heading_must_be_an_angle():
    # before: numpy's TypeError "ufunc 'isfinite' not supported"
    with raises(snakekit.InputTypeError, "heading must be a finite number [rad], got 'north' (str). Give the "
                "tool's heading as an angle from the x axis, e.g. heading=numpy.pi / 2 for 'north' (+y)"):
        snakekit.inverse_kinematics([0.25, 0.10], heading="north")
    assert isinstance(snakekit.InputTypeError("x"), TypeError)


# --- arrays: ragged, text, complex ---------------------------------------------------------------


def test_ragged_rows_say_so():
    with raises(snakekit.ShapeError, "positions must have shape (N, 5), got rows of different lengths (5, 4). "
                "Give every row the same number of values"):
        Trajectory([0, 1], [[0, 0, 0, 0, 0], [0, 0, 0, 0]])
    with raises(snakekit.ShapeError, "q must have shape (5,), got rows of different lengths (2, 3)"):
        snakekit.forward_kinematics([[0, 0], [0, 0, 0]])


def test_text_instead_of_angles():
    # before: ValueError "could not convert string to float: 'a'"
    with raises(snakekit.InputTypeError, "q holds 'a', which is not a number (str); every value must be a real "
                "number. Give one angle [rad] per joint, base to tip"):
        snakekit.forward_kinematics(["a"] * 5)


def test_complex_input_is_refused_not_cut_to_its_real_part(tmp_path):
    # before: Trajectory kept the real parts silently (a ComplexWarning at most)
    with raises(snakekit.InputTypeError, "positions holds 1j, which is a complex number; every value must be a "
                "real number (use .real if the imaginary parts are only rounding noise)"):
        Trajectory([0, 1], np.zeros((2, 5)) + 1j)
    with raises(snakekit.InputTypeError, "q holds 0.1j, which is a complex number"):
        snakekit.forward_kinematics([0.1j, 0, 0, 0, 0])
    with raises(snakekit.InputTypeError, "target_xy holds (0.25+1j), which is a complex number"):
        snakekit.inverse_kinematics([0.25 + 1j, 0.1])
    np.savez(tmp_path / "c.npz", times=[0.0, 1.0], positions=np.zeros((2, 5)) + 1j)
    with raises(snakekit.FileFormatError, "c.npz does not hold a valid trajectory: positions holds 1j, which is a "
                "complex number"):
        Trajectory.load(tmp_path / "c.npz")
    # complex numbers with no imaginary part are their real part
    tr = Trajectory([0, 1], np.full((2, 5), 0.1 + 0j))
    assert tr.positions.dtype == float and (tr.positions == 0.1).all()


# --- trajectories -------------------------------------------------------------------------


def test_joint_trajectory_speed_fraction_and_duration():
    a, b = np.zeros(5), [0.5, 0, 0, 0, 0]
    with raises(snakekit.ConfigurationError, "speed_fraction must be a finite number > 0 and <= 1, got 0. It is "
                "the share of the velocity limit the fastest joint may reach"):
        joint_trajectory(a, b, speed_fraction=0)  # before: ZeroDivisionError
    with raises(snakekit.ConfigurationError, "duration must be a finite number > 0 [s], got inf. Give how long "
                "the move takes"):
        joint_trajectory(a, b, duration=float("inf"))  # before: OverflowError
    with raises(snakekit.ConfigurationError, "rate must be a finite number > 0 and <= 10000 [Hz], got -10"):
        joint_trajectory(a, b, 1.0, rate=-10)  # before: accepted, one point at each end


@pytest.mark.parametrize("rate", [0, -10, float("nan"), float("inf")])
def test_side_sweep_rate_must_be_positive(rate):
    with raises(snakekit.ConfigurationError, f"rate must be a finite number > 0 and <= 10000 [Hz], got {rate!r}. It is how "
                "many goals per second are sent (the task: 10)"):
        side_sweep(rate=rate)


def test_side_sweep_counts_are_whole_numbers():
    with raises(snakekit.ConfigurationError, "points must be a whole number from 2 to 100000, got 1"):
        side_sweep(points=1)
    with raises(snakekit.InputTypeError, "sweeps must be a whole number from 1 to 500, got 2.5 (float)"):
        side_sweep(sweeps=2.5)


# --- the simulator ------------------------------------------------------------------------


def test_sim_step_and_run_options():
    from snakekit.sim import SimRobot

    with SimRobot() as robot:
        with raises(snakekit.ConfigurationError, "duration must be a finite number from 0 to 600 [s], got nan"):
            robot.step(float("nan"))
        with raises(snakekit.ConfigurationError, "duration must be a finite number from 0 to 600 [s], got inf"):
            robot.step(float("inf"))  # before: OverflowError
        with raises(snakekit.InputTypeError, "duration must be a finite number from 0 to 600 [s], got '1' (str)"):
            robot.step("1")
        move = joint_trajectory(np.zeros(5), [0.2, 0, 0, 0, 0], 0.5)
        with raises(snakekit.ConfigurationError, "record_rate must be a finite number > 0 and <= 10000 [Hz], got 0. "
                    "It is how often the state is recorded"):
            robot.run(move, record_rate=0)
        with raises(snakekit.ConfigurationError, "settle must be a finite number from 0 to 3600 [s], got nan"):
            robot.run(move, settle=float("nan"))  # before: ValueError "cannot convert float NaN to integer"
        assert robot.read().time == 0  # nothing ran


def test_render_beyond_the_offscreen_buffer():
    from snakekit.sim import SimRobot

    with SimRobot() as robot:
        buffer = robot.model.vis.global_
        with raises(snakekit.ConfigurationError, f"width must be a whole number from 1 to {buffer.offwidth} "
                    f"[pixels], got 1920. The offscreen buffer is {buffer.offwidth} x {buffer.offheight} pixels"):
            robot.render(width=1920, height=1080)  # before: MuJoCo's own ValueError
        image = robot.render(width=buffer.offwidth, height=buffer.offheight)
        assert image.shape == (buffer.offheight, buffer.offwidth, 3)


# --- files ----------------------------------------------------------------------------------


def small():
    return joint_trajectory(np.zeros(5), [0.3, 0, 0, 0, 0], 1.0, rate=10)


def csv_lines(tmp_path):
    return small().save(tmp_path / "t.csv").read_text().splitlines()


def test_csv_with_an_extra_column(tmp_path):
    lines = csv_lines(tmp_path)
    p = tmp_path / "extra.csv"
    p.write_text("\n".join([lines[0] + ",note"] + [x + ",1" for x in lines[1:]]) + "\n")
    with raises(snakekit.FileFormatError, "extra.csv has the column(s) note that a trajectory does not have; "
                "expected time,q1,q2,q3,q4,q5 (optionally followed by qd1..qd5). Remove them"):
        Trajectory.load(p)  # before: loaded, the column dropped


def test_csv_with_velocities_for_some_joints(tmp_path):
    rows = np.hstack([small().times[:, None], small().positions, small().velocities[:, :2]])
    p = tmp_path / "some.csv"
    p.write_text("time,q1,q2,q3,q4,q5,qd1,qd2\n" + "\n".join(",".join(map(repr, r.tolist())) for r in rows) + "\n")
    with raises(snakekit.FileFormatError, "some.csv has velocities for some joints only (lacks qd3, qd4, qd5); "
                "expected time,q1,q2,q3,q4,q5 (optionally followed by qd1..qd5). Give all of qd1..qd5, or none"):
        Trajectory.load(p)  # before: loaded without velocities


def test_csv_in_latin_1(tmp_path):
    p = tmp_path / "latin.csv"
    p.write_bytes("time,q1,q2,q3,q4,q5\n0,0,0,0,0,0\n0.1,0,0,0,0,0 \xb0\n".encode("latin-1"))
    with raises(snakekit.FileFormatError, "latin.csv, line 3: byte 0xb0 is not UTF-8 text, so this is not a file "
                "Trajectory.save wrote (it may be in another encoding, e.g. Latin-1). Save it again as UTF-8"):
        Trajectory.load(p)  # before: UnicodeDecodeError


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_a_folder_named_like_a_trajectory(tmp_path, suffix):
    (tmp_path / f"runs{suffix}").mkdir()
    with raises(snakekit.FileFormatError, f"runs{suffix} is a folder, not a file; give the path of the file itself"):
        Trajectory.load(tmp_path / f"runs{suffix}")  # before: IsADirectoryError (.csv), "may be truncated" (.npz)
    with raises(snakekit.FileFormatError, "is a folder, not a file"):
        Run.load(tmp_path / f"runs{suffix}")


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_saving_into_a_missing_folder(tmp_path, suffix):
    target = tmp_path / "missing" / f"t{suffix}"
    with raises(snakekit.FileWriteError, f"cannot write trajectory file {target}: folder {target.parent} does not "
                f"exist. Create the folder first (pathlib.Path('{target.parent}').mkdir(parents=True))") as e:
        small().save(target)  # before: FileNotFoundError
    assert isinstance(e.value, OSError)
    with snakekit.make_robot("sim") as robot:
        run = robot.run(small())
    with raises(snakekit.FileWriteError, f"cannot write run file {target.with_suffix('.npz')}: folder"):
        run.save(target.with_suffix(".npz"))
    assert not target.parent.exists()


def test_csv_load_keeps_what_the_old_reader_accepted(tmp_path):
    """The vectorised reader reads what the line-by-line one did: blank lines, spaces and
    quotes around numbers, a missing final newline; and a spreadsheet's UTF-8 byte order mark."""
    tr = small()
    p = tmp_path / "t.csv"
    lines = tr.save(p).read_text().splitlines()
    body = [",".join(f'"{v}"' if i == 2 else f" {v} " if i == 3 else v for i, v in enumerate(x.split(",")))
            for x in lines[1:]]
    p.write_text("\n".join([lines[0] + " ", "", *body[:3], "", *body[3:]]))
    back = Trajectory.load(p)
    np.testing.assert_array_equal(back.times, tr.times)
    np.testing.assert_array_equal(back.positions, tr.positions)
    np.testing.assert_array_equal(back.velocities, tr.velocities)
    bom = tmp_path / "bom.csv"  # what a spreadsheet's "CSV UTF-8" writes: a byte order mark first
    bom.write_bytes(b"\xef\xbb\xbf" + "\n".join(lines).encode())
    np.testing.assert_array_equal(Trajectory.load(bom).positions, tr.positions)
    wide = tmp_path / "wide.csv"
    wide.write_text("time,q1,q2,q3,q4,q5\n0,0,0,0,0,0\n1,0,0,0,0,0,7\n")
    with raises(snakekit.FileFormatError, "wide.csv, line 3: 7 values, expected 6; remove the extra values"):
        Trajectory.load(wide)
    one = tmp_path / "one.csv"
    one.write_text("time,q1,q2,q3,q4,q5\n0,0.1,0,0,0,0\n")
    assert Trajectory.load(one).positions.tolist() == [[0.1, 0, 0, 0, 0]]


# --- the sweep command ---------------------------------------------------------------------


def test_sweep_out_to_a_place_that_refuses_writing_fails_before_the_run(tmp_path):
    # /proc takes no new files, even for root (whom permission bits let write anywhere)
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "sweep", "--out", "/proc/run.npz"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    assert "snakekit sweep: cannot write run file /proc/run.npz: " in r.stderr
    assert "Choose a place you can write to" in r.stderr
    assert "Task 2" not in r.stdout and "Traceback" not in r.stderr  # nothing ran


def test_sweep_never_loses_a_finished_run(tmp_path, monkeypatch, capsys):
    """The place was writable when checked, but the save fails after the run (a full disk):
    the run goes to the working folder instead, and the user is told where."""
    from snakekit import cli, robot

    target = tmp_path / "out" / "run.npz"
    target.parent.mkdir()
    real_savez = np.savez

    def savez(path, **arrays):
        if str(path) == str(target):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        real_savez(path, **arrays)

    monkeypatch.setattr(robot.np, "savez", savez)
    monkeypatch.chdir(tmp_path)
    rc = cli.main(["sweep", "--out", str(target)])
    err = capsys.readouterr().err
    assert rc == 1
    assert f"snakekit sweep: cannot write run file {target}: No space left on device." in err
    kept = sorted(tmp_path.glob("snakekit-run-*.npz"))
    assert len(kept) == 1 and f"the run was saved to {kept[0]} instead" in err
    run = Run.load(kept[0])
    np.testing.assert_array_equal(run.commanded.positions, side_sweep().positions)
    assert len(run.measured) > 500


# --- booleans are not numbers ------------------------------------------------------------------


BOOL_WORDS = "holds True, a boolean, where a number is needed (numpy would read it as 1); every value must be a real number"


def test_booleans_are_not_angles(tmp_path):
    # before: True was taken as 1 rad everywhere (FK of [True, 0, 0, 0, 0] put the tool at x = 0.179 m)
    with raises(snakekit.InputTypeError, "q " + BOOL_WORDS + ". Give one angle [rad] per joint"):
        snakekit.forward_kinematics([True, 0, 0, 0, 0])
    with raises(snakekit.InputTypeError, "q holds True, a boolean"):
        snakekit.forward_kinematics(np.array([1, 0, 0, 0, 0], dtype=bool))
    with raises(snakekit.InputTypeError, "q holds False, a boolean"):
        snakekit.forward_kinematics([0.1, 0.2, np.False_, 0, 0])     # mixed with floats, numpy makes it 0.0
    with raises(snakekit.InputTypeError, "positions " + BOOL_WORDS):
        Trajectory([0, 1], [[0.0] * 5, [True, 0.1, 0, 0, 0]])
    with raises(snakekit.InputTypeError, "times holds False, a boolean, where a number is needed (numpy would read "
                "it as 0)"):
        Trajectory([False, True], np.zeros((2, 5)))
    np.savez(tmp_path / "b.npz", times=[0.0, 1.0], positions=np.ones((2, 5), dtype=bool))
    with raises(snakekit.FileFormatError, "b.npz does not hold a valid trajectory: positions " + BOOL_WORDS):
        Trajectory.load(tmp_path / "b.npz")
    with snakekit.make_robot("sim") as robot:
        with raises(snakekit.InputTypeError, "commanded q " + BOOL_WORDS):
            robot.command([True, 0, 0, 0, 0])
        robot.step(0.2)
        np.testing.assert_array_equal(robot.read().positions, np.zeros(5))     # nothing was sent
    # numbers of every real kind still pass
    assert snakekit.forward_kinematics(np.zeros(5, dtype=np.int32))[0, 3] == pytest.approx(SPEC.reach)


def test_a_fifo_named_like_a_trajectory_is_refused_without_waiting(tmp_path):
    import threading

    os.mkfifo(tmp_path / "pipe.csv")   # before: open() waited forever for a writer
    caught = []
    reader = threading.Thread(target=lambda: caught.append(_error_of(Trajectory.load, tmp_path / "pipe.csv")),
                              daemon=True)
    reader.start()
    reader.join(timeout=30)
    assert caught, "Trajectory.load waited on the pipe"
    assert isinstance(caught[0], snakekit.FileFormatError)
    assert "pipe.csv is not a regular file (a pipe, socket or device); give the path of a file saved on disk" \
        in str(caught[0])


def _error_of(fn, *args, **kwargs):
    try:
        fn(*args, **kwargs)
    except Exception as e:
        return e
    return None


# --- counts, rates and durations have stated bounds --------------------------------------------


@pytest.mark.parametrize("n, kind", [(-1, snakekit.ConfigurationError), (10**12, snakekit.ConfigurationError),
                                     (2.5, snakekit.InputTypeError), ("100", snakekit.InputTypeError),
                                     (None, snakekit.InputTypeError), (float("nan"), snakekit.InputTypeError)])
def test_workspace_points_count_is_a_bounded_whole_number(n, kind):
    # before: numpy's "negative dimensions", "'float' object cannot be interpreted as an integer"...
    with raises(kind, f"n must be a whole number from 1 to 1000000, got {n!r}"):
        snakekit.workspace_points(n)
    assert snakekit.workspace_points(3).shape == (3, 2)


def test_ik_restarts_and_steps_are_bounded():
    # before: restarts=10**6 ran for hours on a target the joint limits keep the tool from
    with raises(snakekit.ConfigurationError, "restarts must be a whole number from 0 to 1000, got 1000000"):
        snakekit.inverse_kinematics([0.25, 0.10], restarts=10**6)
    with raises(snakekit.ConfigurationError, "max_iter must be a whole number from 1 to 10000, got 1000000000"):
        snakekit.inverse_kinematics([0.25, 0.10], max_iter=10**9)


def test_huge_rates_and_durations_are_refused_before_any_memory_is_taken():
    a, b = np.zeros(5), [0.3, 0, 0, 0, 0]
    with raises(snakekit.ConfigurationError,
                "rate must be a finite number > 0 and <= 10000 [Hz], got 1000000000000.0"):
        small().resample(rate=1e12)  # before: MemoryError (7.28 TiB)
    with raises(snakekit.ConfigurationError, "duration is 1e+12 s (1.67e+10 min), longer than the 600 s (10 min) the "
                "kit accepts. Times are in seconds: if these are milliseconds, divide them by 1000"):
        joint_trajectory(a, b, duration=1e12)  # before: MemoryError (728 TiB)
    with raises(snakekit.ConfigurationError, "rate must be a finite number > 0 and <= 10000 [Hz], got 1000000000.0"):
        joint_trajectory(a, b, 1.0, rate=1e9)
    with raises(snakekit.ConfigurationError, "the move would hold 6000001 points (600 s at 10000 Hz), more than the "
                "1000000 the kit makes; lower the rate or shorten the time"):
        joint_trajectory(a, b, 600, rate=1e4)  # each bound is fine alone: together 6 million points
    with raises(snakekit.ConfigurationError, "at speed_fraction=1e-09 the move takes 3.75e+08 s, longer than the "
                "600 s the kit accepts; raise speed_fraction"):
        joint_trajectory(a, b, speed_fraction=1e-9)
    with raises(snakekit.ConfigurationError, "points must be a whole number from 2 to 100000, got 1000000000. It is "
                "how many goals the sweep sends"):
        side_sweep(points=10**9)
    # what the lessons do stays as it was
    assert len(joint_trajectory(a, b, 600, rate=100)) == 60001
    assert len(side_sweep(points=30, sweeps=3)) == 30


@pytest.mark.parametrize("name", ["cubic", "quintic", "trapezoidal"])
@pytest.mark.parametrize("T", [0, -2.0])
def test_time_scalings_need_a_positive_duration(name, T):
    from snakekit import trajectory

    scaling = getattr(trajectory, f"{name}_time_scaling")
    # before: T=0 gave NaN (or ZeroDivisionError), T<0 a number
    with raises(snakekit.ConfigurationError, f"T must be a finite number > 0 [s], got {T!r}. T is how long the "
                "move takes"):
        scaling(T, 0.5)
    assert scaling(2.0, 1.0) == pytest.approx(0.5)


# --- the robot -------------------------------------------------------------------------------


@pytest.mark.parametrize("pv, words", [
    (0, "profile_velocity 0 would let the servos move at full speed (0 = no profile), over the 1.5 rad/s joint "
        "speed limit; use 1..62 (0.229 rev/min units)"),
    (1000, "profile_velocity 1000 would let the servos move at 23.98 rad/s, over the 1.5 rad/s joint speed limit; "
           "use 1..62"),
    (-5, "profile_velocity must be a whole number from 1 to 62, got -5. It is the servos' Profile Velocity register"),
])
def test_the_simulator_refuses_the_profile_velocities_the_driver_refuses(pv, words):
    # before: the simulator took them, and with 0 a step to 1 rad peaked at 5.6 rad/s (limit 1.5)
    with raises(snakekit.ConfigurationError, words):
        snakekit.make_robot("sim", profile_velocity=pv)
    with raises(snakekit.ConfigurationError, words):  # the driver: the same check, before the port opens
        snakekit.make_robot("hardware", port="/dev/no-such-port", profile_velocity=pv)
    with raises(snakekit.ConfigurationError, "profile_acceleration must be a whole number from 1 to 32767, got 0"):
        snakekit.make_robot("sim", profile_acceleration=0)


def test_the_simulator_runs_a_profile_beyond_the_arm_only_when_asked():
    with raises(snakekit.ConfigurationError, "use 1..62 (0.229 rev/min units). To see what such a profile does, the "
                "simulator runs it with any_profile=True (the real arm never does)"):
        snakekit.make_robot("sim", profile_velocity=0)
    # asked: lesson 5 shows what no profile does (a step that breaks the 1.5 rad/s limit)
    with snakekit.make_robot("sim", profile_velocity=0, any_profile=True) as robot:
        robot.command([1.0, 0, 0, 0, 0])
        peak = 0.0
        for _ in range(300):
            robot.step(0.002)
            peak = max(peak, abs(robot.read().velocities[0]))
    assert peak > 3 * SPEC.velocity_limit  # what the refusal keeps off the arm (5.5 rad/s measured)
    # still only what the firmware takes, and never on the arm
    with raises(snakekit.ConfigurationError, "profile_velocity must be a whole number from 0 to 1023, got -5"):
        snakekit.make_robot("sim", profile_velocity=-5, any_profile=True)
    with raises(snakekit.InputTypeError, "the 'hardware' backend has no option 'any_profile'"):
        snakekit.make_robot("hardware", port="/dev/no-such-port", profile_velocity=0, any_profile=True)


def test_make_robot_names_what_is_wrong_with_its_arguments(monkeypatch):
    monkeypatch.delenv("SNAKEKIT_PORT", raising=False)
    with raises(snakekit.InputTypeError, "the backend is named by a string, one of 'sim', 'emulator', 'hardware'; got "
                "['sim'] (list)"):
        snakekit.make_robot(["sim"])  # before: TypeError "unhashable type: 'list'"
    with raises(snakekit.InputTypeError, "the 'sim' backend has no option 'speed'; its options are realtime, q0, spec, "
                "profile_velocity, profile_acceleration"):
        snakekit.make_robot("sim", speed=2)  # before: TypeError from SimRobot.__init__
    with raises(snakekit.InputTypeError, "the 'emulator' backend has no option 'speed'; its options are motion, faults, "
                "q0, timing"):
        snakekit.make_robot("emulator", speed=2)
    with raises(snakekit.ConfigurationError, "the hardware backend needs the arm's serial port: "
                "make_robot('hardware', port='/dev/ttyUSB0')"):
        snakekit.make_robot("hardware")  # before: "missing 1 required positional argument: 'port'"
    with raises(snakekit.InputTypeError, "baudrate must be a whole number >= 1 [baud], got 'fast' (str). Use 57600, "
                "1000000, 2000000, 3000000 or 4000000"):
        snakekit.make_robot("hardware", port="/dev/no-such-port", baudrate="fast")  # before: int()'s ValueError
    for backend in ("sim", "emulator"):
        with raises(snakekit.InputTypeError, "q0 holds 'a', which is not a number (str)"):
            snakekit.make_robot(backend, q0=["a", 0, 0, 0, 0])


def test_a_trajectory_in_milliseconds_is_refused_on_the_robot():
    # a 2 s move written in milliseconds: 33 minutes on the arm, before
    ms = Trajectory(np.linspace(0, 2000, 21), np.zeros((21, 5)))
    words = ("the trajectory's duration is 2000 s (33.3 min), longer than the 600 s (10 min) the kit accepts. "
             "Times are in seconds: if these are milliseconds, divide them by 1000; nothing was sent. To run one "
             "this long on purpose, set robot.max_duration = 2000 first")
    with snakekit.make_robot("sim") as robot:
        with raises(snakekit.ConfigurationError, words):
            robot.run(ms)
        with raises(snakekit.ConfigurationError, "the trajectory's duration is 1e+07 s"):
            robot.run(Trajectory([0, 1e7], np.zeros((2, 5))))  # before: MemoryError
        assert robot.read().time == 0  # nothing ran
        robot.max_duration = 700  # on purpose: it runs
        run = robot.run(Trajectory([0, 650], np.zeros((2, 5))), record_rate=1, settle=0)
        assert run.robot_time == 650
    with snakekit.make_robot("emulator", motion="profile") as robot:
        with raises(snakekit.ConfigurationError, words):
            robot.run(ms)
        assert robot.goals_sent == 0


def test_the_emulator_refuses_a_delay_that_is_not_a_finite_time():
    from snakekit.emulator import Faults

    for bad in (float("nan"), float("inf"), -0.1):
        with raises(snakekit.ConfigurationError, f"Faults.delay_time must be a finite number from 0 to 10 [s], "
                    f"got {bad!r}. It is how late a delayed reply arrives"):
            Faults(delay=0.3, delay_time=bad)
    for value in ("nan", "inf"):  # before: accepted, then a traceback for every delayed packet
        r = subprocess.run([sys.executable, "-m", "snakekit.cli", "emulator", "--delay", "0.3", "--delay-time", value],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 2, r.stdout + r.stderr
        assert f"snakekit emulator: Faults.delay_time must be a finite number from 0 to 10 [s], got {value}" in r.stderr
        assert "Traceback" not in r.stderr and "emulator:" not in r.stdout


# --- `snakekit check` on a file that is not a working lesson -------------------------------------


def _graded(source, **meta):
    from nbformat.v4 import new_code_cell

    cell = new_code_cell(source)
    cell.metadata["nbgrader"] = {"grade": True, "solution": False, "locked": True, **meta}
    return cell


def _broken_lessons():
    """(name, bytes of the file, words of the one-line message) for each kind of broken lesson."""
    import nbformat
    from nbformat.v4 import new_notebook

    def nb(*cells):
        return nbformat.writes(new_notebook(cells=list(cells))).encode()

    fresh = "take a fresh copy of the lesson from the kit's notebooks/ folder and copy your answers into it"
    return [
        ("empty", b"", f"empty.ipynb is empty, not a notebook; {fresh}"),
        ("text", b"print('hello')\n", "text.ipynb is not a Jupyter notebook: it is not JSON (it starts with "
                                     "\"print('hello')\"), perhaps another file renamed to .ipynb"),
        ("other_json", b'{"name": "snake", "joints": 5}', "other_json.ipynb is JSON but not a Jupyter notebook (a "
                                                          "notebook is a JSON object with a list of cells; this has no "
                                                          "'cells' list)"),
        ("no_metadata", b'{"cells": [], "nbformat": 4, "nbformat_minor": 5}',
         "no_metadata.ipynb is JSON but not a Jupyter notebook (The notebook is invalid and is missing an expected "
         "key: metadata)"),
        ("utf16", nb(_graded("assert True", grade_id="a", points=1)).decode().encode("utf-16"),
         "utf16.ipynb is not UTF-8 text (it looks like UTF-16): byte 0 is 0xff. Jupyter saves notebooks as UTF-8; "
         "open it in JupyterLab and save it again there"),
        ("no_grade_id", nb(_graded("assert True", points=1)),
         f"no_grade_id.ipynb: code cell 1 (the one that starts `assert True`) is a graded cell without a grade id (its "
         f"nbgrader metadata was changed); {fresh}"),
        ("string_points", nb(_graded("assert True", grade_id="ex_test", points="2")),
         "string_points.ipynb: the check cell ex_test has points '2', not a number >= 0"),
    ]


@pytest.mark.parametrize("name, data, words", _broken_lessons(), ids=[c[0] for c in _broken_lessons()])
def test_check_on_a_file_that_is_not_a_lesson_says_so_in_one_line(tmp_path, name, data, words):
    (tmp_path / f"{name}.ipynb").write_bytes(data)
    exe = Path(sys.executable).parent / "snakekit"
    r = subprocess.run([str(exe), "check", f"{name}.ipynb"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2, r.stdout + r.stderr
    assert r.stderr.startswith("snakekit check: ") and words in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr + r.stdout


def _check_with_a_3_s_limit(folder, cells):
    """``snakekit check --timeout 3`` on a notebook of ``cells``: its result (exit 1) and rows, split in words."""
    import nbformat
    from nbformat.v4 import new_notebook

    nbformat.write(new_notebook(cells=cells), folder / "lesson.ipynb")
    r = subprocess.run([str(Path(sys.executable).parent / "snakekit"), "check", "--timeout", "3", "lesson.ipynb"],
                       cwd=folder, capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stdout + r.stderr
    return r, [line.split() for line in r.stdout.splitlines()]


def test_check_interrupts_an_endless_loop_and_checks_the_cells_after_it(tmp_path):
    """As in the grader, a runaway cell costs only its own exercise: interrupted at the limit, the
    run goes on, an answer cell's loop is named too, and every later check is reported."""
    import nbformat
    from nbformat.v4 import new_code_cell, new_notebook

    answer = new_code_cell("def settle():\n    n = 0\n    while n < 10:\n        pass\n    return n\nx = 0\n"
                           "while x < 3:\n    y = x",
                           metadata={"nbgrader": {"solution": True, "grade": False, "grade_id": "loop_answer"}})
    cells = [_graded("assert 1 + 1 == 2", grade_id="first_test", points=1), answer,
             _graded("settle()", grade_id="stuck_test", points=2), _graded("assert True", grade_id="after_test", points=3)]
    r, rows = _check_with_a_3_s_limit(tmp_path, cells)
    assert ["first_test", "1", "pt", "passed"] in rows
    assert ["after_test", "3", "pt", "passed"] in rows, r.stdout
    stuck = next(line for line in r.stdout.splitlines() if line.split()[:1] == ["stuck_test"])
    assert "FAILED  stopped after 3 s, the limit for one cell: most likely an endless loop" in stuck, r.stdout
    assert "  also failed: the answer cell loop_answer: stopped after 3 s, the limit for one cell" in r.stdout
    assert "2 of 3 exercises passed, 4 of 6 points" in r.stdout
    assert "stopped:" not in r.stdout and "KeyboardInterrupt" not in r.stdout and "Traceback" not in r.stdout + r.stderr


@pytest.mark.parametrize("body, stopped", [
    ("import signal, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nwhile True:\n    time.sleep(0.1)",
     "stopped: the check cell of exercise 9.2 ran longer than 3 s and did not stop when interrupted"),
    ("import os\nos._exit(1)", "stopped: the Python kernel died while running the check cell of exercise 9.2 (the process ended"),
])
def test_check_reports_a_cell_that_never_ends_or_kills_the_kernel(tmp_path, body, stopped):
    """The cell is named as a student finds it in JupyterLab (by its exercise), not by its index among all cells:
    the markdown cell before it would make that index one a student cannot count."""
    from nbformat.v4 import new_markdown_cell

    cells = [_graded("assert 1 + 1 == 2", grade_id="ex09_1_first_test", points=1), new_markdown_cell("### Exercise 9.2"),
             _graded(body, grade_id="ex09_2_stuck_test", points=2), _graded("assert True", grade_id="ex09_3_after_test", points=3)]
    r, rows = _check_with_a_3_s_limit(tmp_path, cells)
    assert ["ex09_1_first_test", "1", "pt", "passed"] in rows
    assert ["ex09_2_stuck_test", "2", "pt", "FAILED", "stopped", "here", "(see", "below)"] in rows
    assert ["ex09_3_after_test", "3", "pt", "FAILED", "not", "run", "(the", "check", "cell", "of", "exercise", "9.2",
            "stopped", "the", "run)"] in rows
    assert "cell 3" not in r.stdout
    assert "1 of 3 exercises passed, 1 of 6 points" in r.stdout
    assert stopped in r.stdout and "Traceback" not in r.stdout + r.stderr


@pytest.mark.parametrize("value", ["nan", "0", "-5", "inf"])
def test_check_timeout_must_be_a_time(tmp_path, value):
    exe = Path(sys.executable).parent / "snakekit"
    r = subprocess.run([str(exe), "check", "--timeout", value, "lesson.ipynb"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2
    assert "argument --timeout: --timeout must be a finite number > 0 and <= 86400 [s]" in r.stderr


# --- every public function, every argument: generated bad values --------------------------------
#
# For each argument of each public function that takes numbers, arrays, files or options, the
# bad values of its kind are generated, and every one must raise a SnakekitError whose message
# is under 300 characters (an input of a million characters is quoted by a short excerpt).

NAN, INF = float("nan"), float("inf")
LONG = "x" * 1_000_000  # a million characters: the message must quote an excerpt only
HUGE_ROWS = 10_000_000  # rows of a "huge" array: a read-only broadcast, so the test takes no memory for it


def _huge(shape_tail=()):
    return np.broadcast_to(0.0, (HUGE_ROWS, *shape_tail))


def _bad_values(kind, good):
    """(label, value) of the bad values of an argument of ``kind``, built around a ``good`` value."""
    if kind in ("count", "positive", "bounded", "fraction", "seed", "nonneg", "real"):
        out = [("nan", NAN), ("inf", INF), ("bool", True), ("long_str", LONG), ("none", None), ("list", [1.0, 2.0])]
        if kind in ("count", "bounded", "fraction"):  # a seed may be any whole number >= 0
            out.append(("huge", 10 ** 12 if kind == "count" else 1e300))
        if kind in ("count", "positive", "bounded", "fraction", "seed", "nonneg"):
            out.append(("negative", -1))
        if kind in ("count", "seed"):
            out.append(("fraction", 2.5))
        if kind == "real":
            out.remove(("none", None))  # the optional ones take None: see OPTIONAL
        return out
    if kind in ("times", "elementwise"):  # one time or a list of times [s] (elementwise: an array of any shape)
        out = [("nan", [0.1, NAN]), ("inf", [INF]), ("bool", [0.1, True]), ("str", [0.1, "x"]), ("long_str", LONG),
               ("none", None), ("huge", _huge())]
        return out + ([("table", np.zeros((2, 2)))] if kind == "times" else [])
    if kind == "array":  # a float array of a known shape (good), e.g. q (5,), target (2,), positions (N, 5)
        good = np.asarray(good, dtype=float)
        flat = good.ravel().tolist()

        def put(x):
            vals = list(flat)
            vals[len(vals) // 2] = x
            return np.array(vals, dtype=object).reshape(good.shape).tolist()
        return [("nan", put(NAN)), ("inf", put(-INF)), ("bool", put(True)), ("str", put("x")),
                ("long_str", LONG), ("none", None), ("wrong_shape", np.zeros((good.shape[0] + 1, *good.shape[1:])).T
                                                       if good.ndim == 2 else np.zeros(good.size + 1)),
                ("huge", _huge(good.shape[1:])), ("number", 0.5) if good.ndim else ("list", [0.5, 0.5])]
    if kind == "path":
        return [("none", None), ("int", 5), ("list", ["run.npz"]), ("bytes", b"run.npz"),
                ("too_long", "x" * 100_000 + ".npz"), ("nul", "run\0.npz")]
    if kind == "flag":
        return [("str", "no"), ("int", 1), ("none", None), ("nan", NAN)]
    if kind == "spec":
        return [("str", "SPEC"), ("none", None), ("dict", {"n_joints": 5})]
    if kind == "choice":
        return [("unknown", "nonsense"), ("none", None), ("list", ["a"]), ("long_str", LONG)]
    if kind == "trajectory":
        return [("none", None), ("array", np.zeros((10, 5))), ("str", LONG)]
    raise AssertionError(kind)


#: Arguments that take None on purpose (leaving them out): by name, or "function:name".
OPTIONAL = {"heading", "q0", "duration", "velocities", "progress", "ids", "margin", "times", "rate", "robot.render:q"}


def _tr():
    return joint_trajectory(np.zeros(5), [0.2, 0, 0, 0, 0], 1.0, rate=20)


def _public_calls():
    """(function label, argument, kind, good value, call(value)) for every checked argument."""
    from snakekit import trajectory as T
    from snakekit.robot import JointState

    sk = snakekit
    q5, xy = [0.1, 0.2, 0.1, 0.0, -0.1], [0.25, 0.1]
    calls = []

    def add(label, fn, args):
        for arg, kind, good in args:
            calls.append((label, arg, kind, good, (lambda fn, arg: lambda v: fn(**{arg: v}))(fn, arg)))

    for name in ("forward_kinematics", "joint_frames", "tool_pose_2d", "jacobian", "planar_jacobian",
                 "clearance", "as_configuration", "check_limits"):
        f = getattr(sk, name)
        add(name, lambda f=f, q=q5, spec=SPEC: f(q, spec=spec), [("q", "array", q5), ("spec", "spec", SPEC)])
    add("collides", lambda q=q5, margin=None, spec=SPEC: sk.collides(q, spec=spec, margin=margin),
        [("q", "array", q5), ("margin", "nonneg", 0.005), ("spec", "spec", SPEC)])
    ik = dict(target_xy=xy, heading=None, q0=None, tol=1e-6, max_iter=100, restarts=2, seed=0, spec=SPEC)
    add("inverse_kinematics", lambda **kw: sk.inverse_kinematics(**{**ik, **kw}),
        [("target_xy", "array", xy), ("heading", "real", 0.3), ("q0", "array", q5), ("tol", "positive", 1e-6),
         ("max_iter", "count", 100), ("restarts", "count", 2), ("seed", "seed", 0), ("spec", "spec", SPEC)])
    add("closest_reachable_point", lambda target_xy=xy, heading=None, q0=None, seed=0, spec=SPEC:
        sk.closest_reachable_point(target_xy, heading, q0, seed=seed, spec=spec),
        [("target_xy", "array", xy), ("heading", "real", 0.3), ("q0", "array", q5), ("seed", "seed", 0),
         ("spec", "spec", SPEC)])
    add("SnakeSpec", lambda **kw: sk.forward_kinematics(np.zeros(5), spec=sk.SnakeSpec(**kw)),
        [("n_joints", "count", 5), ("link_length", "bounded", 0.071), ("tool_offset", "bounded", 0.0475),
         ("velocity_limit", "bounded", 1.5), ("link_mass", "bounded", 0.012), ("collision_margin", "bounded", 0.005),
         ("lower", "real", -1.57), ("upper", "real", 1.57), ("servo_ids", "array", (1, 2, 3, 4, 5))])
    add("workspace_points", lambda n=3, seed=0, spec=SPEC: sk.workspace_points(n, seed=seed, spec=spec),
        [("n", "count", 3), ("seed", "seed", 0), ("spec", "spec", SPEC)])
    add("workspace_boundary", lambda **kw: sk.workspace_boundary(**kw),
        [("bins", "count", 120), ("samples", "count", 20000), ("refine", "count", 60), ("seed", "seed", 0),
         ("spec", "spec", SPEC)])
    tr = _tr()
    add("Trajectory", lambda times=tr.times, positions=tr.positions, velocities=None, n_joints=5:
        Trajectory(times, positions, velocities, n_joints),
        [("times", "array", tr.times), ("positions", "array", tr.positions), ("velocities", "array", tr.positions),
         ("n_joints", "count", 5)])
    add("Trajectory.sample", lambda t=0.5: tr.sample(t), [("t", "times", [0.1, 0.5])])
    add("Trajectory.resample", lambda rate=None, times=None: tr.resample(rate, times=times),
        [("rate", "bounded", 10.0), ("times", "times", [0.0, 0.5])])
    add("Trajectory.check_limits", lambda spec=SPEC, velocity=True: tr.check_limits(spec, velocity=velocity),
        [("spec", "spec", SPEC), ("velocity", "flag", True)])
    add("Trajectory.limit_violations", lambda spec=SPEC, velocity=True: tr.limit_violations(spec, velocity=velocity),
        [("spec", "spec", SPEC), ("velocity", "flag", True)])
    add("Trajectory.save", lambda path: tr.save(path), [("path", "path", "t.npz")])
    add("Trajectory.load", lambda path="t.npz", n_joints=5: Trajectory.load(path, n_joints=n_joints),
        [("path", "path", "t.npz"), ("n_joints", "count", 5)])
    jt = dict(q_start=np.zeros(5), q_end=q5, duration=1.0, method="quintic", rate=100.0, spec=SPEC, speed_fraction=0.8)
    add("joint_trajectory", lambda **kw: joint_trajectory(**{**jt, **kw}),
        [("q_start", "array", np.zeros(5)), ("q_end", "array", q5), ("duration", "bounded", 1.0),
         ("method", "choice", "quintic"), ("rate", "bounded", 100.0), ("spec", "spec", SPEC)])
    add("joint_trajectory(speed_fraction)", lambda speed_fraction: joint_trajectory(
        np.zeros(5), q5, speed_fraction=speed_fraction), [("speed_fraction", "fraction", 0.8)])
    add("side_sweep", lambda **kw: side_sweep(**kw),
        [("points", "count", 500), ("rate", "bounded", 10.0), ("sweeps", "count", 50), ("amplitude", "real", 0.2),
         ("spec", "spec", SPEC)])
    for name in ("cubic", "quintic", "trapezoidal"):
        f = getattr(T, f"{name}_time_scaling")
        add(f"{name}_time_scaling", lambda f=f, T=2.0, t=1.0: f(T, t), [("T", "positive", 2.0), ("t", "elementwise", [0.5, 1])])
    add("trapezoidal_time_scaling(accel_fraction)", lambda accel_fraction: T.trapezoidal_time_scaling(
        2.0, 1.0, accel_fraction=accel_fraction), [("accel_fraction", "fraction", 0.25)])
    z = np.zeros(5)
    add("JointState", lambda time=0.0, positions=z, velocities=z, efforts=z: JointState(time, positions, velocities,
                                                                                           efforts),
        [("time", "real", 0.0), ("positions", "array", z), ("velocities", "array", z), ("efforts", "array", z)])
    with snakekit.make_robot("sim") as robot:
        run = robot.run(_tr())
    m = run.measured
    add("Run", lambda commanded=run.commanded, measured=m, efforts=run.efforts, backend="sim", wall_time=1.0,
        realtime=False: Run(commanded, measured, efforts, backend, wall_time, realtime),
        [("commanded", "trajectory", run.commanded), ("measured", "trajectory", m), ("efforts", "array", run.efforts),
         ("wall_time", "nonneg", 1.0), ("realtime", "flag", False)])
    add("Run.save", lambda path: run.save(path), [("path", "path", "r.npz")])
    add("Run.load", lambda path: Run.load(path), [("path", "path", "r.npz")])
    add("make_robot('sim')", lambda **kw: snakekit.make_robot("sim", **kw).close(),
        [("realtime", "flag", False), ("q0", "array", q5), ("spec", "spec", SPEC), ("profile_velocity", "count", 30),
         ("profile_acceleration", "count", 10), ("any_profile", "flag", False)])
    add("make_robot('emulator')", lambda **kw: snakekit.make_robot("emulator", **kw).close(),
        [("motion", "choice", "mujoco"), ("q0", "array", q5), ("timing", "flag", False),
         ("boot_time", "bounded", 0.05), ("baudrate", "count", 4_000_000), ("ids", "array", [1, 2, 3, 4, 5]),
         ("latency_timer", "count", 0)])
    add("make_robot('hardware')", lambda **kw: snakekit.make_robot("hardware", **{"port": "/dev/no-such-port", **kw}),
        [("baudrate", "count", 4_000_000), ("retries", "count", 3), ("profile_velocity", "count", 30),
         ("watchdog", "bounded", 0.1), ("on_close", "choice", "torque_off"), ("ids", "array", [1, 2, 3, 4, 5])])
    add("make_robot", lambda backend: snakekit.make_robot(backend), [("backend", "choice", "sim")])
    return calls


def _robot_calls():
    """(method label, argument, kind, good value, call(robot, value)) for a simulated robot's methods."""
    q5 = [0.1, 0.2, 0.1, 0.0, -0.1]
    tr = _tr()
    out = []

    def add(label, fn, args):
        for arg, kind, good in args:
            out.append((label, arg, kind, good, (lambda fn, arg: lambda robot, v: fn(robot, **{arg: v}))(fn, arg)))

    add("robot.command", lambda r, q: r.command(q), [("q", "array", q5)])
    add("robot.move_to", lambda r, q=q5, duration=1.0: r.move_to(q, duration),
        [("q", "array", q5), ("duration", "bounded", 1.0)])
    add("robot.home", lambda r, duration: r.home(duration), [("duration", "bounded", 1.0)])
    add("robot.run", lambda r, trajectory=tr, record_rate=100.0, settle=0.5, progress=None: r.run(
        trajectory, record_rate=record_rate, settle=settle, progress=progress),
        [("trajectory", "trajectory", tr), ("record_rate", "bounded", 100.0), ("settle", "bounded", 0.5),
         ("progress", "flag", False)])
    add("robot.step", lambda r, duration: r.step(duration), [("duration", "bounded", 0.1)])
    add("robot.render", lambda r, q=None, width=64, height=48, camera="perspective": r.render(
        q, width=width, height=height, camera=camera),
        [("q", "array", q5), ("width", "count", 64), ("height", "count", 48), ("camera", "choice", "perspective")])
    return out


def _cases(calls):
    cases = []
    for label, arg, kind, good, call in calls:
        for bad, value in _bad_values(kind, good):
            if value is None and (arg in OPTIONAL or f"{label}:{arg}" in OPTIONAL):
                continue
            cases.append(pytest.param(call, value, id=f"{label}-{arg}-{bad}"))
    return cases


def _refused_clearly(call, value, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _tr().save(tmp_path / "t.npz")
    with pytest.raises(Exception) as e:
        call(value)
    assert isinstance(e.value, snakekit.SnakekitError), f"{type(e.value).__name__}: {str(e.value)[:300]}"
    assert 0 < len(str(e.value)) < 300, f"{len(str(e.value))} characters: {str(e.value)[:400]}"


@pytest.mark.parametrize("call, value", _cases(_public_calls()))
def test_every_public_function_refuses_every_bad_value_in_a_short_message(call, value, tmp_path, monkeypatch):
    _refused_clearly(call, value, tmp_path, monkeypatch)


@pytest.fixture(scope="module")
def sim_robot():
    with snakekit.make_robot("sim") as robot:
        yield robot


@pytest.mark.parametrize("call, value", _cases(_robot_calls()))
def test_every_robot_method_refuses_every_bad_value_in_a_short_message(sim_robot, call, value, tmp_path,
                                                                        monkeypatch):
    _refused_clearly(lambda v: call(sim_robot, v), value, tmp_path, monkeypatch)
    assert not sim_robot.closed


# --- the probe's cases, one by one: what the user reads --------------------------------------------


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A run saved by Run.save (a 1 s move on the simulator), and its bytes."""
    path = tmp_path_factory.mktemp("run") / "run.npz"
    with snakekit.make_robot("sim") as robot:
        robot.run(small()).save(path)
    return path, path.read_bytes()


@pytest.mark.parametrize("fraction", [0.0, 0.1, 0.5, 0.9, 0.999])
def test_a_truncated_run_file_is_refused(tmp_path, run_file, fraction):
    _, data = run_file
    cut = tmp_path / "cut.npz"
    cut.write_bytes(data[: int(len(data) * fraction)])
    words = ("is empty" if fraction == 0 else
             "is not a readable .npz file (File is not a zip file); it may be truncated or damaged. Save runs with "
             "Run.save")
    with raises(snakekit.FileFormatError, f"{cut} " + words if fraction else words):  # before: BadZipFile
        Run.load(cut)


def _zip_structure(data: bytes) -> list[int]:
    """The offsets of every byte of a zip file's headers (local, central directory, end record)."""
    out = []
    for magic, size in ((b"PK\x03\x04", 30), (b"PK\x01\x02", 46), (b"PK\x05\x06", 22)):
        at = data.find(magic)
        while at >= 0:
            out += range(at, min(at + size + 20, len(data)))  # the fixed part and the name after it
            at = data.find(magic, at + 1)
    return sorted(set(out))


def test_every_bit_flip_in_a_run_file_is_refused_or_harmless(tmp_path):
    """A flipped bit in an array breaks its checksum (refused); in a zip or array header, the file
    is refused or, where the byte does not matter (a time stamp), read as the same run. Every byte
    of the headers is flipped (three bits each), and every 13th byte of the rest."""
    with snakekit.make_robot("sim") as robot:
        robot.run(small(), record_rate=10, settle=0).save(tmp_path / "run.npz")
    data = (tmp_path / "run.npz").read_bytes()
    good = Run.load(tmp_path / "run.npz")
    flipped = tmp_path / "flip.npz"
    outcomes = {"refused": 0, "same": 0}
    headers = _zip_structure(data)
    flips = [(at, bit) for at in headers for bit in (0x01, 0x10, 0x80)] + [
        (at, 0x10) for at in range(0, len(data), 13) if at not in headers]
    for at, bit in flips:
        b = bytearray(data)
        b[at] ^= bit
        flipped.write_bytes(bytes(b))
        try:
            run = Run.load(flipped)
        except snakekit.FileFormatError as e:  # before: BadZipFile "Bad CRC-32 for file 'measured_positions.npy'",
            assert str(e).startswith(f"{flipped} is"), str(e)  # RuntimeError "... is encrypted", SyntaxError...
            assert len(str(e).replace(str(flipped), "")) < 250, str(e)
            outcomes["refused"] += 1
            continue
        for a, g in ((run.measured.positions, good.measured.positions), (run.efforts, good.efforts),
                     (run.commanded.positions, good.commanded.positions), (run.measured.times, good.measured.times)):
            np.testing.assert_array_equal(a, g)
        assert (run.backend, run.wall_time, run.realtime) == (good.backend, good.wall_time, good.realtime)
        outcomes["same"] += 1
    assert outcomes["refused"] > 0.4 * len(flips), outcomes  # 1921 of 3342 measured: the rest are time stamps...


def test_a_run_whose_efforts_do_not_match_its_samples_is_refused(tmp_path, run_file):
    path, _ = run_file
    arrays = dict(np.load(path))
    arrays["efforts"] = np.zeros((3, 2))
    np.savez(tmp_path / "efforts.npz", **arrays)
    n = len(arrays["measured_times"])
    with raises(snakekit.FileFormatError, f"efforts.npz is not a snakekit run file (efforts must have shape ({n}, 5) "
                "(one row per measured sample, one column per joint), got shape (3, 2)); save runs with Run.save"):
        Run.load(tmp_path / "efforts.npz")  # before: accepted
    run = Run.load(path)
    with raises(snakekit.ShapeError, f"efforts must have shape ({n}, 5)"):
        Run(run.commanded, run.measured, run.efforts[:, :3], "sim", 1.0, False)


@pytest.mark.parametrize("path", [5, None, ["t.npz"], b"t.npz"])
def test_trajectory_files_are_named_by_paths(tmp_path, path):
    kind = type(path).__name__
    with raises(snakekit.InputTypeError, f"the trajectory file must be a path (a str or pathlib.Path), got {path!r} "
                f"({kind}); e.g. 'run.npz'"):
        Trajectory.load(path)  # before: TypeError "expected str, bytes or os.PathLike object"
    with raises(snakekit.InputTypeError, "the trajectory file must be a path"):
        small().save(path)


def test_a_ten_million_point_trajectory_is_refused_before_memory_is_taken():
    n = 10_000_000
    times = np.broadcast_to(0.0, (n,))  # no memory of its own: only the check may look at it
    with raises(snakekit.ConfigurationError, "trajectory times holds 10000000 points, more than the 1000000 the kit "
                "handles; use fewer points (a lower rate, or shorter moves)"):
        Trajectory(times, np.broadcast_to(0.0, (n, 5)))  # before: MemoryError from robot.run, after 67 s
    with raises(snakekit.ConfigurationError, "t holds 10000000 points"):
        small().sample(times)


def test_a_trajectory_file_of_too_many_points_is_refused_unread(tmp_path):
    np.savez(tmp_path / "big.npz", times=np.zeros(2_000_000), positions=np.zeros((2, 5)))
    with raises(snakekit.FileFormatError, "big.npz: array 'times' has shape (2000000,), more than the 1000000 points "
                "the kit handles; it was not read"):
        Trajectory.load(tmp_path / "big.npz")


def test_the_probes_wrong_types_and_nan_get_clear_errors():
    with raises(snakekit.InputTypeError, "seed must be a whole number >= 0, got 'x' (str). It picks the random draws"):
        snakekit.workspace_points(5, seed="x")  # before: numpy's TypeError from SeedSequence
    from snakekit.trajectory import trapezoidal_time_scaling

    with raises(snakekit.InputTypeError, "accel_fraction must be a finite number > 0 and <= 0.5, got 'x' (str)"):
        trapezoidal_time_scaling(1.0, 0.5, accel_fraction="x")  # before: TypeError "'<' not supported"
    tr = small()
    with raises(snakekit.NotFiniteError, "t holds NaN or infinity; every value must be finite. Give the time(s) [s] "
                "to sample at"):
        tr.sample(float("nan"))  # before: NaN positions
    with raises(snakekit.NotFiniteError, "t holds NaN or infinity (first at index 1)"):
        tr.sample([0.5, float("inf")])  # before: the last point, silently
    with raises(snakekit.ConfigurationError, "boot_time must be a finite number from 0 to 10 [s], got nan"):
        snakekit.make_robot("emulator", boot_time=float("nan"))  # before: accepted


@pytest.mark.parametrize("size", [8_900_000, 150_000_000])
def test_a_message_quotes_a_short_excerpt_of_a_huge_input(size):
    text = "x" * size
    # before: messages of 8.9 and 150 million characters
    with raises(snakekit.InputTypeError, f"rate must be a finite number > 0 and <= 10000 [Hz], got '{'x' * 27}...{'x' * 28}' "
                f"({size} characters) (str)") as e:
        side_sweep(rate=text)
    assert len(str(e.value)) < 250
    with raises(snakekit.InputTypeError, f"q holds '{'x' * 27}...{'x' * 28}' ({size} characters), which is not a number"):
        snakekit.forward_kinematics([text, 0, 0, 0, 0])


def test_a_csv_without_newlines_is_refused_by_its_first_line(tmp_path):
    p = tmp_path / "one_line.csv"
    p.write_text("1," * 5_000_000)
    with raises(snakekit.FileFormatError, f"{p}: its first line is longer than 4096 characters (it starts "
                f"'{'1,' * 15}'), so it is not the header time,q1..q5") as e:
        Trajectory.load(p)
    assert len(str(e.value)) < 300
    p.write_text("time,q1,q2,q3,q4,q5\n" + "1" * 10_000_000)
    with raises(snakekit.FileFormatError, f"{p}, line 2: a value longer than 131072 characters; a trajectory .csv "
                "holds only numbers below its header"):
        Trajectory.load(p)  # before: csv.Error


def test_check_reads_an_nbformat_3_notebook(tmp_path):
    """nbformat 3 keeps its cells in worksheets: the lesson is converted to version 4, as it was before."""
    import nbformat
    from nbformat.v4 import new_notebook

    nb = new_notebook(cells=[_graded("assert 1 + 1 == 2", grade_id="first_test", points=1),
                             _graded("assert 1 == 2, 'one is not two'", grade_id="second_test", points=2)])
    nbformat.write(nbformat.convert(nb, 3), tmp_path / "old.ipynb", version=3)
    assert '"worksheets"' in (tmp_path / "old.ipynb").read_text()
    exe = Path(sys.executable).parent / "snakekit"
    r = subprocess.run([str(exe), "check", "old.ipynb"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stdout + r.stderr  # before: exit 2, "JSON but not a Jupyter notebook"
    rows = [line.split() for line in r.stdout.splitlines()]
    assert ["first_test", "1", "pt", "passed"] in rows
    assert ["second_test", "2", "pt", "FAILED", "AssertionError:", "one", "is", "not", "two"] in rows
    assert "1 of 2 exercises passed, 1 of 3 points" in r.stdout


@pytest.mark.parametrize("backend", ["sim", "emulator"])
def test_ctrl_c_during_sweep_saves_the_partial_run(tmp_path, backend):
    """Ctrl-C part way through ``snakekit sweep --out``: the goals sent and the motion recorded so
    far are saved to the --out file, the user is told, the robot is closed and the exit is 130."""
    import signal
    import time

    options = ["--realtime"] if backend == "sim" else []
    proc = subprocess.Popen([sys.executable, "-m", "snakekit.cli", "sweep", "--backend", backend, *options,
                             "--out", "run.npz"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().startswith("Task 2: 500 goals")  # printed just before the robot is made
        time.sleep(4)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err  # before: 130, but the run was lost
    run = Run.load(tmp_path / "run.npz")
    sent = len(run.commanded)
    assert 0 < sent < 500
    assert f"snakekit sweep: the partial run ({sent} of 500 goals, {run.robot_time:.1f} s recorded) was saved to " \
           "run.npz" in err
    assert err.rstrip().endswith("snakekit sweep: interrupted; the robot was closed")
    np.testing.assert_array_equal(run.commanded.positions, side_sweep().positions[:sent])  # the goals as planned
    # the recording covers the goals sent: the last one went out inside the recorded time
    assert run.commanded.times[-1] <= run.measured.times[-1] + 0.1
    assert run.backend == backend and len(run.measured) > 10


# --- the command line: every bad argument is exit 2 and one line --------------------------------

LONG_NAME = "x" * 5000  # longer than a file name may be


@pytest.mark.parametrize("args, words", [
    (["sweep", "--backend", "gazebo"], "snakekit sweep: argument --backend: invalid choice: 'gazebo'"),
    (["sweep", "--backend", LONG_NAME], "snakekit sweep: argument --backend: invalid choice: 'xxx"),
    (["sweep", "--bogus"], "snakekit: unrecognized arguments: --bogus; see snakekit --help"),
    (["sweep", "--out", "run.txt"], "snakekit sweep: run file run.txt must end in .npz or .mcap or .bag"),
    (["sweep", "--out", "missing/run.npz"], "snakekit sweep: cannot write run file missing/run.npz: folder"),
    (["sweep", "--out", LONG_NAME + ".npz"], "(5004 characters): File name too long. Choose a place you can write"),
    (["sweep", "--plot", "plot.txt"], "snakekit sweep: plot plot.txt must end in .png or .pdf or .svg"),
    (["sweep", "--plot", LONG_NAME + ".png"], "(5004 characters): File name too long"),
    (["sweep", "--backend", "hardware"], "snakekit sweep: --backend hardware needs --port"),
    (["ros", "--backend", "hardware"], "snakekit ros: --backend hardware needs --port"),
    (["ros", "--backend", "gazebo"], "snakekit ros: argument --backend: invalid choice: 'gazebo'"),
    (["ros", "--rate", "0"], "snakekit ros: argument --rate: --rate must be a finite number > 0 and <= 1000 [Hz], got 0.0"),
    (["ros", "--rate", "abc"], "snakekit ros: argument --rate: not a number of Hz: 'abc'"),
    (["check"], "snakekit check: the following arguments are required: notebook; see snakekit check --help"),
    (["check", "missing.ipynb"], "snakekit check: missing.ipynb is not a notebook file"),
    (["check", "notes.txt"], "snakekit check: notes.txt is not a notebook file"),
    (["check", LONG_NAME + ".ipynb"], ".ipynb (5006 characters) can't be opened: File name too long"),
    (["check", "--timeout", "abc", "x.ipynb"], "snakekit check: argument --timeout: not a number of seconds: 'abc'"),
    (["check", "--timeout", LONG_NAME, "x.ipynb"], "not a number of seconds: 'xxxxxxxxxxxxxxxxxxxxxxxxxxx...x"),
    (["generate", "--nothing"], "snakekit: unrecognized arguments: --nothing"),
    ([], "snakekit: the following arguments are required: COMMAND; see snakekit --help"),
], ids=lambda v: v[:40] if isinstance(v, str) else "-".join(x[:12] for x in v) or "none")
def test_every_bad_argument_is_exit_2_and_one_line(tmp_path, monkeypatch, args, words):
    monkeypatch.delenv("SNAKEKIT_PORT", raising=False)
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", *args], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2, r.stdout + r.stderr
    assert words in r.stderr, r.stderr
    # before: usage lines, or a traceback; the length leaves out the working folder (named twice for a missing one)
    assert len(r.stderr.splitlines()) == 1 and len(r.stderr.replace(str(tmp_path), "")) < 300, r.stderr
    assert "Traceback" not in r.stderr and "Task 2" not in r.stdout
