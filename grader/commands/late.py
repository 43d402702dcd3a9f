"""Late penalties by rule, per assignment: nbgrader's late-submission plug-in as ``snakekit release`` writes it.

    per-hour:1      1 point off per started hour late
    per-day:10%     10 % of the notebook's score off per started day late
    zero            a late notebook scores 0
    none            no penalty (late work is marked, not penalised)

``snakekit release A --late-penalty RULE`` puts the rule into the course's ``nbgrader_config.py``
(``c.LatePenalty.rules = {"A": "RULE"}``) with this plug-in as ``AssignLatePenalties.plugin_class``;
nbgrader's ``AssignLatePenalties`` (in ``snakekit grade`` as in its own autograde) then asks
:meth:`LatePenalty.late_submission_penalty` for each late notebook, and caps the penalty at the
notebook's score. An assignment without a rule falls back to nbgrader's
``LateSubmissionPlugin.penalty_method``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from nbgrader.plugins import LateSubmissionPlugin
from traitlets import Dict

from grader.errors import LateRuleError

#: Seconds in each unit a rule may count in.
UNITS = {"minute": 60, "hour": 3600, "day": 86400, "week": 7 * 86400}
_RULE = re.compile(r"per-(?P<unit>[a-z]+):(?P<amount>[^%]+)(?P<percent>%?)")
EXAMPLES = "per-hour:1, per-day:10%, zero or none"


@dataclass(frozen=True)
class LateRule:
    """How much a late notebook loses: ``amount`` points (or percent of its score, when
    ``percent``) per started ``unit`` late, or all of it (``zero``), or nothing (``none``)."""

    kind: str  # "per", "zero" or "none"
    unit: str = ""
    amount: float = 0.0
    percent: bool = False

    def penalty(self, score: float, seconds_late: float) -> float:
        """Points off a notebook that scored ``score`` and came ``seconds_late`` [s] after the due date."""
        if seconds_late <= 0 or self.kind == "none":
            return 0.0
        if self.kind == "zero":
            return float(score)
        started = math.ceil(seconds_late / UNITS[self.unit])
        each = float(score) * self.amount / 100 if self.percent else self.amount
        return min(float(score), round(started * each, 6))

    def describe(self) -> str:
        if self.kind == "zero":
            return "a late notebook scores 0"
        if self.kind == "none":
            return "no late penalty (late work is marked only)"
        each = f"{self.amount:g} % of its score" if self.percent else f"{self.amount:g} point(s)"
        return f"{each} off per started {self.unit} late"


def parse(text: str) -> LateRule:
    """The rule ``text`` says (see the module's table); a :class:`LateRuleError` saying the forms if it is none."""
    raw = str(text).strip().lower()
    if raw in ("zero", "none"):
        return LateRule(raw)
    m = _RULE.fullmatch(raw)
    bad = f"--late-penalty {str(text)[:80]!r} is not a rule; give one of {EXAMPLES}"
    if not m:
        raise LateRuleError(bad)
    if m["unit"] not in UNITS:
        raise LateRuleError(f"--late-penalty {str(text)[:80]!r}: no unit '{m['unit']}'; give per-{', per-'.join(UNITS)} "
                            f"(e.g. {EXAMPLES})")
    try:
        amount = float(m["amount"])
    except ValueError:
        raise LateRuleError(bad) from None
    percent = bool(m["percent"])
    if not (math.isfinite(amount) and amount > 0) or (percent and amount > 100):
        raise LateRuleError(f"--late-penalty {str(text)[:80]!r}: the amount must be a number above 0"
                            + (" and at most 100 %" if percent else " (points)") + f"; e.g. {EXAMPLES}")
    return LateRule("per", m["unit"], amount, percent)


class LatePenalty(LateSubmissionPlugin):
    """nbgrader's late-submission plug-in with a rule per assignment (``c.LatePenalty.rules``)."""

    rules = Dict(default_value={}, help="The late-penalty rule of each assignment, by name, as `snakekit release "
                 f"--late-penalty` writes it ({EXAMPLES})").tag(config=True)

    def late_submission_penalty(self, student_id, score, total_seconds_late):
        assignment = getattr(self.parent, "assignment_id", None)  # AssignLatePenalties sets it before asking
        if assignment in self.rules:
            return parse(self.rules[assignment]).penalty(float(score or 0.0), float(total_seconds_late))
        return super().late_submission_penalty(student_id, score, total_seconds_late)
