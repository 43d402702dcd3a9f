"""The hidden cases: drawn by the grader for every batch, served to the kernels on a socket.

A course keeps one cases module per assignment, ``<course>/cases/<assignment>.py`` (outside
``source/``: never released, never inside a sandbox). It holds one function per handed-in
grade id, named exactly as the grade id, that takes ``(rng, spec)`` -- a
``numpy.random.Generator`` seeded for the batch and the robot spec
(:data:`snakekit.model.SPEC`) -- and returns the list of cases, each a tuple of positional
arguments (Python int/float/bool/str or numpy arrays)::

    def ex06_1_sweep_times_test(rng, spec):
        return [(int(rng.integers(2, 800)), float(rng.uniform(1.0, 200.0))) for _ in range(6)]

Optional module-level settings, keyed by grade id (see grader/README.md, "Cases"):
``TOLERANCES`` (``{"rtol": .., "atol": ..}`` for values, ``{"max": .., "rms": ..}`` for
trajectories and runs, merged over the grader's defaults) and ``DEPENDS`` (a test cell's grade
id -> the answer cells its exercise builds on, e.g. ``{"ex06_3_task2_test": ["ex06_1_sweep_times"]}``:
:mod:`grader.scoring.rerun`).

A batch draws every grade id's cases once, from one seed (:func:`draw`: ``os.urandom``
unless given), each grade id from its own stream (``[seed, crc32(grade_id)]``), so adding a
grade id does not change the others' cases. The seed is printed with the batch: the same seed
draws the same cases again.

While a notebook runs, :class:`CaseServer` answers its kernel on a Unix socket (the wire format
of :mod:`snakekit.handin`): the socket is bound inside each sandbox's own folder, and
``SNAKEKIT_CASES`` names it there.

    python -m grader.scoring.cases run NOTEBOOK --course DIR [--assignment A] [--seed N] [--timeout S]

executes one notebook with drawn cases (not sandboxed: for the instructor's own notebooks)
and prints, per grade id, each case's arguments and what was handed in there.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import os
import shutil
import socket
import struct
import sys
import tempfile
import threading
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from snakekit import host
from snakekit.kernel_client import NotebookClient
from snakekit.errors import SnakekitError
from snakekit.handin import decode_results, encode_cases
from grader.errors import CasesError

__all__ = ["CasesError", "Draw", "CaseServer", "load_module", "draw", "new_seed", "execute", "main"]

#: The longest path a Unix socket may have (``sun_path``, less its terminating zero).
MAX_SOCKET_PATH = 107


@dataclass(frozen=True)
class Draw:
    """One batch's cases: ``cases[grade_id]`` is the list of argument tuples, drawn from ``seed``.

    Attributes:
        assignment: the assignment's name.
        seed: the batch's seed (``--seed`` repeats the draw).
        cases: grade id -> list of argument tuples.
        settings: grade id -> the module's optional settings for it (``tolerances``).
        depends: test cell grade id -> the answer cells (grade ids) its exercise builds on
            (the module's ``DEPENDS``; see :mod:`grader.scoring.rerun`).
    """

    assignment: str
    seed: int
    cases: dict
    settings: dict = field(default_factory=dict)
    depends: dict = field(default_factory=dict)

    def encoded(self) -> dict[str, bytes]:
        """Each grade id's cases in the wire format of :mod:`snakekit.handin`."""
        return {gid: encode_cases(c) for gid, c in self.cases.items()}


def checked_tolerances(table: dict, where: str) -> dict:
    """A grade id's tolerances, each a finite number >= 0 (``rtol`` at most 1), booleans refused: a NaN
    or negative tolerance would judge every case the same (a NaN bound compares false), whatever the hand-in.

    Raises:
        CasesError: a bad value; the message names ``where``, the key, the value and the range.
    """
    from snakekit.validate import number

    out = {}
    for key, value in table.items():
        shown = value[:40] + "..." if isinstance(value, str) and len(value) > 40 else value
        try:
            out[key] = number(shown, f"{where}: tolerance {key!r}", at_least=0, at_most=1.0 if key == "rtol" else None)
        except SnakekitError as e:
            raise CasesError(str(e)) from None
    return out


def cases_path(course: Path, assignment: str) -> Path:
    return Path(course) / "cases" / f"{assignment}.py"


def load_module(course: Path, assignment: str):
    """Import ``<course>/cases/<assignment>.py`` (a fresh module object each time)."""
    path = cases_path(course, assignment)
    if not path.is_file():
        raise CasesError(f"no cases for {assignment}: {path} does not exist. Write one function per handed-in "
                         f"grade id there, taking (rng, spec) and returning a list of argument tuples "
                         f"(see grader/README.md, 'Cases').")
    spec = importlib.util.spec_from_file_location(f"_snakekit_cases_{assignment}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as e:  # noqa: BLE001 - the instructor's file: say where it broke
        raise CasesError(f"{path} cannot be imported: {type(e).__name__}: {e}") from e
    return module


def grade_ids(module) -> list[str]:
    """The grade ids a cases module draws for: its public functions."""
    return sorted(n for n, f in vars(module).items()
                  if callable(f) and not n.startswith("_") and getattr(f, "__module__", None) == module.__name__
                  and not isinstance(f, type))


def new_seed() -> int:
    """A fresh batch seed from the operating system's randomness (63 bits, printable)."""
    return int.from_bytes(os.urandom(8), "big") >> 1


def draw(course: Path, assignment: str, seed: int | None = None, spec=None) -> Draw:
    """Draw every grade id's cases of ``assignment`` from ``seed`` (a fresh one if None)."""
    from snakekit.model import SPEC

    spec = SPEC if spec is None else spec
    seed = new_seed() if seed is None else int(seed)
    module = load_module(course, assignment)
    path = cases_path(course, assignment)
    cases, settings = {}, {}
    for gid in grade_ids(module):
        rng = np.random.default_rng([seed, zlib.crc32(gid.encode())])
        try:
            drawn = getattr(module, gid)(rng, spec)
        except Exception as e:  # noqa: BLE001
            raise CasesError(f"{path}: {gid}(rng, spec) raised {type(e).__name__}: {e}") from e
        if not isinstance(drawn, (list, tuple)) or not drawn or not all(isinstance(c, tuple) for c in drawn):
            raise CasesError(f"{path}: {gid}(rng, spec) must return a non-empty list of tuples (each case's "
                             f"positional arguments), not {type(drawn).__name__}")
        try:
            encode_cases(drawn)
        except SnakekitError as e:
            raise CasesError(f"{path}: {gid}: {e}") from e
        cases[gid] = list(drawn)
        own = {}
        for key in ("TOLERANCES",):
            table = getattr(module, key, {})
            if not isinstance(table, dict) or not all(isinstance(v, dict) for v in table.values()):
                raise CasesError(f"{path}: {key} must map grade ids to dicts of tolerances, e.g. "
                                 f'{{"{gid}": {{"atol": 1e-9}}}}')
            if gid in table:
                own[key.lower()] = checked_tolerances(table[gid], f"{path}: {key}[{gid!r}]")
        settings[gid] = own
    depends = getattr(module, "DEPENDS", {})
    if not isinstance(depends, dict) or not all(
            k in cases and isinstance(v, (list, tuple)) and all(isinstance(c, str) for c in v) for k, v in depends.items()):
        raise CasesError(f"{path}: DEPENDS must map a handed-in grade id to the answer cells it builds on, e.g. "
                         f'{{"ex06_3_task2_test": ["ex06_1_sweep_times", "ex06_2_sweep_positions"]}}')
    if not cases:
        raise CasesError(f"{path} defines no case function (one per handed-in grade id, taking (rng, spec))")
    return Draw(assignment, seed, cases, settings, {k: list(v) for k, v in depends.items()})


# --- the socket -----------------------------------------------------------------------------


def _waiting_socket() -> socket.socket:
    """A Unix socket that waits as long as it takes: the grader's process may have a default socket timeout
    (``socket.setdefaulttimeout``, set by a library or a TA's script), which would end a listener's wait for
    the next sandbox, and the batch's hidden cases with it, after that many seconds."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.setblocking(True)
    return s


class CaseServer:
    """Answers the kernels' requests for cases (one thread per listening socket).

    ``listen(path)`` binds a socket at ``path`` (inside a sandbox's folder, where the sandbox sees
    it at the same path) and serves it until :meth:`close` (or ``stop(path)``). A request names
    a grade id; the answer is that grade id's cases (none if unknown). A connection gets
    ``timeout`` seconds to ask; at most ``max_clients`` are served at once per socket.

    ``listen(path, gate=GATE)`` also binds ``GATE`` (outside the sandbox's view, for root only):
    the sandbox's worker connects to it before it drops its privileges and says which test cell
    runs (``open <grade id>``, ``close``; each answered ``ok``). Then only the grade id of the
    test cell running is answered; a kernel that asks at any other moment (an answer cell that
    asks ahead, to look the answers up) gets no cases, and the request is recorded in
    :attr:`refused`.
    """

    def __init__(self, batch: Draw, *, timeout: float = 10.0, max_clients: int = 4):
        self.encoded = batch.encoded()
        self.timeout = timeout
        self.max_clients = max_clients
        self._listeners: dict[str, socket.socket] = {}
        self._lock = threading.Lock()
        self.requests: list[tuple[str, str]] = []  # (socket path, grade id), for the record
        self.refused: list[tuple[str, str]] = []   # asked for while its test cell was not running
        self._open: dict[str, str | None] = {}     # socket path -> the grade id its gate lets through
        self._gates: dict[str, tuple[str, socket.socket]] = {}

    def listen(self, path: Path, *, mode: int = 0o666, gate: Path | None = None) -> str:
        path = str(path)
        if len(path.encode()) > MAX_SOCKET_PATH:
            raise CasesError(f"the case socket's path is {len(path.encode())} bytes, more than a Unix socket "
                             f"allows ({MAX_SOCKET_PATH}): grade from a shorter working folder ({path})")
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        s = _waiting_socket()
        s.bind(path)
        os.chmod(path, mode)  # the sandbox's user connects to it
        s.listen(8)
        if gate is not None:
            g = _waiting_socket()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(str(gate))
            g.bind(str(gate))
            os.chmod(str(gate), 0o600)
            g.listen(1)
            with self._lock:
                self._open[path] = None
                self._gates[path] = (str(gate), g)
            threading.Thread(target=self._gate, args=(path, g), daemon=True, name=f"gate {gate}").start()
        with self._lock:
            self._listeners[path] = s
        threading.Thread(target=self._serve, args=(path, s), daemon=True, name=f"cases {path}").start()
        return path

    def _gate(self, path: str, g: socket.socket) -> None:
        """The worker's side: which test cell runs now (one connection, the first)."""
        try:
            conn, _ = g.accept()
        except OSError:
            return
        conn.setblocking(True)  # a notebook's cells can run for minutes between two words
        with conn, conn.makefile("rwb", buffering=0) as f:
            for line in f:
                word, _, gid = line.decode("utf-8", "replace").strip().partition(" ")
                with self._lock:
                    if path not in self._open:
                        return
                    self._open[path] = gid if word == "open" else None
                try:
                    f.write(b"ok\n")
                except OSError:
                    return

    def _serve(self, path: str, s: socket.socket) -> None:
        slots = threading.BoundedSemaphore(self.max_clients)
        while True:
            try:
                conn, _ = s.accept()
            except OSError:
                return  # closed
            if not slots.acquire(blocking=False):
                conn.close()
                continue
            threading.Thread(target=self._answer, args=(path, conn, slots), daemon=True).start()

    def _answer(self, path: str, conn: socket.socket, slots) -> None:
        try:
            with conn:
                conn.settimeout(self.timeout)
                line = b""
                while not line.endswith(b"\n") and len(line) < 4096:
                    chunk = conn.recv(4096 - len(line))
                    if not chunk:
                        break
                    line += chunk
                try:
                    gid = json.loads(line.decode("utf-8"))["grade_id"]
                except (ValueError, KeyError, TypeError):
                    return
                data = self.encoded.get(gid, b"") if isinstance(gid, str) else b""
                with self._lock:
                    self.requests.append((path, str(gid)))
                    if path in self._open and self._open[path] != gid:
                        self.refused.append((path, str(gid)))
                        data = b""
                conn.sendall(struct.pack(">Q", len(data)) + data)
        except OSError:
            pass
        finally:
            slots.release()

    def stop(self, path) -> None:
        with self._lock:
            s = self._listeners.pop(str(path), None)
            self._open.pop(str(path), None)
            gate = self._gates.pop(str(path), None)
        if gate is not None:
            with contextlib.suppress(OSError):
                gate[1].shutdown(socket.SHUT_RDWR)  # wakes its accept()
            gate[1].close()
            with contextlib.suppress(OSError):
                os.unlink(gate[0])
        if s is not None:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()
            with contextlib.suppress(OSError):
                os.unlink(str(path))

    def close(self) -> None:
        for path in list(self._listeners):
            self.stop(path)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# --- one notebook, with drawn cases -----------------------------------------------------------


def read_handins(folder: Path) -> dict[str, list]:
    """The hand-ins in ``folder``: grade id -> per case a dict of arrays or an error's text."""
    out = {}
    for f in sorted(Path(folder).glob("*.npz")):
        out[f.stem] = decode_results(f.read_bytes())
    return out


def execute(notebook: Path, batch: Draw, *, timeout: int = 600, allow_errors: bool = False) -> dict[str, list]:
    """Execute ``notebook`` (nbclient, in a scratch copy of its folder) with ``batch``'s cases
    served; returns what it handed in, by grade id. Not sandboxed: for trusted notebooks."""
    import nbclient
    import nbformat
    from traitlets.config import Config

    notebook = Path(notebook)
    with tempfile.TemporaryDirectory(prefix="snakekit-cases-") as tmp, CaseServer(batch) as server:
        work = Path(tmp) / "work"
        shutil.copytree(notebook.parent, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
        handin = Path(tmp) / "handin"
        handin.mkdir()
        sock = server.listen(Path(tmp) / "cases.sock")
        nb = nbformat.read(work / notebook.name, as_version=4)
        env = {"SNAKEKIT_HANDIN_DIR": str(handin), "SNAKEKIT_CASES": sock, "MPLBACKEND": "Agg"}
        with _environ(env):
            client = NotebookClient(nb, timeout=timeout, kernel_name="python3", allow_errors=allow_errors,
                                    resources={"metadata": {"path": str(work)}},
                                    extra_arguments=["--IPKernelApp.log_level=ERROR"],  # no TCP warning
                                    config=Config(host.kernel_sockets(tmp)))  # no port to race for
            try:
                client.execute()
            except nbclient.exceptions.CellExecutionError as e:
                raise CasesError(f"{notebook} failed while it ran:\n{str(e)[-2000:]}") from e
        return read_handins(handin)


@contextlib.contextmanager
def _environ(values: dict):
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def describe(value, width: int = 100) -> str:
    """A short, one-line rendering of an argument or a result (arrays abbreviated)."""
    if isinstance(value, np.ndarray) or isinstance(value, (list, tuple)):
        arr = np.asarray(value)
        text = np.array2string(arr, precision=6, threshold=12, edgeitems=3, max_line_width=10**6,
                               separator=", ").replace("\n", "")
        text = f"{text} (shape {arr.shape})" if arr.ndim > 1 or arr.size > 12 else text
    else:
        text = repr(value)
    return text if len(text) <= width else text[:width - 3] + "..."


def report(batch: Draw, handins: dict[str, list], stream=sys.stdout) -> None:
    """Print each grade id's cases and what was handed in at each."""
    print(f"{batch.assignment}: cases drawn with seed {batch.seed}", file=stream)
    for gid, cases in batch.cases.items():
        got = handins.get(gid)
        print(f"\n{gid}: {len(cases)} case(s)" + ("" if got is not None else ": nothing was handed in"), file=stream)
        for k, args in enumerate(cases):
            print(f"  case {k}: args ({', '.join(describe(a, 60) for a in args)})", file=stream)
            if got is None:
                continue
            r = got[k] if k < len(got) else "not handed in"
            if isinstance(r, str):
                print(f"    -> {r}", file=stream)
            else:
                for name, a in r.items():
                    print(f"    -> {name} = {describe(a)}", file=stream)
    extra = sorted(set(handins) - set(batch.cases))
    if extra:
        print(f"\nhanded in without cases in the cases module: {', '.join(extra)}", file=stream)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m grader.scoring.cases",
                                description="Draw an assignment's hidden cases; run a notebook at them.")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="execute one notebook with drawn cases and print what it handed in")
    r.add_argument("notebook", type=Path)
    r.add_argument("--course", type=Path, default=Path("course"), help="the course folder (its cases/ module)")
    r.add_argument("--assignment", default=None, help="default: the notebook's name")
    r.add_argument("--seed", type=int, default=None, help="draw these cases again (default: a fresh seed)")
    r.add_argument("--timeout", type=int, default=600, help="one cell's limit [s] (default: 600)")
    r.add_argument("--allow-errors", action="store_true", help="go on after a cell that raises")
    d = sub.add_parser("draw", help="print the cases only")
    d.add_argument("assignment")
    d.add_argument("--course", type=Path, default=Path("course"))
    d.add_argument("--seed", type=int, default=None)
    args = p.parse_args(argv)
    try:
        if args.command == "draw":
            batch = draw(args.course, args.assignment, args.seed)
            report(batch, {gid: None for gid in ()})
            return 0
        assignment = args.assignment or args.notebook.stem
        batch = draw(args.course, assignment, args.seed)
        handins = execute(args.notebook, batch, timeout=args.timeout, allow_errors=args.allow_errors)
    except (SnakekitError, OSError) as e:
        print(f"grader.scoring.cases: {e}", file=sys.stderr)
        return 1
    report(batch, handins)
    missing = sorted(set(batch.cases) - set(handins))
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
