"""The control panel, driven through the same callbacks its widgets call (no browser)."""

import numpy as np
import pytest

from tests.conftest import need

need("ipywidgets")
need("meshcat")

import snakekit  # noqa: E402
from snakekit.model import SPEC  # noqa: E402
from snakekit.robot import JointState, Robot  # noqa: E402
from snakekit.kinematics import boundary_configurations  # noqa: E402
from snakekit.viewer import Viewer  # noqa: E402
from snakekit.plots import plot_move  # noqa: E402
from snakekit.widgets import ControlPanel  # noqa: E402


class IdealArm(Robot):
    """A backend written here, to show the panel needs nothing but the Robot interface."""

    backend = "ideal"

    def __init__(self):
        super().__init__(SPEC)
        self.t, self.q, self.sent = 0.0, np.zeros(5), 0

    def read(self):
        return JointState(self.t, self.q, np.zeros(5), np.zeros(5))

    def _send(self, q):
        self.q, self.sent = np.array(q), self.sent + 1

    def _now(self):
        return self.t

    def _advance(self, t):
        self.t = max(self.t, t)


@pytest.fixture(scope="module")
def viewer():
    with Viewer() as v:
        yield v


@pytest.fixture
def sim():
    with snakekit.make_robot("sim") as robot:
        yield robot


def test_sliders_start_at_the_robot_and_move_the_goal(sim, viewer):
    sim.command([0.3, 0, 0, 0, 0])
    sim.step(2.0)
    panel = ControlPanel(sim, viewer)
    assert panel.slider_values == pytest.approx(sim.read().positions, abs=0.01)
    panel.sliders[2].value = 0.9  # what dragging the slider does
    assert panel.goal[2] == 0.9
    x, y, h = snakekit.tool_pose_2d(panel.goal)
    assert (panel.target_x.value, panel.target_y.value) == pytest.approx((x, y))
    assert panel.target_heading.value == pytest.approx(h)
    assert viewer.q == pytest.approx(sim.read().positions)  # the robot arm did not move
    assert "Press Execute" in panel.message


def test_sliders_are_bounded_by_the_joint_limits(sim):
    panel = ControlPanel(sim)
    for s in panel.sliders:
        assert (s.min, s.max) == (SPEC.lower, SPEC.upper)
        assert "[rad]" in s.description
    with pytest.raises(snakekit.LimitError, match="outside the joint limits"):
        panel.set_joints([2.0, 0, 0, 0, 0])


@pytest.mark.parametrize("target", [(0.25, 0.10, 0.3), (0.12, 0.22, 1.6), (-0.05, -0.20, None)])
def test_target_is_reached_by_forward_kinematics(sim, target):
    panel = ControlPanel(sim)
    x, y, heading = target
    q = panel.set_target(x, y, heading)
    assert q is not None and panel.execute_button.disabled is False
    assert np.all(np.abs(q) <= SPEC.upper)
    pose = snakekit.tool_pose_2d(q)
    assert pose[:2] == pytest.approx([x, y], abs=1e-5)
    if heading is not None:
        assert pose[2] == pytest.approx(heading, abs=1e-5)
    assert panel.slider_values == pytest.approx(q)
    assert "reachable" in panel.message


def test_moving_the_target_controls_solves_ik(sim):
    panel = ControlPanel(sim, heading=False)
    panel.target_x.value = 0.2  # what dragging the control does: the callback solves IK
    assert snakekit.tool_pose_2d(panel.goal)[:2] == pytest.approx([0.2, 0.0], abs=1e-5)
    panel.target_y.value = 0.12
    assert snakekit.tool_pose_2d(panel.goal)[:2] == pytest.approx([0.2, 0.12], abs=1e-5)
    assert panel.slider_values == pytest.approx(panel.goal)


def test_unreachable_target_names_the_closest_point(sim, viewer):
    panel = ControlPanel(sim, viewer)
    before = panel.goal.copy()
    assert panel.set_target(0.45, 0.05) is None
    # the closest reachable point to a target beyond reach is on the reach circle, towards it
    direction = np.array([0.45, 0.05]) / np.hypot(0.45, 0.05)
    expected = SPEC.reach * direction
    assert panel.closest == pytest.approx(expected, abs=0.003)
    assert f"Closest reachable tool point: ({panel.closest[0]:.3f}, {panel.closest[1]:.3f}) m" in panel.message
    assert panel.message.startswith("Unreachable")
    assert 'color:#c62828' in panel.status.value
    assert panel.goal == pytest.approx(before)
    assert panel.execute_button.disabled
    start = sim.read().positions
    assert panel.execute() is None and "unreachable" in panel.message
    assert sim.read().positions == pytest.approx(start)


def test_position_reachable_but_heading_not(sim):
    panel = ControlPanel(sim)
    assert panel.set_target(0.33, 0.0, np.pi) is None
    assert "but not with heading" in panel.message and "hold heading" in panel.message


def test_closest_point_is_no_farther_than_the_workspace_boundary(sim):
    panel = ControlPanel(sim)
    points, _ = boundary_configurations()
    for target in [(-0.35, 0.2), (0.0, -0.40), (-0.30, -0.05)]:
        panel.set_target(*target)
        cx, cy = panel.closest
        nearest = np.linalg.norm(points - target, axis=1).min()
        assert np.hypot(cx - target[0], cy - target[1]) <= nearest + 1e-9
        assert f"({cx:.3f}, {cy:.3f})" in panel.message


def test_execute_moves_the_robot_smoothly_within_limits(sim, viewer):
    panel = ControlPanel(sim, viewer)
    goal = panel.set_target(0.20, 0.15, 0.5)
    run = panel.execute()
    assert run is panel.last_run and run.backend == "sim"
    run.commanded.check_limits()  # positions and speeds
    v = run.commanded.finite_difference_velocities()
    assert np.abs(v[0]).max() < 0.05 and np.abs(v[-1]).max() < 0.05  # starts and ends at rest
    assert sim.read().positions == pytest.approx(goal, abs=0.01)
    assert snakekit.tool_pose_2d(sim.read().positions)[:2] == pytest.approx([0.20, 0.15], abs=0.003)
    assert viewer.q == pytest.approx(run.measured.positions[-1])
    assert panel.message.startswith("Move 1 done")


def test_plot_shows_commanded_and_measured_with_units(sim):
    panel = ControlPanel(sim)
    panel.set_joints([0.5, -0.3, 0.2, 0.0, 0.1])
    run = panel.execute()
    ax = panel.last_figure.axes[0]
    assert ax.get_xlabel() == "time [s]" and ax.get_ylabel() == "joint angle [deg]"
    lines = [ln for ln in ax.get_lines() if len(ln.get_xdata())]
    assert len(lines) == 10  # measured and commanded, per joint
    measured = lines[0]
    assert measured.get_ydata() == pytest.approx(np.degrees(run.measured.positions[:, 0]))
    assert lines[1].get_linestyle() == "--"
    assert plot_move(run).axes[0].get_legend() is not None


def test_execute_button_click_runs_the_move(sim):
    panel = ControlPanel(sim)
    panel.set_joints([0.2, 0.2, 0, 0, 0])
    panel.execute_button.click()
    assert panel.last_run is not None
    assert sim.read().positions == pytest.approx([0.2, 0.2, 0, 0, 0], abs=0.01)


def test_a_refused_move_is_reported_not_raised():
    robot = snakekit.make_robot("sim")
    panel = ControlPanel(robot)
    panel.set_joints([0.3, 0, 0, 0, 0])
    robot.close()
    assert panel.execute() is None
    assert "refused" in panel.message and "closed" in panel.message
    assert panel.execute_button.disabled is False


def test_a_goal_that_folds_the_arm_is_shown_and_not_executed(sim, viewer):
    panel = ControlPanel(sim, viewer, show_plot=False)
    panel.set_joints([1.57, 1.57, 1.57, 1.57, 0])
    assert panel.execute_button.disabled and panel.fold is not None
    assert panel.message.startswith("the move to the goal, ")
    assert "would fold the arm onto itself: base_link and link4 are" in panel.message
    assert "Execute is disabled" in panel.message and "#c62828" in panel.status.value
    assert panel.execute() is None and panel.runs == []
    assert "Nothing executed" in panel.message
    assert np.abs(sim.read().positions).max() < 1e-3
    panel.set_joints([0.3, 0.2, 0, 0, 0])  # open again: Execute comes back
    assert not panel.execute_button.disabled and panel.fold is None
    assert panel.execute() is not None


def test_a_goal_whose_move_folds_is_shown_even_when_the_goal_does_not():
    with snakekit.make_robot("sim", q0=[0.0, 0.5, 1.5, 1.5, -1.0]) as robot:
        panel = ControlPanel(robot, show_plot=False)
        panel.set_joints([0.0, 0.5, 1.5, 1.5, 1.5])
        assert panel.execute_button.disabled
        assert "the move to the goal" in panel.message and "base_link and link5" in panel.message


def test_any_backend_three_goal_changes():
    """The study's Task 1 on a backend that only implements the Robot interface."""
    arm = IdealArm()
    panel = ControlPanel(arm)
    for x, y, h in [(0.25, 0.10, 0.3), (0.12, 0.22, 1.6), (0.28, -0.08, -0.4)]:
        q = panel.set_target(x, y, h)
        panel.execute()
        assert arm.read().positions == pytest.approx(q)
        assert snakekit.tool_pose_2d(arm.read().positions) == pytest.approx([x, y, h], abs=1e-5)
    assert len(panel.runs) == 3 and arm.sent > 100


def test_emulated_bus_backend():
    with snakekit.make_robot("emulator") as robot:
        panel = ControlPanel(robot, duration=0.5)
        panel.set_joints([0.15, -0.1, 0, 0, 0])
        run = panel.execute()
        assert run.backend == "emulator"
        assert robot.read().positions == pytest.approx([0.15, -0.1, 0, 0, 0], abs=0.02)


def test_a_late_echo_from_the_browser_does_not_overwrite_the_goal(sim):
    """The browser sends back every value the kernel sets; an old one can arrive late."""
    panel = ControlPanel(sim)
    first = panel.set_target(0.28, -0.08, -0.4)
    panel.set_joints([0.6, -0.4, 0.8, -0.5, 0.3])
    panel.sliders[2].value = float(first[2]) + 1e-13  # the browser echoing the first value
    assert panel.goal == pytest.approx([0.6, -0.4, 0.8, -0.5, 0.3], abs=1e-12)
    assert panel.sliders[2].value == pytest.approx(0.8, abs=1e-12)
    panel.sliders[2].value = 0.55  # a student's drag still moves the goal
    assert panel.goal[2] == 0.55


def test_a_closed_view_gets_a_polite_message_not_an_error(sim):
    with Viewer() as view:
        panel = ControlPanel(sim, view)
        panel.set_joints([0.3, 0.0, 0.0, 0.0, 0.0])
    # the view is closed now (its cell was run again, or the kernel tidied up)
    run = panel.execute()
    assert run is not None and sim.read().positions[0] == pytest.approx(0.3, abs=0.01)
    assert panel.message.startswith("Move 1 done")
    assert "The 3D view is closed, so it no longer follows the arm" in panel.message
    assert panel.viewer is None
    panel.set_joints([0.0, 0.2, 0.0, 0.0, 0.0])  # and the panel goes on working
    assert "3D view is closed" not in panel.message


def test_a_graded_run_keeps_the_panels_figure_but_draws_it_into_no_widget():
    """In a kernel the panel's plot is a picture in its output widget. While the grader runs the notebook
    (``SNAKEKIT_CASES`` names its socket) the figure is made (``last_figure``) but not drawn: the widget's
    contents are in no page (the feedback shows a widget as one line), and a PNG per move was a third of
    lesson 00's grading time."""
    nbformat = need("nbformat")
    from tests.conftest import notebook_client

    setup = ("%matplotlib inline\nimport os\nimport snakekit\nfrom snakekit.widgets import ControlPanel\n"
             "os.environ.pop('SNAKEKIT_CASES', None)\nrobot = snakekit.make_robot('sim')")
    move = ("panel = ControlPanel(robot)\npanel.set_joints([0.3, -0.2, 0.1, 0.0, 0.0])\nrun = panel.execute()\n"
            "print(type(panel.last_figure).__name__, len(panel.last_figure.axes[0].get_lines()))")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(setup), nbformat.v4.new_code_cell(move),
                                         nbformat.v4.new_code_cell("os.environ['SNAKEKIT_CASES'] = 'graded.sock'"),
                                         nbformat.v4.new_code_cell(move)])
    notebook_client(nb, timeout=120, kernel_name="python3").execute()
    printed = ["".join(o.get("text", "") for o in c.outputs if o.output_type == "stream") for c in nb.cells]
    assert printed[1] == printed[3] == "RunFigure 12\n", printed  # made both times: 5 joints x 2 lines + 2 legend keys
    state = nb.metadata["widgets"]["application/vnd.jupyter.widget-state+json"]["state"]
    outputs = [m["state"].get("outputs", []) for m in state.values() if m["model_name"] == "OutputModel"]
    # one output widget per panel, in the order made: the first holds the plot as a picture, the graded one nothing
    pictures = [[o for o in out if "image/png" in o.get("data", {})] for out in outputs]
    assert [len(p) for p in pictures] == [1, 0], outputs
    assert pictures[0][0]["data"]["image/png"]  # base64 of a PNG
