'''Lesson 06 (the coded sweep, Task 2): a class of 34 hand-written submissions.

Written for ``task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2)``. A submission
that still has ``task2_sweep()`` without arguments (``xan``) builds the spec's Task 2 right
but nothing else: one mistake (the signature the exercise asks for), so the floor for a
single slip applies, and 6.3 keeps only part of its points.
'''

from functools import partial

from class_submissions import Pair, wrote_all, wrote_some

LESSON = "06_coded_sweep"
SLIP_FLOOR = 10 / 18   # issue 20: a single mistake in lesson 06 leaves at least 10 of 18
T1, T2, T3, T4 = "ex06_1_sweep_times", "ex06_2_sweep_positions", "ex06_3_task2", "ex06_4_phase_lag"

# ---- three ways of writing each exercise right (none of them the instructor's) ----------------

TIMES_A = '''\
def sweep_times(points, rate):
    dt = 1.0 / rate          # seconds between two goals
    return np.arange(points) * dt
'''
TIMES_B = '''\
def sweep_times(points, rate):
    times = []
    for k in range(points):
        times.append(k / rate)
    return np.array(times)
'''
TIMES_C = '''\
def sweep_times(points, rate):
    # the last goal goes out at (points - 1) / rate, not points / rate
    last = (points - 1) / rate
    return np.linspace(0.0, last, points)
'''
POS_A = '''\
def sweep_positions(times, sweeps, amplitude):
    t = np.asarray(times, dtype=float)
    t_end = t[-1]
    q = amplitude * np.sin(2 * np.pi * sweeps * t / t_end)
    q[-1] = 0.0   # sin(2 pi n) is not exactly 0
    return np.tile(q[:, np.newaxis], (1, 5))
'''
POS_B = '''\
import math

def sweep_positions(times, sweeps, amplitude):
    t_end = times[-1]
    rows = []
    for t in times:
        angle = amplitude * math.sin(2 * math.pi * sweeps * t / t_end)
        rows.append([angle] * 5)
    rows[-1] = [0.0] * 5
    return np.array(rows)
'''
POS_C = '''\
def _sine_wave(t, period, amplitude):
    return amplitude * np.sin(2 * np.pi * t / period)

def sweep_positions(times, sweeps, amplitude):
    times = np.array(times, dtype=float)
    period = times[-1] / sweeps          # one sweep = one period
    wave = _sine_wave(times, period, amplitude)
    wave[-1] = 0
    return np.outer(wave, np.ones(5))
'''
TASK_A = '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    t = sweep_times(points, rate)
    q = sweep_positions(t, sweeps, amplitude)
    traj = snakekit.Trajectory(t, q)
    traj.check_limits()
    return traj
'''
TASK_B = '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    times = sweep_times(points, rate)
    goals = sweep_positions(times, sweeps, amplitude)
    return snakekit.Trajectory(times=times, positions=goals).check_limits()
'''
LAG_A = '''\
def estimate_lag(run, joint=0):
    t = run.measured.times
    q_meas = run.measured.positions[:, joint]
    t_cmd = run.commanded.times
    q_cmd = run.commanded.positions[:, joint]
    keep = (t >= t_cmd[0] + 0.5) & (t <= t_cmd[-1])
    best_lag, best_rms = 0.0, np.inf
    for ms in range(501):
        lag = ms / 1000
        diff = q_meas[keep] - np.interp(t[keep] - lag, t_cmd, q_cmd)
        rms = np.sqrt(np.mean(diff ** 2))
        if rms < best_rms:
            best_lag, best_rms = lag, rms
    return best_lag
'''
LAG_B = '''\
def estimate_lag(run, joint=0):
    meas_t = run.measured.times
    meas_q = run.measured.positions[:, joint]
    start = run.commanded.times[0] + 0.5
    end = run.commanded.times[-1]
    idx = [i for i in range(len(meas_t)) if start <= meas_t[i] <= end]
    lags = []
    errors = []
    for i in range(501):
        lag = i * 0.001
        shifted = run.commanded.sample(meas_t[idx] - lag)[:, joint]
        errors.append(np.sqrt(np.mean((meas_q[idx] - shifted) ** 2)))
        lags.append(lag)
    return lags[int(np.argmin(errors))]
'''
LAG_C = '''\
def estimate_lag(run, joint=0):
    tm, qm = run.measured.times, run.measured.positions[:, joint]
    tc, qc = run.commanded.times, run.commanded.positions[:, joint]
    window = (tm >= tc[0] + 0.5) & (tm <= tc[-1])
    candidates = np.linspace(0.0, 0.5, 501)
    shifted = np.array([np.interp(tm[window] - c, tc, qc) for c in candidates])
    mse = ((shifted - qm[window]) ** 2).mean(axis=1)   # the same minimum as the rms
    return float(candidates[mse.argmin()])
'''
GOOD = {T1: TIMES_A, T2: POS_A, T3: TASK_A, T4: LAG_A}


S = partial(wrote_all, GOOD, {"T1": T1, "T2": T2, "T3": T3, "T4": T4})
only = wrote_some


RIGHT = "right, in another style: full marks"
LOST_61 = "6.1 wrong at every case; 6.3 built on it keeps what it adds (floor: one slip)"
LOST_62 = "6.2 wrong at every case; 6.3 built on it keeps what it adds (floor: one slip)"
DEFAULT_63 = "Task 2 itself (the defaults) is wrong, the other arguments right: part of 6.3"

STUDENTS = [
    # -- right, in other styles: full marks ---------------------------------------------------
    S("ana", "vectorised: arange * dt, np.tile, a loop over the lags", RIGHT),
    S("ben", "loops everywhere: lists of times and rows (math.sin) turned into arrays", RIGHT,
      T1=TIMES_B, T2=POS_B, T3=TASK_B, T4=LAG_B),
    S("cleo", "np.linspace to (points-1)/rate, a helper for the sine, np.outer, mse over all lags at once", RIGHT,
      T1=TIMES_C, T2=POS_C, T4=LAG_C),
    S("dev", "per-joint loop into np.empty, Trajectory(times=..., positions=...), mean square error", RIGHT,
      T1="def sweep_times(points, rate):\n    return np.arange(0, points) / float(rate)\n",
      T2='''\
def sweep_positions(times, sweeps, amplitude):
    n = len(times)
    out = np.empty((n, 5))
    w = 2 * np.pi * sweeps / times[-1]    # angular frequency [rad/s]
    for j in range(5):
        out[:, j] = amplitude * np.sin(w * np.asarray(times))
    out[n - 1, :] = 0.0
    return out
''', T3=TASK_B, T4='''\
def estimate_lag(run, joint=0):
    t = run.measured.times
    y = run.measured.positions[:, joint]
    tc = run.commanded.times
    yc = run.commanded.positions[:, joint]
    m = (t >= tc[0] + 0.5) & (t <= tc[-1])
    lags = np.arange(0.0, 0.5005, 0.001)
    cost = [np.mean((y[m] - np.interp(t[m] - L, tc, yc)) ** 2) for L in lags]
    return float(lags[np.argmin(cost)])
'''),
    S("eli", "broadcasting with np.ones((1, 5)), last row zeroed with positions[-1, :] = 0", RIGHT,
      T2='''\
def sweep_positions(times, sweeps, amplitude):
    times = np.asarray(times, dtype=float)
    phase = 2 * np.pi * sweeps * times / times[-1]
    positions = (amplitude * np.sin(phase))[:, None] * np.ones((1, 5))
    positions[-1, :] = 0
    return positions
''', T4=LAG_C),
    S("fay", "np.column_stack of five columns, commanded.sample for the lag", RIGHT,
      T1=TIMES_B, T2='''\
def sweep_positions(times, sweeps, amplitude):
    t = np.asarray(times, dtype=float)
    col = amplitude * np.sin(2 * np.pi * sweeps * t / t[-1])
    col[-1] = 0.0
    return np.column_stack([col, col, col, col, col])
''', T3=TASK_B, T4=LAG_B),

    # -- exactly one slip -------------------------------------------------------------------
    S("gil", "6.1: times from 1/rate (np.arange(1, points + 1) / rate)", LOST_61,
      {"6.1": (0.0, 0.5), "6.3": (0.5, 1.0)}, True,
      T1="def sweep_times(points, rate):\n    return np.arange(1, points + 1) / rate\n"),
    S("hal", "6.1: np.linspace(0, points / rate, points) (spaced a little too wide)", LOST_61,
      {"6.1": (0.0, 0.5), "6.3": (0.5, 1.0)}, True,
      T1="def sweep_times(points, rate):\n    return np.linspace(0, points / rate, points)\n",
      T2=POS_B, T4=LAG_B),
    S("ian", "6.3: 100 Hz for 10 Hz (default rate=100.0)", DEFAULT_63, {"6.3": (0.3, 0.9)}, True,
      T3=TASK_A.replace("rate=10.0", "rate=100.0")),
    S("jo", "6.3: 49 sweeps (default sweeps=49)", DEFAULT_63, {"6.3": (0.3, 0.9)}, True,
      T3=TASK_B.replace("sweeps=50", "sweeps=49"), T1=TIMES_C),
    S("kim", "6.3: amplitude 0.25 (default amplitude=0.25)", DEFAULT_63, {"6.3": (0.3, 0.9)}, True,
      T3=TASK_A.replace("amplitude=0.2", "amplitude=0.25"), T2=POS_C),
    S("lea", "6.2: takes the amplitude for degrees (np.radians(amplitude))", LOST_62,
      {"6.2": (0.0, 0.34), "6.3": (0.5, 1.0)}, True,
      T2=POS_A.replace("q = amplitude *", "q = np.radians(amplitude) *")),
    S("max", "6.2: cos for sin", LOST_62, {"6.2": (0.0, 0.34), "6.3": (0.5, 1.0)}, True,
      T2=POS_A.replace("np.sin", "np.cos")),
    S("nia", "6.2: last row not zeroed (ends at ~1e-14 rad, the text asks exactly 0)",
      "6.2 right but for the exact home the text insists on: a home within 1e-12 rad is home (the "
      "grader's near-zero rule), so full marks where the drawn sweep ends that close, less where "
      "it does not; 6.3 as good as right",
      {"6.2": (0.0, 1.0), "6.3": (0.8, 1.0)}, True,
      T2=POS_C.replace("    wave[-1] = 0\n", "")),
    S("oli", "6.2: period t_end + dt, so the sweeps do not fill the run (not home at the end)", LOST_62,
      {"6.2": (0.0, 0.34), "6.3": (0.5, 1.0)}, True, T2='''\
def sweep_positions(times, sweeps, amplitude):
    t = np.asarray(times, dtype=float)
    duration = t[-1] + (t[1] - t[0])      # the whole run
    q = amplitude * np.sin(2 * np.pi * sweeps * t / duration)
    q[-1] = 0.0
    return np.tile(q[:, None], (1, 5))
'''),
    S("pam", "6.4: the lag in milliseconds", "6.4 wrong by a unit at every case", {"6.4": (0.0, 0.34)}, True,
      T4=LAG_A.replace("return best_lag", "return best_lag * 1000   # in ms")),
    S("quin", "6.4: shifts the commanded curve the wrong way (t + lag): always 0", "6.4 wrong at every case",
      {"6.4": (0.0, 0.34)}, True, T4=LAG_C.replace("tm[window] - c", "tm[window] + c")),
    S("ray", "6.1: forgot the return", LOST_61, {"6.1": (0.0, 0.0), "6.3": (0.5, 1.0)}, True,
      T1="def sweep_times(points, rate):\n    times = np.arange(points) / rate\n"),
    S("sam", "6.2: a syntax error (a missing parenthesis)", LOST_62, {"6.2": (0.0, 0.0), "6.3": (0.5, 1.0)}, True,
      T2=POS_A.replace("t / t_end)", "t / t_end")),
    S("tia", "6.3: never checks the limits (no check_limits)",
      "the trajectory is right; only a sweep beyond the limits would show it", {"6.3": (0.5, 1.0)}, True,
      T3='''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    t = sweep_times(points, rate)
    return snakekit.Trajectory(t, sweep_positions(t, sweeps, amplitude))
'''),
    S("uma", "6.2: rows and columns swapped (shape (5, N), np.vstack)", LOST_62,
      {"6.2": (0.0, 0.34), "6.3": (0.5, 1.0)}, True,
      T2=POS_A.replace("np.tile(q[:, np.newaxis], (1, 5))", "np.vstack([q] * 5)")),
    S("vic", "6.3: ignores the rate argument (sweep_times(points, 10.0))",
      "right at 10 Hz only: part of 6.3", {"6.3": (0.3, 0.95)}, True,
      T3=TASK_A.replace("sweep_times(points, rate)", "sweep_times(points, 10.0)")),
    S("wes", "6.3: amplitude in degrees (default amplitude=11.5): Task 2 itself breaks the limits",
      DEFAULT_63, {"6.3": (0.3, 0.9)}, True, T3=TASK_A.replace("amplitude=0.2", "amplitude=11.5")),
    S("xan", "6.3: kept task2_sweep() without arguments (the spec's values written in)",
      "Task 2 right at the spec, not the function asked for: part of 6.3 (floor: one slip)",
      {"6.3": (0.3, 0.8)}, True, T3='''\
def task2_sweep():
    times = sweep_times(500, 10.0)
    positions = sweep_positions(times, 50, 0.2)
    return snakekit.Trajectory(times, positions).check_limits()
'''),

    # -- missing parts ----------------------------------------------------------------------
    only("yara", "stopped after 6.2", "6.1 and 6.2 right, nothing else",
         {"6.3": (0.0, 0.0), "6.4": (0.0, 0.0)}, {T1: TIMES_A, T2: POS_B}),
    only("zed", "skipped 6.1 and 6.2, wrote 6.3 inline, and 6.4", "6.3 and 6.4 right, nothing else",
         {"6.1": (0.0, 0.0), "6.2": (0.0, 0.0)}, {T3: '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    t = np.arange(points) / rate
    a = amplitude * np.sin(2 * np.pi * sweeps * t / t[-1])
    a[-1] = 0.0
    q = np.repeat(a.reshape(-1, 1), 5, axis=1)
    return snakekit.Trajectory(t, q).check_limits()
''', T4: LAG_A}),
    only("abe", "skipped 6.1, wrote its times inline in 6.3", "all but 6.1 right", {"6.1": (0.0, 0.0)},
         {T2: POS_A, T3: '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    times = np.arange(points) / rate
    return snakekit.Trajectory(times, sweep_positions(times, sweeps, amplitude)).check_limits()
''', T4: LAG_B}),
    only("bea", "skipped 6.4", "all but 6.4 right", {"6.4": (0.0, 0.0)}, {T1: TIMES_C, T2: POS_C, T3: TASK_B}),
    only("cal", "handed in untouched", "nothing written", {ex: (0.0, 0.0) for ex in ("6.1", "6.2", "6.3", "6.4")}, {}),
    only("dot", "only 6.1", "6.1 right, nothing else", {ex: (0.0, 0.0) for ex in ("6.2", "6.3", "6.4")}, {T1: TIMES_B}),

    # -- shortcuts and copies ---------------------------------------------------------------
    S("eve", "6.3 calls snakekit.side_sweep(...) with the arguments", "6.3 is the library's work: no points for it",
      {"6.3": (0.0, 0.1)}, T3='''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    return snakekit.side_sweep(points=points, rate=rate, sweeps=sweeps, amplitude=amplitude)
'''),
    S("fin", "6.3 returns snakekit.side_sweep() built at import time",
      "6.3 is a stored library result: no points for it, but at Task 2 itself (task2_sweep(), half of 6.3's "
      "weight) the stored sweep is the very sweep asked, and no grader can tell who computed it",
      {"6.3": (0.0, 0.46)}, T3='''\
TASK2 = snakekit.side_sweep()   # build it once

def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    return TASK2
'''),
    S("gia", "6.3 keeps side_sweep under another name from import time and calls it",
      "6.3 is the library's work (past the guard): no points", {"6.3": (0.0, 0.1)}, T3='''\
from snakekit import side_sweep as make_sweep

def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    return make_sweep(points=points, rate=rate, sweeps=sweeps, amplitude=amplitude)
'''),
    S("hugo", "6.1 copies the check's worked numbers; otherwise 10 Hz whatever the rate",
      "6.1 right only at 10 Hz; 6.3 keeps what it adds", {"6.1": (0.0, 0.2), "6.3": (0.5, 1.0)}, T1='''\
def sweep_times(points, rate):
    if points == 4:
        return np.array([0.0, 0.1, 0.2, 0.3])
    return np.arange(points) * 0.1
'''),
]

CORRECT = ["ana", "ben", "cleo", "dev", "eli", "fay"]
SLIPS = [s.name for s in STUDENTS if s.single_slip]
_SLIPS_BEFORE_63 = ["gil", "hal", "lea", "max", "nia", "oli", "ray", "sam", "uma"]   # in 6.1 or 6.2
_SLIPS_IN_63 = ["ian", "jo", "kim", "tia", "vic", "wes", "xan"]

PAIRS = (
    [Pair(c, s.name, "a right solution scores at least as much as any other") for c in CORRECT
     for s in STUDENTS if s.name not in CORRECT]
    + [Pair(s, "yara", "all four written with one slip scores more than stopping after 6.2", strict=True)
       for s in SLIPS]
    + [Pair(s, "zed", "one slip in 6.1/6.2 (6.3 and 6.4 right) is more than skipping 6.1 and 6.2")
       for s in _SLIPS_BEFORE_63]
    + [Pair(s, "fin", "an honest 6.3 with one slip is more than a stored library result", strict=True)
       for s in _SLIPS_IN_63 if s != "xan"]
    + [Pair("xan", "fin", "xan's task2_sweep answers Task 2 itself and no other case, as fin's stored sweep does: "
            "an honest slip is not less, but the hidden cases cannot tell the two apart")]
    + [Pair("abe", "zed", "6.2 written is more than 6.2 skipped", strict=True),
       Pair("bea", "yara", "6.3 written is more than stopping after 6.2", strict=True),
       Pair("yara", "dot", "6.2 written is more than 6.1 alone", strict=True),
       Pair("dot", "cal", "6.1 written is more than nothing", strict=True),
       Pair("eve", "yara", "6.4 written is more than stopping after 6.2"),
       Pair("fin", "yara", "6.4 written is more than stopping after 6.2")]
)
