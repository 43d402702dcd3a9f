"""How a value that is not close enough to the expected one is judged and named: one rule and one
wording, for the notebook's check (:meth:`snakekit.checks.Exercise.close`) and the grader's hidden cases
(``grader.scoring.score``), so a student who reads both messages of one mistake reads the same entry in
the same words.

Which entry a message names (:func:`worst`): of the entries beyond their tolerance, the one furthest
from its expected value, ``|got - expected|`` in the value's own numbers (the first of equals, in reading
order: a time vector that starts one step late is named at its first entry). That is the entry a student learns most from: the first wrong entry is often a rounding-sized
slip while the real mistake sits further on (a last row that is not home, a heading not accumulated),
and an entry far off is seldom a tolerance question. The one exception is a table of rows read from the
top (a row's columns named: 4.4's ``violations`` of time, joint and kind): a row missed or one too many
shifts every row after it, so its first wrong row is the cause, and that is the one named.

>>> import numpy as np
>>> got, want = np.array([1.0, 2.0 + 3e-9, 3.5]), np.array([1.0, 2.0, 3.0])
>>> b = bound(want, atol=0.0, rtol=1e-9)
>>> worst(got, want, b)
(2,)
>>> print(sentence("send times[2]", got[2], want[2], b[2], "s", atol=1e-12, rtol=1e-9))
send times[2] is 3.5 s, expected 3 s: off by 0.5 s (tolerance 3e-09 s: exact math, 1e-9 relative).
"""

from __future__ import annotations

import numpy as np

__all__ = ["TIE", "ZERO", "bound", "entry_name", "is_table", "not_finite", "per_row", "sentence", "tolerance", "unit_of",
           "worst"]

#: The absolute floor of every closeness check [unit of the value]: a result within it of the
#: expected one passes (a last row of 3.9e-16 where the text asks exactly 0), locally as graded.
ZERO = 1e-12


#: How close two differences are to count as equal when choosing the entry to name (relative): a time vector
#: shifted by one step is off by the same step everywhere, give or take rounding, and its first entry is named.
TIE = 1e-9


def bound(expected, *, atol: float, rtol: float) -> np.ndarray:
    """The tolerance of each entry of ``expected``: ``atol + rtol * |expected|``, never below :data:`ZERO`; an
    ``atol`` at or below :data:`ZERO` is that floor itself (a check that gives no ``atol`` and the grader's
    default of :data:`ZERO` judge alike, and say the same tolerance)."""
    atol = float(atol) if atol > ZERO else 0.0
    return np.maximum(atol + rtol * np.abs(np.asarray(expected, dtype=float)), ZERO)


def is_table(labels, shape: tuple) -> bool:
    """Whether a value of ``shape`` with column ``labels`` is a table of rows (one label per column)."""
    return labels is not None and len(shape) == 2 and len(labels) == shape[1]


def worst(got, expected, tol, *, table: bool = False) -> tuple | None:
    """The index of the entry a message names (see the module's docstring), None when every entry is within
    its tolerance ``tol`` (an array like ``expected``). ``table``: a table of rows, named by its first wrong entry.

    >>> worst(np.array([[0.0, 9.0], [5.0, 1.0]]), np.zeros((2, 2)), np.full((2, 2), 1e-9))
    (0, 1)
    >>> worst(np.array([[0.0, 9.0], [5.0, 1.0]]), np.zeros((2, 2)), np.full((2, 2), 1e-9), table=True)
    (0, 1)
    >>> worst(np.array([[0.0, 0.0], [5.0, 1.0]]), np.zeros((2, 2)), np.full((2, 2), 1e-9), table=True)
    (1, 0)
    >>> worst(np.arange(1, 418) / 63.2, np.arange(417) / 63.2, np.full(417, 1e-9))   # one step late throughout
    (0,)
    """
    g, e = np.asarray(got, dtype=float), np.asarray(expected, dtype=float)
    diff = np.abs(g - e)
    wrong = ~(diff <= tol)
    if not wrong.any():
        return None
    if not table:   # the first of the entries furthest off, equal past floating-point rounding
        far = np.where(wrong, diff, -1.0)
        wrong = far >= far.max() * (1 - TIE)
    return tuple(int(k) for k in np.argwhere(wrong)[0])


#: Words that make a value's name a phrase ("Jacobian of g", "tool after move 2"): an index written straight after it
#: would read as indexing its last word ("g[2, 2]"), so the entry is named before it ("entry [2, 2] of Jacobian of g").
_LINKING = {"of", "in", "at", "after", "for", "to", "from", "on", "by", "with"}


def _plain(what: str) -> bool:
    """Whether ``what`` is a plain name that an index or a label may follow ("send times", "tool")."""
    words = what.split()
    return bool(words) and all(w.isalpha() or w.replace("-", "").replace("_", "").isalpha() for w in words) \
        and not _LINKING & {w.lower() for w in words}


def entry_name(what: str, index: tuple, ndim: int, labels=None) -> str:
    """The entry at ``index`` as both messages name it: ``tool heading`` (a labelled 1-D value),
    ``violations[2] joint`` (a table's row and column), ``send times[3]``, or ``what`` for a single number. A
    name that is a phrase (a number in it, brackets, "of": what an index after it would seem to index) has
    the entry named before it: ``entry [2, 2] of Jacobian of g``, ``x of tip of solution 1``.

    >>> entry_name("tool", (2,), 1, ("x", "y", "heading")), entry_name("violations", (2, 1), 2, ("time", "joint"))
    ('tool heading', 'violations[2] joint')
    >>> entry_name("Jacobian", (1, 3), 2), entry_name("reach", (), 0)
    ('Jacobian[1, 3]', 'reach')
    >>> entry_name("Jacobian of g", (2, 2), 2), entry_name("Jacobian row 3 (the heading)", (0,), 1)
    ('entry [2, 2] of Jacobian of g', 'entry [0] of Jacobian row 3 (the heading)')
    >>> entry_name("tip of solution 1", (0,), 1, ("x", "y")), entry_name("lag of joint 3", (), 0)
    ('x of tip of solution 1', 'lag of joint 3')
    """
    if not index or ndim == 0:
        return what
    plain = _plain(what)
    if labels is not None and ndim == 1 and index[0] < len(labels):
        return f"{what} {labels[index[0]]}" if plain else f"{labels[index[0]]} of {what}"
    if labels is not None and ndim == 2 and index[1] < len(labels):
        return f"{what}[{int(index[0])}] {labels[index[1]]}" if plain else \
            f"{labels[index[1]]} of row {int(index[0])} of {what}"
    at = ", ".join(str(int(k)) for k in index)
    return f"{what}[{at}]" if plain else f"entry [{at}] of {what}"


class per_row(tuple):
    """The units of a matrix's rows, one per row (a check's ``unit=``): a Jacobian's position rows in m (per
    rad), its heading row in rad/rad. A plain tuple of units names a value's entries, or a table's columns.

    >>> unit_of(per_row("m", "m", "rad/rad"), (2, 0)), unit_of(("m", "m", "rad"), (0, 2)), unit_of("s", (4,))
    ('rad/rad', 'rad', 's')
    """

    def __new__(cls, *units):
        return super().__new__(cls, units)


def unit_of(unit, index: tuple) -> str:
    """The unit of the entry at ``index`` of a value whose check gives ``unit``: one unit for every entry, one
    per entry of its last axis (a tuple), or one per row (:class:`per_row`)."""
    if isinstance(unit, per_row):
        return unit[index[0]] if index and index[0] < len(unit) else ""
    if isinstance(unit, (tuple, list)):
        return unit[index[-1]] if index and index[-1] < len(unit) else ""
    return unit or ""


def not_finite(what: str, value, where: str = "") -> str:
    """The sentence of a value that holds nan or infinity, locally and graded: its first such entry, named as
    :func:`entry_name` names it (a single number: the value itself).

    >>> not_finite("manipulability", np.float64("nan"), " at q=[0, 0, 0, 0, 0]")
    'manipulability at q=[0, 0, 0, 0, 0] is nan: every value must be a finite number.'
    >>> not_finite("Jacobian", np.array([[0.0, np.inf]]))
    'Jacobian[0, 1] is inf: every value must be a finite number.'
    """
    arr = np.asarray(value, dtype=float)
    idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0]) if arr.ndim else ()
    return f"{entry_name(what, idx, arr.ndim)}{where} is {arr[idx]}: every value must be a finite number."


# --- numbers in messages -----------------------------------------------------------------


def number(v: float, unit: str) -> str:
    """A value with its unit, to 4 significant digits (3 below 1e-3)."""
    s = f"{v:.4g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.3g}"
    return f"{s} {unit}".rstrip()


def pair(got: float, want: float, unit: str) -> tuple[str, str]:
    """A value and the expected one, with as many digits as it takes to tell them apart.

    >>> pair(0.30000001, 0.3, "m")
    ('0.30000001 m', '0.3 m')
    """
    a, b = number(got, unit), number(want, unit)
    digits = 5
    while a == b and got != want and digits <= 17:
        a, b = (f"{x:.{digits}g} {unit}".rstrip() for x in (got, want))
        digits += 1
    return a, b


def difference(d: float, unit: str) -> str:
    """A difference as a student reads it: metres as millimetres, radians also in degrees."""
    if unit == "m":
        return f"{d * 1000:.4g} mm"
    if unit == "rad":
        return f"{d:.4g} rad ({np.degrees(d):.3g} deg)"
    return number(d, unit)


def tolerance(at: float, unit: str, *, atol: float, rtol: float, why: str | None = None) -> str:
    """The tolerance of an entry (``at``, from :func:`bound`) and where it comes from: ``why``, in the lesson's
    words, else exact math with its relative and absolute parts (the floor :data:`ZERO`, everyone's, unsaid).

    >>> tolerance(3e-10, "m", atol=0.0, rtol=1e-9), tolerance(1e-6, "", atol=1e-6, rtol=0.0, why="finite differences")
    ('3e-07 mm: exact math, 1e-9 relative', '1e-06: finite differences')
    >>> tolerance(1e-12, "", atol=0.0, rtol=0.0)
    '1e-12: exact math'
    """
    text = f"{difference(float(at), unit)}: {why or 'exact math'}"
    if why is None:
        parts = ([f"{rtol:g}".replace("e-0", "e-") + " relative"] if rtol else []) + \
                ([difference(atol, unit)] if atol > ZERO else [])
        text += ", " + " + ".join(parts) if parts else ""
    return text


def sentence(name: str, got: float, want: float, at: float, unit: str, *, atol: float, rtol: float,
             why: str | None = None, where: str = "") -> str:
    """The one sentence of a wrong entry, locally and graded: ``name`` (:func:`entry_name`), ``where`` (the
    inputs, when the message has not said them before), the value, the expected value, how far off, and the
    tolerance ``at`` that entry (:func:`tolerance`)."""
    shown, wanted = pair(float(got), float(want), unit)
    return (f"{name}{where} is {shown}, expected {wanted}: off by {difference(abs(float(got) - float(want)), unit)} "
            f"(tolerance {tolerance(at, unit, atol=atol, rtol=rtol, why=why)}).")
