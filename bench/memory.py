"""Memory per user: one student's single-user server, as a hub's memory limit sees it.

Each run starts the image (``snakekit-lab:latest``) as a hub's spawner would, one container per
student with its default command (`start-lab`: JupyterLab; under a hub the same script runs
`jupyterhub-singleuser`, the same server with the hub's login), and reads the container's
memory cgroup at three points:

* **idle**: the server up, nobody connected;
* **with a lesson kernel**: lesson 00 opened (a session and its kernel) and its first code cell
  run: the kit, the simulated arm and the viewer's server;
* **with the 3D view open**: headless Chromium on the lesson in JupyterLab and on the 3D view's
  page (its websocket connected, the arm drawn).

Figures per point: the cgroup's usage (``memory.current``, v1 ``memory.usage_in_bytes``: what
the limit counts, page cache included), its working set (usage less inactive file pages: what
`docker stats` shows and what Kubernetes evicts and reports on) and the peak since the
container started (``memory.peak``, v1 ``memory.max_usage_in_bytes``). Medians over the runs.
From the 3D-view figures: users that fit in a 24 GB node with a kernel each.

It uses a Docker engine that is already running and its image; without one, as root with
Debian's docker.io, it runs itself again under bench/container-engine.sh (the private engine
of docker/engine.sh), like bench/container.py.

Run: ``.venv/bin/python bench/memory.py [--repeats 3] [--json PATH]``
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.machinery
import importlib.util
import os
import re
import statistics
import sys
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO))
import container  # noqa: E402
from _common import add_json_argument, write_json  # noqa: E402
from container import IMAGE, docker, free_port, free_range, wait_for_lab  # noqa: E402

LESSON = "00_meet_the_arm.ipynb"
TOKEN = container.TOKEN  # wait_for_lab asks with it
NETWORK = f"snakekit-memory-{os.getpid()}"
MIB = 1024 * 1024
NODE_GB = 24
#: what a 24 GB node keeps for itself (OS, kubelet, container runtime, the image puller, eviction
#: threshold): Kubernetes' kube-reserved + system-reserved as the large clouds set them for 24 GB
NODE_RESERVED_GB = 2.5
_loader = importlib.machinery.SourceFileLoader("open_lesson", str(REPO / "binder/open-lesson"))
open_lesson = importlib.util.module_from_spec(importlib.util.spec_from_loader("open_lesson", _loader))
_loader.exec_module(open_lesson)


def cgroup(cid: str) -> dict:
    """The container's memory cgroup, read on the host (cgroup v2 or v1), in MiB."""
    full = docker("inspect", "-f", "{{.Id}}", cid).stdout.strip()
    v2 = [Path(f"/sys/fs/cgroup/system.slice/docker-{full}.scope"), Path(f"/sys/fs/cgroup/docker/{full}")]
    for d in v2:
        if (d / "memory.current").exists():
            stat = dict(line.split() for line in (d / "memory.stat").read_text().splitlines())
            usage = int((d / "memory.current").read_text())
            peak = int((d / "memory.peak").read_text()) if (d / "memory.peak").exists() else usage
            return {"usage": usage / MIB, "working_set": (usage - int(stat["inactive_file"])) / MIB,
                    "peak": peak / MIB, "cgroup": "v2"}
    d = Path(f"/sys/fs/cgroup/memory/docker/{full}")
    if not (d / "memory.usage_in_bytes").exists():
        raise RuntimeError(f"the container's memory cgroup is not at {v2[0]}, {v2[1]} or {d}")
    stat = dict(line.split() for line in (d / "memory.stat").read_text().splitlines())
    usage = int((d / "memory.usage_in_bytes").read_text())
    return {"usage": usage / MIB, "working_set": (usage - int(stat["total_inactive_file"])) / MIB,
            "peak": int((d / "memory.max_usage_in_bytes").read_text()) / MIB, "cgroup": "v1"}


def settle(cid: str, seconds: float = 4.0) -> dict:
    time.sleep(seconds)
    return cgroup(cid)


def viewer_page(lab: str, printed: str) -> str:
    """The 3D view's page as the host reaches it, from what `print(viewer)` printed."""
    m = re.search(r"serving (\S+?)>?$", printed.strip())
    if not m:
        raise RuntimeError(f"lesson 00's first cell did not print its viewer: {printed[-300:]!r}")
    url = m.group(1)
    if url.startswith("/"):  # under the Jupyter server (jupyter-server-proxy), with its login
        return f"{lab}{url}?token={TOKEN}"
    port = re.search(r"://[^/:]+:(\d+)", url)
    return f"http://127.0.0.1:{port.group(1)}/static/" if port else url


def one_run(run: int) -> dict:
    lab_port, viewers = free_port(), free_range()
    lab = f"http://127.0.0.1:{lab_port}"
    name = f"snakekit-memory-{os.getpid()}-{run}"
    t0 = time.monotonic()
    docker("run", "-d", "--rm", "--name", name, "--network", NETWORK, "--init", "-e", f"JUPYTER_TOKEN={TOKEN}",
           "-e", f"SNAKEKIT_VIEWER_PORTS={viewers}", "-p", f"127.0.0.1:{lab_port}:8888",
           "-p", f"127.0.0.1:{viewers}:{viewers}", IMAGE)
    try:
        wait_for_lab(lab_port, t0)
        out = {"idle": settle(name, 6.0)}
        sess = open_lesson.api(lab, TOKEN, "/api/sessions", {"path": LESSON, "name": LESSON, "type": "notebook",
                                                               "kernel": {"name": "python3"}})
        nb = open_lesson.api(lab, TOKEN, f"/api/contents/{LESSON}")["content"]
        first = next("".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code")
        ws = lab.replace("http", "ws", 1) + f"/api/kernels/{sess['kernel']['id']}/channels"
        status, texts = asyncio.run(open_lesson.execute(ws, TOKEN, first))
        if status != "ok":
            raise RuntimeError(f"lesson 00's first cell failed: {''.join(texts)[-500:]}")
        out["kernel"] = settle(name)
        out["view"] = with_view(name, lab, viewer_page(lab, "".join(texts)))
        return out
    finally:
        docker("rm", "-f", name, check=False)


def with_view(cid: str, lab: str, view_url: str) -> dict:
    """The lesson open in JupyterLab and the 3D view's page, both in headless Chromium."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout
    from playwright.sync_api import sync_playwright

    from tests.system.test_browser import CHROMIUM_FLAGS

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_FLAGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(f"{lab}/lab/tree/{LESSON}?token={TOKEN}")
            page.locator(".jp-NotebookPanel .jp-CodeCell").first.wait_for(timeout=90_000)
            # the lesson's running kernel: JupyterLab may ask which one (the session exists already)
            accept = page.locator(".jp-Dialog button.jp-mod-accept")
            try:
                accept.first.wait_for(timeout=5_000)
                accept.first.click()
            except PlaywrightTimeout:
                pass
            page.locator(".jp-StatusBar-Widget", has_text=re.compile(r"\| Idle")).first.wait_for(timeout=120_000)
            view = browser.new_page(viewport={"width": 900, "height": 700})
            with urllib.request.urlopen(view_url, timeout=10) as r:
                if r.status != 200:
                    raise RuntimeError(f"the 3D view's page {view_url} answered {r.status}")
            view.goto(view_url)
            view.locator("canvas").first.wait_for(timeout=60_000)
            return settle(cid, 6.0)
        finally:
            browser.close()


def med(runs: list[dict], point: str, key: str) -> float:
    return statistics.median(r[point][key] for r in runs)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    add_json_argument(parser)
    args = parser.parse_args(argv)
    elsewhere = container.engine_here_or_private(argv, args.json, Path(__file__).resolve())
    if elsewhere is not None:
        return elsewhere
    docker("network", "create", NETWORK, check=False)
    try:
        runs = [one_run(i) for i in range(args.repeats)]
    finally:
        docker("network", "rm", NETWORK, check=False)
    results: dict = {"image": IMAGE, "runs": runs, "cgroup": runs[0]["idle"]["cgroup"], "node_gb": NODE_GB,
                     "node_reserved_gb": NODE_RESERVED_GB}
    for point in ("idle", "kernel", "view"):
        results[point] = {k: med(runs, point, k) for k in ("usage", "working_set", "peak")}
    per_user = results["view"]["peak"]
    results["users_per_node"] = int((NODE_GB - NODE_RESERVED_GB) * 1000**3 / MIB // per_user)
    labels = {"idle": "idle", "kernel": "with lesson 00's kernel", "view": "with the 3D view open"}
    print(f"memory per user, median of {args.repeats} runs ({IMAGE}, cgroup {results['cgroup']}):")
    for point, label in labels.items():
        r = results[point]
        print(f"  {label:26s} usage {r['usage']:6.0f} MiB  working set {r['working_set']:6.0f} MiB  "
              f"peak {r['peak']:6.0f} MiB")
    print(f"  users per {NODE_GB} GB node with a kernel and the 3D view each ({NODE_RESERVED_GB} GB kept for the "
          f"node, {per_user:.0f} MiB each at their peak): {results['users_per_node']} (target >= 80"
          f"{'' if results['users_per_node'] >= 80 else ': MISSED'})")
    write_json(args.json, results)
    return 0 if results["users_per_node"] >= 80 else 1  # a missed target: figures given, exit 1


if __name__ == "__main__":
    sys.exit(main())
