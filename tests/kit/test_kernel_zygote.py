"""The suite's forked lesson kernels (tests/kernel_zygote.py) behave as fresh ones: the same facts, the same
outputs, an interrupt that stops a cell, and no process left when the kernel is shut down."""

import os
import time

import nbformat

from tests.conftest import notebook_client
from tests.kernel_zygote import ForkedKernel, _Server, _start_time, why_fresh

# after the kit's import, as in a lesson (MuJoCo's sets PYOPENGL_PLATFORM, which the server has imported already)
FACTS = """
import os, sys, json, matplotlib, snakekit
ip = get_ipython()
print(json.dumps({
    "cwd": os.getcwd(), "path0": sys.path[0], "cwd_on_path": "" in sys.path, "backend": matplotlib.get_backend(),
    "env": sorted(k for k in os.environ if not k.startswith("JPY_") and k != "PYTEST_CURRENT_TEST"),
    "widget_target": "jupyter.widget" in ip.kernel.comm_manager.targets if "ipywidgets" in sys.modules else None,
    "png_formatter": bool(ip.display_formatter.formatters["image/png"].type_printers),
    "ipywidgets_loaded": "ipywidgets" in sys.modules,
}))
"""

CELLS = [
    FACTS,
    "import matplotlib.pyplot as plt\nplt.plot([1, 2]); plt.show()",          # a figure without %matplotlib inline
    "import ipywidgets as w\nw.IntSlider(3)",                                   # a widget, imported in the kernel
    "import ipywidgets, sys\nprint('jupyter.widget' in get_ipython().kernel.comm_manager.targets)",
    "import numpy as np, snakekit\nfrom snakekit.plots import plot_move\n"
    "with snakekit.make_robot('sim') as r:\n    run = r.run(snakekit.joint_trajectory(np.zeros(5), [0.2] * 5, 0.5))\n"
    "plot_move(run)",
    "import os\nprint('tests.kernel_zygote' in open(f'/proc/{os.getppid()}/cmdline').read())",  # forked, or not
]


def _run(tmp_path, fresh: bool):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in CELLS])
    kw = {}
    if fresh:
        from jupyter_client.manager import AsyncKernelManager

        kw["kernel_manager_class"] = AsyncKernelManager
    client = notebook_client(nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}},
                             **kw)
    client.execute()
    return nb


def _shape(nb):
    """Each cell's outputs as a person reads them: their kinds, their formats, and the printed text."""
    return [[(o["output_type"], sorted(o.get("data", {})), o.get("text", "")) for o in c.outputs] for c in nb.cells]


def test_a_forked_kernel_shows_what_a_fresh_one_shows(tmp_path):
    forked, fresh = _run(tmp_path, False), _run(tmp_path, True)
    assert [_shape(nb)[-1][0][2] for nb in (forked, fresh)] == ["True\n", "False\n"], _Server.last_fresh
    assert _shape(forked)[:-1] == _shape(fresh)[:-1]
    assert "image/png" in forked.cells[1].outputs[0]["data"]                     # the figure is a picture
    assert "application/vnd.jupyter.widget-view+json" in forked.cells[2].outputs[0]["data"]
    assert forked.cells[3].outputs[0]["text"].strip() == "True"                  # the widgets' comm target is set up
    import json

    facts = json.loads(forked.cells[0].outputs[0]["text"])
    assert facts["cwd"] == str(tmp_path) and facts["backend"].endswith("backend_inline")
    assert facts["path0"] != str(tmp_path) and facts["cwd_on_path"]  # the folder after the library, as IPython puts it
    assert facts["ipywidgets_loaded"] is False                                   # nothing the kernel imports at start


def test_a_forked_kernel_is_interrupted_at_its_cells_timeout_and_gone_after_shutdown(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("import os\nprint(os.getpid(), os.getppid())"),
                                         nbformat.v4.new_code_cell("while True: pass"),
                                         nbformat.v4.new_code_cell("print('after')")])
    client = notebook_client(nb, timeout=3, kernel_name="python3", interrupt_on_timeout=True, allow_errors=True,
                             resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    pid, parent = map(int, nb.cells[0].outputs[0]["text"].split())
    assert parent != os.getpid() and "tests.kernel_zygote" in open(f"/proc/{parent}/cmdline").read()  # forked
    assert nb.cells[1].outputs[-1]["ename"] == "KeyboardInterrupt"      # the interrupt reached the kernel
    assert nb.cells[2].outputs[0]["text"] == "after\n"
    deadline = time.monotonic() + 30
    while _start_time(pid) is not None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _start_time(pid) is None, f"the kernel {pid} outlived its shutdown"


def test_the_kernels_process_object_never_takes_a_reused_id_for_the_kernel():
    """The server's kernels are reaped by the system, so an id can come back: the start time tells them apart."""
    me = ForkedKernel(os.getpid(), _start_time(os.getpid()))
    assert me.poll() is None
    other = ForkedKernel(os.getpid(), "1")          # this id, another start: not the kernel
    assert other.poll() == 0
    other.kill()                                    # never signals the process that has the id now
    assert me.poll() is None


def test_a_kernel_is_forked_only_in_the_environment_the_server_imported_in():
    """A variable an import may read (the kit's, MuJoCo's, Python's, the BLAS's) set otherwise by a test: a fresh
    kernel; any other (PATH, a grader's variable), or one the server's imports set to the same value: forked, with
    the environment it is asked for."""
    import sys

    from tests.kernel_zygote import SESSION_ENV

    cmd = [sys.executable, "-m", "ipykernel_launcher", "-f", "k.json"]
    imported = {"PYOPENGL_PLATFORM": "egl"}
    assert why_fresh(cmd, dict(SESSION_ENV), imported) == ""
    for key, value in (("PATH", "/x"), ("JPY_PARENT_PID", "1"), ("JUPYTER_CONFIG_PATH", "/c"),
                       ("PYOPENGL_PLATFORM", "egl")):
        assert why_fresh(cmd, {**SESSION_ENV, key: value}, imported) == "", key
    for key in ("SNAKEKIT_CASES", "MUJOCO_GL", "MPLBACKEND", "PYTHONPATH", "OPENBLAS_NUM_THREADS", "HOME",
                "PYOPENGL_PLATFORM"):
        why = why_fresh(cmd, {**SESSION_ENV, key: "another"}, imported)
        assert why == f"the environment differs from the session's in {key}", why
    assert why_fresh(["/usr/bin/python3", *cmd[1:]], dict(SESSION_ENV), imported).startswith("not this Python")
    assert why_fresh([sys.executable, "-m", "other_kernel"], dict(SESSION_ENV), imported).startswith("not this")
