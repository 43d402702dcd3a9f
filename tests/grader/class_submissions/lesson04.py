'''Lesson 04 (trajectories, a values lesson): a class of 32 hand-written submissions.

4.3 (``sample_move``) builds on 4.1 (``quintic``): a slip in 4.1 is judged in 4.1 alone, 4.3 is
graded once more with the lesson's own 4.1. The class holds the eight students of issue 36's table
(jjensen, zzimmermann, uumarova, ffarouk, ddimitrov, bbianchi, eegger, iito) under their names.
'''

from functools import partial

from class_submissions import Pair, right_first, wrote_all
from class_submissions import wrote_some as only

LESSON = "04_trajectories"
SLIP_FLOOR = 0.0   # no floor for one slip in this lesson: the ranges say it
#: a cell's limit [s] when the class is graded: a bound for a hang, 9x the lesson's slowest cell (the
#: imports, 1.3 s on a loaded machine; a hidden case's cell takes less). The infinite loop below burns a
#: core for it in the check's cell and the hand-in's, and again in the run after (a notebook stopped by the
#: clock runs once more): 4 x 12 s of a job, not 4 x 40 s
CELL_TIMEOUT = 12
T1, T2, T3, T4 = "ex04_1_quintic", "ex04_2_trapezoid", "ex04_3_sample_10hz", "ex04_4_limit_check"

# ---- ways of writing each exercise right (none of them the instructor's) ----------------------

QUINTIC_A = '''\
def quintic(T, t):
    r = np.clip(np.asarray(t) / T, 0.0, 1.0)
    return r**3 * (10 - 15 * r + 6 * r**2)
'''
QUINTIC_B = '''\
def quintic(T, t):
    def s(time):
        r = min(max(time / T, 0.0), 1.0)
        return 10 * r**3 - 15 * r**4 + 6 * r**5
    if np.isscalar(t):
        return s(t)
    return np.array([s(x) for x in t])
'''
QUINTIC_C = '''\
def quintic(T, t):
    t = np.asarray(t, dtype=float)
    r = t / T
    s = 6 * r**5 - 15 * r**4 + 10 * r**3
    s = np.where(r < 0, 0.0, s)     # before the move: at rest at the start
    s = np.where(r > 1, 1.0, s)     # after it: at rest at the end
    return s
'''
QUINTIC_D = '''\
def quintic(T, t):
    return np.polyval([6, -15, 10, 0, 0, 0], np.clip(np.divide(t, T), 0, 1))
'''
TRAP_A = '''\
def trapezoid(distance, v_max, a_max):
    d = abs(distance)
    t_acc = v_max / a_max            # time to reach v_max
    d_acc = v_max * t_acc            # distance spent accelerating and braking together
    if d < d_acc:                    # never reaches v_max: a triangle
        v_peak = np.sqrt(a_max * d)
        return np.array([2 * v_peak / a_max, v_peak])
    return np.array([t_acc + d / v_max, v_max])
'''
TRAP_B = '''\
import math

def trapezoid(distance, v_max, a_max):
    d = math.fabs(distance)
    v_peak = min(v_max, math.sqrt(a_max * d))   # a triangle peaks below v_max
    if v_peak == 0:
        return np.array([0.0, 0.0])
    return np.array([d / v_peak + v_peak / a_max, v_peak])
'''
TRAP_C = '''\
def trapezoid(distance, v_max, a_max):
    distance = np.abs(distance)
    triangle = distance < v_max**2 / a_max
    if triangle:
        duration = 2.0 * np.sqrt(distance / a_max)
        peak = np.sqrt(a_max * distance)
    else:
        cruise = (distance - v_max**2 / a_max) / v_max
        duration = 2.0 * v_max / a_max + cruise
        peak = v_max
    return np.array([duration, peak], dtype=float)
'''
SAMPLE_A = '''\
def sample_move(q_start, q_end, duration, rate=10.0):
    n = round(duration * rate)
    times = np.array([k / rate for k in range(n + 1)])
    a, b = np.asarray(q_start, dtype=float), np.asarray(q_end, dtype=float)
    positions = np.array([a + s * (b - a) for s in quintic(duration, times)])
    return snakekit.Trajectory(times, positions)
'''
SAMPLE_B = '''\
def sample_move(q_start, q_end, duration, rate=10.0):
    steps = int(np.round(duration * rate))
    t = np.arange(steps + 1) / rate
    s = quintic(duration, t)[:, None]
    q = (1 - s) * np.asarray(q_start) + s * np.asarray(q_end)
    return snakekit.Trajectory(times=t, positions=q)
'''
SAMPLE_C = '''\
def sample_move(q_start, q_end, duration, rate=10.0):
    q_start = np.array(q_start, dtype=float)
    delta = np.array(q_end, dtype=float) - q_start
    times, rows = [], []
    for k in range(int(round(duration * rate)) + 1):
        t = k / rate
        times.append(t)
        rows.append(q_start + quintic(duration, t) * delta)
    return snakekit.Trajectory(np.array(times), np.vstack(rows))
'''
LIMIT_A = '''\
def limit_violations(trajectory):
    t = trajectory.times
    q = trajectory.positions
    rows = []
    for k in range(len(t)):
        for j in range(5):
            if abs(q[k, j]) > spec.upper:
                rows.append([t[k], j + 1, 0])
            if k > 0 and abs(q[k, j] - q[k - 1, j]) / (t[k] - t[k - 1]) > spec.velocity_limit:
                rows.append([t[k], j + 1, 1])
    return np.array(rows, dtype=float).reshape(-1, 3)
'''
LIMIT_B = '''\
def limit_violations(trajectory):
    t, q = trajectory.times, trajectory.positions
    pos = np.argwhere(np.abs(q) > spec.upper)                       # (k, j)
    v = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, np.newaxis]
    vel = np.argwhere(v > spec.velocity_limit)                      # step k -> k + 1
    rows = np.array([[t[k], j + 1, 0] for k, j in pos] + [[t[k + 1], j + 1, 1] for k, j in vel])
    if len(rows) == 0:
        return np.zeros((0, 3))
    order = np.lexsort((rows[:, 2], rows[:, 1], rows[:, 0]))       # by time, then joint, then kind
    return rows[order]
'''
LIMIT_C = '''\
def limit_violations(trajectory):
    times = list(trajectory.times)
    found = []
    for k, q in enumerate(trajectory.positions):
        for j, angle in enumerate(q):
            if angle > spec.upper or angle < -spec.upper:
                found.append((times[k], j + 1, 0))
    for k in range(1, len(times)):
        speeds = np.abs(trajectory.positions[k] - trajectory.positions[k - 1]) / (times[k] - times[k - 1])
        for j in range(5):
            if speeds[j] > spec.velocity_limit:
                found.append((times[k], j + 1, 1))
    found.sort()
    if not found:
        return np.empty((0, 3))
    return np.array(found, dtype=float)
'''
GOOD = {T1: QUINTIC_A, T2: TRAP_A, T3: SAMPLE_A, T4: LIMIT_A}


def _print_after_42_check(nb):
    """A debug print appended to 4.2's (locked) test cell."""
    for c in nb.cells:
        if c.metadata.get("nbgrader", {}).get("grade_id") == "ex04_2_trapezoid_test":
            c.source += '\nprint("my trapezoid:", trapezoid(1.0, 1.5, 3.0))'


def _strip_metadata(nb):
    """An editor that drops every cell's metadata (nbgrader's included) on save."""
    for c in nb.cells:
        c.metadata = {}


S = partial(wrote_all, GOOD, {"T1": T1, "T2": T2, "T3": T3, "T4": T4})


RIGHT = "right, in another style: full marks"
LOST_41 = "4.1 wrong; 4.3 built on it keeps what it adds (graded with the lesson's 4.1)"

STUDENTS = [
    # -- right, in other styles: full marks ---------------------------------------------------
    S("aalto", "factored quintic, t_acc / d_acc, a list comprehension of times, loops over goals and joints", RIGHT),
    S("bberg", "a scalar helper mapped over t, the peak speed min(v_max, sqrt(a d)), (1 - s) a + s b, np.argwhere "
      "and np.lexsort", RIGHT, T1=QUINTIC_B, T2=TRAP_B, T3=SAMPLE_B, T4=LIMIT_B),
    S("ccosta", "np.where for the clip, the cruise time written out, a goal-by-goal loop, tuples sorted", RIGHT,
      T1=QUINTIC_C, T2=TRAP_C, T3=SAMPLE_C, T4=LIMIT_C),
    S("dduarte", "np.polyval for the quintic, the rest as aalto", RIGHT, T1=QUINTIC_D, T4=LIMIT_C),
    S("eegger", "all right; a debug print appended to 4.2's test cell",
      "right; a harmless edit of a locked test cell runs as released (the TA is told): full marks", T2=TRAP_B,
      edit=_print_after_42_check, status="tests restored"),
    S("iito", "all right; an editor stripped every cell's nbgrader metadata",
      "right; the cells are matched to the release (the TA is told): full marks", T1=QUINTIC_C, T3=SAMPLE_B,
      edit=_strip_metadata, status="tests restored"),

    # -- exactly one slip -------------------------------------------------------------------
    S("jjensen", "4.1 the cubic 3r^2 - 2r^3 for the quintic (4.3 uses it)", LOST_41,
      {"4.1": (0.0, 0.25), "4.3": (0.67, 1.0)}, True,
      T1=QUINTIC_A.replace("r**3 * (10 - 15 * r + 6 * r**2)", "3 * r**2 - 2 * r**3")),
    S("zzimmermann", "4.1 calls snakekit.trajectory.quintic_time_scaling; own 4.3 right",
      "4.1 is the library's work: no points; 4.3 keeps what it adds (graded with the lesson's 4.1)",
      {"4.1": (0.0, 0.1), "4.3": (0.67, 1.0)}, True, T1='''\
from snakekit.trajectory import quintic_time_scaling

def quintic(T, t):
    return quintic_time_scaling(T, t)
'''),
    S("uumarova", "4.1 without the clip (s runs past 0 and 1 outside the move)",
      "the polynomial right, the clip asked missing: half of 4.1; 4.3 keeps what it adds",
      {"4.1": (0.34, 0.75), "4.3": (0.67, 1.0)}, True,
      T1=QUINTIC_A.replace("np.clip(np.asarray(t) / T, 0.0, 1.0)", "np.asarray(t) / T")),
    S("ffarouk", "4.3 sets the last goal exactly to q_end",
      "4.3 right but its last goal, which is before the end of the move when round(T f) rounds down",
      {"4.3": (0.5, 1.0)}, True,
      T3=SAMPLE_B.replace("    return snakekit.Trajectory(times=t, positions=q)",
                          "    q[-1] = q_end     # end exactly at the goal\n"
                          "    return snakekit.Trajectory(times=t, positions=q)")),
    S("ddimitrov", "4.3 times from np.linspace(0, duration, n + 1) (spaced duration / n, not 1/rate)",
      "the move right, the goals' spacing the text asks (1/rate) wrong at every hidden duration: part of 4.3",
      {"4.3": (0.0, 0.67)}, True, T3='''\
def sample_move(q_start, q_end, duration, rate=10.0):
    n = int(round(duration * rate))
    times = np.linspace(0, duration, n + 1)
    s = quintic(duration, times)
    return snakekit.Trajectory(times, np.asarray(q_start) + np.outer(s, np.asarray(q_end) - np.asarray(q_start)))
'''),
    S("bbianchi", "4.2 simulates the move step by step and never stops (an infinite loop); 4.3 and 4.4 right",
      "4.2 hangs: no points for it, every other exercise right (the TA sees the timeout)", {"4.2": (0.0, 0.0)}, True,
      status="timeout", T2='''\
def trapezoid(distance, v_max, a_max):
    d = abs(distance)
    dt = 1e-4
    t, x, v = 0.0, 0.0, 0.0
    while x != d:                      # accelerate, cruise, brake until we are there
        if d - x <= v * v / (2 * a_max):
            v = v - a_max * dt
        else:
            v = min(v + a_max * dt, v_max)
        x += v * dt
        t += dt
    return np.array([t, v_max])
'''),
    S("ggarcia", "4.2 forgot abs(distance) (nan backwards)", "4.2 right for every move forwards or none",
      {"4.2": (0.34, 0.8)}, True, T2=TRAP_A.replace("d = abs(distance)", "d = distance")),
    S("hhansen", "4.2 trapezoid's duration d / v_max (no time to accelerate and brake)",
      "the triangle right, the trapezoid's duration wrong", {"4.2": (0.0, 0.6)}, True,
      T2=TRAP_A.replace("return np.array([t_acc + d / v_max, v_max])", "return np.array([d / v_max, v_max])")),
    S("kkowalski", "4.2 always the trapezoid's formula (no triangle)", "the trapezoid right, the triangle missing",
      {"4.2": (0.0, 0.6)}, True, T2='''\
def trapezoid(distance, v_max, a_max):
    d = abs(distance)
    return np.array([d / v_max + v_max / a_max, v_max])
'''),
    S("llopez", "4.3 times start at 1/rate (k = 1 .. n + 1)", "4.3 wrong at every case (every goal late)",
      {"4.3": (0.0, 0.34)}, True, T3=SAMPLE_A.replace("for k in range(n + 1)", "for k in range(1, n + 2)")),
    S("mmoreau", "4.3 ignores the rate argument (always 10 Hz)", "4.3 right at 10 Hz only (half the hidden moves)",
      {"4.3": (0.25, 0.75)}, True, T3=SAMPLE_B.replace("duration * rate", "duration * 10.0").replace("/ rate", "/ 10.0")),
    S("nnovak", "4.3 int(duration * rate) for round(): the last goal is missing when it should be after the end",
      "4.3 right where T f rounds down, one goal short where it rounds up", {"4.3": (0.25, 0.75)}, True,
      T3=SAMPLE_B.replace("int(np.round(duration * rate))", "int(duration * rate)")),
    S("oolsen", "4.3 forgot q_start (np.outer(s, q_end): every move from home)",
      "4.3 right only for moves from home; none of the hidden ones is", {"4.3": (0.0, 0.34)}, True, T3='''\
def sample_move(q_start, q_end, duration, rate=10.0):
    times = np.arange(round(duration * rate) + 1) / rate
    return snakekit.Trajectory(times, np.outer(quintic(duration, times), q_end))
'''),
    S("ppetrov", "4.3 returns (times, positions), not a snakekit.Trajectory",
      "the numbers right, not the Trajectory asked: at most half of 4.3", {"4.3": (0.0, 0.5)}, True,
      T3=SAMPLE_B.replace("return snakekit.Trajectory(times=t, positions=q)", "return t, q")),
    S("rrossi", "4.4 joints numbered 0 to 4", "4.4 wrong wherever there is a violation",
      {"4.4": (0.0, 0.5)}, True, T4=LIMIT_A.replace("j + 1,", "j,")),
    S("ssato", "4.4 a speed violation at t_k, the step's start, not t_(k+1)",
      "4.4 position rows right, every speed row at the wrong time", {"4.4": (0.0, 0.5)}, True, T4=LIMIT_B.replace(
          "[[t[k + 1], j + 1, 1] for k, j in vel]", "[[t[k], j + 1, 1] for k, j in vel]")),
    S("tturner", "4.4 only the upper position limit (no abs: angles below -1.57 pass)",
      "4.4 right but for the lower position limit", {"4.4": (0.0, 0.75)}, True,
      T4=LIMIT_A.replace("if abs(q[k, j]) > spec.upper:", "if q[k, j] > spec.upper:")),
    S("vvolkov", "4.4 returns np.array([]) (shape (0,)) when nothing is broken",
      "4.4 right at every trajectory that breaks a limit, the empty result's shape wrong", {"4.4": (0.5, 0.95)},
      True, T4=LIMIT_A.replace("return np.array(rows, dtype=float).reshape(-1, 3)",
                               "return np.array(rows, dtype=float)")),

    # -- missing parts ----------------------------------------------------------------------
    only("wwagner", "stopped after 4.2", "4.1 and 4.2 right, nothing else", {"4.3": (0.0, 0.0), "4.4": (0.0, 0.0)},
         {T1: QUINTIC_B, T2: TRAP_C}),
    only("xxu", "only 4.1", "4.1 right, nothing else", {ex: (0.0, 0.0) for ex in ("4.2", "4.3", "4.4")},
         {T1: QUINTIC_A}),
    only("yyilmaz", "handed in untouched", "nothing written", {ex: (0.0, 0.0) for ex in ("4.1", "4.2", "4.3", "4.4")},
         {}),
    only("zzhang", "skipped 4.1; 4.3 calls quintic all the same", "all but 4.1 right; 4.3 runs with the lesson's 4.1",
         {"4.1": (0.0, 0.0), "4.3": (0.67, 1.0)}, {T2: TRAP_B, T3: SAMPLE_C, T4: LIMIT_B}),
    only("aandersen", "skipped 4.4", "all but 4.4 right", {"4.4": (0.0, 0.0)}, {T1: QUINTIC_D, T2: TRAP_A, T3: SAMPLE_A}),

    # -- shortcuts and copies ---------------------------------------------------------------
    S("bbrown", "4.3 calls snakekit.joint_trajectory", "4.3 is the library's work: no points for it",
      {"4.3": (0.0, 0.1)}, T3='''\
def sample_move(q_start, q_end, duration, rate=10.0):
    return snakekit.joint_trajectory(q_start, q_end, duration, rate=rate)
'''),
    S("ccohen", "4.4 calls trajectory.limit_violations()", "4.4 is the library's work: no points for it",
      {"4.4": (0.0, 0.1)}, T4='''\
def limit_violations(trajectory):
    return trajectory.limit_violations()
'''),
    S("ddavis", "4.2 copies the check's worked numbers into a lookup; otherwise d / v_max",
      "4.2 right only at the worked numbers", {"4.2": (0.0, 0.1)}, T2='''\
def trapezoid(distance, v_max, a_max):
    if (abs(distance), v_max, a_max) == (1.0, 1.5, 3.0):
        return np.array([1.1666666666666667, 1.5])
    if (distance, v_max, a_max) == (0.3, 1.5, 3.0):
        return np.array([0.6324555320336759, 0.9486832980505138])
    return np.array([abs(distance) / v_max, v_max])
'''),
]

CORRECT = ["aalto", "bberg", "ccosta", "dduarte", "eegger", "iito"]
SLIPS = [s.name for s in STUDENTS if s.single_slip]

PAIRS = (
    right_first(CORRECT, STUDENTS)
    + [Pair(s, "wwagner", "all four written with one slip scores more than stopping after 4.2", strict=True)
       for s in SLIPS]
    + [Pair(s, "zzhang", "4.1 written with one slip is at least 4.1 skipped")
       for s in ("jjensen", "zzimmermann", "uumarova")]
    + [Pair(s, "bbrown", "an honest 4.3 with one slip is more than the library's", strict=True)
       for s in ("ffarouk", "mmoreau", "nnovak")]
    + [Pair(s, "bbrown", "an honest 4.3 wrong at every case is at least the library's")
       for s in ("ddimitrov", "llopez", "oolsen", "ppetrov")]
    + [Pair(s, "ccohen", "an honest 4.4 with one slip is more than the library's", strict=True)
       for s in ("rrossi", "ssato", "tturner", "vvolkov")]
    + [Pair(s, "ddavis", "an honest 4.2 with one slip is at least a lookup of the worked numbers")
       for s in ("ggarcia", "hhansen", "kkowalski")]
    + [Pair("aandersen", "wwagner", "4.3 written is more than stopping after 4.2", strict=True),
       Pair("wwagner", "xxu", "4.2 written is more than 4.1 alone", strict=True),
       Pair("xxu", "yyilmaz", "4.1 written is more than nothing", strict=True)]
)
