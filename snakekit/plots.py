"""Plots of runs and of a move's clearance, with matplotlib (no display needed).

Angles are drawn in degrees, the unit people read at a glance (the API stays in radians);
every axis says its unit. The figures are not attached to pyplot (no global state, nothing
to close), and show as a PNG picture when they are the last value of a notebook cell or
are passed to ``display``, whatever matplotlib backend the kernel has loaded.
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.ticker import MaxNLocator

from .model import SPEC, SnakeSpec, base_plate
from .robot import Run
from .validate import as_configuration, check_count

#: the unit of every angle in a plot or a summary
ANGLE_UNIT = "deg"
#: the smallest range of angles a row of :func:`plot_run` shows [deg]
MIN_SPAN_DEG = 4.0


class RunFigure(Figure):
    """A matplotlib Figure that a notebook shows as a PNG picture.

    IPython shows a bare ``Figure`` as text (``<Figure size 1200x990 with 10 Axes>``) until
    pyplot's inline backend has registered an image formatter; this one brings its own.
    """

    def _repr_png_(self) -> bytes:
        buf = io.BytesIO()
        self.savefig(buf, format="png", dpi=self.dpi)
        return buf.getvalue()


def plot_run(run: Run, *, title: str | None = None, zoom: float = 3.0):
    """Commanded against measured angle for every joint.

    One row per joint: the whole run on the left, the first ``zoom`` seconds on the right
    (where a fast motion can be seen). Joint limits are drawn when the motion comes near them.
    Returns the matplotlib Figure (save it with ``fig.savefig(path)``).
    """
    n = run.measured.n_joints
    width, height = 12.0, 1.8 * n + 0.9
    fig = RunFigure(figsize=(width, height))
    # margins in inches, fixed: the labels' room is known (two-line joint labels; angles within the joint
    # limits, a row spanning at least MIN_SPAN_DEG; one line of title), and a layout engine would measure
    # every text of the 2n axes again at each draw (constrained layout took half of this figure's drawing time)
    left, right, top, bottom, gap = 1.0, 0.3, 0.78, 0.52, 0.18
    fig.subplots_adjust(left=left / width, right=1 - right / width, top=1 - top / height, bottom=bottom / height,
                        hspace=gap * n / (height - top - bottom - gap * (n - 1)), wspace=0.04)
    axes = fig.subplots(n, 2, sharex="col", sharey="row", width_ratios=[3, 1], squeeze=False)
    err = run.tracking_error()
    cmd_t, cmd_q = run.commanded.times, np.degrees(run.commanded.positions)
    meas_t, meas_q = run.measured.times, np.degrees(run.measured.positions)
    t_start = run.measured.times[0]
    zoomed = run.measured.duration > 2 * zoom
    lim_deg = np.degrees([run.spec.lower, run.spec.upper])
    for j in range(n):
        lo, hi = min(cmd_q[:, j].min(), meas_q[:, j].min()), max(cmd_q[:, j].max(), meas_q[:, j].max())
        span = max(hi - lo, 1.0)
        for ax in axes[j]:
            ax.step(cmd_t, cmd_q[:, j], where="post", color="tab:orange", lw=1.0, label="commanded goal")
            ax.plot(meas_t, meas_q[:, j], color="tab:blue", lw=1.2, label="measured")
            for bound in lim_deg:
                if abs(bound - (lo + hi) / 2) < span:
                    ax.axhline(bound, color="tab:red", lw=0.8, ls="--", label="joint limit")
            ax.grid(alpha=0.3)
        if hi - lo < MIN_SPAN_DEG:  # a joint that barely moves: a scale of whole degrees, not of its noise
            axes[j, 0].set_ylim((lo + hi) / 2 - MIN_SPAN_DEG / 2, (lo + hi) / 2 + MIN_SPAN_DEG / 2)
        axes[j, 0].set_ylabel(f"joint {j + 1}\nangle [{ANGLE_UNIT}]")
        axes[j, 0].text(0.995, 0.04, f"max tracking error {np.degrees(err[j]):.2f} deg",
                        transform=axes[j, 0].transAxes, ha="right", va="bottom", fontsize=8,
                        bbox=dict(facecolor="white", alpha=0.7, lw=0))
        axes[j, 1].set_xlim(t_start, t_start + (zoom if zoomed else run.measured.duration))
    axes[0, 0].legend(loc="upper left", fontsize=8, ncols=3)
    axes[0, 0].set_title("whole run")
    axes[0, 1].set_title(f"first {zoom:g} s" if zoomed else "whole run")
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s]")
    fig.suptitle(title or f"{run.backend}: commanded vs measured joint angles "
                 f"({len(run.commanded)} goals over {run.commanded.duration:.1f} s; "
                 f"limits {lim_deg[0]:.0f}..{lim_deg[1]:.0f} deg)")
    return fig


def plot_move(run: Run, *, title: str | None = None):
    """Commanded (dashed) and measured (solid) angle [deg] of every joint against time.

    All joints share one panel: made for the short moves of the control panel (see
    :func:`plot_run` for long runs). Returns the figure (a notebook shows it as a picture).
    """
    fig = RunFigure(figsize=(7.5, 3.2), layout="constrained")
    ax = fig.add_subplot()
    colors = [f"C{j}" for j in range(run.commanded.n_joints)]
    for j, c in enumerate(colors):
        ax.plot(run.measured.times, np.degrees(run.measured.positions[:, j]), color=c, lw=1.6, label=f"joint {j + 1}")
        ax.plot(run.commanded.times, np.degrees(run.commanded.positions[:, j]), color=c, lw=1.0, ls="--")
    ax.plot([], [], color="k", lw=1.0, ls="--", label="commanded")
    ax.plot([], [], color="k", lw=1.6, label="measured")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"joint angle [{ANGLE_UNIT}]")
    ax.set_title(title or f"commanded vs measured ({run.backend}); "
                          f"largest tracking error {np.degrees(np.max(run.tracking_error())):.2f} {ANGLE_UNIT}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8, frameon=False)
    return fig


def plot_clearance(a, b, *, steps: int = 101, spec: SnakeSpec = SPEC):
    """How close the links come along the straight joint-space line from pose ``a`` to pose ``b`` [rad].

    Left: the distance [mm] between the closest pair of links that are not neighbours
    (:func:`snakekit.clearance`) at ``steps`` evenly spaced fractions of the way, with the
    safety margin (``spec.collision_margin``). Right: the arm seen from above [mm] at ``a``, at
    ``b`` and at the closest pose on the way, over the base plate; the legend sits outside the
    drawing, so it hides no link. Returns the figure (a notebook shows it as a picture).

    Raises:
        ShapeError, NotFiniteError: ``a`` or ``b`` is not one finite angle per joint.
        ConfigurationError: ``steps`` is not a whole number from 2 to 10000.
    """
    from .collision import clearance          # Pinocchio and coal, only when a clearance is drawn
    from .kinematics import joint_frames

    a, b = as_configuration(a, spec, "a"), as_configuration(b, spec, "b")
    s = np.linspace(0.0, 1.0, check_count(steps, "steps", 2, 10_000))
    d = np.array([clearance(a + x * (b - a), spec=spec).distance for x in s])
    closest = a + s[int(np.argmin(d))] * (b - a)

    fig = RunFigure(figsize=(11, 4.0), layout="constrained")
    left, right = fig.subplots(1, 2, width_ratios=[1, 1.15])
    left.plot(s, 1000 * d, label="closest links")
    left.axhline(1000 * spec.collision_margin, color="tab:red", ls="--", label="margin")
    left.set(xlabel="fraction of the move a -> b", ylabel="closest links [mm]", title="Clearance along the move")
    left.legend(loc="upper right", fontsize=8)
    left.grid(alpha=0.3)

    centre, size = base_plate(spec)
    right.add_patch(Rectangle(1000 * (centre[:2] - size[:2] / 2), 1000 * size[0], 1000 * size[1], color="0.75",
                              label="base plate", zorder=0))
    for q, style, label in ((a, "-o", "a"), (b, "-s", "b"), (closest, "r-o", "closest on the way")):
        xy = 1000 * joint_frames(q, spec=spec)[:, :2, 3]
        right.plot(xy[:, 0], xy[:, 1], style, label=label)
    right.set_aspect("equal")
    right.xaxis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 5, 10]))   # round millimetres, room between
    right.yaxis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 5, 10]))
    right.grid(alpha=0.3)
    right.set(xlabel="x [mm]", ylabel="y [mm]", title="The arm at a, at b, and in between")
    right.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0.0)
    return fig
