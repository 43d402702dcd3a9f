"""Judging a hand-in: the hidden cases, the comparisons, the rules, the references, the verdicts."""
