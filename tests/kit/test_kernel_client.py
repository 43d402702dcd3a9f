"""The kit's notebook client (snakekit.kernel_client): a cell the kernel finished (IOPub: its outputs,
then idle) whose execute_reply never arrives counts as finished LATE_REPLY s after the idle, with the
outputs it sent, instead of waiting out the cell's timeout. ipykernel 7 loses such a reply now and
then on a busy machine (lesson 0's control panel cells, about one run in two under stress-ng);
`snakekit check`, the suite's notebook runs and the grader's sandboxes all use the client."""

from __future__ import annotations

import io
import time

import nbclient
import pytest

from snakekit import kernel_client
from snakekit.notebook_check import check_notebook
from tests.conftest import need, notebook_client

LOSE = "# lose my reply"


@pytest.fixture
def losing_shell(monkeypatch):
    """The shell channel loses the execute_reply of each cell whose code holds LOSE; returns the
    cells' indices whose reply was lost, in order."""
    lost, codes = [], {}
    real_start = nbclient.NotebookClient.async_start_new_kernel_client

    async def start(self, *a, **k):
        kc = await real_start(self, *a, **k)
        channel = kc.shell_channel
        get = channel.get_msg

        async def losing(*a, **k):
            msg = await get(*a, **k)
            while msg["msg_type"] == "execute_reply" and LOSE in codes.get(msg["parent_header"]["msg_id"], ""):
                lost.append(msg["parent_header"]["msg_id"])
                msg = await get(*a, **k)
            return msg

        channel.get_msg = losing
        real = kc.execute

        def execute(code, *a, **k):
            msg_id = real(code, *a, **k)
            codes[msg_id] = code
            return msg_id

        kc.execute = execute
        return kc

    monkeypatch.setattr(nbclient.NotebookClient, "async_start_new_kernel_client", start)
    monkeypatch.setattr(kernel_client, "LATE_REPLY", 1.0)
    return lost


def _notebook(*sources, graded=()):
    nbformat = need("nbformat")
    cells = [nbformat.v4.new_code_cell(src) for src in sources]
    for i in graded:
        cells[i].metadata["nbgrader"] = {"grade": True, "grade_id": f"ex_{i}_test", "points": 1, "solution": False}
    nb = nbformat.v4.new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    return nb


def test_a_lost_reply_costs_late_reply_seconds_and_the_cell_keeps_its_outputs_and_its_error(tmp_path, losing_shell):
    nb = _notebook("x = 6 * 7\nprint('first', x)",
                   f"{LOSE}\nprint('second', x + 1)",
                   f"{LOSE}\nprint('third', x + 2)\nraise ValueError('kept as the cell error')",
                   "print('fourth', x + 3)")
    client = notebook_client(nb, timeout=60, kernel_name="python3", allow_errors=True,
                             resources={"metadata": {"path": str(tmp_path)}})
    started = time.monotonic()
    client.execute()
    took = time.monotonic() - started
    text = ["".join(o.get("text", "") for o in c.outputs if o.output_type == "stream") for c in nb.cells]
    assert text == ["first 42\n", "second 43\n", "third 44\n", "fourth 45\n"]
    assert [o.ename for o in nb.cells[2].outputs if o.output_type == "error"] == ["ValueError"]
    assert not any(o.output_type == "error" for c in (nb.cells[0], nb.cells[1], nb.cells[3]) for o in c.outputs)
    assert [c.execution_count for c in nb.cells] == [1, 2, 3, 4]
    assert len(losing_shell) == 2
    # the cells did not wait for their 60-s timeout (a bound for a hang, not a speed)
    assert took < 60, took


def test_without_allow_errors_a_lost_reply_of_a_failing_cell_still_stops_the_run_with_its_error(tmp_path, losing_shell):
    nb = _notebook("print('one')", f"{LOSE}\nraise KeyError('the cell error')", "print('never')")
    client = notebook_client(nb, timeout=60, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    with pytest.raises(nbclient.exceptions.CellExecutionError, match="KeyError") as raised:
        client.execute()
    assert "the cell error" in str(raised.value)
    assert nb.cells[2].outputs == [] and len(losing_shell) == 1


def test_snakekit_check_grades_cells_whose_replies_were_lost_as_their_outputs_say(tmp_path, losing_shell):
    nbformat = need("nbformat")
    nb = _notebook("def answer():\n    return 42",
                   f"{LOSE}\nassert answer() == 42",
                   f"{LOSE}\nassert answer() == 43, 'answer() is 42, expected 43'",
                   "assert answer() == 42",
                   graded=(1, 2, 3))
    path = tmp_path / "lesson.ipynb"
    nbformat.write(nb, path)
    out = io.StringIO()
    assert check_notebook(path, out=out, timeout=60) == 1, out.getvalue()
    rows = [line.split() for line in out.getvalue().splitlines()[1:4]]
    assert [(r[0], r[3]) for r in rows] == [("ex_1_test", "passed"), ("ex_2_test", "FAILED"), ("ex_3_test", "passed")]
    assert "answer() is 42, expected 43" in out.getvalue()
    assert "2 of 3 exercises passed" in out.getvalue()
    assert len(losing_shell) == 2


@pytest.mark.parametrize("outputs, status", [
    ([], "ok"),
    ([{"output_type": "stream", "name": "stdout", "text": "x"}], "ok"),
    ([{"output_type": "error", "ename": "E", "evalue": "v", "traceback": ["t"]}], "error"),
    # an error shown and then left behind (the cell printed after it): the cell itself ended well
    ([{"output_type": "error", "ename": "E", "evalue": "v", "traceback": []},
      {"output_type": "stream", "name": "stdout", "text": "after"}], "ok"),
])
def test_the_reply_made_from_the_outputs_is_an_error_only_when_the_cell_ended_on_one(outputs, status):
    reply = kernel_client.reply_from_outputs(outputs)
    assert reply["status"] == status
    if status == "error":
        assert (reply["ename"], reply["evalue"], reply["traceback"]) == ("E", "v", ["t"])


#: what a cell raises: a busy machine's faults on the emulated bus (run again), and another error (the result)
FAULTS = {
    "silence": "raise snakekit.CommunicationError('servo 1 on /dev/pts/9 did not answer the SyncRead of the joint "
               "state (timed out, 4 tries); check the cable and power, or the id.')",
    "watchdog": "raise snakekit.BusWatchdogError('during the run, the Bus Watchdog stopped servo(s) 1, 2, 3, 4, 5 on "
                "/dev/pts/9: they heard nothing for more than 0.5 s, so they hold where they stopped and refuse goals. "
                "Call robot.torque_on() to clear it and go on.')",
    "overload": "raise snakekit.CommunicationError('servo 2 on /dev/pts/9 reported an overload')",
}


@pytest.mark.parametrize("allow_errors", [False, True])
@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("faulted_runs", [0, 1, 2])
def test_the_suites_notebook_runs_run_again_once_on_a_busy_machines_bus_fault(tmp_path, allow_errors, fault,
                                                                              faulted_runs):
    """The suite's notebook client (tests/conftest.py's ``notebook_client``) runs a notebook once more, in a new
    kernel, when a cell ended in a busy machine's fault on the emulated bus: the emulated servos' silence (the
    machine held the emulator's thread up) or a Bus Watchdog stop (it held the kernel up past 0.5 s); it warns; a
    second fault is the notebook's result. Any other error is the result at once."""
    nbformat = need("nbformat")
    runs = tmp_path / "runs"
    cell = (f"import snakekit, pathlib\np = pathlib.Path({str(runs)!r})\np.write_text(p.read_text() + 'x' "
            f"if p.exists() else 'x')\nif len(p.read_text()) <= {faulted_runs}:\n    " + FAULTS[fault])
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(cell), nbformat.v4.new_code_cell("print('done')")])
    client = notebook_client(nb, timeout=120, kernel_name="python3", allow_errors=allow_errors)
    machine = fault != "overload"
    again = faulted_runs > 0 and machine
    error = (faulted_runs > 1 and machine) or (faulted_runs > 0 and not machine)   # the notebook's result
    ename = "BusWatchdogError" if fault == "watchdog" else "CommunicationError"
    with pytest.warns() if again else _no_warning() as seen:
        if error and not allow_errors:
            with pytest.raises(nbclient.exceptions.CellExecutionError, match=ename):
                client.execute()
        else:
            client.execute()
    ran = len(runs.read_text())
    assert ran == (2 if again else 1), ran
    if again:
        assert any(f"a busy machine's fault on the emulated bus, the notebook was run again: {ename}: "
                   in str(w.message) for w in seen), [str(w.message) for w in seen]
    errors = [o for o in nb.cells[0].outputs if o.output_type == "error"]
    if error and allow_errors:
        assert [o.ename for o in errors] == [ename]
    elif not error:
        assert errors == [] and nb.cells[1].outputs[0].text == "done\n"


class _no_warning:
    """A context like ``pytest.warns``: records warnings and fails on any about the emulated bus."""

    def __enter__(self):
        import warnings

        self._ctx = warnings.catch_warnings(record=True)
        self.list = self._ctx.__enter__()
        warnings.simplefilter("always")
        return self.list

    def __exit__(self, *exc):
        self._ctx.__exit__(*exc)
        assert not any("emulated bus" in str(w.message) for w in self.list), [str(w.message) for w in self.list]
        return False


def test_the_suites_runs_of_hidden_cases_find_a_busy_machines_fault_in_a_hand_in(tmp_path):
    """tests/conftest.py's ``handin_faults``, by which the suite's own runs of lesson 07's hidden cases (outside the
    grader) are made once more: every fault of the arm's bus at any case of any hand-in, and nothing else (an error
    an exercise asks for, a result)."""
    np = need("numpy")
    from snakekit import errors
    from snakekit.handin import encode_results
    from tests.conftest import handin_faults

    (tmp_path / "ex07_2_safe_move_test.npz").write_bytes(encode_results([
        {"duration": np.array(0.5)}, errors.LimitError("joint 1 is within 0.05 rad of its limit"),
        errors.BusWatchdogError("the Bus Watchdog stopped servo(s) 1")]))
    (tmp_path / "ex07_3_fault_test.npz").write_bytes(encode_results([
        errors.CommunicationError("servo 2 did not answer"), {"recovered": np.array([1, 2])}]))
    (tmp_path / "ex07_1_ticks_test.npz").write_bytes(encode_results([{"ticks": np.array([2048])}]))
    assert handin_faults(tmp_path) == [
        "ex07_2_safe_move_test at case 2: BusWatchdogError: the Bus Watchdog stopped servo(s) 1",
        "ex07_3_fault_test at case 0: CommunicationError: servo 2 did not answer"]
