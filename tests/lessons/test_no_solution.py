"""No solution in sight: nothing a student is handed computes what an exercise asks.

A handed-out check compares with worked numbers or with properties (course/README.md,
"Adding an exercise"), because a student can call anything a visible cell defines. Tried here:

* every function (or lambda given a name) a visible test cell defines is tried as the answer
  of every exercise of its lesson, in a kernel running the instructor version with the
  student's test cells: each exercise's visible check must then fail;
* the known mistakes, written as a student would, still get their hints (recognised from
  worked numbers, not from code);
* a visible test cell never calls the library function its exercise's shortcut guard forbids;
* outside the answer and check cells, a handed-out lesson defines no function (a
  demonstration waits for the exercise instead of using a ready-made version of it).
"""

from __future__ import annotations

import ast
import os
import shutil
import sys
from pathlib import Path

import pytest

from grader import markup
from tests.conftest import need, notebook_client

ROOT = Path(__file__).resolve().parents[2]
HIDDEN = "### BEGIN HIDDEN TESTS"
LESSONS = sorted(p.stem for p in (ROOT / "course" / "source").glob("*/*.ipynb"))


def read(path: Path):
    return need("nbformat").read(path, as_version=4)


def meta(cell) -> dict:
    return cell.metadata.get("nbgrader", {})


def parse(source: str) -> ast.Module:
    """A cell's code as Python (IPython's magics turned into calls first)."""
    from IPython.core.inputtransformer2 import TransformerManager

    return ast.parse(TransformerManager().transform_cell(source))


def helpers(source: str) -> list[str]:
    """Names of the functions, and of the lambdas assigned to a name, that ``source`` defines."""
    names = []
    for node in ast.walk(parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            names.append(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Lambda):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names += [t.id for t in targets if isinstance(t, ast.Name)]
    return names


def answer_function(source: str) -> ast.FunctionDef:
    """The function an answer cell asks for: the first one it defines."""
    return next(n for n in parse(source).body if isinstance(n, ast.FunctionDef))


def stand_ins(answer: ast.FunctionDef, helper: str) -> list[str]:
    """Answers made of ``helper``: passing on the arguments as given, or all of them (defaults
    filled in as the exercise's signature gives them); returning what :data:`PARTS` take."""
    params = [a.arg for a in answer.args.posonlyargs + answer.args.args + answer.args.kwonlyargs]
    forms = [("*a, **k", "*a, **k"), (ast.unparse(answer.args), ", ".join(params))]
    return [f"def {answer.name}({signature}):\n    result = {helper}({call})\n    return {part}"
            for signature, call in forms for part in PARTS]


def exercises(instructor, student) -> list[dict]:
    """Each exercise: its answer cell's index and function, its test cell's index and visible code.

    The visible code is the student version's test cell, which must be the instructor's test
    cell without its hidden tests.
    """
    shown = {meta(c)["grade_id"]: c.source for c in student.cells if meta(c).get("grade")}
    out, answers = [], {}
    for i, cell in enumerate(instructor.cells):
        m = meta(cell)
        if cell.cell_type == "code" and m.get("solution") and not m.get("grade"):
            answers[m["grade_id"] + "_test"] = i
        elif m.get("grade"):
            gid = m["grade_id"]
            visible = shown[gid]
            assert visible.strip() == markup.visible_part(cell.source).strip(), \
                f"{gid}: the student's test cell is not the instructor's visible part (run `make student`)"
            a = answers[gid]
            function = answer_function(instructor.cells[a].source)
            out.append({"grade_id": gid, "answer": a, "name": function.name, "function": function,
                        "test": i, "visible": visible, "hidden": "".join(markup.HIDDEN.findall(cell.source))})
    return out


# What a stand-in returns of a helper's result: all of it, one of its first parts (a helper may
# return the answer with what it was made from), or its two parts as a trajectory.
PARTS = ("result", "result[0]", "result[1]", "result[2]", '__import__("snakekit").Trajectory(*result)')


#: after a trial: fails when the counted stand-in's helper returned at least once (and resets the count)
NEVER_RETURNED = "assert not globals().pop('_stand_in_returned', None)"


def counted(stand_in: str) -> str:
    """The stand-in, noting in the kernel each time its helper returns (rather than raises).

    >>> print(counted("def f(x):\\n    result = g(x)\\n    return result"))
    def f(x):
        result = g(x)
        globals().setdefault('_stand_in_returned', []).append(1)
        return result
    """
    head, _, tail = stand_in.partition("\n    return ")
    return f"{head}\n    globals().setdefault('_stand_in_returned', []).append(1)\n    return {tail}"


def answers_in_sight(instructor_path: Path, student_path: Path, work: Path,
                     mistakes: tuple = ()) -> tuple[list[str], list[str]]:
    """Run the lesson and try every helper of its visible test cells as every exercise's answer.

    The notebook is the instructor's (so every exercise is answered right) with the student's
    test cells. ``mistakes`` are (grade id, a wrong answer cell, the hint its check must show).
    Returns (the stand-ins that passed a visible check, problems).
    """
    nbformat = need("nbformat")
    need("nbclient")
    instructor, student = read(instructor_path), read(student_path)
    shutil.copytree(instructor_path.parent, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.npz"))
    found = exercises(instructor, student)
    nb = nbformat.v4.new_notebook(metadata=instructor.metadata)
    for cell in instructor.cells:
        nb.cells.append(nbformat.from_dict(cell))
    for ex in found:
        nb.cells[ex["test"]].source = ex["visible"]
    names = sorted({h for ex in found for h in helpers(ex["visible"])})
    passed, problems = [], []
    client = notebook_client(nb, timeout=180, kernel_name="python3", allow_errors=True,
                             resources={"metadata": {"path": str(work)}})

    lesson_cells = list(nb.cells)
    nb.cells.append(nbformat.v4.new_code_cell(""))     # where the trials run

    def run(source: str) -> str | None:
        """None when the cell runs, else its error's message."""
        cell = client.execute_cell(nbformat.v4.new_code_cell(source), len(nb.cells) - 1)
        errors = [o for o in cell.outputs if o.output_type == "error"]
        return f"{errors[0].ename}: {errors[0].evalue}" if errors else None

    with client.setup_kernel():
        for index, cell in enumerate(lesson_cells):
            if cell.cell_type == "code":
                client.execute_cell(cell, index)
                if any(o.output_type == "error" for o in cell.outputs) and meta(cell).get("grade"):
                    problems.append(f"{meta(cell)['grade_id']} fails with the instructor's answer")
        for ex in found:
            tried = False
            for helper in names:
                if helper == ex["name"]:
                    continue
                made = stand_ins(ex["function"], helper)
                for form in range(0, len(made), len(PARTS)):
                    for k, stand_in in enumerate(made[form:form + len(PARTS)]):
                        tried = True
                        run(stand_in if k else counted(stand_in))
                        if run(ex["visible"]) is None:
                            passed.append(f"{ex['grade_id']}: this answer passes its visible check:\n{stand_in}")
                        if not k and run(NEVER_RETURNED) is None:
                            # the helper raised at every call, so no part of its result was ever
                            # taken: the other parts' trials would run exactly as this one did
                            break
            for gid, wrong, hint, *anywhere in mistakes:
                if gid == ex["grade_id"]:
                    tried = True
                    run(wrong)
                    shown = run(ex["visible"])
                    said = shown if anywhere or shown is None else shown.partition("\nHint: ")[2]
                    if shown is None or hint not in said:
                        problems.append(f"{gid}: the answer\n{wrong}\nshould be told {hint!r}; its check said {shown!r}")
            # the right answer back: the check passes again (so the failures above were the trials')
            if tried:
                shown = run(lesson_cells[ex["answer"]].source) or run(ex["visible"])
                if shown:
                    problems.append(f"{ex['grade_id']} fails with the instructor's answer after the trials: {shown}")
    return passed, problems


# Wrong answers of the kind students write, and the hint each one's visible check must give:
# the hints are recognised from worked numbers, so they are tried here with the mistake itself.
# With a fourth element (True) the words may be anywhere in the message, not only in its hint:
# a beginner's slip (a missing return, a list), a shortcut, a missing ValueError.
_FK = "    phi = np.cumsum(q)\n    L = spec.lengths\n"
_DLS = ("    e = np.asarray(target, dtype=float) - snakekit.tool_pose_2d(q)[:2]\n"
        "    J = snakekit.planar_jacobian(q)[:2]\n")
_SOLVE = ("def solve_ik(target, q0=None, tol=1e-6, max_iter=200):\n"
          "    q = np.zeros(5) if q0 is None else np.asarray(q0, dtype=float)\n"
          "    for _ in range(max_iter):\n"
          "        if np.linalg.norm(np.asarray(target) - snakekit.tool_pose_2d(q)[:2]) < tol:\n"
          "            break\n"
          "        q = np.clip(dls_step(q, target), spec.lower, spec.upper)\n"
          "    return q")
_IK2 = ("    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)\n"
        "    if abs(c2) > 1 + 1e-12:\n        raise ValueError('out of reach')\n    q2 = np.arccos(np.clip(c2, -1, 1))\n")
_TASK1 = ("def task1(panel, targets):\n    out = []\n    for x, y, heading in targets:\n"
          "        panel.set_target(x, y, heading)\n        run = panel.execute()\n"
          "        out.append({})\n    return np.array(out)")
_LIMITS = ("def limit_violations(trajectory):\n    t, p = trajectory.times, trajectory.positions\n"
           "    rows = [[t[k], j + 1, 0] for k, j in zip(*np.nonzero(np.abs(p) > spec.upper))]\n"
           "    speed = np.abs(np.diff(p, axis=0)) / np.diff(t)[:, None]\n"
           "    rows += [[t[k + 1], j + 1, 1] for k, j in zip(*np.nonzero(speed > spec.velocity_limit))]\n"
           "    return np.array(sorted(rows), dtype=float).reshape(-1, 3)")
# lesson 08's compare_runs, with one of its parts written as a student may slip
COMPARE = ("def compare_runs(times, positions, ref_times, ref_positions):\n"
           "    times, positions = np.asarray(times, dtype=float), np.asarray(positions, dtype=float)\n"
           "    ref_times, ref_positions = np.asarray(ref_times, dtype=float), np.asarray(ref_positions, dtype=float)\n"
           "    inside = {inside}\n"
           "    if not inside.any():\n        raise ValueError('no overlap')\n"
           "    t = times[inside]\n"
           "    reference = np.column_stack([np.interp(t, ref_times, ref_positions[:, j]) for j in range(5)])\n"
           "    error = positions[inside] - reference\n"
           "    k, j = np.unravel_index(np.argmax(np.abs(error)), error.shape)\n"
           "    result = {{'rms': {rms}, 'largest': {largest}, 'joint': {joint}}}\n"
           "    result['when'] = float(t[k])\n    return result")
COMPARE_RIGHT = {"inside": "(times >= ref_times[0]) & (times <= ref_times[-1])", "rms": "np.sqrt(np.mean(error ** 2, axis=0))",
                 "largest": "float(np.abs(error[k, j]))", "joint": "int(j) + 1"}

# lesson 08's read_joint_states, with its times (or what it returns) written as a student may slip
READ = ("def read_joint_states(path):\n    with AnyReader([Path(path)]) as bag:\n"
        "        wanted = [c for c in bag.connections if c.topic == '/joint_states']\n"
        "        got = [(t, bag.deserialize(raw, c.msgtype)) for c, t, raw in bag.messages(connections=wanted)]\n"
        "    if not wanted or not got:\n        raise ValueError('no /joint_states')\n"
        "    messages = [m for _, m in got]\n"
        "    {times}\n"
        "    positions = np.array([[m.position[list(m.name).index(f'joint{{j}}')] for j in range(1, 6)] for m in messages])\n"
        "    return {result}")
READ_RIGHT = {"times": "ns = np.array([m.header.stamp.sec * 1000000000 + m.header.stamp.nanosec for m in messages]); "
                       "times = (ns - ns[0]) * 1e-9", "result": "times, positions"}

MISTAKES = {
    "00_meet_the_arm": [
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return float(np.hypot(x - target[0], y - target[1]))", "this looks like metres"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    d = 1000 * float(np.hypot(x - target[0], y - target[1]))", "returned None when called with", True),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return 1000 * ((x - target[0]) ** 2 + (y - target[1]) ** 2)", "the squared distance"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return (1000 * (x - target[0])) ** 2 + (1000 * (y - target[1])) ** 2", "the squared distance in mm^2"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return float(np.hypot(x - target[0], y - target[1])) / 1000", "divided by 1000"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return 1000 * abs(x - target[0])", "only the x difference"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(np.radians(q))\n"
         "    return 1000 * float(np.hypot(x - target[0], y - target[1]))", "q is in radians already"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return 1000 * float(np.hypot(x - target[0], y - target[0]))", "the target's y is target[1]"),
        ("ex00_1_tool_distance_test", "def distance_mm(q, target):\n    x, y, _ = snakekit.tool_pose_2d(q)\n"
         "    return [1000 * np.hypot(x - target[0], y - target[1])]", "return one number, not a list")],
    "01_forward_kinematics": [
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    L = spec.lengths\n"
         "    return np.array([np.sum(L * np.cos(q)), np.sum(L * np.sin(q)), np.sum(q)])",
         "a joint angle is not accumulated"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    L = spec.lengths\n"
         "    return np.array([np.sum(L * np.cos(q)), np.sum(L * np.sin(q)), q[-1]])",
         "a joint angle is not accumulated"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi)), q[-1]])",
         "the heading is the sum of all five angles"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi)), np.angle(np.exp(1j * phi[-1]))])",
         "the heading is wrapped"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    return np.array([np.sum(L * np.sin(phi)), np.sum(L * np.cos(phi)), phi[-1]])", "cos and sin are swapped"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    return np.array([np.sum(1000 * L * np.cos(phi)), np.sum(1000 * L * np.sin(phi)), phi[-1]])",
         "the lengths look like millimetres"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    return snakekit.tool_pose_2d(q)",
         "`snakekit.tool_pose_2d` was called", True),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi)), phi[-1]])", "returned None when called with", True),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n"
         "    steps = spec.lengths[:, None] * np.column_stack([np.cos(q), np.sin(q)])\n"
         "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])", "a joint angle is not accumulated"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    xy = [[0.0, 0.0]]\n    for l, p in zip(L, phi):\n"
         "        xy.append([xy[-1][0] + l * np.cos(p), xy[-1][1] + l * np.sin(p)])\n    return xy",
         "not a numpy array", True),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n    return snakekit.joint_frames(q)[:, :2, 3]",
         "`snakekit.joint_frames` was called", True),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    steps = 1000 * L[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])\n"
         "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])", "look like millimetres"),
        ("ex01_3_reach_test", "def reach(n_joints, link_length, tool_offset):\n"
         "    return n_joints * link_length + tool_offset", "counts one link too many"),
        ("ex01_3_reach_test", "def reach(n_joints, link_length, tool_offset):\n"
         "    return (n_joints - 1) * link_length", "the tool offset is missing"),
        ("ex01_3_reach_test", "def reach(n_joints, link_length, tool_offset):\n"
         "    return 1000 * ((n_joints - 1) * link_length + tool_offset)", "this looks like millimetres"),
        ("ex01_3_reach_test", "def reach(n_joints, link_length, tool_offset):\n    return 4 * 0.071 + 0.0475",
         "not the arguments"),
        ("ex01_3_reach_test", "def reach(n_joints, link_length, tool_offset):\n    return spec.reach",
         "`snakekit.SnakeSpec.reach` was called", True),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi)), np.degrees(phi[-1])])",
         "the heading looks like degrees"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    phi = np.cumsum(np.radians(q))\n    L = spec.lengths\n"
         "    return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi)), phi[-1]])",
         "np.radians converts it a second time"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    phi = np.cumsum(q) - q\n    L = spec.lengths\n"
         "    return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi)), np.sum(q)])", "off by one joint"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    x = y = heading = 0.0\n    for i in range(5):\n"
         "        x += spec.lengths[i] * np.cos(heading)\n        y += spec.lengths[i] * np.sin(heading)\n"
         "        heading += q[i]\n    return np.array([x, y, heading])", "off by one joint"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n    x = y = heading = 0.0\n    for i in range(1, 5):\n"
         "        heading += q[i]\n        x += spec.lengths[i] * np.cos(heading)\n"
         "        y += spec.lengths[i] * np.sin(heading)\n    return np.array([x, y, heading])", "link 1 is missing"),
        ("ex01_1_planar_fk_test", "def planar_fk(q):\n" + _FK +
         "    return np.array([np.sum(L[:4] * np.cos(phi[:4])), np.sum(L[:4] * np.sin(phi[:4])), phi[-1]])",
         "the tool link is missing"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    return np.cumsum(L[:, None] * np.column_stack([np.cos(phi), np.sin(phi)]), axis=0)",
         "row 0 is joint 1 at the origin"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    steps = L[:4, None] * np.column_stack([np.cos(phi[:4]), np.sin(phi[:4])])\n"
         "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])", "the tool row is missing"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    return np.vstack([[0.0, 0.0], L[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])])",
         "these are the link vectors"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    steps = L[:, None] * np.column_stack([np.sin(phi), np.cos(phi)])\n"
         "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])", "cos and sin are swapped"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n" + _FK +
         "    steps = L[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])\n"
         "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)]).T", "the transpose of the expected shape"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n    phi = np.cumsum(q) - q\n    L = spec.lengths\n"
         "    steps = L[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])\n"
         "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])", "off by one joint"),
        ("ex01_2_joint_positions_test", "def joint_positions(q):\n    xy, heading = [[0.0, 0.0]], 0.0\n"
         "    for i in range(5):\n        x, y = xy[-1]\n"
         "        xy.append([x + spec.lengths[i] * np.cos(heading), y + spec.lengths[i] * np.sin(heading)])\n"
         "        heading += q[i]\n    return np.array(xy)", "off by one joint")],
    "02_jacobian": [
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n"
         "    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
         "    return np.vstack([down(L * np.sin(phi)), down(L * np.cos(phi)), np.ones(len(q))])",
         "the x row's sign is flipped"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n"
         "    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
         "    return np.vstack([down(L * np.sin(phi)), down(-L * np.cos(phi)), np.ones(len(q))])",
         "the signs are flipped"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n"
         "    return np.vstack([np.cumsum(-L * np.sin(phi)), np.cumsum(L * np.cos(phi)), np.ones(len(q))])",
         "not from the base to i"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
         "    return np.vstack([down(-L * np.sin(q)), down(L * np.cos(q)), np.ones(len(q))])",
         "a joint angle is not accumulated"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    return snakekit.planar_jacobian(q)",
         "`snakekit.planar_jacobian` was called", True),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q, h=1e-6):\n    q = np.asarray(q, dtype=float)\n"
         "    return np.column_stack([(snakekit.tool_pose_2d(q + h * e) - snakekit.tool_pose_2d(q - h * e)) / (2 * h)\n"
         "                            for e in np.eye(len(q))])", "finite differences are exercise 2.2's method"),
        ("ex02_2_numerical_jacobian_test", "def numerical_jacobian(f, q, h=1e-6):\n"
         "    q = np.asarray(q, dtype=float)\n"
         "    return np.column_stack([(np.asarray(f(q + h * e)) - np.asarray(f(q))) / h for e in np.eye(len(q))])",
         "one-sided difference"),
        ("ex02_2_numerical_jacobian_test", "def numerical_jacobian(f, q, h=1e-6):\n"
         "    q = np.asarray(q, dtype=float)\n"
         "    return np.column_stack([(np.asarray(f(q + h * e)) - np.asarray(f(q - h * e))) / h for e in np.eye(len(q))])",
         "this is twice the answer"),
        ("ex02_2_numerical_jacobian_test", "def numerical_jacobian(f, q, h=1e-6):\n"
         "    q = np.asarray(q, dtype=float)\n"
         "    return np.vstack([(np.asarray(f(q + h * e)) - np.asarray(f(q - h * e))) / (2 * h) for e in np.eye(len(q))])",
         "the transpose of the expected shape"),
        ("ex02_3_manipulability_test", "def manipulability(q):\n    J = snakekit.planar_jacobian(q)[:2]\n"
         "    return float(np.linalg.det(J @ J.T))", "without the square root"),
        ("ex02_3_manipulability_test", "def manipulability(q):\n    J = snakekit.planar_jacobian(q)\n"
         "    return float(np.sqrt(np.linalg.det(J @ J.T)))", "this uses all three rows"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n"
         "    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
         "    return np.vstack([down(-L * np.sin(phi)), down(L * np.cos(phi)), np.ones(len(q))]).T",
         "the transpose of the expected shape"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n"
         "    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
         "    return np.vstack([down(-L * np.sin(phi)), down(L * np.cos(phi)), np.zeros(len(q))])", "a row of ones"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n    J = np.ones((3, 5))\n"
         "    for i in range(5):\n        J[0, i] = -np.sum(L[i + 1:] * np.sin(phi[i + 1:]))\n"
         "        J[1, i] = np.sum(L[i + 1:] * np.cos(phi[i + 1:]))\n    return J", "column i starts at link i itself"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n    J = np.ones((3, 5))\n"
         "    for i in range(5):\n        J[0, i] = -np.sum(L[i:] * np.cos(phi[i:]))\n"
         "        J[1, i] = np.sum(L[i:] * np.sin(phi[i:]))\n    return J", "cos and sin are swapped"),
        ("ex02_1_planar_jacobian_test", "def planar_jacobian(q):\n    phi = np.cumsum(q)\n    J = np.ones((3, 5))\n"
         "    for i in range(5):\n        J[0, i] = -np.sum(L[i:] * np.sin(phi[i:]))\n"
         "        J[1, i] = np.sum(L[i:] * np.cos(phi[i:]))\n    return J.tolist()", "not a numpy array", True),
        ("ex02_2_numerical_jacobian_test", "def numerical_jacobian(f, q, h=1e-6):\n    columns = []\n"
         "    for i in range(len(q)):\n        qp = q\n        qp[i] += h\n        up = f(qp)\n        qm = q\n"
         "        qm[i] -= 2 * h\n        columns.append((up - f(qm)) / (2 * h))\n    return np.column_stack(columns)",
         "`qp = q` does not copy an array"),
        ("ex02_2_numerical_jacobian_test", "def numerical_jacobian(f, q, h=1e-6):\n    q = np.asarray(q, dtype=float)\n"
         "    return np.column_stack([(f(q + h * e) - f(q - h * e)) / 2 * h for e in np.eye(len(q))])",
         "write `/ (2 * h)`"),
        ("ex02_2_numerical_jacobian_test", "def numerical_jacobian(f, q, h=1e-6):\n    q = np.asarray(q, dtype=float)\n"
         "    return np.column_stack([(f(q + 1e-6 * e) - f(q - 1e-6 * e)) / 2e-6 for e in np.eye(len(q))])",
         "not for the step you were given"),
        ("ex02_3_manipulability_test", "def manipulability(q):\n    J = snakekit.planar_jacobian(q)[:2]\n"
         "    return float(np.sqrt(np.linalg.det(J @ J.T)))", "Clip it at 0 first"),
        ("ex02_3_manipulability_test", "def manipulability(q):\n    J = snakekit.planar_jacobian(q)[:2]\n"
         "    return float(np.sqrt(max(np.linalg.det(J.T @ J), 0.0)))", "take det(J J^T), 2 x 2"),
        ("ex02_3_manipulability_test", "def manipulability(q):\n    J = snakekit.planar_jacobian(q)[1:]\n"
         "    return float(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)))", "this uses rows y and theta")],
    "03_inverse_kinematics": [
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n"
         "    c2 = np.clip((x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1, 1)\n"
         "    q2 = np.arccos(c2)\n"
         "    rows = [[np.arctan2(y, x) - np.arctan2(l2 * np.sin(s), l1 + l2 * np.cos(s)), s] for s in (q2, -q2)]\n"
         "    return np.degrees(np.array(rows))", "the angles look like degrees"),
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n"
         "    c2 = np.clip((x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1, 1)\n"
         "    q2 = np.arccos(c2)\n"
         "    rows = [[np.arctan2(y, x) - np.arctan2(l2 * np.sin(s), l1 + l2 * np.cos(s)), s] for s in (q2, -q2)]\n"
         "    return np.array(rows)", "raise a ValueError there", True),
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n"
         "    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)\n"
         "    if abs(c2) > 1:\n        raise ValueError('out of reach')\n    q2 = np.arccos(c2)\n"
         "    rows = [[np.arctan2(y, x) - np.arctan2(l2 * np.sin(s), l1 + l2 * np.cos(s)), s] for s in (q2, -q2)]\n"
         "    return np.array(rows)", "np.clip the cosine"),
        ("ex03_2_dls_step_test", "def dls_step(q, target, damping=1e-3):\n" + _DLS +
         "    return J.T @ np.linalg.solve(J @ J.T + damping ** 2 * np.eye(2), e)", "this is only the step"),
        ("ex03_2_dls_step_test", "def dls_step(q, target, damping=1e-3):\n" + _DLS +
         "    return q + J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(2), e)", "use the `damping` argument"),
        ("ex03_2_dls_step_test", "def dls_step(q, target, damping=1e-3):\n" + _DLS +
         "    return q + J.T @ np.linalg.solve(J @ J.T + damping * np.eye(2), e)", "lambda, squared"),
        ("ex03_2_dls_step_test", "def dls_step(q, target, damping=1e-3):\n" + _DLS +
         "    return q - J.T @ np.linalg.solve(J @ J.T + damping ** 2 * np.eye(2), e)", "e = target - tool"),
        ("ex03_2_dls_step_test", "def dls_step(q, target, damping=1e-3):\n" + _DLS +
         "    return q + J.T @ np.linalg.solve(J @ J.T, e)", "the damping term + damping**2 * I"),
        ("ex03_2_dls_step_test", "def dls_step(q, target, damping=1e-3):\n    q = np.asarray(q, dtype=float)\n"
         "    h, here = 1e-8, snakekit.tool_pose_2d(q)[:2]\n"
         "    J = np.column_stack([(snakekit.tool_pose_2d(q + h * d)[:2] - here) / h for d in np.eye(5)])\n"
         "    e = np.asarray(target, dtype=float) - here\n"
         "    return q + J.T @ np.linalg.solve(J @ J.T + damping ** 2 * np.eye(2), e)", "is your Jacobian one-sided"),
        ("ex03_3_ik_loop_test", _SOLVE, "raise a ValueError there", True),
        ("ex03_3_ik_loop_test", _SOLVE.replace("np.clip(dls_step(q, target), spec.lower, spec.upper)",
                                               "dls_step(q, target)").replace("    return q", "    return q\n"
         "    raise ValueError('no solution')"), "clamp q after every step"),
        ("ex03_3_ik_loop_test", "def solve_ik(target, q0=None, tol=1e-6, max_iter=200):\n"
         "    return snakekit.inverse_kinematics(target)", "`snakekit.inverse_kinematics` was called", True),
        ("ex03_4_task1_test", _TASK1.format("run.measured.positions[-1]"), "looks like joint angles"),
        ("ex03_4_task1_test", _TASK1.format("snakekit.tool_pose_2d(run.measured.positions[-1])"),
         "raise a ValueError there", True),
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n" + _IK2 +
         "    return np.array([[np.arctan(y / x) - np.arctan2(l2 * np.sin(s), l1 + l2 * np.cos(s)), s] for s in (q2, -q2)])",
         "Use np.arctan2(y, x)"),
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n" + _IK2 +
         "    q1 = np.arctan2(y, x) - np.arctan2(l2 * np.sin([q2, -q2]), l1 + l2 * np.cos(q2))\n"
         "    return np.array([q1, [q2, -q2]])", "rows and columns are swapped"),
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n" + _IK2 +
         "    return np.array([[np.arctan2(y, x) + np.arctan2(l2 * np.sin(s), l1 + l2 * np.cos(s)), s] for s in (q2, -q2)])",
         "the second angle is subtracted"),
        ("ex03_1_two_link_ik_test", "def two_link_ik(x, y, l1, l2):\n" + _IK2 +
         "    return np.array([[np.arctan2(x, y) - np.arctan2(l2 * np.sin(s), l1 + l2 * np.cos(s)), s] for s in (q2, -q2)])",
         "np.arctan2 takes y first"),
        ("ex03_3_ik_loop_test", _SOLVE.replace("< tol", "< 1e-4").replace("    return q", "    return q\n"
         "    raise ValueError('no solution')"), "does your loop stop once the distance is below `tol`"),
        ("ex03_4_task1_test", _TASK1.format("snakekit.tool_pose_2d(run.measured.positions[-1])[:2]"),
         "keep the heading too"),
        ("ex03_4_task1_test", _TASK1.format("(x, y, heading)"), "these are the targets you set"),
        ("ex03_3_ik_loop_test", "def solve_ik(target, q0=None, tol=1e-6, max_iter=200):\n    q = np.zeros(5)\n"
         "    for _ in range(max_iter):\n        if np.linalg.norm(np.asarray(target) - snakekit.tool_pose_2d(q)[:2]) < tol:\n"
         "            return q\n        q = np.clip(dls_step(q, target), spec.lower, spec.upper)\n"
         "    raise ValueError('no solution')", "Start from q0 when it is given"),
        ("ex03_3_ik_loop_test", "def solve_ik(target, q0=None, tol=1e-6, max_iter=200):\n"
         "    q = np.zeros(5) if q0 is None else np.asarray(q0, dtype=float)\n    for _ in range(max_iter):\n"
         "        if np.linalg.norm(np.asarray(target) - snakekit.tool_pose_2d(q)[:2]) < tol:\n"
         "            return np.clip(q, spec.lower, spec.upper)\n        q = dls_step(q, target)\n"
         "    raise ValueError('no solution')", "clamp inside the loop, after every step"),
        ("ex03_3_ik_loop_test", _SOLVE.replace("spec.lower, spec.upper", "-np.pi / 2, np.pi / 2").replace(
            "    return q", "    return q\n    raise ValueError('no solution')"), "not at +-pi/2"),
        ("ex03_4_task1_test", _TASK1.format("snakekit.tool_pose_2d(run.measured.positions[-1])").replace(
            "set_target(x, y, heading)", "set_target(x, y)"), "the heading in radians: pass all three")],
    "04_trajectories": [
        ("ex04_1_quintic_test", "def quintic(T, t):\n    r = np.clip(np.asarray(t, dtype=float) / T, 0, 1)\n"
         "    return 3 * r ** 2 - 2 * r ** 3", "this is the cubic"),
        ("ex04_1_quintic_test", "def quintic(T, t):\n    r = np.asarray(t, dtype=float) / T\n"
         "    return 10 * r ** 3 - 15 * r ** 4 + 6 * r ** 5", "t is not clipped"),
        ("ex04_2_trapezoid_test", "def trapezoid(distance, v_max, a_max):\n"
         "    return np.array([abs(distance) / v_max, v_max])", "the accelerating and braking time counts"),
        ("ex04_2_trapezoid_test", "def trapezoid(distance, v_max, a_max):\n    d = abs(distance)\n"
         "    return np.array([d / v_max + v_max / a_max, v_max])", "use the triangle"),
        ("ex04_2_trapezoid_test", "def trapezoid(distance, v_max, a_max):\n    d = distance\n"
         "    if d >= v_max ** 2 / a_max:\n        return np.array([d / v_max + v_max / a_max, v_max])\n"
         "    return np.array([2 * np.sqrt(d / a_max), np.sqrt(a_max * d)])", "take abs(distance)"),
        ("ex04_2_trapezoid_test", "def trapezoid(distance, v_max, a_max):\n    d = abs(distance)\n"
         "    if d >= v_max / a_max:\n        return np.array([d / v_max + v_max / a_max, v_max])\n"
         "    return np.array([2 * np.sqrt(d / a_max), np.sqrt(a_max * d)])", "(not v_max / a_max)"),
        ("ex04_3_sample_10hz_test", "def sample_move(q_start, q_end, duration, rate=10.0):\n"
         "    times = np.arange(1, int(round(duration * rate)) + 2) / rate\n"
         "    s = quintic(duration, times - 1 / rate)\n"
         "    return snakekit.Trajectory(times, q_start + np.outer(s, np.asarray(q_end) - q_start))",
         "the times start at 1/rate"),
        ("ex04_3_sample_10hz_test", "def sample_move(q_start, q_end, duration, rate=10.0):\n"
         "    times = np.arange(int(round(duration * 100)) + 1) / 100\n"
         "    return snakekit.Trajectory(times, q_start + np.outer(quintic(duration, times), np.asarray(q_end) - q_start))",
         "the rate looks like 100 Hz"),
        ("ex04_3_sample_10hz_test", "def sample_move(q_start, q_end, duration, rate=10.0):\n"
         "    times = np.arange(int(duration * rate) + 1) / rate\n"
         "    return snakekit.Trajectory(times, q_start + np.outer(quintic(duration, times), np.asarray(q_end) - q_start))",
         "one goal short: int() cuts 4.6 goal periods down to 4 (round gives 5)"),
        ("ex04_4_limit_check_test", "def limit_violations(trajectory):\n    return np.array([])",
         "an empty result has shape (0, 3)"),
        ("ex04_4_limit_check_test", _LIMITS.replace("np.abs(p) > spec.upper", "p > spec.upper"),
         "breaks the position limit too: compare np.abs(q)"),
        ("ex04_4_limit_check_test", _LIMITS.replace("np.abs(np.diff(p, axis=0))", "np.diff(p, axis=0)"),
         "breaks the speed limit too"),
        ("ex04_4_limit_check_test", _LIMITS.replace("sorted(rows)", "rows"), "sort them by time, then joint"),
        ("ex04_1_quintic_test", "def quintic(T, t):\n    r = np.clip(np.atleast_1d(np.asarray(t, dtype=float)) / T, 0, 1)\n"
         "    return 10 * r ** 3 - 15 * r ** 4 + 6 * r ** 5", "s has the shape of t"),
        ("ex04_2_trapezoid_test", "def trapezoid(distance, v_max, a_max):\n    d = abs(distance)\n"
         "    if d >= v_max ** 2 / a_max:\n        return np.array([d / v_max + v_max / a_max, v_max])\n"
         "    v_peak = np.sqrt(a_max * d)\n    return np.array([2 * d / v_peak, v_peak])", "dividing by the peak speed"),
    ] + [("ex04_3_sample_10hz_test", "def sample_move(q_start, q_end, duration, rate=10.0):\n"
          f"    times = {times}\n"
          "    return snakekit.Trajectory(times, q_start + np.outer(quintic(duration, times), np.asarray(q_end) - q_start))",
          hint) for times, hint in (
        ("np.arange(int(np.ceil(duration * rate)) + 1) / rate", "not rounded up as np.ceil does"),
        ("np.arange(0, duration + 1 / rate, 1 / rate)", "steps once past it, since its stop is not exact"),
        ("np.arange(0, duration, 1 / rate)", "np.arange(0, duration, 1 / rate) stops before duration"))
    ] + [
        ("ex04_4_limit_check_test", "def limit_violations(trajectory):\n    t, p = trajectory.times, trajectory.positions\n"
         "    dt = t[1] - t[0]\n    rows = []\n    for k in range(len(t)):\n        for j in range(5):\n"
         "            if abs(p[k, j]) > spec.upper:\n                rows.append([t[k], j + 1, 0])\n"
         "            if k > 0 and abs(p[k, j] - p[k - 1, j]) / dt > spec.velocity_limit:\n"
         "                rows.append([t[k], j + 1, 1])\n    return np.array(rows, dtype=float).reshape(-1, 3)",
         "the times are not evenly spaced: divide each step by its own dt, np.diff(t)")],
    "05_simulation": [
        ("ex05_1_rise_time_test", "def rise_time(t, y, target):\n    t, y = np.asarray(t), np.asarray(y)\n"
         "    progress = y / target\n"
         "    return float(t[np.argmax(progress >= 0.9)] - t[np.argmax(progress >= 0.1)])",
         "measured from the start y[0]"),
        ("ex05_1_rise_time_test", "def rise_time(t, y, target):\n    t, y = np.asarray(t), np.asarray(y)\n"
         "    progress = (y - y[0]) / (target - y[0])\n    return float(t[np.argmax(progress >= 0.9)])",
         "the time to reach 90 %"),
        ("ex05_1_rise_time_test", "def rise_time(t, y, target):\n    t, y = np.asarray(t), np.asarray(y)\n"
         "    progress = (y - y[0]) / (target - y[0])\n"
         "    return 1000 * float(t[np.argmax(progress >= 0.9)] - t[np.argmax(progress >= 0.1)])",
         "this is in milliseconds"),
        ("ex05_2_overshoot_test", "def overshoot(y, target):\n    y = np.asarray(y, dtype=float)\n"
         "    return float(max(0.0, ((y - target) / (target - y[0])).max()))", "this is a fraction"),
        ("ex05_2_overshoot_test", "def overshoot(y, target):\n    y = np.asarray(y, dtype=float)\n"
         "    return float(100 * ((y - target) / (target - y[0])).max())", "no overshoot: 0, not a negative number"),
        # a step down: the peak taken as max(y), or the step's size taken for the step
        ("ex05_2_overshoot_test", "def overshoot(y, target):\n    y = np.asarray(y, dtype=float)\n"
         "    return float(100 * max(0.0, (y.max() - target) / (target - y[0])))", "not at max(y)"),
        ("ex05_2_overshoot_test", "def overshoot(y, target):\n    y = np.asarray(y, dtype=float)\n"
         "    return float(100 * max(0.0, ((y - target) / abs(target - y[0])).max()))",
         "divide by the (negative) step, target - y[0], not its size"),
        ("ex05_3_steady_state_error_test", "def steady_state_error(y, target, window=10):\n"
         "    return float(np.mean(np.asarray(y, dtype=float)[-window:]) - target)", "the sign"),
        ("ex05_3_steady_state_error_test", "def steady_state_error(y, target, window=10):\n"
         "    return float(target - y[-1])", "not one sample"),
        ("ex05_3_steady_state_error_test", "def steady_state_error(y, target, window=1):\n"
         "    return float(target - np.mean(np.asarray(y, dtype=float)[-window:]))", "the window's default is 10 samples"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    return abs(distance) / (profile_velocity * 0.229 * 2 * np.pi / 60)",
         "the accelerating and braking time counts"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi / 60\n    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    return abs(distance) / v + v / a", "a triangle"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi / 60\n    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    if distance >= v * v / a:\n        return distance / v + v / a\n    return 2 * np.sqrt(distance / a)",
         "take abs(distance)"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = min(profile_velocity * 0.229 * 2 * np.pi / 60, snakekit.SPEC.velocity_limit)\n"
         "    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "timed at the arm's 1.5 rad/s"),
        # the unit slips, each in an otherwise right answer
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229\n    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the velocity unit is 0.229 rev/min"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 2 * np.pi / 60\n    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the velocity unit is 0.229 rev/min"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi\n    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the velocity unit is 0.229 rev/min"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 / 60\n    a = profile_acceleration * 214.577 * 2 * np.pi / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the velocity unit is 0.229 rev/min"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi / 60\n    a = profile_acceleration * 214.577\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the acceleration unit is 214.577 rev/min^2"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi / 60\n    a = profile_acceleration * 2 * np.pi / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the acceleration unit is 214.577 rev/min^2"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi / 60\n    a = profile_acceleration * 214.577 / 3600\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the acceleration unit is 214.577 rev/min^2"),
        ("ex05_4_profile_velocity_test", "def profile_move_time(distance, profile_velocity, profile_acceleration):\n"
         "    v = profile_velocity * 0.229 * 2 * np.pi / 60\n    a = profile_acceleration * 214.577 * 2 * np.pi / 60\n"
         "    d = abs(distance)\n    return d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)",
         "the acceleration unit is 214.577 rev/min^2")],
    "06_coded_sweep": [
        ("ex06_1_sweep_times_test", "def sweep_times(points, rate):\n    return np.arange(1, points + 1) / rate",
         "the times start at 1/rate"),
        ("ex06_1_sweep_times_test", "def sweep_times(points, rate):\n    return np.arange(points) / (10 * rate)",
         "these times are 100 Hz apart"),
        ("ex06_1_sweep_times_test", "def sweep_times(points, rate):\n    return np.linspace(0, points / rate, points)",
         "np.linspace"),
        ("ex06_1_sweep_times_test", "def sweep_times(points, rate):\n    return np.arange(points) / 10.0",
         "the rate is an argument"),
        ("ex06_1_sweep_times_test", "def sweep_times(points, rate):\n    return np.arange(0, points / rate, 1 / rate)",
         "one time too many"),
        ("ex06_1_sweep_times_test", "def sweep_times(points, rate):\n    return np.round(np.arange(points) / rate, 3)",
         "these times are rounded"),
        ("ex06_2_sweep_positions_test", "def sweep_positions(times, sweeps, amplitude):\n"
         "    angle = amplitude * np.cos(2 * np.pi * sweeps * times / times[-1])\n"
         "    return np.repeat(angle[:, None], 5, axis=1)", "use sin"),
        ("ex06_2_sweep_positions_test", "def sweep_positions(times, sweeps, amplitude):\n"
         "    angle = amplitude * np.cos(2 * np.pi * sweeps * times / times[-1])\n    angle[-1] = 0.0\n"
         "    return np.repeat(angle[:, None], 5, axis=1)", "use sin"),
        ("ex06_2_sweep_positions_test", "def sweep_positions(times, sweeps, amplitude):\n"
         "    angle = amplitude * np.sin(2 * np.pi * sweeps * times / times[-1])\n    angle[-1] = 0.0\n"
         "    return np.repeat(angle[None, :], 5, axis=0)", "rows and columns are swapped"),
        ("ex06_2_sweep_positions_test", "def sweep_positions(times, sweeps, amplitude):\n"
         "    angle = amplitude * np.sin(2 * np.pi * sweeps * times / (times[-1] + times[1] - times[0]))\n"
         "    return np.repeat(angle[:, None], 5, axis=1)", "the sweeps do not fill the run"),
        ("ex06_2_sweep_positions_test", "def sweep_positions(times, sweeps, amplitude):\n"
         "    angle = np.degrees(amplitude * np.sin(2 * np.pi * sweeps * times / times[-1]))\n    angle[-1] = 0.0\n"
         "    return np.repeat(angle[:, None], 5, axis=1)", "degrees"),
        ("ex06_3_task2_test", "def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):\n"
         "    times = sweep_times(500, 10.0)\n"
         "    return snakekit.Trajectory(times, sweep_positions(times, 50, 0.2)).check_limits()", "use the arguments"),
        ("ex06_3_task2_test", "def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):\n"
         "    times = sweep_times(points, rate)\n"
         "    return snakekit.Trajectory(times, sweep_positions(times, sweeps, amplitude))", "check_limits"),
        ("ex06_4_phase_lag_test", "def estimate_lag(run, joint=0):\n    t = run.measured.times\n"
         "    m = run.measured.positions[:, joint]\n    ct, cq = run.commanded.times, run.commanded.positions[:, joint]\n"
         "    inside = (t >= ct[0] + 0.5) & (t <= ct[-1])\n    lags = np.arange(0, 501)\n"
         "    rms = [np.sqrt(np.mean((m[inside] - np.interp(t[inside] - lag / 1000, ct, cq)) ** 2)) for lag in lags]\n"
         "    return float(lags[int(np.argmin(rms))])", "in milliseconds"),
        ("ex06_4_phase_lag_test", "def estimate_lag(run, joint=0):\n    t = run.measured.times\n"
         "    m = run.measured.positions[:, joint]\n    ct, cq = run.commanded.times, run.commanded.positions[:, joint]\n"
         "    inside = (t >= ct[0] + 0.5) & (t <= ct[-1])\n    lags = np.arange(0, 0.5 + 1e-9, 0.05)\n"
         "    rms = [np.sqrt(np.mean((m[inside] - np.interp(t[inside] - lag, ct, cq)) ** 2)) for lag in lags]\n"
         "    return float(lags[int(np.argmin(rms))])", "between your grid's steps"),
        ("ex06_4_phase_lag_test", "def estimate_lag(run, joint=0):\n    t = run.measured.times\n"
         "    m = run.measured.positions[:, joint]\n    ct, cq = run.commanded.times, run.commanded.positions[:, joint]\n"
         "    inside = (t >= ct[0] + 0.5) & (t <= ct[-1])\n    lags = np.arange(0, 0.5 + 1e-9, 0.02)\n"
         "    rms = [np.sqrt(np.mean((m[inside] - np.interp(t[inside] - lag, ct, cq)) ** 2)) for lag in lags]\n"
         "    return float(lags[int(np.argmin(rms))])", "between your grid's steps")],
    "07_real_robot": [
        ("ex07_1_ticks_test", "def to_ticks(q):\n"
         "    return (2048 + np.asarray(q, dtype=float) * 4096 / (2 * np.pi)).astype(int)", "astype(int) cuts toward zero"),
        ("ex07_1_ticks_test", "def to_ticks(q):\n"
         "    return np.rint(np.asarray(q, dtype=float) * 4096 / (2 * np.pi)).astype(int)", "add the offset"),
        ("ex07_1_ticks_test", "def to_ticks(q):\n"
         "    return np.rint(2048 + np.asarray(q, dtype=float) * 4096 / 360).astype(int)", "2 pi rad (not 360)"),
        ("ex07_2_safe_move_test", "def safe_move(robot, q, margin=0.05):\n    q = np.asarray(q, dtype=float)\n"
         "    if np.any(np.abs(q) > spec.upper - margin):\n        raise snakekit.LimitError('too close')\n"
         "    return robot.move_to(q, max(1.875 * np.abs(q).max() / 1.5, 0.2))", "from where the arm is now"),
        ("ex07_2_safe_move_test", "def safe_move(robot, q, margin=0.05):\n    q = np.asarray(q, dtype=float)\n"
         "    if np.any(np.abs(q) > spec.upper - 0.05):\n        raise snakekit.LimitError('too close')\n"
         "    d = np.abs(q - robot.read().positions).max()\n"
         "    return robot.move_to(q, max(1.875 * d / 1.5, 0.2))", "use the margin argument"),
        ("ex07_2_safe_move_test", "def safe_move(robot, q, margin=0.05):\n    q = np.asarray(q, dtype=float)\n"
         "    if np.any(np.abs(q) > spec.upper - margin):\n        raise ValueError('too close')\n"
         "    d = np.abs(q - robot.read().positions).max()\n"
         "    return robot.move_to(q, max(1.875 * d / 1.5, 0.2))", "raise snakekit.LimitError"),
        ("ex07_2_safe_move_test", "def safe_move(robot, q, margin=0.05):\n    q = np.asarray(q, dtype=float)\n"
         "    if np.any(q > spec.upper - margin):\n        raise snakekit.LimitError('too close')\n"
         "    d = np.abs(q - robot.read().positions).max()\n"
         "    return robot.move_to(q, max(1.875 * d / 1.5, 0.2))", "the limits hold on both sides"),
        ("ex07_3_fault_test", "def recover(robot):\n    for i in robot.ids:\n        robot.reboot(i)\n"
         "    robot.torque_on()\n    return list(robot.ids)", "reboot only the servos")],
    "08_ros": [
        ("ex08_1_sweep_message_test", "def sweep_message(trajectory):\n"
         "    empty = np.zeros(0)\n"
         "    points = [msgs.JointTrajectoryPoint(positions=np.array(q, dtype=float), velocities=empty, accelerations=empty, effort=empty,\n"
         "                                        time_from_start=msgs.Duration(sec=int(t), nanosec=0))\n"
         "              for t, q in zip(trajectory.times, trajectory.positions)]\n"
         "    return msgs.JointTrajectory(header=msgs.Header(seq=0, stamp=msgs.Time(sec=0, nanosec=0), frame_id=''),\n"
         "                                joint_names=JOINTS, points=points)", "the fraction of a second is lost"),
        ("ex08_1_sweep_message_test", "def sweep_message(trajectory):\n"
         "    empty = np.zeros(0)\n"
         "    points = [msgs.JointTrajectoryPoint(positions=np.array(q, dtype=float), velocities=empty, accelerations=empty, effort=empty,\n"
         "                                        time_from_start=msgs.Duration(sec=int(t), nanosec=int(round(t % 1 * 1e6))))\n"
         "              for t, q in zip(trajectory.times, trajectory.positions)]\n"
         "    return msgs.JointTrajectory(header=msgs.Header(seq=0, stamp=msgs.Time(sec=0, nanosec=0), frame_id=''),\n"
         "                                joint_names=JOINTS, points=points)",
         "nanosec is in nanoseconds"),
        ("ex08_1_sweep_message_test", "def sweep_message(trajectory):\n"
         "    empty = np.zeros(0)\n"
         "    points = [msgs.JointTrajectoryPoint(positions=np.degrees(np.array(q, dtype=float)), velocities=empty, accelerations=empty, effort=empty,\n"
         "                                        time_from_start=msgs.Duration(*divmod(int(round(t * 1e9)), 1000000000)))\n"
         "              for t, q in zip(trajectory.times, trajectory.positions)]\n"
         "    return msgs.JointTrajectory(header=msgs.Header(seq=0, stamp=msgs.Time(sec=0, nanosec=0), frame_id=''),\n"
         "                                joint_names=JOINTS, points=points)",
         "the positions are in degrees"),
        ("ex08_1_sweep_message_test", "def sweep_message(trajectory):\n"
         "    empty = np.zeros(0)\n"
         "    points = [msgs.JointTrajectoryPoint(positions=np.array(q, dtype=float), velocities=empty, accelerations=empty, effort=empty,\n"
         "                                        time_from_start=msgs.Duration(sec=int(t), nanosec=int(t % 1 * 1e9)))\n"
         "              for t, q in zip(trajectory.times, trajectory.positions)]\n"
         "    return msgs.JointTrajectory(header=msgs.Header(seq=0, stamp=msgs.Time(sec=0, nanosec=0), frame_id=''),\n"
         "                                joint_names=JOINTS, points=points)",
         "time_from_start is a nanosecond off"),
        ("ex08_2_read_joint_states_test", "def read_joint_states(path):\n    with AnyReader([Path(path)]) as bag:\n"
         "        wanted = [c for c in bag.connections if c.topic == '/joint_states']\n"
         "        messages = [bag.deserialize(raw, c.msgtype) for c, _, raw in bag.messages(connections=wanted)]\n"
         "    if not wanted or not messages:\n        raise ValueError('no /joint_states')\n"
         "    ns = np.array([m.header.stamp.sec * 1000000000 + m.header.stamp.nanosec for m in messages])\n"
         "    positions = np.array([[m.position[list(m.name).index(f'joint{j}')] for j in range(1, 6)] for m in messages])\n"
         "    return ns * 1e-9, positions", "the times start at the first message's stamp"),
        ("ex08_2_read_joint_states_test", "def read_joint_states(path):\n    with AnyReader([Path(path)]) as bag:\n"
         "        wanted = [c for c in bag.connections if c.topic == '/joint_states']\n"
         "        messages = [bag.deserialize(raw, c.msgtype) for c, _, raw in bag.messages(connections=wanted)]\n"
         "    if not wanted or not messages:\n        raise ValueError('no /joint_states')\n"
         "    ns = np.array([m.header.stamp.sec * 1000000000 + m.header.stamp.nanosec for m in messages])\n"
         "    return (ns - ns[0]) * 1e-9, np.array([m.position for m in messages])", "in its own order"),
    ] + [("ex08_2_read_joint_states_test", READ.format(**{**READ_RIGHT, **slip}), *hint) for slip, hint in (
        ({"times": "ns = np.array([t for t, _ in got]); times = (ns - ns[0]) * 1e-9"},
         ("the times the bag received the messages",)),
        ({"times": "s = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in messages]); "
                   "times = s - s[0]"}, ("the stamps went through floats",)),
        ({"times": "ns = np.array([m.header.stamp.sec * 1e9 + m.header.stamp.nanosec for m in messages]); "
                   "times = (ns - ns[0]) * 1e-9"}, ("the stamps went through floats",)),
        ({"times": "us = np.array([m.header.stamp.sec * 1000000 + m.header.stamp.nanosec // 1000 for m in messages]); "
                   "times = (us - us[0]) * 1e-6"}, ("cut to whole microseconds",)),
        ({"times": "ns = np.array([m.header.stamp.sec * 1000000000 + m.header.stamp.nanosec for m in messages]); "
                   "times = ns - ns[0]"}, ("these are nanoseconds",)),
        ({"result": "list(times), positions.tolist()"}, ("not a numpy array", True)))
    ] + [("ex08_3_compare_runs_test", COMPARE.format(**{**COMPARE_RIGHT, **slip}), hint) for slip, hint in (
        ({"rms": "np.mean(error ** 2, axis=0)"}, "take its square root"),
        ({"rms": "np.full(5, np.sqrt(np.mean(error ** 2)))"}, "over all five joints together"),
        ({"inside": "np.ones(len(times), dtype=bool)"}, "after the reference ends there is nothing to compare with"),
        ({"largest": "float(error[k, j])"}, "the largest |e| (its size)"),
        ({"largest": "float(np.max(error))"}, "the largest e itself misses errors below the reference"),
        ({"joint": "int(j)"}, "the joints count from 1"))
    ] + [("ex08_3_compare_runs_test", COMPARE.format(**COMPARE_RIGHT).replace(right, slip), hint) for right, slip, hint in (
        ("float(t[k])", "float(times[k])", "counts only the compared ones"),
        ("k, j = np.unravel_index(np.argmax(np.abs(error)), error.shape)",
         "j = int(np.argmax(np.sqrt(np.mean(error ** 2, axis=0)))); k = int(np.argmax(np.abs(error[:, j])))",
         "the largest error of the joint with the largest rms"))],
}


@pytest.fixture
def kernel_env(monkeypatch):
    monkeypatch.setenv("SNAKEKIT_TEST", "1")
    monkeypatch.delenv("SNAKEKIT_HANDIN_DIR", raising=False)
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")


@pytest.mark.parametrize("name", LESSONS)
def test_no_function_of_a_visible_check_passes_as_an_answer(name, tmp_path, kernel_env):
    """No function a visible check defines passes as an answer; the known mistakes are still named."""
    passed, problems = answers_in_sight(ROOT / "course" / "source" / name / f"{name}.ipynb",
                                        ROOT / "notebooks" / f"{name}.ipynb", tmp_path / name, MISTAKES.get(name, ()))
    assert problems == [], "\n".join(problems)
    assert passed == [], "a handed-out check holds a solution:\n" + "\n".join(passed)


def forbidden_names(source: str, tuples: dict | None = None) -> set[str]:
    """The library functions a test forbids ("snakekit.x.y" -> "y"): its own "snakekit.*" strings,
    and those of the lesson's tuples of them (``FK_SHORTCUTS``) it refers to."""
    out = set()
    for node in ast.walk(parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("snakekit."):
            out.add(node.value.rsplit(".", 1)[1])
        elif isinstance(node, ast.Name) and node.id in (tuples or {}):
            out |= tuples[node.id]
    return out


def shortcut_tuples(nb) -> dict[str, set[str]]:
    """The lesson's named tuples of library functions: ``FK_SHORTCUTS = ("snakekit.x", ...)``."""
    out = {}
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for node in ast.walk(parse(cell.source)):
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Tuple):
                names = forbidden_names(ast.unparse(node.value))
                out.update({t.id: names for t in node.targets if isinstance(t, ast.Name) and names})
    return out


def used_names(source: str, own: str) -> set[str]:
    """Every attribute ``source`` reads, module member it imports, and name other than ``own`` it
    refers to (string constants do not count)."""
    out = set()
    for node in ast.walk(parse(source)):
        if isinstance(node, ast.Name) and node.id != own:
            out.add(node.id)
        elif isinstance(node, ast.Attribute):
            out.add(node.attr)
        elif isinstance(node, ast.alias):
            out.add(node.name.rsplit(".", 1)[-1])
    return out


@pytest.mark.parametrize("name", LESSONS)
def test_no_visible_check_calls_the_library_function_its_exercise_asks_to_write(name):
    instructor = read(ROOT / "course" / "source" / name / f"{name}.ipynb")
    student = read(ROOT / "notebooks" / f"{name}.ipynb")
    tuples = shortcut_tuples(instructor)
    for ex in exercises(instructor, student):
        shortcuts = forbidden_names(ex["hidden"], tuples) | forbidden_names(ex["visible"], tuples)
        shown = used_names(ex["visible"], ex["name"]) & shortcuts
        assert not shown, f"{ex['grade_id']}'s visible check calls {sorted(shown)}, which computes its answer"


def test_a_helper_that_computes_the_answer_is_found(tmp_path, kernel_env):
    """The search above finds a solution a check hands out (and a check that holds none passes)."""
    nbformat = need("nbformat")

    def lesson(check: str):
        answer = nbformat.v4.new_code_cell('def double(x):\n    ### BEGIN SOLUTION\n    return 2 * x\n'
                                           '    ### END SOLUTION')
        answer.metadata["nbgrader"] = {"grade_id": "ex99_1_double", "solution": True, "grade": False}
        test = nbformat.v4.new_code_cell(check)
        test.metadata["nbgrader"] = {"grade_id": "ex99_1_double_test", "grade": True, "points": 1}
        return nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("from snakekit import checks"), answer, test])

    hands_out = ('def expected(x):\n    return x + x\n\nscale = lambda x: 3 * x\n'
                 'ex = checks.Exercise("99.1", "double")\n'
                 'ex.close(ex(double, 0.25), expected(0.25), what="double", where="x=0.25")\n'
                 'ex.close(ex(double, 1.5), expected(1.5), what="double", where="x=1.5")')
    worked = ('scale = lambda x: 3 * x\nex = checks.Exercise("99.1", "double")\n'
              'ex.close(ex(double, 0.25), 0.5, what="double", where="x=0.25")')
    for folder, check in (("out", hands_out), ("worked", worked)):
        (tmp_path / folder).mkdir()
        path = tmp_path / folder / "99_double.ipynb"
        nbformat.write(lesson(check + f"\n{HIDDEN}\nex.done()\n### END HIDDEN TESTS"), path)
        nbformat.write(lesson(check), tmp_path / folder / "student.ipynb")
    passed, problems = answers_in_sight(tmp_path / "out" / "99_double.ipynb", tmp_path / "out" / "student.ipynb",
                                        tmp_path / "run_out")
    assert problems == [] and len(passed) == 2, passed          # given both ways: (*a, **k) and (x)
    assert all("result = expected(" in p and p.endswith("\n    return result") for p in passed), passed
    passed, problems = answers_in_sight(tmp_path / "worked" / "99_double.ipynb", tmp_path / "worked" / "student.ipynb",
                                        tmp_path / "run_worked")
    assert (passed, problems) == ([], [])


@pytest.mark.parametrize("name", LESSONS)
def test_demonstrations_wait_for_the_exercise_instead_of_computing_it(name):
    """Outside the answer and check cells a handed-out lesson defines no function: a demonstration
    that needs an exercise uses the student's function inside ``checks.waiting_for``, never a
    ready-made stand-in (which would be a solution in sight)."""
    student = read(ROOT / "notebooks" / f"{name}.ipynb")
    for index, cell in enumerate(student.cells):
        if cell.cell_type == "code" and not meta(cell).get("solution") and not meta(cell).get("grade"):
            assert helpers(cell.source) == [], f"cell {index} of notebooks/{name}.ipynb defines {helpers(cell.source)}"
