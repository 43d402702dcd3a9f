"""The local set-up (the venv that `make lab` makes): time to a working lesson kernel, time to
JupyterLab ready, and the install size.

* Time to a working lesson kernel: from asking jupyter_client for a kernel (the lessons'
  ``python3`` kernel of this environment) to the end of lesson 00's first code cell (imports,
  the simulated arm, the 3D viewer with its server, the workspace drawn): what a student waits
  for before the first lesson answers.
* Time to JupyterLab ready: from ``make lab`` (which checks the environment first) to the
  moment the server serves the ``/lab`` page to a browser that has the token.
* Install size: the disk space of ``.venv`` (every Python package the kit installs). The
  system packages tools/setup adds (Chromium for the browser tests, debootstrap and
  docker.io for the container tests) are not counted: a student does not need them.

Run: ``.venv/bin/python bench/setups.py [--repeats 3] [--json PATH]``
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import add_json_argument, spread, wait_for_lab, write_json  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
# the lessons: this repository's, or the container image's copy (bench/container.py runs this there)
NOTEBOOKS = next((p for p in (REPO / "notebooks", Path("/opt/snakekit/notebooks")) if p.is_dir()), REPO / "notebooks")
LESSON = NOTEBOOKS / "00_meet_the_arm.ipynb"


def first_cell(path: Path = LESSON) -> str:
    nb = json.loads(path.read_text())
    return next("".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code")


def time_to_kernel(code: str) -> float:
    """Seconds from asking for a kernel to the end of ``code`` run in it."""
    from jupyter_client.manager import start_new_kernel

    t0 = time.perf_counter()
    km, kc = start_new_kernel(kernel_name="python3", cwd=str(NOTEBOOKS))
    try:
        reply = kc.execute_interactive(code, timeout=120, output_hook=lambda msg: None)
        dt = time.perf_counter() - t0
        if reply["content"]["status"] != "ok":
            raise RuntimeError(f"lesson 00's first cell failed in the kernel: {reply['content'].get('evalue')}")
        return dt
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def time_to_lab(command: list[str] | None = None, port: int | None = None, timeout: float = 120.0) -> float:
    """Seconds from ``make lab`` (or ``command``, serving on ``port``) to the /lab page served
    (token given, as a browser has it)."""
    port, token = port or free_port(), "snakekit-bench"
    cmd = command or ["make", "-s", "lab", f"LAB_PORT={port}"]
    env = {**os.environ, "JUPYTER_TOKEN": token}
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        def gone():
            if proc.poll() is not None:
                return f"`{' '.join(cmd)}` exited with code {proc.returncode} before JupyterLab was ready"
            return None

        return wait_for_lab(port, token, t0, timeout, gone=gone, poll=0.02)
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def disk_usage(path: Path) -> int:
    """Bytes on disk under ``path`` (hard links counted once)."""
    total, seen = 0, set()
    for root, dirs, files in os.walk(path):
        for name in files + dirs:
            try:
                st = os.lstat(os.path.join(root, name))
            except OSError:
                continue
            if (st.st_dev, st.st_ino) in seen:
                continue
            seen.add((st.st_dev, st.st_ino))
            total += st.st_blocks * 512
    return total


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--kernel-only", action="store_true", help="only the time to a lesson kernel")
    add_json_argument(parser)
    args = parser.parse_args(argv)
    code = first_cell()
    if args.kernel_only:
        kernel = [time_to_kernel(code) for _ in range(args.repeats)]
        print(f"time to a working lesson kernel: {spread(kernel)['median']:.2f} s")
        write_json(args.json, {"kernel_s": spread(kernel)})
        return 0
    kernel, lab = [], []
    for _ in range(args.repeats):  # interleaved, so a busy moment hits both alike
        kernel.append(time_to_kernel(code))
        lab.append(time_to_lab())
    venv = Path(sys.prefix)
    size = disk_usage(venv)
    print(f"local venv set-up, {args.repeats} repeats (median, min-max)")
    print(f"time to a working lesson kernel (lesson 00, first cell): {spread(kernel)['median']:.2f} s "
          f"({min(kernel):.2f}-{max(kernel):.2f})")
    print(f"time to JupyterLab ready (make lab):                     {spread(lab)['median']:.2f} s "
          f"({min(lab):.2f}-{max(lab):.2f})  target <= 3 s")
    print(f"install size (.venv):                                     {size / 1e9:.2f} GB")
    write_json(args.json, {"kernel_s": spread(kernel), "lab_s": spread(lab), "install_bytes": size,
                           "install_what": ".venv"})
    return 0 if spread(lab)["median"] <= 3 else 1


if __name__ == "__main__":
    sys.exit(main())
