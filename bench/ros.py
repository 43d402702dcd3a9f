"""The study's third framework: the multi-container ROS set-up (compose's `ros` profile), Tasks 1 and 2.

Compose's `ros` profile (docs/ros.md) is started as a user starts it, its ROS services only
(`docker compose --profile ros up -d rviz`: roscore, the arm as `snakekit ros` on the simulator in
real time, robot_state_publisher, RViz on Xvfb served by x11vnc and noVNC). Headless Chromium opens
the printed noVNC page and stays connected, so RViz's display is really drawn and served all along.
A small node in the arm's container (this file, ``--driver``, with the kit's Python and Debian's
rospy) sends the goals on /arm/command and waits for the arm's word on /rosout:

* **Task 2**: the study's coded movement, ``snakekit.side_sweep()`` (500 points at 10 Hz, 50
  side-to-side sweeps and back home) as ONE ``trajectory_msgs/JointTrajectory``;
* **Task 1**: three consecutive goal changes, as a user sends them from a terminal: bench/interactive.py's
  three tool targets, solved by the kit's IK beforehand, each sent as a single-point goal 2 s after
  the arm said the previous one was done. (The study dragged MoveIt's goal in RViz; there is no
  MoveIt here.)

Counted: the four containers together, from their cgroups read on the host every 0.5 s (cgroup v1
or v2): CPU time (``cpuacct.usage``, v2 ``cpu.stat`` usage_usec) over wall time, in percent of one
core, and memory as `docker stats` counts it (usage less inactive file pages), summed; the peak is
watched every 0.1 s. Processes started with `docker exec` (the driver node) are in the arm's
container and counted; Chromium, on the host, is not (as in bench/interactive.py).
Also: start to a working shell (`up -d` to the arm's node answering, images cached; RViz's noVNC
page answering too) and the ROS image's size. Medians of ``--repeats`` (default 3).

It uses a Docker engine that already runs with the images ``snakekit-lab:latest`` and
``snakekit-ros:latest``; without one, as root with Debian's docker.io, it runs itself again under
bench/container-engine.sh (the private engine of docker/engine.sh, both images built or reused from
its cache), like bench/container.py. Otherwise it says what is missing and exits 2.

Run: ``.venv/bin/python bench/ros.py [--repeats 3] [--json PATH]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

ROS_IMAGE = os.environ.get("SNAKEKIT_ROS_IMAGE", "snakekit-ros:latest")
SERVICES = ("roscore", "arm", "state-publisher", "rviz")
PAUSE = 2.0  # [s] between the arm's "goal done" and the next goal in Task 1 (a user looks, then sends)
HANG = 300.0  # [s] a bound for each wait on a busy machine (a quiet one: Task 2's 50 s, a start's 10 s)


# --- the driver: a node inside the stack ------------------------------------------------------

def driver() -> None:
    """In the arm's container: send the tasks' goals when told on stdin, say when the arm is done."""
    import numpy as np

    import snakekit
    from snakekit.ros import COMMAND, NODE, import_ros

    _, rospy, _, trajectory_msgs = import_ros()
    from rosgraph_msgs.msg import Log

    from interactive import TARGETS

    names = [f"joint{i + 1}" for i in range(5)]
    words: list[str] = []
    rospy.init_node("bench_task", disable_signals=True)
    log_sub = rospy.Subscriber("/rosout", Log, lambda m: m.name == f"/{NODE}" and m.msg.startswith("goal ")
                               and words.append(m.msg), queue_size=None)
    goals = rospy.Publisher(COMMAND, trajectory_msgs.JointTrajectory, queue_size=10)

    def until(ready, what: str) -> None:
        end = time.monotonic() + HANG
        while not ready():
            if time.monotonic() > end:
                raise SystemExit(f"ros-driver: no {what} within {HANG:g} s")
            time.sleep(0.01)

    until(goals.get_num_connections, "subscriber of goals (the arm's node)")
    until(lambda: any(c.callerid_pub == f"/{NODE}" for c in log_sub.impl.connections), "/rosout from the arm")

    def message(times, positions):
        return trajectory_msgs.JointTrajectory(joint_names=names, points=[
            trajectory_msgs.JointTrajectoryPoint(positions=[float(v) for v in p],
                                                 time_from_start=rospy.Duration.from_sec(float(t)))
            for t, p in zip(times, positions)])

    def send(msg) -> str:
        said = len(words)
        goals.publish(msg)
        until(lambda: len(words) > said, "word from the arm on /rosout")
        if not words[said].startswith("goal done"):
            raise SystemExit(f"ros-driver: the arm refused a goal: {words[said]}")
        return words[said]

    # Task 1's goals: the three tool targets solved beforehand, each a single point reached in
    # a time that keeps every joint under 1 rad/s (the limit is 1.5), at least 1 s
    task1, q = [], np.zeros(5)
    for x, y, heading in TARGETS:
        goal = snakekit.inverse_kinematics([x, y], heading, q0=q)
        task1.append(message([max(1.0, float(np.abs(goal - q).max()))], [goal]))
        q = goal
    home = message([max(1.0, float(np.abs(q).max()))], [np.zeros(5)])
    sweep = snakekit.side_sweep()
    task2 = message(sweep.times, sweep.positions)
    print("ready", flush=True)
    for line in sys.stdin:
        what = line.strip()
        if what == "task1":
            said = []
            for i, msg in enumerate(task1):
                if i:
                    time.sleep(PAUSE)
                said.append(send(msg))
            time.sleep(PAUSE)  # the user looks at the last pose too
        elif what == "task2":
            said = [send(task2)]
        elif what == "home":  # between two measured runs: home, settled
            said = [send(home)]
            time.sleep(PAUSE)
        else:
            break
        print("done " + json.dumps(said), flush=True)


# --- the containers' cgroups ------------------------------------------------------------------

def cgroup_dirs(pid: int) -> dict[str, Path]:
    """The cgroup folders of a process, by what they count ("cpu", "memory"), v1 or v2."""
    dirs = {}
    for line in Path(f"/proc/{pid}/cgroup").read_text().splitlines():
        _, controllers, path = line.split(":", 2)
        path = path.lstrip("/")
        if controllers == "":  # v2, unified
            d = Path("/sys/fs/cgroup") / path
            if (d / "cpu.stat").exists() and (d / "memory.current").exists():
                dirs.setdefault("cpu", d)
                dirs.setdefault("memory", d)
        for c in controllers.split(","):
            if c in ("cpuacct", "memory"):
                d = Path("/sys/fs/cgroup") / controllers / path
                if not d.exists():
                    d = Path("/sys/fs/cgroup") / c / path
                dirs["cpu" if c == "cpuacct" else "memory"] = d
    if set(dirs) != {"cpu", "memory"}:
        raise RuntimeError(f"no CPU and memory cgroup found for process {pid} (/proc/{pid}/cgroup)")
    return dirs


def cpu_seconds(d: Path) -> float:
    if (d / "cpuacct.usage").exists():
        return int((d / "cpuacct.usage").read_text()) / 1e9
    stat = dict(line.split() for line in (d / "cpu.stat").read_text().splitlines())
    return int(stat["usage_usec"]) / 1e6


def working_set(d: Path) -> float:
    """Memory as `docker stats` shows it: usage less inactive file pages [MB]."""
    stat = dict(line.split() for line in (d / "memory.stat").read_text().splitlines())
    if (d / "memory.current").exists():
        return (int((d / "memory.current").read_text()) - int(stat["inactive_file"])) / 1e6
    return (int((d / "memory.usage_in_bytes").read_text()) - int(stat["total_inactive_file"])) / 1e6


class CgroupSampler:
    """CPU and memory of a set of containers, summed, every ``period`` s (the peak every period / 5).

    The series has bench/_common.Sampler's form (``t``, ``cpu`` [% of one core], ``rss`` [MB],
    ``cpu_avg``, ``rss_peak``, ``wall``), its memory being the containers' working set; ``by_container``
    gives each container's average CPU [%] and peak memory [MB] over the same time.
    """

    def __init__(self, containers: dict[str, dict[str, Path]], period: float = 0.5):
        self.containers = containers
        self.period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _read(self) -> tuple[dict[str, float], dict[str, float]]:
        return ({n: cpu_seconds(d["cpu"]) for n, d in self.containers.items()},
                {n: working_set(d["memory"]) for n, d in self.containers.items()})

    def start(self) -> "CgroupSampler":
        self._cpu0, mem = self._read()
        self._last_cpu = self._cpu0
        self._peak, self._peak_each = sum(mem.values()), dict(mem)
        self.samples: list[tuple[float, float, float]] = []
        self._t0 = self._last = time.perf_counter()
        self._thread.start()
        return self

    def _loop(self) -> None:
        tick = self.period / 5
        while not self._stop.wait(tick):
            if time.perf_counter() - self._last >= self.period - tick / 2:
                self._take()
            else:
                self._watch(self._read()[1])

    def _watch(self, mem: dict[str, float]) -> None:
        self._peak = max(self._peak, sum(mem.values()))
        for n, v in mem.items():
            self._peak_each[n] = max(self._peak_each[n], v)

    def _take(self) -> None:
        cpu, mem = self._read()
        now = time.perf_counter()
        used = sum(cpu.values()) - sum(self._last_cpu.values())
        self.samples.append((now - self._t0, 100 * used / max(now - self._last, 1e-6), sum(mem.values())))
        self._watch(mem)
        self._last, self._last_cpu = now, cpu

    def stop(self) -> dict:
        self._stop.set()
        self._thread.join()
        self._take()
        wall = self.samples[-1][0]
        return {"t": [s[0] for s in self.samples], "cpu": [s[1] for s in self.samples],
                "rss": [s[2] for s in self.samples],
                "cpu_avg": 100 * (sum(self._last_cpu.values()) - sum(self._cpu0.values())) / wall,
                "rss_peak": self._peak, "wall": wall,
                "by_container": {n: {"cpu_avg": 100 * (self._last_cpu[n] - self._cpu0[n]) / wall,
                                     "mem_peak": self._peak_each[n]} for n in self.containers}}


# --- the stack ----------------------------------------------------------------------------------

class Stack:
    """compose's `ros` profile, its ROS services only, in a project of its own."""

    def __init__(self):
        from container import COMPOSE, free_port

        self.project = f"snakekit-bench-ros-{os.getpid()}"
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.base = [*COMPOSE, "-p", self.project, "-f", str(REPO / "docker" / "compose.yaml"), "--profile", "ros"]
        self.env = {**os.environ, "SNAKEKIT_ROS_PORT": str(self.port)}

    def compose(self, *args, check=True, timeout=HANG) -> subprocess.CompletedProcess:
        r = subprocess.run([*self.base, *args], capture_output=True, text=True, timeout=timeout, env=self.env)
        if check and r.returncode:
            raise RuntimeError(f"docker compose {' '.join(args)} failed: {(r.stderr or r.stdout).strip()[-400:]}")
        return r

    def up(self) -> dict:
        """Start the stack; seconds from `up` to the arm's node answering and to noVNC's page."""
        import urllib.request

        t0 = time.perf_counter()
        self.compose("up", "-d", "--no-build", "rviz")
        arm = novnc = None
        while arm is None or novnc is None:
            if time.perf_counter() - t0 > HANG:
                raise RuntimeError(f"the stack was not up within {HANG:g} s: "
                                   f"{self.compose('logs', '--tail', '5', check=False).stdout[-600:]}")
            if arm is None and "snakekit ros: the sim arm is node" in self.compose("logs", "arm", check=False).stdout:
                arm = time.perf_counter() - t0
            if novnc is None:
                try:
                    with urllib.request.urlopen(f"{self.url}/vnc.html", timeout=2) as r:
                        if b"noVNC" in r.read():
                            novnc = time.perf_counter() - t0
                except OSError:
                    pass
            time.sleep(0.1)
        return {"arm_s": arm, "novnc_s": novnc}

    def ids(self) -> dict[str, str]:
        return {s: self.compose("ps", "-q", s).stdout.strip() for s in SERVICES}

    def down(self) -> None:
        self.compose("down", "--volumes", "--remove-orphans", check=False)


def container_cgroups(ids: dict[str, str]) -> dict[str, dict[str, Path]]:
    from container import docker

    return {name: cgroup_dirs(int(docker("inspect", "-f", "{{.State.Pid}}", cid).stdout)) for name, cid in ids.items()}


def rviz_check():
    """docker/ros/rviz-check as a module: its colour test of the arm's links and Chromium's flags."""
    import importlib.machinery
    import importlib.util

    loader = importlib.machinery.SourceFileLoader("rviz_check", str(REPO / "docker" / "ros" / "rviz-check"))
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader("rviz_check", loader))
    loader.exec_module(module)
    return module


def arm_pixels(page, check) -> int:
    import io

    import numpy as np
    from PIL import Image

    png = page.locator("#noVNC_container canvas").screenshot()
    return check.orange(np.asarray(Image.open(io.BytesIO(png)).convert("RGB")))


def reply(node) -> str:
    """The driver's next word ("ready", "done [...]"), past anything else it printed; "" when it ended."""
    for line in node.stdout:
        if line.startswith(("ready", "done ")):
            return line.strip()
    return ""


def measure(repeats: int) -> dict:
    from playwright.sync_api import sync_playwright

    from _common import spread

    stack = Stack()
    starts = []
    try:
        for _ in range(repeats - 1):  # the last start stays up for the tasks
            starts.append(stack.up())
            stack.down()
        starts.append(stack.up())
        ids = stack.ids()
        groups = container_cgroups(ids)
        from container import docker

        docker("cp", str(HERE) + "/.", f"{ids['arm']}:/tmp/bench")
        node = subprocess.Popen([*stack.base, "exec", "-T", "arm", "python", "/tmp/bench/ros.py", "--driver"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=stack.env)
        check = rviz_check()
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=check.FLAGS)
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(f"{stack.url}/vnc.html?autoconnect=1&resize=scale", timeout=HANG * 1000)
            end = time.monotonic() + HANG
            while arm_pixels(page, check) <= check.ARM_PIXELS:
                if time.monotonic() > end:
                    raise RuntimeError(f"RViz in noVNC did not show the arm within {HANG:g} s")
                time.sleep(0.5)
            if reply(node) != "ready":
                raise RuntimeError("the driver node in the arm's container did not start")

            def task(what: str) -> tuple[dict, list[str]]:
                sampler = CgroupSampler(groups).start()
                node.stdin.write(what + "\n")
                node.stdin.flush()
                line = reply(node)
                series = sampler.stop()
                if not line.startswith("done "):
                    raise RuntimeError(f"the driver node stopped during {what}")
                return series, json.loads(line[5:])

            def unmeasured(what: str) -> None:
                node.stdin.write(what + "\n")
                node.stdin.flush()
                if not reply(node).startswith("done "):
                    raise RuntimeError(f"the driver node stopped during {what}")

            task1, task2 = [], []
            for _ in range(repeats):
                task1.append(task("task1"))
                unmeasured("home")
            for _ in range(repeats):
                task2.append(task("task2"))
                unmeasured("home")
            drawn = arm_pixels(page, check)
            browser.close()
        node.stdin.write("quit\n")
        node.stdin.flush()
        node.wait(timeout=60)
        if drawn <= check.ARM_PIXELS:
            raise RuntimeError(f"RViz in noVNC no longer showed the arm after the tasks ({drawn} pixels)")
    finally:
        stack.down()

    def summary(runs):
        mid = sorted(runs, key=lambda r: r[0]["cpu_avg"])[len(runs) // 2][0]
        return {"cpu": spread(r[0]["cpu_avg"] for r in runs), "ram": spread(r[0]["rss_peak"] for r in runs),
                "wall": spread(r[0]["wall"] for r in runs), "said": runs[0][1], "series": mid,
                "by_container": {n: {"cpu": spread(r[0]["by_container"][n]["cpu_avg"] for r in runs),
                                     "mem_peak": spread(r[0]["by_container"][n]["mem_peak"] for r in runs)}
                                 for n in SERVICES}}

    return {"start_arm_s": spread(s["arm_s"] for s in starts), "start_novnc_s": spread(s["novnc_s"] for s in starts),
            "task1": summary(task1), "task2": summary(task2), "arm_pixels_after": drawn,
            "cgroup": "v2" if (groups["arm"]["cpu"] / "cpu.stat").exists() and not
            (groups["arm"]["cpu"] / "cpuacct.usage").exists() else "v1"}


# --- running --------------------------------------------------------------------------------------

def missing() -> str | None:
    """What is missing to measure here (engine, images), or None."""
    from container import docker, engine

    why = engine()
    if why:
        return why
    if docker("image", "inspect", ROS_IMAGE, check=False).returncode != 0:
        return (f"not measured: no image {ROS_IMAGE} (build it: "
                "docker compose -f docker/compose.yaml --profile ros build roscore)")
    return None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="starts and runs of each task (medians; default 3)")
    parser.add_argument("--driver", action="store_true", help=argparse.SUPPRESS)
    from _common import add_json_argument, write_json

    add_json_argument(parser)
    args = parser.parse_args(argv)
    if args.driver:
        driver()
        return 0
    if args.repeats < 1:
        parser.error(f"--repeats is {args.repeats}; give 1 or more")

    import container

    why = missing()
    if why and not os.environ.get("SNAKEKIT_BENCH_ENGINE") and container.private_engine_possible():
        os.environ["SNAKEKIT_BENCH_ROS"] = "1"  # bench/container-engine.sh builds the ROS image too
        return container.under_private_engine(argv if argv is not None else sys.argv[1:], args.json,
                                              script=Path(__file__).resolve())
    if why:
        print(f"bench/ros.py: {why}; run it as root with Debian's docker.io for the private engine "
              "(docker/engine.sh), or set DOCKER_HOST to an engine with both images", file=sys.stderr)
        write_json(args.json, {"not_measured": why})
        return 2
    from run import machine

    before = machine()  # the ROS row may be measured alone (run.py --only ros): its own machine and load
    results = measure(args.repeats)
    results["machine"] = before
    results["image_bytes"] = int(container.docker("image", "inspect", "-f", "{{.Size}}", ROS_IMAGE).stdout)
    results["lab_image_bytes"] = int(container.docker("image", "inspect", "-f", "{{.Size}}", container.IMAGE).stdout)
    results["repeats"] = args.repeats
    if os.environ.get("SNAKEKIT_BENCH_ENGINE"):
        results["engine"] = json.loads(os.environ["SNAKEKIT_BENCH_ENGINE"])
    for key, title in (("task1", "Task 1 (three goal changes)"), ("task2", "Task 2 (the sweep, one JointTrajectory)")):
        r = results[key]
        each = ", ".join(f"{n} {c['cpu']['median']:.1f} %" for n, c in r["by_container"].items())
        print(f"{title}: CPU {r['cpu']['median']:.2f} % of one core (min {r['cpu']['min']:.2f}, max {r['cpu']['max']:.2f}), "
              f"peak memory {r['ram']['median']:.0f} MB, {r['wall']['median']:.1f} s; by container: {each}; "
              f"the arm said: {r['said'][-1]}")
    print(f"start to the arm's node answering: {results['start_arm_s']['median']:.1f} s (noVNC's page: "
          f"{results['start_novnc_s']['median']:.1f} s); ROS image {results['image_bytes'] / 1e9:.2f} GB")
    write_json(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
