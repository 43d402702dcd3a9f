"""Test cells as released, whatever an editor did to them: nothing a student's notebook does to a
test cell costs or earns points.

Before a submission runs, every test cell the release has is put back as released: an edited one
gets the released source (what nbgrader's own ``OverwriteCells`` would run), an un-locked one or
one whose points changed its released metadata, a deleted one is inserted again after the answer of
its exercise, a duplicated one runs once. Cells whose nbgrader metadata an editor stripped (some
editors drop unknown metadata) are matched to the release: a test cell by its content (its
released source, nearest its released position), an answer cell by its position relative to its
exercise's test cell. A graded cell the release does not have loses its grade. Each repair is
named (grade id -> what was done) so the TA sees it: the CSV's status ``tests restored``, the
page and formgrader; the points are what the released tests give.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import nbformat

from grader.markup import visible_part

__all__ = ["release_order", "restore"]

_KEEP = ("grade", "grade_id", "locked", "points", "schema_version", "solution", "task")


def _norm(s: str) -> str:
    return "\n".join(line.rstrip() for line in s.splitlines() if line.strip())


def _gid(cell) -> str | None:
    return cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")


def _exercise(gid: str) -> str:
    m = re.match(r"(ex\d+(?:_\d+)?)_", gid)
    return m.group(1) if m else gid


def release_order(course: Path, assignment: str, notebook: str) -> list[tuple[str | None, dict]]:
    """The release's cells in order: (grade id or None, its nbgrader metadata), from the source
    notebook (``nbgrader generate_assignment`` keeps every cell where it is)."""
    path = Path(course) / "source" / assignment / f"{notebook}.ipynb"
    if not path.is_file():
        return []
    nb = nbformat.read(path, as_version=4)
    return [(_gid(c), {k: v for k, v in c.get("metadata", {}).get("nbgrader", {}).items() if k in _KEEP})
            for c in nb.cells]


def _released(gid: str, info: dict, meta: dict):
    """A fresh test cell as released: its visible source and its nbgrader metadata."""
    cell = nbformat.v4.new_code_cell(visible_part(info["source"]))
    cell.metadata["nbgrader"] = dict(meta)
    return cell


def restore(nb, a, notebook: str, order: list) -> tuple[object, dict[str, str]]:
    """``nb`` with every test cell of ``notebook`` as released, and what was repaired (grade id ->
    what was done, in the TA's words). ``a``: the assignment (:func:`grader.assignment.load_assignment`);
    ``order``: :func:`release_order`. The notebook given is not changed."""
    nb = nbformat.from_dict(copy.deepcopy(nb))
    where = {gid: i for i, (gid, _) in enumerate(order) if gid}
    metas = {gid: meta for gid, meta in order if gid}
    mine = {gid: info for gid, info in a.locked.items() if info["notebook"] == notebook}
    fixed: dict[str, str] = {}

    # 1. metadata an editor stripped: test (and other locked) cells by content, answers by position
    have = {_gid(c) for c in nb.cells}
    bare = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and not _gid(c)]
    for gid, info in mine.items():
        if gid in have or not info["locked"] or gid not in metas:
            continue
        want = _norm(visible_part(info["source"]))
        hits = [i for i in bare if _norm(nb.cells[i].source) in (want, _norm(info["source"]))]
        if hits:
            i = min(hits, key=lambda k: abs(k - where[gid]))
            nb.cells[i].metadata["nbgrader"] = dict(metas[gid])
            bare.remove(i)
            fixed[gid] = "its nbgrader metadata was lost: matched to the release by its content"
    have = {_gid(c) for c in nb.cells}
    position = {_gid(c): i for i, c in enumerate(nb.cells) if _gid(c)}
    for gid, info in mine.items():
        if gid in have or info["locked"] or gid not in metas:
            continue
        tests = [t for t in position if t in a.tests and _exercise(t) == _exercise(gid) and t in where]
        guesses = [position[t] - (where[t] - where[gid]) for t in tests]
        if len(nb.cells) == len(order):
            guesses.append(where[gid])
        for i in guesses:
            if i in bare:
                nb.cells[i].metadata["nbgrader"] = dict(metas[gid])
                bare.remove(i)
                fixed[gid] = "its nbgrader metadata was lost: matched to the release by its position"
                break

    # 2. every test cell as released
    seen: set = set()
    cells = []
    for cell in nb.cells:
        gid = _gid(cell)
        if gid in mine and gid in a.tests and gid in seen:
            fixed[gid] = "duplicated: run once, as released"
            continue
        if gid and gid not in a.locked and cell.get("metadata", {}).get("nbgrader", {}).get("grade"):
            del cell.metadata["nbgrader"]
            fixed[gid] = "a test cell the assignment does not have: not graded"
        elif gid in mine and gid in a.tests:
            seen.add(gid)
            info, meta, want = mine[gid], cell.metadata["nbgrader"], metas.get(gid, {})
            released = visible_part(info["source"])
            if cell.cell_type != "code":
                fixed.setdefault(gid, "its cell type changed: run as released")
                cell = _released(gid, info, want or meta)
            elif _norm(cell.source) not in (_norm(released), _norm(info["source"])):
                fixed.setdefault(gid, "edited: run as released")
                cell.source = released
            if any(meta.get(k) != want.get(k) for k in ("grade", "locked", "points", "solution") if k in want):
                fixed.setdefault(gid, "its nbgrader metadata changed (un-locked, or its points): run as released")
                cell.metadata["nbgrader"] = {**meta, **want}
        cells.append(cell)
    for gid, info in mine.items():
        if gid in a.tests and gid not in seen and gid in metas:
            before = [k for k, c in enumerate(cells) if _gid(c) and _exercise(_gid(c)) == _exercise(gid)]
            at = before[-1] + 1 if before else min(where[gid], len(cells))
            cells.insert(at, _released(gid, info, metas[gid]))
            fixed[gid] = "deleted: put back as released"
    nb.cells = cells
    return nb, fixed
