"""Where the browser finds a viewer's page: through the Jupyter server, or on its own port.

The viewer's server listens on a port of this machine (:mod:`.server`). A browser on the same
machine reaches it there, but JupyterHub, Binder, a container with only Jupyter's port
published, or an SSH tunnel expose Jupyter's port alone. jupyter-server-proxy (a dependency
of the kit, enabled in every Jupyter server of its environment) serves any local port under
the server's own URL, at ``<base_url>proxy/<port>/``, with the server's login, websockets
included. So the page's address is chosen here, in this order:

1. ``SNAKEKIT_VIEWER_URL``, when set: the viewer's root with ``{port}`` in it, for set-ups
   the rules below get wrong, e.g. ``/user/ana/proxy/{port}/``,
   ``https://lab.example.org/proxy/{port}/`` or ``http://localhost:{port}/`` (its own port);
2. in a notebook kernel, the base URL of the Jupyter server that started the kernel: the
   server's pid is the kernel's ``JPY_PARENT_PID`` (jupyter_client sets it), and the server
   writes its base URL to ``jpserver-<pid>.json`` in Jupyter's runtime directory (the file
   ``jupyter server list`` reads);
3. in a notebook kernel, JupyterHub's ``JUPYTERHUB_SERVICE_PREFIX`` (``/user/<name>/``),
   which a hub gives every single-user server and its kernels;
4. otherwise (a script, plain Python, a kernel that no Jupyter server started, such as a
   headless notebook run): the viewer's own port, ``http://<host>:<port>/``, as before.

A proxied address is a path without a host (``/user/ana/proxy/7001/static/``), so the
browser asks the very host and port it shows JupyterLab from, whatever a tunnel or a hub's
proxy in between made of them.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path

from ..errors import ConfigurationError

#: the environment variable that overrides the address (a URL or path with ``{port}``)
URL_VARIABLE = "SNAKEKIT_VIEWER_URL"


def server_base_url(environ: Mapping[str, str] | None = None, runtime_dir: str | Path | None = None) -> str | None:
    """The base URL (``/`` or ``/user/ana/``) of the Jupyter server that started this process.

    Read from ``jpserver-<JPY_PARENT_PID>.json`` in Jupyter's runtime directory (default:
    ``jupyter_core.paths.jupyter_runtime_dir()``, which honours ``JUPYTER_RUNTIME_DIR``).
    None when this process was not started by a running Jupyter server.
    """
    environ = os.environ if environ is None else environ
    pid = environ.get("JPY_PARENT_PID", "")
    if not pid.isdigit():
        return None
    if runtime_dir is None:
        try:
            from jupyter_core.paths import jupyter_runtime_dir
        except ImportError:
            return None
        runtime_dir = jupyter_runtime_dir()
    try:
        info = json.loads((Path(runtime_dir) / f"jpserver-{int(pid)}.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    base = info.get("base_url") if isinstance(info, dict) else None
    if not isinstance(base, str) or not base.startswith("/") or info.get("pid") not in (None, int(pid)):
        return None
    return base if base.endswith("/") else base + "/"


def _hub_prefix(environ: Mapping[str, str]) -> str | None:
    prefix = environ.get("JUPYTERHUB_SERVICE_PREFIX", "")
    if not prefix.startswith("/"):
        return None
    return prefix if prefix.endswith("/") else prefix + "/"


def viewer_root(port: int, host: str, *, in_kernel: bool, url_host: str | None = None,
                environ: Mapping[str, str] | None = None, runtime_dir: str | Path | None = None) -> str:
    """The root URL of the viewer listening on ``host``:``port``, as the browser reaches it.

    Args:
        port: the viewer's port.
        host: the interface it listens on.
        in_kernel: whether this runs in a notebook kernel (only there is the page proxied
            without ``SNAKEKIT_VIEWER_URL``).
        url_host: a host name the browser reaches the viewer's own port by: given, the
            address is ``http://<url_host>:<port>/``, whatever the environment says.
        environ: the environment (default: ``os.environ``).
        runtime_dir: Jupyter's runtime directory (default: Jupyter's own).

    Returns:
        the root, ending in ``/``; the page is at ``<root>static/`` and its websocket at
        ``<root>``.

    Raises:
        ConfigurationError: ``SNAKEKIT_VIEWER_URL`` has no ``{port}``, or other fields.
    """
    environ = os.environ if environ is None else environ
    if url_host is None:
        template = environ.get(URL_VARIABLE, "").strip()
        if template:
            try:
                root = template.format(port=port)
            except (KeyError, IndexError, ValueError):
                root = None
            if root is None or "{port}" not in template:
                raise ConfigurationError(
                    f"{URL_VARIABLE} must be the viewer's address with {{port}} where its port goes, such as "
                    f"/user/ana/proxy/{{port}}/ or http://localhost:{{port}}/; got {template!r}. Fix it or unset it.")
            return root if root.endswith("/") else root + "/"
        if in_kernel:
            base = server_base_url(environ, runtime_dir) or _hub_prefix(environ)
            if base is not None:
                return f"{base}proxy/{port}/"
    shown = url_host or ("localhost" if host in ("0.0.0.0", "", "::") else host)
    if ":" in shown and not shown.startswith("["):
        shown = f"[{shown}]"
    return f"http://{shown}:{port}/"
