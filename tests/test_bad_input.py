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
         f"no_grade_id.ipynb: cell 1 is a graded cell without a grade id (its nbgrader metadata was changed); {fresh}"),
        ("string_points", nb(_graded("assert True", grade_id="ex_test", points="2")),
         "string_points.ipynb: graded cell ex_test (cell 1) has points '2', not a number >= 0"),
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


@pytest.mark.parametrize("body, stopped", [
    ("while True:\n    pass", "stopped: cell 2 ran longer than 3 s and was stopped (an endless loop, or a long run"),
    ("import os\nos._exit(1)", "stopped: the Python kernel died while running cell 2 (the process ended"),
])
def test_check_reports_a_cell_that_never_ends_or_kills_the_kernel(tmp_path, body, stopped):
    import nbformat
    from nbformat.v4 import new_notebook

    cells = [_graded("assert 1 + 1 == 2", grade_id="first_test", points=1),
             _graded(body, grade_id="stuck_test", points=2), _graded("assert True", grade_id="after_test", points=3)]
    nbformat.write(new_notebook(cells=cells), tmp_path / "lesson.ipynb")
    exe = Path(sys.executable).parent / "snakekit"
    r = subprocess.run([str(exe), "check", "--timeout", "3", "lesson.ipynb"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 1, r.stdout + r.stderr
    rows = [line.split() for line in r.stdout.splitlines()]
    assert ["first_test", "1", "pt", "passed"] in rows
    assert ["stuck_test", "2", "pt", "FAILED", "stopped", "here", "(see", "below)"] in rows
    assert ["after_test", "3", "pt", "FAILED", "not", "run", "(cell", "2", "stopped", "the", "run)"] in rows
    assert "1 of 3 exercises passed, 1 of 6 points" in r.stdout
    assert stopped in r.stdout and "Traceback" not in r.stdout + r.stderr


@pytest.mark.parametrize("value", ["nan", "0", "-5", "inf"])
def test_check_timeout_must_be_a_time(tmp_path, value):
    exe = Path(sys.executable).parent / "snakekit"
    r = subprocess.run([str(exe), "check", "--timeout", value, "lesson.ipynb"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2
    assert "argument --timeout: --timeout must be a finite number > 0 and <= 86400 [s]" in r.stderr
