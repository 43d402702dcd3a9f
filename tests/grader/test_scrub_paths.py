"""A feedback page shows no path of the grading machine's kernel: a traceback through a function a cell defined
names the kernel's file of that cell (``/tmp/ipykernel_NN/NNNN.py``), and an error about a file made in a temporary
folder names that folder; the page says ``<notebook cell>`` and ``<temporary folder>`` instead."""

import os
import sys
import tempfile
from pathlib import Path

from grader.feedback.scrub import machine_paths, scrub_cell
from tests.conftest import need, notebook_client

CELLS = ["import tempfile\nfrom pathlib import Path\nimport numpy as np\n\ndef read_joint_states(path):\n"
         "    raise ValueError(f'{path} holds no /joint_states messages')\n\ndef rms(e):\n    return np.sqrt(e)",
         "rms(-1.0)",     # numpy's warning names the line of the cell's function, in the kernel's file of the cell
         # a file in a temporary folder (the folder removed again: the error still names it)
         "folder = Path(tempfile.mkdtemp())\nfolder.rmdir()\nread_joint_states(folder / 'recorded.bag')"]


def test_a_traceback_through_a_cells_function_shows_no_kernel_file_and_no_temporary_folder(tmp_path, monkeypatch):
    nbformat = need("nbformat")
    need("nbclient")
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in CELLS])
    notebook_client(nb, timeout=300, kernel_name="python3", allow_errors=True,
                    resources={"metadata": {"path": str(tmp_path)}}).execute()
    warned = next(o for o in nb.cells[1].outputs if o.output_type == "stream" and "RuntimeWarning" in o.text)
    assert "ipykernel_" in warned.text and f"{tempfile.gettempdir()}/tmp" in nb.cells[2].outputs[0].evalue  # as run
    for cell in nb.cells[1:]:
        scrub_cell(cell, set(), machine_paths())
    warned = next(o for o in nb.cells[1].outputs if o.output_type == "stream" and "RuntimeWarning" in o.text)
    assert warned.text.startswith("<notebook cell>:9: RuntimeWarning: invalid value encountered in sqrt"), warned.text
    error = nb.cells[2].outputs[0]
    assert error.evalue == "<temporary folder>/recorded.bag holds no /joint_states messages"
    assert tempfile.gettempdir() + "/tmp" not in "".join(error.traceback), error.traceback
