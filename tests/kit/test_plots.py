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
