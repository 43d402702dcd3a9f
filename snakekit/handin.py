"""The hidden cases: what crosses between the grader and a student's kernel.

Cases go from the grader to the kernel over a Unix socket, at the moment a test cell asks for
them (:meth:`snakekit.checks.Exercise.hand_in`); the results go back as a file in the hand-in
folder. Both are npz without pickles: the grader decodes what a student's kernel wrote with
``allow_pickle=False``. One request: a JSON line ``{"grade_id": ...}``; one answer: an 8-byte
big-endian length, then the npz of :func:`encode_cases` (length 0: no cases for that id).
"""

from __future__ import annotations

import io
import json
import os
import socket
import struct

import numpy as np

from .errors import FileFormatError, InputTypeError, whole_sentences

__all__ = ["encode_cases", "decode_cases", "fetch_cases", "encode_results", "decode_results", "quick", "graded",
           "live_off"]


# --- how this run goes: graded (``SNAKEKIT_CASES`` set) or shortened under test -----------------

def quick() -> bool:
    """True when long runs should shrink: ``SNAKEKIT_QUICK=1`` (or the suite's ``SNAKEKIT_TEST=1``)."""
    return any(os.environ.get(v, "").lower() not in ("", "0", "false", "no")
               for v in ("SNAKEKIT_QUICK", "SNAKEKIT_TEST"))


def graded() -> bool:
    """True while the grader runs the notebook: its socket of hidden cases is named (``SNAKEKIT_CASES``)."""
    return bool(os.environ.get("SNAKEKIT_CASES"))


def live_off() -> str | None:
    """Why a lesson's live part (a ROS master, a node in real time) is left out here, or None: while the
    grader runs the notebook (it grades what needs no live master), and when long runs shrink (:func:`quick`)."""
    if graded():
        return "a graded run leaves the live arm out (the grade comes from the exercises, which need no ROS master)"
    if quick():
        return "quick mode leaves the live arm out"
    return None


def _npz(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def encode_cases(cases) -> bytes:
    """The arguments of each case (a sequence of tuples of numbers, strings or arrays) as bytes."""
    arrays = {"__cases__": np.array(len(cases))}
    for k, args in enumerate(cases):
        for j, a in enumerate(args):
            arr = np.asarray(a)
            if arr.dtype == object:
                raise InputTypeError(f"case {k}, argument {j}: {type(a).__name__} is not numbers, a string or an array")
            arrays[f"{k}/{j}"] = arr
    return _npz(arrays)


def decode_cases(data: bytes) -> list[tuple]:
    """The cases :func:`encode_cases` wrote; 0-d values come back as Python int, float, bool or str."""
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        n = int(z["__cases__"])
        out = []
        for k in range(n):
            args, j = [], 0
            while f"{k}/{j}" in z.files:
                a = z[f"{k}/{j}"]
                args.append(a.item() if a.ndim == 0 else a)
                j += 1
            out.append(tuple(args))
    return out


def fetch_cases(socket_path: str, grade_id: str, timeout: float = 30.0) -> list[tuple]:
    """Ask the grader's socket for the cases of ``grade_id`` (none if it has none)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        s.connect(socket_path)
        s.sendall(json.dumps({"grade_id": grade_id}).encode() + b"\n")
        head = _recv(s, 8)
        (size,) = struct.unpack(">Q", head)
        return decode_cases(_recv(s, size)) if size else []


def _recv(s, size: int) -> bytes:
    chunks, left = [], size
    while left:
        chunk = s.recv(min(left, 1 << 20))
        if not chunk:
            raise ConnectionError("the grader's socket closed early")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


class Returned:
    """A case at which the student's function ``name`` returned a ``what`` (a type's name) the test cell's
    own code could not use (it stumbled on it): handed in as ``"returned <what> from <name>"``, so the
    grader names the wrong kind of result, not an error of the student's function."""

    def __init__(self, name: str, what: str):
        self.name, self.what = name, what

    def said(self) -> str:
        """As the hand-in file holds it: ``"returned tuple from task2_sweep"``."""
        return f"returned {self.what} from {self.name}"


class NotAnArray(Returned):
    """A case at which the student's function ``name`` returned a Python list or tuple (``what``) where the
    exercise asks for a numpy array (``part``: which of a pair of results): handed in as ``"not an array: list
    from two_link_ik"`` (``"not an array: list times from read_joint_states"``), and graded wrong in the words of
    the notebook's check (:func:`snakekit.watch.not_an_array`)."""

    def __init__(self, name: str, what: str, part: str = ""):
        super().__init__(name, what)
        self.part = part

    def said(self) -> str:
        return f"not an array: {self.what}{' ' + self.part if self.part else ''} from {self.name}"


class ReturnedNone(Returned):
    """A case at which the student's function ``name`` returned None (a forgotten ``return``),
    whatever the code that called it made of that: handed in as ``"returned None from <name>"``."""

    def __init__(self, name: str):
        super().__init__(name, "None")


def encode_results(results, *, array: bool = False) -> bytes:
    """One entry per case: ``<k>/value`` (an array), ``<k>/<name>`` (a dict's arrays), or
    ``<k>/__error__`` (an exception raised, ``"<type>: <message>"``; a result that is not numbers
    is one too: ``"returned None"``, ``"returned str"``; a :class:`Returned`:
    ``"returned None from <name>"``, ``"returned tuple from <name>"``). With ``array`` (the exercise asks for a numpy array, as its
    check's ``close(..., array=True)``), a Python list or tuple where a result is expected is one
    too (``"returned list"``): the grader then judges as the local check does."""
    arrays = {"__cases__": np.array(len(results))}
    for k, r in enumerate(results):
        if isinstance(r, Returned):
            arrays[f"{k}/__error__"] = np.array(r.said())
            continue
        if isinstance(r, BaseException):
            arrays[f"{k}/__error__"] = np.array(f"{type(r).__name__}: {whole_sentences(str(r))}")
            continue
        parts = r if isinstance(r, dict) else {"value": r}
        entry = {}
        for name, v in parts.items():
            try:
                a = None if v is None else np.asarray(v)
            except Exception:  # noqa: BLE001 - a student's object that numpy cannot read
                a = None
            if a is None or a.dtype == object or a.dtype.kind not in "biuf" or (array and isinstance(v, (list, tuple))):
                what = "None" if v is None else type(v).__name__
                entry = {"__error__": np.array(f"returned {what}" + ("" if name == "value" else f" for {name}"))}
                break
            entry[str(name).replace("/", "_")] = a
        arrays.update({f"{k}/{n}": a for n, a in entry.items()})
    return _npz(arrays)


def decode_results(data: bytes) -> list[dict | str]:
    """The results :func:`encode_results` wrote: per case a dict of arrays, or the error's text."""
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        n = int(z["__cases__"])
        out: list[dict | str] = [{} for _ in range(n)]
        for key in z.files:
            if key == "__cases__":
                continue
            k, _, name = key.partition("/")
            k = int(k)
            if not 0 <= k < n:
                raise FileFormatError(f"result {key} outside the {n} cases")
            if name == "__error__":
                out[k] = str(z[key])
            elif isinstance(out[k], dict):
                out[k][name] = z[key]
    return out
