"""meshcat's kernel side, imported without meshcat's own server.

The kernel needs meshcat's scene description (geometry, commands, animation) and its
``Visualizer``, which sends commands over ZeroMQ to the server the kit starts in a thread
(:mod:`snakekit.viewer.server`). Importing ``meshcat`` the usual way also imports that server:
its package ``__init__`` imports ``meshcat.visualizer``, which imports
``meshcat.servers.zmqserver`` and with it tornado's web server, asyncio and ssl (about 8 MB
resident). Here they are imported when a :class:`~snakekit.viewer.Viewer` is made, so a
lesson or a grading run that imports the kit but opens no view does not pay for them.

:func:`load` imports the same modules from the installed meshcat, unmodified, with two
differences that a user does not see:

* the ``meshcat`` package is made without running its ``__init__``; its names (``Visualizer``,
  ``geometry``, ``viewer_assets_path``, ...) are looked up on first use, so
  ``import meshcat; meshcat.Visualizer()`` in a lesson still works;
* ``meshcat.servers.zmqserver`` is imported when its launcher is first called (by a user's own
  ``meshcat.Visualizer()`` without a window), not before.

If meshcat is already imported the usual way, that import is used as it is.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import types
import warnings

from ..errors import MissingDependencyError

_SERVER_MODULE = "meshcat.servers.zmqserver"


def server_module() -> types.ModuleType:
    """The real ``meshcat.servers.zmqserver``, in place of the placeholder from now on."""
    if sys.modules.get(_SERVER_MODULE) is _placeholder:
        del sys.modules[_SERVER_MODULE]
    return importlib.import_module(_SERVER_MODULE)


def _start_zmq_server_as_subprocess(*args, **kwargs):
    """meshcat's own server launcher, imported on its first call (the kit never calls it)."""
    return server_module().start_zmq_server_as_subprocess(*args, **kwargs)


_placeholder = types.ModuleType(_SERVER_MODULE, "meshcat's server, imported on first use")
_placeholder.start_zmq_server_as_subprocess = _start_zmq_server_as_subprocess


def _server_attribute(name: str):
    """Any other name of the server module: from the real module (the import system's own
    probes, like ``__path__``, are answered by the placeholder)."""
    if name.startswith("__"):
        raise AttributeError(name)
    return getattr(server_module(), name)


_placeholder.__getattr__ = _server_attribute


def _package(name: str, path: list[str], attributes: dict) -> types.ModuleType:
    package = types.ModuleType(name)
    package.__path__ = path
    package.__package__ = name

    def __getattr__(attr: str):  # the package __init__'s names, imported when first asked for
        if attr.startswith("__"):
            raise AttributeError(f"module '{name}' has no attribute '{attr}'")
        if attr in attributes:
            module, member = attributes[attr]
            value = importlib.import_module(module)
            value = getattr(value, member) if member else value
        else:
            try:
                value = importlib.import_module(f"{name}.{attr}")
            except ModuleNotFoundError:
                raise AttributeError(f"module '{name}' has no attribute '{attr}'") from None
        setattr(package, attr, value)
        return value

    package.__getattr__ = __getattr__
    return package


def load() -> types.ModuleType:
    """The ``meshcat`` package with its kernel-side modules imported (see the module doc)."""
    if "meshcat.visualizer" not in sys.modules:
        spec = importlib.util.find_spec("meshcat")
        if spec is None or not spec.submodule_search_locations:
            raise MissingDependencyError("No module named 'meshcat'")
        root = list(spec.submodule_search_locations)
        if "meshcat" not in sys.modules:
            package = _package("meshcat", root, {"Visualizer": ("meshcat.visualizer", "Visualizer")})
            package.viewer_assets_path = lambda: os.path.abspath(os.path.join(root[0], "viewer"))
            sys.modules["meshcat"] = package
        if "meshcat.servers" not in sys.modules:
            sys.modules["meshcat.servers"] = _package("meshcat.servers", [os.path.join(root[0], "servers")], {})
        sys.modules.setdefault(_SERVER_MODULE, _placeholder)
        with warnings.catch_warnings():  # meshcat 0.3 imports a pyzmq module deprecated since 17
            warnings.simplefilter("ignore", DeprecationWarning)
            for name in ("commands", "geometry", "transformations", "animation", "visualizer"):
                importlib.import_module(f"meshcat.{name}")
    return sys.modules["meshcat"]
