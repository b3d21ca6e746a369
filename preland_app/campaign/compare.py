"""Comparing two campaigns (two stores, or two campaigns of one store): before and after a change.

Scenarios are matched by label and source. Per scenario: each side's mean and
its bootstrap 95 % confidence interval, and the difference of the means (after
minus before) with its own bootstrap interval (`stats.difference_of_means`).
"""

from __future__ import annotations

from dataclasses import dataclass

from .stats import Difference, difference_of_means
from .store import ResultsStore

MEASURES = {"landing_error_cm": "landing error (cm)", "landing_time_s": "landing time (s)"}


@dataclass(frozen=True, kw_only=True)
class ScenarioComparison:
    """One scenario on both sides; `difference` is None when a side has no value of the measure."""

    scenario: str
    source: str
    before_n: int
    after_n: int
    difference: Difference | None


def _values(store: ResultsStore, campaign: str, measure: str) -> dict[tuple[str, str], list[float]]:
    values: dict[tuple[str, str], list[float]] = {}
    order: dict[tuple[str, str], int] = {}
    for trial in store.trials(campaign):
        key = (trial["scenario"], trial["source"])
        order.setdefault(key, trial["scenario_index"])
        bucket = values.setdefault(key, [])
        if trial["outcome"] == "landed" and trial[measure] is not None:
            bucket.append(float(trial[measure]))
    return dict(sorted(values.items(), key=lambda item: order[item[0]]))


def compare(before: tuple[ResultsStore, str], after: tuple[ResultsStore, str], *,
            measure: str = "landing_error_cm") -> list[ScenarioComparison]:
    """Per-scenario comparison of `measure` (a trials column: landing_error_cm, landing_time_s) between the
    (store, campaign) pairs, over the trials that landed; scenarios on one side only have no difference."""
    if measure not in MEASURES:
        raise ValueError(f"measure must be one of {', '.join(MEASURES)}")
    left, right = _values(*before, measure), _values(*after, measure)
    keys = list(left) + [k for k in right if k not in left]
    rows = []
    for key in keys:
        b, a = left.get(key, []), right.get(key, [])
        rows.append(ScenarioComparison(scenario=key[0], source=key[1], before_n=len(b), after_n=len(a),
                                       difference=difference_of_means(b, a)))
    return rows
