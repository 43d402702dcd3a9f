"""Submissions too alike to be chance: a screen that flags pairs for a TA to read; it never changes a grade.

**Code.** Only the answer cells are compared (nbgrader's ``solution`` cells, by grade id), with
copydetect (MOSS's winnowing over the code as copydetect's filter writes it: every name, function name and
string made one letter, so renamed variables and edited comments change nothing (:func:`filtered`); fingerprints of ``K`` characters, one
at least in every ``WINDOW``). Chosen over Dolos (a Node.js program, a server to run) and JPlag (Java):
a Python library on PyPI the grader calls in its own process, whose tokeniser already reads Python.
What is nobody's own is taken out first, as copydetect's boilerplate: the hand-out's text of the cell
(``release/``) and the instructor's solution (``source/``: two students writing it as the lesson does
are not copying each other); and, as MOSS does, a passage more than ``common`` submissions share (a
lesson's idiom). A pair's similarity is the share of both students' remaining code the two have in
common; pairs at or above ``threshold`` are flagged with their cells side by side.

**Trajectories.** Where a trajectory exercise's result at the spec's case is kept
(``autograded/<student>/<a>/lab/<grade id>.npz``, what ``snakekit grade`` keeps for the lab), two
students whose trajectories are *wrong* at that case (not right in full: a right one is the same for
everybody, the spec leaves no freedom there) and equal within float noise (``NOISE``) made the same
wrong trajectory to the last digit. A wrong trajectory more than ``common`` students share is a
common mistake, not a copy, and is not flagged.
"""

from __future__ import annotations

import builtins
import io
import json
import keyword
import tokenize
from collections import defaultdict
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np

from grader.files import MAX_FILE

__all__ = ["AlikePair", "SameTrajectory", "answer_cells", "code_pairs", "trajectory_pairs", "common_limit"]

#: copydetect's defaults: a fingerprint is 25 characters of tokenised code, and a match of 30 is always found.
K, GUARANTEE = 25, 30
WINDOW = GUARANTEE - K + 1
#: A pair this alike is flagged: the share of both students' own code they have in common.
THRESHOLD = 0.8
#: Two trajectories this close are the same one: float noise [rad] and [s].
NOISE = 1e-9


@dataclass(frozen=True)
class AlikePair:
    """Two students whose answer cells are alike: ``similarity`` in [0, 1]; ``cells`` grade id ->
    (the first's text, the second's, that cell's similarity), the most alike first."""

    first: str
    second: str
    similarity: float
    cells: tuple


@dataclass(frozen=True)
class SameTrajectory:
    """Two students who handed in the same wrong trajectory for ``grade_id`` (largest difference ``diff``)."""

    first: str
    second: str
    grade_id: str
    diff: float


def common_limit(students: int) -> int:
    """A passage more submissions than this share is a lesson's idiom, not a copy (MOSS's ``-m``):
    5 % of the class, at least 3.

    >>> common_limit(34), common_limit(500)
    (3, 25)
    """
    return max(3, students // 20)


def _read(path: Path) -> dict | None:
    try:
        if path.stat().st_size > MAX_FILE:
            return None
        return json.loads(path.read_bytes())
    except (OSError, ValueError):
        return None


def _source(cell) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else str(src)


def _answers(nb: dict | None) -> dict[str, str]:
    out = {}
    for cell in (nb or {}).get("cells", []):
        meta = cell.get("metadata", {}).get("nbgrader", {}) if isinstance(cell, dict) else {}
        if cell.get("cell_type") == "code" and meta.get("solution") and not meta.get("grade") and meta.get("grade_id"):
            out[str(meta["grade_id"])] = _source(cell)
    return out


def answer_cells(course: Path, assignment: str) -> tuple[dict, dict]:
    """``(answers, handout)``: student -> grade id -> the answer cell they handed in (``submitted/``), and
    grade id -> the texts that are nobody's own (the released cell, the instructor's solution)."""
    course = Path(course)
    answers = {}
    for folder in sorted((course / "submitted").glob(f"*/{assignment}")):
        cells = {}
        for path in sorted(folder.glob("*.ipynb")):
            cells.update(_answers(_read(path)))
        if cells:
            answers[folder.parent.name] = cells
    handout = defaultdict(list)
    for where in ("release", "source"):
        for path in sorted((course / where / assignment).glob("*.ipynb")):
            for gid, text in _answers(_read(path)).items():
                handout[gid].append(text)
    return answers, dict(handout)


def filtered(code: str) -> str:
    """``code`` as copydetect's filter writes it (every name ``V``, a function's name ``F``, a class's ``O``, a
    string ``S``; keywords, builtins, numbers and operators kept; comments and blanks dropped), tokenised by
    Python's own tokenizer, 7 times faster than pygments' lexer copydetect uses (a class of 500 has 2000
    cells); a cell Python cannot tokenise goes through copydetect's own filter.

    >>> filtered("def area(w, h):  # of a box\\n    return abs(w * h) + len('x')\\n")
    'defF(V,V):returnabs(V*V)+len(S)'
    """
    out, previous = [], ""
    try:
        for tok in tokenize.generate_tokens(io.StringIO(code).readline):
            if tok.type == tokenize.NAME:
                if keyword.iskeyword(tok.string) or tok.string in _BUILTINS:
                    out.append(tok.string)
                else:
                    out.append({"def": "F", "class": "O"}.get(previous, "V"))
            elif tok.type == tokenize.STRING:
                out.append("S")
            elif tok.type in (tokenize.NUMBER, tokenize.OP):
                out.append(tok.string)
            if tok.type not in (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
                previous = tok.string
    except (tokenize.TokenError, IndentationError, SyntaxError):
        from copydetect.utils import filter_code

        return filter_code(code, "cell.py", "python")[0]
    return "".join(out)


_BUILTINS = frozenset(dir(builtins))


def stable_kgrams(string: str, k: int) -> np.ndarray:
    """A hash of every ``k`` characters of ``string`` (a polynomial over their code points, modulo 2**64):
    the same in every run. copydetect's own uses Python's ``hash``, which is salted anew in each process,
    so its fingerprints, and a pair's similarity, moved between two reports of the same class.

    >>> a, b = stable_kgrams("defF(V):returnV", 5), stable_kgrams("xdefF(V):returnV", 5)
    >>> len(a), bool((a == b[1:]).all()), int(stable_kgrams("abcde", 5)[0]) == int(stable_kgrams("abcde", 5)[0])
    (11, True, True)
    """
    codes = np.frombuffer(string.encode("utf-32-le"), dtype=np.uint32).astype(np.uint64)
    n = len(codes) - k + 1
    if n <= 0:
        return np.zeros(0, dtype=np.int64)
    h = np.zeros(n, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for j in range(k):
            h = h * np.uint64(1_000_003) + codes[j:j + n]
    return h.view(np.int64)


def _fingerprint(text: str, boilerplate=None, window: int = WINDOW):
    import copydetect.utils
    from copydetect import CodeFingerprint

    copydetect.utils.hashed_kgrams = stable_kgrams   # what copydetect's fingerprints hash with: the same every run
    return CodeFingerprint("cell.py", K, window, boilerplate=boilerplate, filter=False, fp=io.StringIO(filtered(text)))


def code_pairs(answers: dict, handout: dict, *, threshold: float = THRESHOLD, common: int | None = None) -> list[AlikePair]:
    """The pairs of students whose answer cells are at least ``threshold`` alike, the most alike first."""
    from copydetect import compare_files
    from copydetect.utils import get_token_coverage

    common = common_limit(len(answers)) if common is None else common
    boiler = {gid: np.array(sorted(set().union(*(_fingerprint(t, window=1).hashes for t in texts))), dtype=np.int64)
              for gid, texts in handout.items()}
    prints = {s: {gid: _fingerprint(text, boiler.get(gid)) for gid, text in cells.items()} for s, cells in answers.items()}
    holders = defaultdict(set)
    for s, cells in prints.items():
        for gid, fp in cells.items():
            for h in fp.hashes:
                holders[(gid, h)].add(s)
    for (gid, h), who in holders.items():
        if len(who) > common:
            for s in who:
                fp = prints[s][gid]
                fp.hashes.discard(h)
                fp.hash_idx.pop(h, None)
    for cells in prints.values():
        for fp in cells.values():
            fp.token_coverage = get_token_coverage(fp.hash_idx, K, len(fp.filtered_code))
    candidates = set()
    for who in holders.values():
        if 1 < len(who) <= common:
            candidates.update(combinations(sorted(who), 2))
    out = []
    for a, b in sorted(candidates):
        shared, total, cells = 0.0, 0.0, []
        for gid in sorted(set(prints[a]) | set(prints[b])):
            fa, fb = prints[a].get(gid), prints[b].get(gid)
            cov = (fa.token_coverage if fa else 0) + (fb.token_coverage if fb else 0)
            total += cov
            if fa is None or fb is None or not cov:
                continue
            overlap, _, _ = compare_files(fa, fb)
            overlap_b, _, _ = compare_files(fb, fa)
            shared += overlap + overlap_b
            if overlap:
                cells.append((gid, answers[a][gid], answers[b][gid], round(float((overlap + overlap_b) / cov), 3)))
        similarity = float(shared / total) if total else 0.0
        if similarity >= threshold:
            cells.sort(key=lambda c: -c[3])
            out.append(AlikePair(a, b, round(similarity, 3), tuple(cells)))
    out.sort(key=lambda p: (-p.similarity, p.first, p.second))
    return out


def kept_trajectories(course: Path, assignment: str) -> dict[str, dict]:
    """grade id -> student -> (times, positions) of the trajectories ``snakekit grade`` kept for the lab."""
    out = defaultdict(dict)
    for path in sorted(Path(course).glob(f"autograded/*/{assignment}/lab/*.npz")):
        try:
            if path.stat().st_size > MAX_FILE:
                continue
            with np.load(path, allow_pickle=False) as z:
                out[path.stem][path.parts[-4]] = (np.asarray(z["times"], float), np.asarray(z["positions"], float))
        except (OSError, ValueError, KeyError):
            continue
    return dict(out)


def trajectory_pairs(trajectories: dict, right: set, *, common: int) -> list[SameTrajectory]:
    """The pairs of students with the same wrong trajectory (``trajectories``: grade id -> student ->
    (times, positions); ``right``: the ``(student, grade id)`` right in full at that case)."""
    out = []
    for gid, by_student in sorted(trajectories.items()):
        shapes = defaultdict(list)
        for s, (t, q) in sorted(by_student.items()):
            if (s, gid) not in right and np.isfinite(q).all() and np.isfinite(t).all():
                shapes[(t.shape, q.shape)].append(s)
        for (tshape, qshape), who in shapes.items():
            if len(who) < 2:
                continue
            t = np.stack([by_student[s][0] for s in who])
            q = np.stack([by_student[s][1] for s in who]).reshape(len(who), -1)
            same = []
            for i in range(len(who) - 1):
                diff = np.maximum(np.abs(q[i + 1:] - q[i]).max(axis=1, initial=0.0),
                                  np.abs(t[i + 1:] - t[i]).max(axis=1, initial=0.0))
                same += [(who[i], who[i + 1 + j], float(diff[j])) for j in np.flatnonzero(diff <= NOISE)]
            groups = defaultdict(set)   # the students who share one trajectory: more than `common` is a common mistake
            for a, b, _ in same:
                groups[a].add(b)
                groups[b].add(a)
            out += [SameTrajectory(a, b, gid, d) for a, b, d in same if len(groups[a]) + 1 <= common]
    return out
