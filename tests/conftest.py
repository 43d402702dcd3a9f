"""Shared test helpers.

``need(module)`` imports an optional dependency: outside CI a missing one skips the test,
with ``CI=true`` it fails, so a missing install step can't hide behind a skip.
"""

from __future__ import annotations

import functools
import importlib
import os
import re
import shutil
import signal
import socket
import threading
import time

import pytest

from snakekit.host import choose_mujoco_gl

choose_mujoco_gl()  # before anything imports MuJoCo: EGL on Linux
import tests.kernel_zygote  # noqa: E402 - its SESSION_ENV: the environment as the session starts, before any test
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")

# A runner that starts the suite in the background (`make test &` in a script) starts it with
# SIGINT ignored, and the programs the tests start inherit that: Ctrl-C sent to them would be
# lost. The tests stand for a user at a terminal, so SIGINT gets its usual handler back here
# (a handled signal is reset to the default in a child, an ignored one is not).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def need(module: str):
    """Import ``module`` or skip (fail under CI=true)."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        if IN_CI:
            pytest.fail(f"{module} is missing under CI=true: {e}; `make setup` must install it")
        pytest.skip(f"{module} is not installed: {e}")


def need_program(name: str) -> str:
    """Path of an executable, or skip (fail under CI=true)."""
    path = shutil.which(name)
    if path is None:
        if IN_CI:
            pytest.fail(f"program '{name}' is missing under CI=true; `make setup` must install it")
        pytest.skip(f"program '{name}' is not installed")
    return path


_KERNEL_SOCKETS: list[str] = []


def notebook_client(nb, **kwargs):
    """``nbclient.NotebookClient(nb, **kwargs)`` whose kernel listens on Unix sockets in a folder of its
    own (snakekit.host.kernel_sockets, as `snakekit check` and the grader's instructor run), not on
    TCP ports: kernels started at once by the parallel workers never race for a port. It is the kit's
    client (snakekit.kernel_client): a reply the kernel never sends after a cell's idle costs
    LATE_REPLY s, not the cell's timeout. Its kernel is forked from this test process's warm server
    (tests/kernel_zygote.py) when it is this Python's kernel and the variables an import reads are the session's."""
    import atexit
    import tempfile

    from traitlets.config import Config

    from snakekit.host import kernel_sockets
    from snakekit.kernel_client import NotebookClient

    if not _KERNEL_SOCKETS:  # one short folder per test process, removed when it ends
        _KERNEL_SOCKETS.append(tempfile.mkdtemp(prefix="snakekit-kernels-"))
        atexit.register(shutil.rmtree, _KERNEL_SOCKETS[0], True)
    folder = tempfile.mkdtemp(dir=_KERNEL_SOCKETS[0])
    if "kernel_manager_class" not in kwargs and os.environ.get("SNAKEKIT_FRESH_KERNELS") != "1":
        # forked from a warm process when it can (tests/kernel_zygote.py; SNAKEKIT_FRESH_KERNELS=1: never)
        kwargs = {**kwargs, "kernel_manager_class": tests.kernel_zygote.ZygoteKernelManager}
    client = _run_again_on_bus_silence(NotebookClient)(nb, config=Config(kernel_sockets(folder)), **kwargs)
    client.again = lambda: notebook_client(nb, **kwargs)
    return client


def _machine_fault(ename, evalue) -> bool:
    """Whether an error is a busy machine's on the emulated bus: the emulated servos silent through the driver's
    tries (a CommunicationError that says "did not answer"), or a stall of the kernel's process past the servos'
    Bus Watchdog (a BusWatchdogError)."""
    return (ename == "CommunicationError" and "did not answer" in str(evalue)) or ename == "BusWatchdogError"


def bus_silence(nb) -> str:
    """The first error of ``nb``'s outputs that is a busy machine's on the emulated bus (:func:`_machine_fault`), as
    "<type>: <message>", or "" when there is none."""
    for cell in nb.cells:
        for o in cell.get("outputs", []):
            if o.get("output_type") == "error" and _machine_fault(o.get("ename"), o.get("evalue", "")):
                return f"{o['ename']}: {o['evalue']}"
    return ""


def handin_faults(folder) -> list[str]:
    """The hand-ins in ``folder`` (``<grade id>.npz``) that hold a busy machine's fault on the emulated bus at a case
    (``grader.scoring.verdict.is_fault``: CommunicationError, PortLostError, BusWatchdogError), each as
    "<grade id> at case <k>: <error>". A run of lesson 07's hidden cases with one is run again, as the grader does."""
    from grader.scoring.cases import read_handins
    from grader.scoring.verdict import is_fault

    return [f"{gid} at case {k}: {r}" for gid, results in read_handins(folder).items()
            for k, r in enumerate(results) if is_fault(r)]


@functools.cache
def _run_again_on_bus_silence(base):
    """``base`` (a NotebookClient class) whose ``execute`` runs the notebook once more, in a new kernel, when a cell
    ended in a busy machine's fault on the emulated bus (:func:`bus_silence`: the machine held the emulator's thread
    or the kernel up; the grader runs such a submission again too, ``grader.batch``'s ``bus_faults``). It says so as
    a warning, which CI's summary shows; a second fault is the notebook's result."""
    import warnings

    from nbclient.exceptions import CellExecutionError

    class Client(base):
        again = None

        def execute(self, **kw):
            try:
                result = super().execute(**kw)
                said = bus_silence(self.nb) if self.again is not None else ""
            except CellExecutionError as e:
                if self.again is None or not _machine_fault(e.ename, e.evalue):
                    raise
                said = f"{e.ename}: {e.evalue}"
            if not said:
                return result
            warnings.warn(f"a busy machine's fault on the emulated bus, the notebook was run again: {said}",
                          stacklevel=2)
            second = self.again()
            second.again = None
            return second.execute(**kw)

    return Client


#: What a class adds to the course folder (and what a run of an instructor notebook writes beside it).
def copy_course(dest):
    """A copy of the repository's course, as a class would grade it: its sources, cases, references and lab
    settings, none of a class's folders, no run's ``.npz`` beside a notebook. Returns ``dest``."""
    from grader.course.folder import course_copy_ignore

    shutil.copytree(os.path.join(ROOT, "course"), dest, ignore=course_copy_ignore)
    return dest


@pytest.fixture(scope="session")
def graded_classes(tmp_path_factory):
    """``lesson -> result``: a class of ``tests/grader/class_submissions/`` graded by ``snakekit grade`` on its
    first use in this test process (``tests/grader/test_class_grades.py``'s ``grade_class``). Grading a class
    costs minutes: test_class_grades.py and test_report.py read the same graded course (the report's tests
    copy it before they change anything); test_report.py's tests join the class's xdist group, so under
    ``make test`` they run on the worker that grades it."""
    done = {}

    def graded(lesson: str) -> dict:
        if lesson not in done:
            import sys

            sys.path.insert(0, os.path.join(ROOT, "tests", "grader"))
            from test_class_grades import grade_class

            done[lesson] = grade_class(lesson, tmp_path_factory.mktemp(f"class{lesson[:2]}"))
        return done[lesson]

    return graded


@pytest.fixture
def fresh_verdicts():
    """The kernel's verdicts as they were: what a check passed, failed or built on in a test is not left to
    other tests (snakekit.verdicts' PASSED, CAUSES and BUILDS_ON)."""
    from snakekit.verdicts import BUILDS_ON, CAUSES, PASSED

    saved = [(d, dict(d)) for d in (PASSED, CAUSES, BUILDS_ON)]
    yield
    for d, before in saved:
        d.clear()
        d.update(before)


@pytest.fixture(scope="session")
def graded_slips(tmp_path_factory):
    """``lesson -> graded course folder``: a lesson's slips handed in together and graded in one batch of
    ``snakekit grade`` (:func:`grader.course.fairness.grade_students`) on its first use in this test process:
    its known mistakes (tests/grader/test_hints_graded.py's ``packed``), its forgotten returns
    (tests/lessons/test_forgot_return.py's ``returnless``) and the variants of its answers that the fairness rules
    are checked on (tests/grader/test_fairness_mutation.py: ``fairness.SAMPLE``). One batch start and one
    instructor run per lesson for the three files, where each had its own. The students' names differ between them
    (``group*``, ``slip*``, ``exNN_k_<operator>``) and each file reads only its own; under `make test` the three
    files' tests of a lesson join one xdist group (``slipsNN``). ``graded.batches[lesson]``: the variants graded,
    the batch's seconds and ``snakekit grade``'s stderr."""
    done, batches = {}, {}

    def graded(lesson: str):
        if lesson not in done:
            from grader.course import fairness
            from grader.course.mutants import variants
            from tests.grader.test_hints_graded import packed
            from tests.lessons.test_forgot_return import returnless

            mistakes, returns = packed(lesson)[0], returnless(lesson)[0]
            made, skipped = variants(fairness.ROOT / "course", lesson, fairness.SAMPLE)
            assert made and not skipped, (lesson, skipped)
            mutants = fairness.variant_students(made)
            assert not set(mistakes) & set(returns) and not set(mutants) & (set(mistakes) | set(returns))
            course, seconds, stderr = fairness.grade_students(lesson, {**mistakes, **returns, **mutants},
                                                              tmp_path_factory.mktemp(f"slips{lesson[:2]}"))
            print(f"\n{lesson}: {len(mistakes)} notebooks of known mistakes, {len(returns)} of forgotten returns and "
                  f"{len(mutants)} variants graded in {seconds:.0f} s")
            done[lesson], batches[lesson] = course, (made, seconds, stderr)
        return done[lesson]

    graded.batches = batches
    return graded


_DATA_URI = re.compile(r"data:[\w/+.-]+;base64,[A-Za-z0-9+/=\s]+")


def without_data(page: str) -> str:
    """``page`` with the payload of every ``data:`` URI (a plot's base64 PNG) left out: a check for an address
    ("http") reads the page's text and tags, where a picture's bytes spell "http" now and then by chance."""
    return _DATA_URI.sub("data:", page)


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def once_goals_arrive(bus, action, goals: int = 5) -> threading.Thread:
    """Call ``action()`` (cut the line, stop the bridge, lose every packet) once a run's first ``goals`` goals reached
    every servo of the emulated ``bus``: a loaded machine can start a run later than any fixed delay (beside other
    work, 0.4 s was before its first goal, and the message then rightly said no goal had been sent)."""
    before = len(bus.writes(116, 4))

    def wait_then_act():
        end = time.perf_counter() + 120   # a bound for a hang
        while len(bus.writes(116, 4)) < before + goals * len(bus.ids) and time.perf_counter() < end:
            time.sleep(0.005)
        action()

    thread = threading.Thread(target=wait_then_act, daemon=True)
    thread.start()
    return thread


#: how often a raw-SDK read that got no answer in time is sent again (see :func:`sdk_read`)
SDK_READ_TRIES = 5


def sdk_read(ph, port, dxl: int, address: int, size: int, *, clock=None):
    """One register read through the unmodified dynamixel-sdk: its value, checked. The SDK waits a few
    milliseconds for the answer (its packet timeout: the bytes' time plus the latency timer), which a busy
    machine can outlast: a read that got no answer (COMM_RX_TIMEOUT) is sent again, up to SDK_READ_TRIES
    times; a read has no effect on the servo. Any other failure, or an error number in the answer, fails the
    test with the SDK's words (the Alert bit, a servo's hardware error, still reads). With ``clock`` (the
    emulator's ``now``): (value, the middle of the answered exchange, when the servo sampled it)."""
    sdk = need("dynamixel_sdk")
    read = {1: ph.read1ByteTxRx, 2: ph.read2ByteTxRx, 4: ph.read4ByteTxRx}[size]
    for _ in range(SDK_READ_TRIES):
        t0 = clock() if clock else None
        value, result, error = read(port, dxl, address)
        if result != sdk.COMM_RX_TIMEOUT:
            break
    assert result == sdk.COMM_SUCCESS and not error & 0x7F, (  # the Alert bit (a hardware error) still reads
        f"servo {dxl}, address {address}: {ph.getTxRxResult(result)} {ph.getRxPacketError(error)}".strip())
    return (value, (t0 + clock()) / 2) if clock else value


# --- the suite in parallel (`make test`: pytest-xdist, --dist loadgroup) ----------------------------
# A test module whose module-scoped fixture builds something expensive (a graded class, an
# instructor run) runs on one worker, so the fixture is built once: its tests that use such a
# fixture form one group (one per parameter of a parametrized one). The tests that start the
# private Docker engine form the group ENGINE_GROUP (tests/system/_engine.py): one engine at a time.
# The longest start first, groups and single tests alike (each group weighs what its tests took),
# so no long one starts last while the other worker has nothing left: the last run's durations
# (artifacts/test-durations.txt) over those kept in the repository (tests/durations.txt, which a
# fresh clone has: `tools/keep-durations` writes it from a quiet run's artifacts).

#: The xdist group of the tests that run a script on the private Docker engine (docker/engine.sh).
ENGINE_GROUP = "docker-engine"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DURATIONS = os.path.join(ROOT, "artifacts", "test-durations.txt")
#: the run before `make test`'s (tools/run-tests sets it aside, so that its own file holds this run alone)
PREVIOUS_DURATIONS = os.path.join(ROOT, "artifacts", "test-durations.previous.txt")
KEPT_DURATIONS = os.path.join(ROOT, "tests", "durations.txt")


def _module_group(item) -> str | None:
    """The group of a test that uses a module-scoped fixture of its own module, else None."""
    info = getattr(item, "_fixtureinfo", None)
    module = item.nodeid.split("::")[0]
    if info is None:
        return None
    params = getattr(getattr(item, "callspec", None), "params", {})
    keys = []
    for name in info.names_closure:
        for fixturedef in info.name2fixturedefs.get(name, ()):
            if fixturedef.scope == "module" and fixturedef.baseid == module:
                keys.append(f"{name}={params[name]}" if name in params else "")
    if not keys:
        return None
    # no brackets: xdist reads the group after the last "@" only when no "]" follows it
    return ":".join([module, *sorted(k for k in set(keys) if k)])


def _durations(path: str) -> dict[str, float]:
    """Seconds per test (setup + call + teardown) from a durations file (artifacts/test-durations.txt's lines)."""
    seconds: dict[str, float] = {}
    try:
        with open(path) as f:
            for line in f:
                parts = line.rstrip("\n").split(None, 2)
                if len(parts) == 3 and parts[0].endswith("s") and parts[1] in ("setup", "call", "teardown"):
                    nodeid = parts[2].split("@")[0]
                    seconds[nodeid] = seconds.get(nodeid, 0.0) + float(parts[0][:-1])
    except (OSError, ValueError):
        pass
    return seconds


def _bare(nodeid: str) -> str:
    """A node id without the "@group" xdist appends."""
    return nodeid.split("@")[0]


def _last_durations() -> dict[str, float]:
    """Seconds per test: the last runs' (artifacts/test-durations.txt, and the one before a `make test`) over the
    kept ones (tests/durations.txt)."""
    return {**_durations(KEPT_DURATIONS), **_durations(PREVIOUS_DURATIONS), **_durations(DURATIONS)}


#: Tests whose check rides on the wall clock of this machine: the emulated servos and the arm's lab
#: in real time (a stall past the Bus Watchdog's 0.5 s, or past the lab's stall bound, is a fault),
#: and the adversarial batch's 20 s cell clock. Marked ``serial``: `make test` (tools/run-tests)
#: runs them one at a time, in a process of their own at a higher priority, beside the rest.
SERIAL_FILES = {"tests/grader/test_arm_lab.py", "tests/grader/test_lab_safety.py", "tests/grader/test_return_lab.py",
                "tests/grader/test_grader_adversarial.py", "tests/kit/test_bridge.py", "tests/kit/test_emulator.py",
                "tests/kit/test_hardware.py", "tests/kit/test_late_replies.py", "tests/kit/test_servo_path.py",
                "tests/kit/test_safety.py", "tests/kit/test_bus_protocol.py"}
#: ...and every test of lesson 07 (the real robot's lesson runs on the emulated bus in real time),
#: and the references' check
SERIAL_IDS = ("07_real_robot", "[lesson07",  # the latter: the mutation and hint tests' lesson 07
              # each lesson's instructor notebook run again (lesson 00's took 611 s beside the
              # engine tests in the parallel part, 8 s alone)
              "test_course_references_are_current")


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the xdist_group marks
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.split("::")[0] in SERIAL_FILES or any(k in item.nodeid for k in SERIAL_IDS):
            item.add_marker(pytest.mark.serial)
    groups = {}
    for item in items:
        group = _module_group(item)
        if group and not any(m.args[:1] for m in item.iter_markers("xdist_group")):
            item.add_marker(pytest.mark.xdist_group(group))
        names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                        for m in item.iter_markers("xdist_group")})
        if names:
            groups[item] = "_".join(names)
    if not config.getoption("loadgroup", False):  # set on xdist's workers under --dist loadgroup
        return
    last = _last_durations()
    weight: dict[str, float] = {}
    for item, group in groups.items():
        weight[group] = weight.get(group, 0.0) + last.get(_bare(item.nodeid), 1.0)
    weight[ENGINE_GROUP] = float("inf") if not last else weight.get(ENGINE_GROUP, 0.0)
    # the longest first (a group by its sum); stable: inside a group, and among equals, the files' order stays
    items.sort(key=lambda item: -(weight[groups[item]] if item in groups else last.get(_bare(item.nodeid), 1.0)))
    for item, group in groups.items():
        # xdist sends a group's tests to one worker by the "@group" it appends to their node ids;
        # pytest 9.2 keeps the id in item._id, where xdist 3.8 does not write it (pytest-xdist
        # issue 1386): written here, the same suffix xdist would write
        if hasattr(item, "_id") and "@" not in item.nodeid:
            from _pytest.nodeid import NodeId

            item._id = NodeId.parse(f"{item.nodeid}@{group}")


# --- every run's durations, in artifacts/test-durations.txt --------------------------------------
# (and each failure as it happens, in artifacts/test-failures.txt)
# Every phase of every test, the longest first (what --durations=0 prints), with the run's wall
# time: kept where the terminal's 30 slowest scroll away. Written by the main process (with xdist,
# the workers' reports reach it); a run that ran no test (--collect-only) leaves the last file.

_reports: list[tuple[float, str, str, str]] = []
_started = time.time()


FAILURES = os.path.join(ROOT, "artifacts", "test-failures.txt")


def pytest_sessionstart(session):
    if not hasattr(session.config, "workerinput") and not os.environ.get("SNAKEKIT_DURATIONS_PART"):
        if os.path.exists(FAILURES):
            os.remove(FAILURES)


def pytest_runtest_logreport(report):
    _reports.append((report.duration, report.when, report.nodeid, report.outcome))
    if report.failed and not os.environ.get("PYTEST_XDIST_WORKER"):
        # as it happens (the terminal's summary comes only at the end of a long run)
        os.makedirs(os.path.dirname(FAILURES), exist_ok=True)
        with open(FAILURES, "a") as f:
            f.write(f"{time.strftime('%H:%M:%S')} FAILED ({report.when}) {report.nodeid}\n"
                    f"{str(report.longrepr)[-12000:]}\n\n")


def pytest_sessionfinish(session, exitstatus):
    if hasattr(session.config, "workerinput") or not _reports:
        return
    outcomes: dict[str, int] = {}
    for _, when, _, outcome in _reports:
        if when == "call" or outcome != "passed":
            outcomes[outcome] = outcomes.get(outcome, 0) + 1
    workers = getattr(session.config.option, "numprocesses", None)
    lines = [f"# pytest {' '.join(session.config.invocation_params.args)}",
             f"# {time.strftime('%Y-%m-%d %H:%M:%S %Z', time.localtime(_started))}: {time.time() - _started:.1f} s wall, "
             f"exit {int(exitstatus)}, {', '.join(f'{n} {o}' for o, n in sorted(outcomes.items()))}"
             f"{f', {workers} workers' if workers else ''}",
             "# seconds phase test"]
    lines += [f"{d:.2f}s {when:<8} {nodeid}" for d, when, nodeid, _ in sorted(_reports, key=lambda r: -r[0])]
    os.makedirs(os.path.dirname(DURATIONS), exist_ok=True)
    # a part of `make test` (tools/run-tests) writes its own file, which the script appends when
    # both parts have ended
    part = os.environ.get("SNAKEKIT_DURATIONS_PART")
    path = DURATIONS.replace(".txt", f".{part}.txt") if part else DURATIONS
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(path + ".tmp", path)
