"""Plots as a person meets them: a picture in the notebook, angles in degrees, labelled."""

import numpy as np
import pytest
from IPython.core.formatters import DisplayFormatter

import snakekit
from snakekit.plots import ANGLE_UNIT, plot_move, plot_run


@pytest.fixture(scope="module")
def run():
    move = snakekit.joint_trajectory(np.zeros(5), [0.5, -0.3, 0.2, 0.0, 0.1], 1.0)
    with snakekit.make_robot("sim") as robot:
        return robot.run(move)


@pytest.mark.parametrize("plot", [plot_run, plot_move])
def test_a_plot_shows_as_a_picture_without_pyplot(run, plot):
    """A fresh IPython display formatter (no inline backend registered) gets a PNG."""
    data, _ = DisplayFormatter().format(plot(run))
    assert "image/png" in data
    assert data["image/png"][:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_run_draws_degrees(run):
    fig = plot_run(run)
    left = fig.axes[0]
    assert left.get_ylabel() == "joint 1\nangle [deg]" and ANGLE_UNIT == "deg"
    measured = [ln for ln in left.get_lines() if ln.get_label() == "measured"][0]
    assert measured.get_ydata() == pytest.approx(np.degrees(run.measured.positions[:, 0]))


def test_plot_runs_texts_all_lie_in_the_figure_and_none_overlaps_another():
    """The figure's margins are fixed (no layout engine measures them at each draw): each label, tick label, title
    and the legend must still have room, for a short run and a long one (its zoom panel), with angles near the
    limits (tick labels of three digits and a sign) and with the largest values a summary prints."""
    near = np.zeros(5)
    near[0] = np.broadcast_to(np.asarray(snakekit.SPEC.upper, float), (5,))[0] - 0.05  # joint 1 near its limit
    for duration, goal in ((1.0, [0.5, -0.3, 0.2, 0.0, 0.1]), (12.0, near), (12.0, -near), (1.0, np.zeros(5))):
        move = snakekit.joint_trajectory(np.zeros(5), goal, duration)
        with snakekit.make_robot("sim") as robot:
            fig = plot_run(robot.run(move), title=None)
        renderer = _drawn(fig)
        page = fig.bbox
        shown = [fig._suptitle] + [t for ax in fig.axes for t in (ax.title, ax.xaxis.label, ax.yaxis.label, *ax.texts)]
        texts = [(t, t.get_window_extent(renderer)) for t in shown if t is not None and t.get_visible() and t.get_text()]
        texts += [(t, t.get_window_extent(renderer)) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)
                  for tick, t in zip(axis.get_major_ticks(), axis.get_ticklabels())
                  if t.get_visible() and t.get_text() and min(axis.get_view_interval()) - 1e-9 <= tick.get_loc()
                  <= max(axis.get_view_interval()) + 1e-9]
        texts += [(ax.get_legend(), ax.get_legend().get_window_extent(renderer)) for ax in fig.axes if ax.get_legend()]
        assert len(texts) > 40, len(texts)
        out = [str(t) for t, b in texts if b.x0 < page.x0 - 0.5 or b.y0 < page.y0 - 0.5 or b.x1 > page.x1 + 0.5
               or b.y1 > page.y1 + 0.5]
        assert not out, f"{duration} s run: outside the figure: {out}"
        crowded = [(str(p), str(q)) for i, (p, a) in enumerate(texts) for q, b in texts[i + 1:] if _overlap(a, b)]
        assert not crowded, f"{duration} s run: texts overlap: {crowded[:5]}"


def test_plot_move_draws_degrees(run):
    ax = plot_move(run).axes[0]
    assert ax.get_ylabel() == "joint angle [deg]"
    assert ax.get_lines()[0].get_ydata() == pytest.approx(np.degrees(run.measured.positions[:, 0]))
    assert "deg" in ax.get_title() and "rad" not in ax.get_title()


def test_the_summary_speaks_degrees(run):
    text = run.summary()
    final = np.degrees(run.measured.positions[-1])
    assert "final joint angles: " + " ".join(f"{q:+.2f}" for q in final) + " deg" in text
    assert "rad" not in text


# --- the clearance of a move (lesson 4, section 5) -----------------------------------------------------------------

FOLD_A, FOLD_B = np.array([0.0, 0.5, 1.5, 1.5, -1.0]), np.array([0.0, 0.5, 1.5, 1.5, 1.5])   # lesson 4's move


def _drawn(fig):
    """The figure laid out as on the page: the renderer its texts were measured with."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


def _overlap(p, q) -> bool:
    """Whether two display boxes share more than a pixel's sliver."""
    return min(p.x1, q.x1) - max(p.x0, q.x0) > 0.5 and min(p.y1, q.y1) - max(p.y0, q.y0) > 0.5


@pytest.fixture(scope="module")
def clearance_figure():
    from snakekit.plots import plot_clearance

    return plot_clearance(FOLD_A, FOLD_B)


def test_the_clearance_plot_draws_the_distance_of_the_closest_links_in_mm(clearance_figure):
    left, right = clearance_figure.axes
    curve = next(ln for ln in left.get_lines() if ln.get_label() == "closest links")
    s = curve.get_xdata()
    assert s[0] == 0 and s[-1] == 1 and len(s) == 101
    for k in (0, 40, 79, 100):
        assert curve.get_ydata()[k] == pytest.approx(1000 * snakekit.clearance(FOLD_A + s[k] * (FOLD_B - FOLD_A)).distance)
    margin = next(ln for ln in left.get_lines() if ln.get_label() == "margin")
    assert margin.get_ydata()[0] == pytest.approx(1000 * snakekit.SPEC.collision_margin)
    at_b = next(ln for ln in right.get_lines() if ln.get_label() == "b")
    tool = snakekit.tool_pose_2d(FOLD_B)
    assert (at_b.get_xdata()[-1], at_b.get_ydata()[-1]) == pytest.approx((1000 * tool[0], 1000 * tool[1]))
    assert right.get_xlabel() == "x [mm]" and left.get_ylabel() == "closest links [mm]"


def test_the_clearance_plots_legend_hides_neither_the_base_plate_nor_the_arm(clearance_figure):
    renderer = _drawn(clearance_figure)
    right = clearance_figure.axes[1]
    legend = right.get_legend().get_window_extent(renderer)
    plate = next(p for p in right.patches if p.get_label() == "base plate")
    assert not _overlap(legend, plate.get_window_extent(renderer)), "the legend sits on the base plate"
    for line in right.get_lines():
        points = right.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
        inside = [(x, y) for x, y in points if legend.x0 <= x <= legend.x1 and legend.y0 <= y <= legend.y1]
        assert not inside, f"the legend hides the joints of '{line.get_label()}' at {inside}"


def test_the_clearance_plots_tick_labels_do_not_overlap(clearance_figure):
    renderer = _drawn(clearance_figure)
    for ax in clearance_figure.axes:
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
            assert len(boxes) >= 3, f"{ax.get_title()}: only {len(boxes)} tick labels"
            crowded = [(i, i + 1) for i in range(len(boxes) - 1) if _overlap(boxes[i], boxes[i + 1])]
            assert not crowded, f"{ax.get_title()}: tick labels {crowded} overlap"


def test_the_clearance_plot_refuses_a_pose_without_one_angle_per_joint():
    from snakekit.errors import ShapeError
    from snakekit.plots import plot_clearance

    with pytest.raises(ShapeError, match="b"):
        plot_clearance(FOLD_A, [0.0, 0.5])
