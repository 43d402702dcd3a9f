"""The kit's own notebook runs reach their kernel over Unix sockets (snakekit.host.kernel_sockets):
no TCP port is picked by the client and bound later by the kernel, so kernels started at once
(the suite's workers, a class graded beside `snakekit check`) cannot take each other's ports."""

from __future__ import annotations

import io
import json
import os
import stat

from snakekit import host
from snakekit.notebook_check import check_notebook
from tests.conftest import need, notebook_client

PROBE = ("import json, os, ipykernel.connect\n"
         "info = json.load(open(ipykernel.connect.get_connection_file()))\n"
         "print(json.dumps({'transport': info['transport'], 'ip': info['ip'],\n"
         "                  'ports': [info[k] for k in ('shell_port', 'iopub_port', 'stdin_port', 'control_port', 'hb_port')]}))")


def test_the_settings_name_a_socket_folder_on_linux_and_macos_and_tcp_on_windows(tmp_path):
    assert host.kernel_sockets(tmp_path, platform="linux") == {
        "KernelManager": {"transport": "ipc", "ip": str(tmp_path / "kernel")}}
    assert host.kernel_sockets(tmp_path, platform="darwin")["KernelManager"]["transport"] == "ipc"
    assert host.kernel_sockets(tmp_path, platform="win32") == {}
    # a path a socket's name cannot hold (108 bytes on Linux): TCP, as Jupyter's default
    assert host.kernel_sockets("/" + "d" * 100, platform="linux") == {}


def test_a_kernel_started_with_them_listens_on_sockets_in_the_folder_and_on_no_tcp_port(tmp_path):
    nbformat = need("nbformat")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(PROBE)])
    client = notebook_client(nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    with client.setup_kernel():
        client.execute_cell(nb.cells[0], 0)
        ip = client.km.ip
        folder = os.path.dirname(ip)
        sockets = sorted(os.listdir(folder))
        modes = [os.stat(os.path.join(folder, s)).st_mode for s in sockets]
    said = json.loads(nb.cells[0].outputs[0]["text"])
    assert said["transport"] == "ipc" and said["ip"] == ip and os.path.isabs(ip), said
    # five channels, each a socket file "<ip>-<n>" in a folder of the run's own, numbered 1 to 5:
    # no TCP port was picked for them
    assert sockets == [f"kernel-{n}" for n in range(1, 6)] and all(stat.S_ISSOCK(m) for m in modes), sockets
    assert sorted(said["ports"]) == [1, 2, 3, 4, 5], said
    assert os.listdir(folder) == []  # the kernel's shut-down removed them


def test_snakekit_check_runs_its_kernel_on_sockets(tmp_path, monkeypatch):
    """`snakekit check`'s run: the notebook's graded cell passes only when its own kernel is on sockets
    in the run's folder, and the folder goes with the run."""
    nbformat = need("nbformat")
    seen = []
    real = host.kernel_sockets
    monkeypatch.setattr(host, "kernel_sockets", lambda folder, **kw: seen.append(str(folder)) or real(folder, **kw))
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell(PROBE),
        nbformat.v4.new_code_cell("assert info['transport'] == 'ipc', info\n"
                                  "assert os.path.basename(os.path.dirname(info['ip'])).startswith('snakekit-kernel-'), info",
                                  metadata={"nbgrader": {"grade": True, "grade_id": "ex_sockets_test", "points": 1,
                                                         "solution": False}}),
    ])
    path = tmp_path / "lesson.ipynb"
    nbformat.write(nb, path)
    out = io.StringIO()
    assert check_notebook(path, out=out) == 0, out.getvalue()
    assert "1 of 1" in out.getvalue(), out.getvalue()
    assert len(seen) == 1 and not os.path.exists(seen[0]), seen
