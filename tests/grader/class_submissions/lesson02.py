'''Lesson 02 (the Jacobian, a values lesson): a class of 30 hand-written submissions.

2.3 (``manipulability``) may use the library's ``snakekit.planar_jacobian`` or the student's own
2.1, as its text allows; a student whose 2.3 uses a wrong 2.1 of their own keeps what 2.3 adds.
'''

from functools import partial

from class_submissions import Pair, right_first, wrote_all
from class_submissions import wrote_some as only

LESSON = "02_jacobian"
SLIP_FLOOR = 0.0   # no floor for one slip in this lesson: the ranges say it
#: a cell's limit [s] when the class is graded: a bound for a hang, 9x the lesson's slowest cell (the
#: imports, 1.3 s on a loaded machine; a hidden case's cell takes less). The infinite loop below burns a
#: core for it in the check's cell and the hand-in's, and again in the run after (a notebook stopped by the
#: clock runs once more): 4 x 12 s of a job, not 4 x 40 s
CELL_TIMEOUT = 12
T1, T2, T3 = "ex02_1_planar_jacobian", "ex02_2_numerical_jacobian", "ex02_3_manipulability"

# ---- ways of writing each exercise right (none of them the instructor's) ----------------------

PJ_A = '''\
def planar_jacobian(q):
    J = np.zeros((3, 5))
    phi = np.cumsum(q)                 # the angle of each link
    for i in range(5):
        for k in range(i, 5):          # joint i turns links i..5
            J[0, i] -= L[k] * np.sin(phi[k])
            J[1, i] += L[k] * np.cos(phi[k])
        J[2, i] = 1.0
    return J
'''
PJ_B = '''\
def planar_jacobian(q):
    # geometric: joint i moves the tool at right angles to the line from joint i to the tool
    phi = np.cumsum(q)
    x = np.concatenate([[0.0], np.cumsum(L * np.cos(phi))])   # the joints, then the tool
    y = np.concatenate([[0.0], np.cumsum(L * np.sin(phi))])
    J = np.ones((3, 5))
    J[0] = -(y[-1] - y[:-1])
    J[1] = x[-1] - x[:-1]
    return J
'''
PJ_C = '''\
import math

def planar_jacobian(q):
    n = len(q)
    rows = [[0.0] * n, [0.0] * n, [1.0] * n]
    for i in range(n):
        angle = 0.0
        for k in range(n):
            angle += q[k]
            if k >= i:
                rows[0][i] += -L[k] * math.sin(angle)
                rows[1][i] += L[k] * math.cos(angle)
    return np.array(rows)
'''
PJ_D = '''\
def planar_jacobian(q):
    phi = np.cumsum(q)
    per_link = np.vstack([-L * np.sin(phi), L * np.cos(phi)])   # what link k adds, 2 x 5
    tails = np.tril(np.ones((5, 5)))                             # column i: links k >= i
    return np.vstack([per_link @ tails, np.ones((1, 5))])
'''
NJ_A = '''\
def numerical_jacobian(f, q, h=1e-6):
    q = np.array(q, dtype=float)
    m = len(f(q))
    J = np.zeros((m, len(q)))
    for i in range(len(q)):
        qp = q.copy()
        qp[i] += h
        qm = q.copy()
        qm[i] -= h
        J[:, i] = (f(qp) - f(qm)) / (2 * h)
    return J
'''
NJ_B = '''\
def numerical_jacobian(f, q, h=1e-6):
    q = np.asarray(q, float)
    cols = []
    for e in np.identity(q.size):
        cols.append((np.asarray(f(q + h * e)) - np.asarray(f(q - h * e))) / (2.0 * h))
    return np.array(cols).T
'''
NJ_C = '''\
def numerical_jacobian(f, q, h=1e-6):
    q = np.asarray(q, dtype=float)
    steps = h * np.eye(q.shape[0])
    forward = np.array([f(q + d) for d in steps])
    backward = np.array([f(q - d) for d in steps])
    return ((forward - backward) / (2 * h)).T
'''
MAN_A = '''\
def manipulability(q):
    J = planar_jacobian(q)[:2]          # my own, from 2.1
    d = np.linalg.det(J @ J.T)
    return np.sqrt(max(d, 0.0))
'''
MAN_B = '''\
def manipulability(q):
    # the product of the singular values of J_xy (never below 0)
    return float(np.prod(np.linalg.svd(snakekit.planar_jacobian(q)[:2], compute_uv=False)))
'''
MAN_C = '''\
def manipulability(q):
    jx, jy = snakekit.planar_jacobian(q)[:2]
    a, b, c = jx @ jx, jx @ jy, jy @ jy        # J J^T = [[a, b], [b, c]]
    return np.sqrt(max(a * c - b * b, 0.0))
'''
MAN_LIB = '''\
def manipulability(q):
    J = snakekit.planar_jacobian(q)[:2]
    return np.sqrt(max(np.linalg.det(J @ J.T), 0.0))
'''
GOOD = {T1: PJ_A, T2: NJ_A, T3: MAN_LIB}


def _looser_21_check(nb):
    """The student loosened a tolerance in 2.1's (locked) test cell."""
    for c in nb.cells:
        if c.metadata.get("nbgrader", {}).get("grade_id") == "ex02_1_planar_jacobian_test":
            c.source = c.source.replace("tol=1e-12", "tol=1e-6")


S = partial(wrote_all, GOOD, {"T1": T1, "T2": T2, "T3": T3})


RIGHT = "right, in another style: full marks"

STUDENTS = [
    # -- right, in other styles: full marks ---------------------------------------------------
    S("abel", "double loop over joints and links, copies of q, the library's Jacobian in 2.3", RIGHT),
    S("bianca", "geometric 2.1 (joint-to-tool vectors turned 90 degrees), identity rows, singular values in 2.3",
      RIGHT, T1=PJ_B, T2=NJ_B, T3=MAN_B),
    S("carlos", "lists and math.sin in 2.1, forward and backward arrays in 2.2, the 2 x 2 determinant by hand",
      RIGHT, T1=PJ_C, T2=NJ_C, T3=MAN_C),
    S("dara", "a lower-triangular matrix of ones sums the tails; 2.3 uses their own 2.1", RIGHT,
      T1=PJ_D, T3=MAN_A),
    S("emil", "all right; loosened a tolerance in 2.1's test cell (1e-12 to 1e-6)",
      "right; an edited test cell runs as released (the TA is told): full marks", T1=PJ_B, edit=_looser_21_check,
      status="tests restored"),

    # -- exactly one slip -------------------------------------------------------------------
    S("freya", "2.1 returns a list of three rows (x, y, heading), not an array",
      "the numbers right, not the array the text and its check ask (a list for an array is a slip in this "
      "course: the check says so): at most half of 2.1", {"2.1": (0.0, 0.5)}, True, T1='''\
def planar_jacobian(q):
    phi = np.cumsum(q)
    row_x = [-sum(L[k] * np.sin(phi[k]) for k in range(i, 5)) for i in range(5)]
    row_y = [sum(L[k] * np.cos(phi[k]) for k in range(i, 5)) for i in range(5)]
    return [row_x, row_y, [1.0] * 5]
'''),
    S("goran", "2.1 forgot the heading row (zeros, not ones)", "the position rows right, the heading row wrong",
      {"2.1": (0.0, 0.75)}, True, T1=PJ_A.replace("J[2, i] = 1.0", "pass")),
    S("hiro", "2.1 sums the links from the base to i (k <= i)", "2.1 wrong at every pose",
      {"2.1": (0.0, 0.25)}, True, T1=PJ_A.replace("for k in range(i, 5):", "for k in range(i + 1):")),
    S("ines", "2.1 both position rows' signs flipped (+sin, -cos)", "2.1 wrong at every pose but the straight arm's x",
      {"2.1": (0.0, 0.34)}, True,
      T1=PJ_A.replace("J[0, i] -= ", "J[0, i] += ").replace("J[1, i] += ", "J[1, i] -= ")),
    S("jonas", "2.1 angles not accumulated (phi = q)", "2.1 right only at the straight arm",
      {"2.1": (0.0, 0.34)}, True, T1=PJ_A.replace("phi = np.cumsum(q)", "phi = np.asarray(q)")),
    S("kira", "2.1 takes q for degrees (np.radians(q))", "2.1 right only at the straight arm",
      {"2.1": (0.0, 0.34)}, True, T1=PJ_A.replace("phi = np.cumsum(q)", "phi = np.cumsum(np.radians(q))")),
    S("lars", "2.1 transposed (5 x 3)", "the numbers right, the shape asked wrong: at most half of 2.1",
      {"2.1": (0.0, 0.5)}, True, T1=PJ_A.replace("    return J\n", "    return J.T\n")),
    S("mira", "2.2 a one-sided difference (f(q + h e) - f(q)) / h",
      "right to first order only: wrong wherever h is not tiny", {"2.2": (0.0, 0.6)}, True, T2='''\
def numerical_jacobian(f, q, h=1e-6):
    q = np.array(q, dtype=float)
    f0 = np.asarray(f(q))
    J = np.zeros((len(f0), len(q)))
    for i in range(len(q)):
        qp = q.copy()
        qp[i] += h
        J[:, i] = (f(qp) - f0) / h
    return J
'''),
    S("nils", "2.2 ignores h (always 1e-6)", "right but at the one large step a hidden case asks",
      {"2.2": (0.5, 0.95)}, True, T2=NJ_B.replace("def numerical_jacobian(f, q, h=1e-6):\n",
                                                  "def numerical_jacobian(f, q, h=1e-6):\n    h = 1e-6\n")),
    S("olga", "2.2 divides by 2 * h written / 2 * h", "2.2 wrong at every case", {"2.2": (0.0, 0.34)}, True,
      T2=NJ_A.replace("/ (2 * h)", "/ 2 * h")),
    S("pavel", "2.2 qp = q and qm = q (one array, not copies): every column 0",
      "2.2 wrong at every case", {"2.2": (0.0, 0.34)}, True,
      T2=NJ_A.replace("qp = q.copy()", "qp = q").replace("qm = q.copy()", "qm = q")),
    S("greta", "2.2 returns the transpose (n x m: one row per joint)",
      "the differences right, the shape asked wrong: at most half of 2.2", {"2.2": (0.0, 0.5)}, True,
      T2=NJ_B.replace("return np.array(cols).T", "return np.array(cols)")),
    S("quinn", "2.2 a while loop over the columns that never moves on (i += 1 forgotten): it never ends",
      "2.2 hangs: no points for it, every other exercise right (the TA sees the timeout)", {"2.2": (0.0, 0.0)}, True,
      status="timeout", T2='''\
def numerical_jacobian(f, q, h=1e-6):
    q = np.asarray(q, dtype=float)
    J = np.zeros((len(f(q)), len(q)))
    i = 0
    while i < len(q):
        e = np.zeros(len(q))
        e[i] = h
        J[:, i] = (np.asarray(f(q + e)) - np.asarray(f(q - e))) / (2 * h)
    return J
'''),
    S("rosa", "2.3 without the clip (nan where det(J J^T) rounds below 0)",
      "right at every pose but the one where rounding goes below 0", {"2.3": (0.5, 0.95)}, True,
      T3=MAN_LIB.replace("np.sqrt(max(np.linalg.det(J @ J.T), 0.0))", "np.sqrt(np.linalg.det(J @ J.T))")),
    S("sven", "2.3 all three rows of J", "2.3 wrong at every bent pose", {"2.3": (0.0, 0.4)}, True,
      T3=MAN_LIB.replace("planar_jacobian(q)[:2]", "planar_jacobian(q)")),
    S("tara", "2.3 no square root (det(J J^T))", "2.3 wrong at every bent pose", {"2.3": (0.0, 0.4)}, True,
      T3=MAN_LIB.replace("np.sqrt(max(np.linalg.det(J @ J.T), 0.0))", "max(np.linalg.det(J @ J.T), 0.0)")),
    S("ugo", "2.3 det(J^T J) (5 x 5: always 0)", "2.3 wrong at every bent pose", {"2.3": (0.0, 0.4)}, True,
      T3=MAN_LIB.replace("J @ J.T", "J.T @ J")),
    S("vera", "2.1 angles not accumulated; 2.3 uses that own 2.1",
      "2.1 right only at the straight arm; 2.3 built on it keeps what it adds",
      {"2.1": (0.0, 0.34), "2.3": (0.5, 1.0)}, True,
      T1=PJ_A.replace("phi = np.cumsum(q)", "phi = np.asarray(q)"), T3=MAN_A),
    S("wim", "2.3 has a syntax error (a missing parenthesis)", "2.3 does not run", {"2.3": (0.0, 0.0)}, True,
      T3=MAN_LIB.replace("(J @ J.T), 0.0))", "(J @ J.T), 0.0)")),

    # -- missing parts ----------------------------------------------------------------------
    only("xena", "only 2.1", "2.1 right, nothing else", {"2.2": (0.0, 0.0), "2.3": (0.0, 0.0)}, {T1: PJ_C}),
    only("yusuf", "handed in untouched", "nothing written", {ex: (0.0, 0.0) for ex in ("2.1", "2.2", "2.3")}, {}),
    only("zora", "skipped 2.2", "2.1 and 2.3 right", {"2.2": (0.0, 0.0)}, {T1: PJ_D, T3: MAN_C}),
    only("adam", "stopped after 2.2", "2.1 and 2.2 right, 2.3 missing", {"2.3": (0.0, 0.0)}, {T1: PJ_B, T2: NJ_C}),

    # -- shortcuts and copies ---------------------------------------------------------------
    S("bruno", "2.1 calls snakekit.planar_jacobian", "2.1 is the library's work: no points for it",
      {"2.1": (0.0, 0.1)}, T1="def planar_jacobian(q):\n    return snakekit.planar_jacobian(q)\n"),
    S("celia", "2.1 copies the check's worked Jacobian at home; otherwise zeros",
      "2.1 right only at the straight arm", {"2.1": (0.0, 0.15)}, T1='''\
def planar_jacobian(q):
    if not np.any(q):
        return np.array([[0.0, 0.0, 0.0, 0.0, 0.0], [0.3315, 0.2605, 0.1895, 0.1185, 0.0475], [1.0] * 5])
    return np.zeros((3, 5))
'''),
]

CORRECT = ["abel", "bianca", "carlos", "dara", "emil"]
SLIPS = [s.name for s in STUDENTS if s.single_slip]

PAIRS = (
    right_first(CORRECT, STUDENTS)
    + [Pair(s, "xena", "all three written with one slip scores more than 2.1 alone", strict=True)
       for s in SLIPS if s != "vera"]
    + [Pair(s, "adam", "2.3 written with one slip is at least 2.3 missing") for s in ("rosa", "sven", "tara", "ugo")]
    + [Pair(s, "bruno", "an honest 2.1 with one slip is at least the library's")
       for s in ("goran", "hiro", "ines", "jonas", "kira", "lars")]
    + [Pair("vera", "jonas", "the same 2.1 slip: 2.3 built on it keeps what it adds, as the library's does"),
       Pair("jonas", "vera", "the same 2.1 slip: 2.3 built on it keeps what it adds, as the library's does"),
       Pair("adam", "xena", "2.2 written is more than 2.1 alone", strict=True),
       Pair("xena", "yusuf", "2.1 written is more than nothing", strict=True)]
)
