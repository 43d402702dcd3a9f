"""The 3D view through the Jupyter server's port (jupyter-server-proxy) against its own port.

Run as ``python bench/viewer_proxy.py``. A Jupyter server runs under a hub-like base URL
(``/user/ana/``) with jupyter-server-proxy; a viewer runs in this process. Measured, the two
routes in turn so that drifts of the machine's load hit both:

1. the page a notebook cell loads (meshcat's page and its 0.85 MB script): time to fetch
   both, through ``/user/ana/proxy/<port>/static/`` and from the viewer's own port;
2. an update: ``viewer.show(q)`` to the last of its five messages arriving on a page's
   websocket, one websocket through the proxy and one on the viewer's own port, both open
   at once (each update reaches both);
3. the Jupyter server's resident memory just started, with jupyter-server-proxy and with the
   extension turned off, and once the proxy has served the view (what the proxy costs a
   single-user server).

Prints medians and the 95th percentile, and the ratios side by side.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import secrets
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from _common import add_json_argument, write_json  # noqa: E402
from setups import free_port  # noqa: E402

BASE_URL = "/user/ana/"


class Server:
    """A Jupyter server on a free loopback port, with or without jupyter-server-proxy."""

    def __init__(self, home: Path, proxy: bool = True):
        self.port, self.token = free_port(), secrets.token_hex(16)
        args = [sys.executable, "-m", "jupyter", "server", "--no-browser", "--allow-root", "--ip=127.0.0.1",
                f"--port={self.port}", "--ServerApp.port_retries=0", f"--IdentityProvider.token={self.token}",
                f"--ServerApp.base_url={BASE_URL}", f"--ServerApp.root_dir={home}"]
        if not proxy:
            args += ["--ServerApp.jpserver_extensions", "jupyter_server_proxy=False"]
        env = dict(os.environ, JUPYTER_RUNTIME_DIR=str(home / "runtime"), JUPYTER_CONFIG_DIR=str(home / "config"))
        self.log = open(home / f"server-{self.port}.log", "wb")
        self.proc = subprocess.Popen(args, env=env, stdout=self.log, stderr=subprocess.STDOUT)
        self.url = f"http://127.0.0.1:{self.port}{BASE_URL}"
        deadline = time.monotonic() + 90
        while True:
            try:
                self.get("api/status")
                return
            except OSError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    self.stop()
                    raise SystemExit(f"the Jupyter server did not start; see {self.log.name}")
                time.sleep(0.3)

    def get(self, path: str) -> bytes:
        req = urllib.request.Request(self.url + path, headers={"Authorization": f"token {self.token}"})
        return urllib.request.urlopen(req, timeout=10).read()

    def rss_mb(self) -> float:
        import psutil

        return psutil.Process(self.proc.pid).memory_info().rss / 1e6

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.log.close()


def fetch_page(get) -> float:
    t = time.perf_counter()
    page = get("static/")
    script = get("static/main.min.js")
    assert b"viewer.connect(" in page and len(script) > 500_000
    return time.perf_counter() - t


async def updates(viewer, server: Server, n: int) -> tuple[list[float], list[float]]:
    """Times [s] from viewer.show() to its last message on the proxied and on the direct websocket."""
    import numpy as np
    from tornado.httpclient import HTTPRequest
    from tornado.websocket import websocket_connect

    headers = {"Authorization": f"token {server.token}", "Origin": f"http://127.0.0.1:{server.port}"}
    proxied = await websocket_connect(HTTPRequest(f"ws://127.0.0.1:{server.port}{BASE_URL}proxy/{viewer.port}/",
                                                  headers=headers))
    direct = await websocket_connect(f"ws://127.0.0.1:{viewer.port}/")
    loop = asyncio.get_running_loop()

    async def drain(ws):  # the scene sent on connecting
        while True:
            try:
                await asyncio.wait_for(ws.read_message(), 0.5)
            except asyncio.TimeoutError:
                return

    await drain(proxied)
    await drain(direct)
    per_show = viewer.spec.n_joints  # one set_transform per link

    async def arrive(ws, t0: float) -> float:
        for _ in range(per_show):
            message = await asyncio.wait_for(ws.read_message(), 10)
            assert message is not None, "the websocket closed"
        return time.perf_counter() - t0

    through, own = [], []
    rng = np.random.default_rng(1)
    for _ in range(n):
        q = rng.uniform(-0.5, 0.5, viewer.spec.n_joints)
        t0 = time.perf_counter()
        waits = asyncio.gather(arrive(proxied, t0), arrive(direct, t0))
        await loop.run_in_executor(None, viewer.show, q)
        a, b = await waits
        through.append(a)
        own.append(b)
    proxied.close()
    direct.close()
    return through, own


def p95(xs: list[float]) -> float:
    return sorted(xs)[max(0, int(round(0.95 * len(xs))) - 1)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20, help="page loads per route")
    ap.add_argument("--updates", type=int, default=200, help="viewer.show() calls")
    add_json_argument(ap)
    args = ap.parse_args(argv)

    from snakekit.viewer import Viewer

    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp, Viewer(replace=False) as viewer:
        home = Path(tmp)
        server = Server(home)
        idle_with_proxy = server.rss_mb()
        try:
            def own(path: str) -> bytes:
                return urllib.request.urlopen(f"http://127.0.0.1:{viewer.port}/{path}", timeout=10).read()

            def through(path: str) -> bytes:
                return server.get(f"proxy/{viewer.port}/{path}")

            fetch_page(through)  # the first request through the proxy sets up its client
            pages = {"proxied": [], "direct": []}
            for _ in range(args.repeats):
                pages["proxied"].append(fetch_page(through))
                pages["direct"].append(fetch_page(own))
            via, direct = asyncio.run(updates(viewer, server, args.updates))
            with_proxy = server.rss_mb()
        finally:
            server.stop()
        plain = Server(home, proxy=False)
        try:
            plain.get("api/status")
            without_proxy = plain.rss_mb()
        finally:
            plain.stop()

    med = statistics.median
    results["page_ms"] = {k: {"median": 1000 * med(v), "p95": 1000 * p95(v)} for k, v in pages.items()}
    results["page_ratio"] = med(pages["proxied"]) / med(pages["direct"])
    results["update_ms"] = {"proxied": {"median": 1000 * med(via), "p95": 1000 * p95(via)},
                            "direct": {"median": 1000 * med(direct), "p95": 1000 * p95(direct)}}
    results["update_ratio"] = med(via) / med(direct)
    results["server_rss_mb"] = {"with_proxy": with_proxy, "with_proxy_idle": idle_with_proxy,
                                "without_proxy": without_proxy}
    results["updates"], results["repeats"] = args.updates, args.repeats

    pm, um = results["page_ms"], results["update_ms"]
    print(f"page + script (0.85 MB), median of {args.repeats}: through the proxy {pm['proxied']['median']:.1f} ms "
          f"(p95 {pm['proxied']['p95']:.1f}), own port {pm['direct']['median']:.1f} ms "
          f"(p95 {pm['direct']['p95']:.1f}); ratio {results['page_ratio']:.2f}")
    print(f"viewer.show() to the page's websocket, median of {args.updates}: through the proxy "
          f"{um['proxied']['median']:.2f} ms (p95 {um['proxied']['p95']:.2f}), own port {um['direct']['median']:.2f} ms "
          f"(p95 {um['direct']['p95']:.2f}); ratio {results['update_ratio']:.2f}")
    print(f"Jupyter server resident memory, just started: {idle_with_proxy:.0f} MB with jupyter-server-proxy, "
          f"{without_proxy:.0f} MB with it turned off; {with_proxy:.0f} MB once the proxy has served the view")
    write_json(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
