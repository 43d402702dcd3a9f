"""Lesson 03's hidden cases, drawn by the grader anew for every grading batch.

3.1 and 3.3 are judged by a property (the tip on the target, inside the joint limits; 3.3 from a
start q0 that decides the solution, near q0), 3.4 by where its moves end and the poses the arm
measured there; an unreachable target is a case too: the instructor's function raises a
ValueError there, so the student's must raise one.
"""

import numpy as np

#: The grader's tolerances per grade id: 3.1 the tip on the target (0.1 um, the number the notebook's
#: check gives as TIP_TOL: tests/grader/test_grader_tolerances.py keeps them one. A fair grader accepts
#: every right method and no mistake: the textbook triangle method, q2 = acos(c), loses precision near
#: c = 1, and at the fully stretched arm puts the tip up to ~1e-8 m off with every step right, while
#: the smallest real mistake (degrees, a sign, atan instead of atan2) moves it by millimetres),
#: 3.2 the new q (0.1 urad, the check's STEP_TOL: a Jacobian by lesson 2's central differences, h = 1e-6,
#: is within 6e-8 rad of the exact step over 200 draws, every mistake 1e-4 rad or more away), 3.3 the tool
#: on the target (the solver stops within 1e-6 m; 1e-5 m leaves room), 3.4 the tool after each move (the servo settles within a few mrad: 3 mm).
TOLERANCES = {"ex03_1_two_link_ik_test": {"rtol": 1e-9, "atol": 1e-7},
              "ex03_2_dls_step_test": {"rtol": 1e-9, "atol": 1e-7},
              "ex03_3_ik_loop_test": {"rtol": 0.0, "atol": 1e-5},
              "ex03_4_task1_test": {"rtol": 0.0, "atol": 0.003}}

#: 3.3's loop takes its steps from 3.2's dls_step: a slip there is graded again with the lesson's own.
DEPENDS = {"ex03_3_ik_loop_test": ["ex03_2_dls_step"]}


def ex03_1_two_link_ik_test(rng, spec):
    """two_link_ik(x, y, l1, l2): 10 cases; reachable targets of random links, two fully stretched
    arms (both elbows coincide), one of them where the cosine of q2 rounds above 1 (the visible check's
    (0.1, 0, 0.07, 0.03): an unclipped arccos is nan there, wrong graded as locally), and two targets
    out of reach (too far, too near). The first target is always behind the base (x < 0), where
    arctan(y / x) turns the wrong way round, at every draw (the visible check has one too)."""
    cases = []
    for k in range(6):
        l1, l2 = rng.uniform(0.05, 0.2, 2)
        a, b = rng.uniform(-3.0, 3.0), rng.uniform(0.05, 3.0)
        if k == 0 and l1 * np.cos(a) + l2 * np.cos(a + b) >= 0:   # the whole arm turned half a turn
            a += np.pi
        cases.append((float(l1 * np.cos(a) + l2 * np.cos(a + b)), float(l1 * np.sin(a) + l2 * np.sin(a + b)),
                      float(l1), float(l2)))
    l1, l2 = rng.uniform(0.05, 0.2, 2)
    a = rng.uniform(-3.0, 3.0)
    cases.append((float((l1 + l2) * np.cos(a)), float((l1 + l2) * np.sin(a)), float(l1), float(l2)))
    cases.append((0.1, 0.0, 0.07, 0.03))
    far = (l1 + l2) * rng.uniform(1.1, 2.0)
    cases.append((float(far * np.cos(a)), float(far * np.sin(a)), float(l1), float(l2)))
    l2 = l1 * rng.uniform(0.3, 0.6)                 # a target inside the inner circle: too near
    near = (l1 - l2) * rng.uniform(0.1, 0.8)
    cases.append((float(near * np.cos(a)), float(near * np.sin(a)), float(l1), float(l2)))
    return cases


def _tool_xy(q, spec):
    phi = np.cumsum(q)
    return np.array([np.sum(spec.lengths * np.cos(phi)), np.sum(spec.lengths * np.sin(phi))])


def ex03_2_dls_step_test(rng, spec):
    """dls_step(q, target, damping): 8 cases, random poses and targets, dampings from 1e-3 to
    0.1, and the straight arm (singular: the damping matters)."""
    cases = []
    for _ in range(6):
        cases.append((rng.uniform(-1.2, 1.2, spec.n_joints), rng.uniform(-0.2, 0.25, 2) + [0.05, 0.0],
                      float(10 ** rng.uniform(-3, -1))))
    cases.append((np.zeros(spec.n_joints), rng.uniform(0.1, 0.3, 2), float(10 ** rng.uniform(-3, -1))))
    cases.append((np.zeros(spec.n_joints), np.array([rng.uniform(0.2, 0.3), rng.uniform(0.01, 0.05)]), 1e-3))
    return cases


def _loop(target, q0, spec, tol=1e-6, max_iter=200, damping=1e-3, clamp=True):
    """The lesson's loop (DLS steps, clamped into the limits unless ``clamp`` is False): the angles
    it ends at when it reaches ``target`` from ``q0``, else None."""
    q = np.array(q0, dtype=float)
    for _ in range(max_iter):
        phi = np.cumsum(q)
        e = target - _tool_xy(q, spec)
        if np.linalg.norm(e) < tol:
            return q
        dx, dy = -spec.lengths * np.sin(phi), spec.lengths * np.cos(phi)
        J = np.vstack([np.cumsum(dx[::-1])[::-1], np.cumsum(dy[::-1])[::-1]])
        q = q + J.T @ np.linalg.solve(J @ J.T + damping ** 2 * np.eye(2), e)
        if clamp:
            q = np.clip(q, spec.lower, spec.upper)
    return None


def _converges(target, q0, spec):
    """Whether the lesson's loop reaches ``target`` from ``q0``: the hidden reachable targets are
    ones it reaches, so a right answer never has to raise there."""
    return _loop(target, q0, spec) is not None


def _inside_unclamped(target, q0, spec):
    """Whether the loop reaches ``target`` from ``q0`` with or without clamping, and unclamped ends
    inside the limits: the cases that judge the loop itself, where clamping changes nothing (a
    loop that never clamps is judged by the three cases of :func:`_needs_clamping` alone)."""
    q = _loop(target, q0, spec, clamp=False)
    return _converges(target, q0, spec) and q is not None and not bool(((q < spec.lower) | (q > spec.upper)).any())


def _needs_clamping(target, spec):
    """Whether the loop reaches ``target`` from home clamped, but unclamped ends outside the limits
    (or not at all): a loop that never clamps is caught there."""
    q = _loop(target, np.zeros(spec.n_joints), spec, clamp=False)
    return _converges(target, np.zeros(spec.n_joints), spec) and (
        q is None or bool(((q < spec.lower) | (q > spec.upper)).any()))


def _rests_at_a_limit(target, spec):
    """Whether the clamped loop's solution from home holds a joint at its limit (1.57 rad): there a loop
    clamped at +-pi/2 (1.5708 rad) instead of the arm's limits ends outside them, as at the visible check's
    (0.09, 0.21)."""
    q = _loop(target, np.zeros(spec.n_joints), spec)
    return q is not None and bool((np.abs(q) >= spec.upper - 1e-12).any())


def _decided_by_start(rng, spec):
    """(target, q0) where the start decides the solution: q0 a zigzag pose (every joint 0.5 to 1.2 rad
    either way) a little off one that reaches the target; the loop from q0 ends within 0.25 rad of it,
    and from home (q0 ignored) it ends 1 rad away or more, bent another way, or not at all. The grader
    asks the solution to lie within ``grader.scoring.rules.START_NEAR`` (0.5 rad) of q0 there."""
    while True:
        bent = rng.uniform(0.5, 1.2, spec.n_joints) * rng.choice([-1.0, 1.0], spec.n_joints)
        t = _tool_xy(bent, spec)
        q0 = np.clip(bent + rng.uniform(-0.1, 0.1, spec.n_joints), spec.lower, spec.upper)
        if not _inside_unclamped(t, q0, spec) or np.abs(_loop(t, q0, spec) - q0).max() > 0.25:
            continue
        home = _loop(t, np.zeros(spec.n_joints), spec)
        if home is None or np.abs(home - q0).max() >= 1.0:
            return t, q0


def ex03_3_ik_loop_test(rng, spec):
    """solve_ik(target[, q0]): 9 cases; five targets the arm reaches inside its limits whether the
    loop clamps or not (three from home, two from a start q0 that decides the solution: a loop that
    ignores q0 ends elsewhere), three whose unclamped solution leaves the limits (the loop must
    clamp; the first of them rests at a limit, where a clamp at +-pi/2 lets a joint past it), and one out of
    reach (a ValueError expected)."""
    cases = []
    while len(cases) < 3:
        t = _tool_xy(rng.uniform(-0.9, 0.9, spec.n_joints), spec)
        if _inside_unclamped(t, np.zeros(spec.n_joints), spec):
            cases.append((t,))
    while len(cases) < 5:
        cases.append(_decided_by_start(rng, spec))
    while len(cases) < 8:   # about a third of bent poses' targets: a few tries each
        t = _tool_xy(rng.uniform(-1.5, 1.5, spec.n_joints), spec)
        if _needs_clamping(t, spec) and (len(cases) > 5 or _rests_at_a_limit(t, spec)):
            cases.append((t,))
    a = rng.uniform(-np.pi, np.pi)
    cases.append((spec.reach * rng.uniform(1.1, 1.4) * np.array([np.cos(a), np.sin(a)]),))
    return cases


def ex03_4_task1_test(rng, spec):
    """graded_task1(targets): 2 cases, each an (n, 3) array of (x, y, heading) targets: three the
    arm reaches (each move costs a simulator run), and one out of reach (a ValueError expected,
    before any move)."""
    def reachable(n):
        out = []
        for q in rng.uniform(-0.7, 0.7, (n, spec.n_joints)):
            out.append([*_tool_xy(q, spec), float(np.sum(q))])
        return np.array(out)

    a = rng.uniform(-np.pi / 2, np.pi / 2)
    far = spec.reach * rng.uniform(1.1, 1.3)
    return [(reachable(3),), (np.array([[far * np.cos(a), far * np.sin(a), 0.0]]),)]
