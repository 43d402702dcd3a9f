"""The verdict plots: a trajectory exercise's run against the instructor's reference, as PNG."""

from __future__ import annotations

import hashlib
import io
import threading
from collections import OrderedDict

import numpy as np

_plots: OrderedDict[bytes, bytes] = OrderedDict()  # recent plots by a digest of what they draw
_plots_lock = threading.Lock()
PLOT_CACHE = 16  # plots kept; each is a few hundred kB


def plot_png(curves: dict, title: str) -> bytes:
    """The student's run against the reference, one row per joint, as PNG bytes.

    Left: the whole run. Right: 5 s around the largest difference between the student's
    curve and the reference (or the start, when they agree), where one can see it. The
    reference is drawn wide and grey underneath, the student's curves in colour on top.

    The simulator repeats a run bit for bit, so every student whose sweep is right hands in
    the same curves: a plot of the same title and arrays is drawn once and its bytes reused.
    """
    digest = hashlib.blake2b(title.encode(), digest_size=20)
    for name in sorted(curves):
        for a in curves[name]:
            a = np.ascontiguousarray(a)
            digest.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
            digest.update(a.data)
    key = digest.digest()
    with _plots_lock:
        if key in _plots:
            _plots.move_to_end(key)
            return _plots[key]
    png = _draw(curves, title)
    with _plots_lock:
        _plots[key] = png
        while len(_plots) > PLOT_CACHE:
            _plots.popitem(last=False)
    return png


def _draw(curves: dict, title: str) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    n = next(iter(curves.values()))[1].shape[1]
    height = 1.45 * n + 1.0
    fig = Figure(figsize=(10, height), dpi=72)  # fixed margins: a layout engine would double the drawing time
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.5 / height, top=1 - 0.75 / height, wspace=0.04, hspace=0.15)
    FigureCanvasAgg(fig)
    # shared axes: the inner rows draw no tick labels (most of a panel's drawing time is its ticks)
    axes = np.atleast_2d(fig.subplots(n, 2, sharex="col", sharey="row", width_ratios=(2, 1)))
    styles = {"reference measured": dict(color="0.7", lw=3.5, zorder=1),
              "reference commanded": dict(color="0.35", lw=1, ls=":", zorder=2),
              "commanded": dict(color="C0", lw=1, ls="--", zorder=3),
              "measured": dict(color="C1", lw=1.2, zorder=4)}
    centre, worst = 0.0, ""
    for mine, ref in (("measured", "reference measured"), ("commanded", "reference commanded")):
        if mine in curves and ref in curves:
            (ts, qs), (tr, qr) = curves[mine], curves[ref]
            ts, tr = ts - ts[0], tr - tr[0]
            grid = ts[(ts >= 0) & (ts <= tr[-1])]
            if len(grid):
                diff = np.abs(qs[: len(grid)] - np.column_stack([np.interp(grid, tr, qr[:, j]) for j in range(n)]))
                if diff.max() > 1e-9:
                    i, j = np.unravel_index(int(np.argmax(diff)), diff.shape)
                    centre, worst = float(grid[i]), f"largest difference: {mine} joint {j + 1} at t={grid[i]:.1f} s"
                    break
    lo = max(centre - 2.5, 0.0)
    for name in sorted(curves, key=lambda k: styles.get(k, {}).get("zorder", 5)):
        t, q = curves[name]
        t = t - t[0]
        every = max(1, len(t) // 2000)  # the whole run: at most ~2000 points a curve (the panel is ~600 px wide)
        for j in range(n):
            for col, keep in ((0, slice(None, None, every)), (1, (t >= lo) & (t <= lo + 5))):
                axes[j, col].plot(t[keep], q[keep, j], label=name if (j, col) == (0, 0) else None,
                                  **styles.get(name, {}))
    for j in range(n):
        axes[j, 0].set_ylabel(f"joint {j + 1} [rad]", fontsize=8)
        for col in (0, 1):
            axes[j, col].grid(alpha=0.3)
            axes[j, col].tick_params(labelsize=7)
        axes[j, 0].yaxis.set_major_locator(MaxNLocator(4, steps=[1, 2, 5, 10]))
    axes[-1, 0].set_xlabel("time from the first point [s]", fontsize=8)
    axes[-1, 1].set_xlabel(f"zoom: {lo:.1f} to {lo + 5:.1f} s", fontsize=8)
    axes[0, 1].set_title(worst or "your curves match the reference", fontsize=8)
    fig.legend(loc="upper right", bbox_to_anchor=(0.99, 1.0), fontsize=8, ncols=4, frameon=False)
    fig.suptitle(title, fontsize=10, x=0.01, ha="left")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def verdict_plot(ex) -> bytes | None:
    """The plot of a trajectory exercise's run against the reference (None for other exercises)."""
    return plot_png(ex.curves, f"{ex.grade_id}: your run (colour) and the reference (grey)") if ex.curves else None

