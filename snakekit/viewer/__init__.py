"""The arm in a 3D view in a notebook cell, on meshcat, served from this machine.

>>> from snakekit.viewer import Viewer
>>> with Viewer() as viewer:                       # doctest: +SKIP
...     viewer.show([0.3, -0.2, 0.4, 0.1, 0.0])
...     viewer                                      # the last line of a cell shows it

Modules: :mod:`.scene` (:class:`Viewer`: the arm, goals, marks, playback),
:mod:`.server` (the meshcat server, a thread of the kernel), :mod:`.urls` (where the browser finds
the page: through the Jupyter server's proxy in a notebook, docs/viewer.md), :mod:`.urdf_visuals`
(the boxes drawn, read from the generated URDF). The workspace boundary is computed in
:func:`snakekit.kinematics.workspace_boundary`.
"""

from ..errors import ViewerError
from ..kinematics import boundary_configurations, workspace_boundary
from .scene import GOAL, MARKS, ROBOT, Viewer
from .urdf_visuals import VisualBox, visual_boxes

__all__ = ["Viewer", "ViewerError", "VisualBox", "visual_boxes", "workspace_boundary",
           "boundary_configurations", "ROBOT", "GOAL", "MARKS"]
