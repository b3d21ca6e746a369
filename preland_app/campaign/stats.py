"""Spread of a sample and confidence intervals, for reports and comparisons.

The 95 % confidence interval of a mean is a percentile bootstrap (resampling
the trials with replacement), seeded so that a report is the same every time it
is written. With ten trials, as the thesis flew, a bootstrap interval is a little
narrower than a t interval; it makes no assumption of normality, which landing
errors (bounded at zero, skewed) do not meet.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

import numpy as np

BOOTSTRAP_RESAMPLES = 4000
CONFIDENCE = 0.95
REPORT_SEED = 2024  # fixed: the same store gives the same intervals
MIN_VALUES_FOR_CI = 5  # below this a bootstrap interval is little more than the sample's range: none is given


@dataclass(frozen=True)
class Spread:
    """A sample's size, mean, sample standard deviation (None below 2 values), median, min, max and the
    bootstrap confidence interval of the mean (None below MIN_VALUES_FOR_CI values), in the sample's unit."""

    n: int
    mean: float
    sd: float | None
    median: float
    minimum: float
    maximum: float
    ci_low: float | None
    ci_high: float | None


def bootstrap_mean_ci(values: list[float], *, rng: np.random.Generator, resamples: int = BOOTSTRAP_RESAMPLES,
                      confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """Percentile bootstrap interval of the mean; None for fewer than MIN_VALUES_FOR_CI values."""
    if len(values) < MIN_VALUES_FOR_CI:
        return None
    data = np.asarray(values, dtype=float)
    means = data[rng.integers(0, len(data), size=(resamples, len(data)))].mean(axis=1)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return float(low), float(high)


def describe(values: list[float], *, seed: int = REPORT_SEED) -> Spread | None:
    """The spread of `values` (None when empty); the interval is seeded with `seed`."""
    values = [float(v) for v in values if v is not None and math.isfinite(v)]
    if not values:
        return None
    interval = bootstrap_mean_ci(values, rng=np.random.default_rng(seed))
    return Spread(n=len(values), mean=statistics.fmean(values),
                  sd=statistics.stdev(values) if len(values) > 1 else None, median=statistics.median(values),
                  minimum=min(values), maximum=max(values),
                  ci_low=interval[0] if interval else None, ci_high=interval[1] if interval else None)


@dataclass(frozen=True)
class Difference:
    """`after` minus `before`: the difference of means and its bootstrap confidence interval (None when a
    side has fewer than MIN_VALUES_FOR_CI values)."""

    before: Spread
    after: Spread
    difference: float
    ci_low: float | None
    ci_high: float | None

    @property
    def significant(self) -> bool:
        """Whether the interval excludes zero."""
        return self.ci_low is not None and (self.ci_low > 0 or self.ci_high < 0)

    @property
    def intervals_overlap(self) -> bool:
        """Whether the two means' own intervals overlap (both must exist)."""
        b, a = self.before, self.after
        if None in (b.ci_low, b.ci_high, a.ci_low, a.ci_high):
            return True
        return b.ci_low <= a.ci_high and a.ci_low <= b.ci_high


def difference_of_means(before: list[float], after: list[float], *, seed: int = REPORT_SEED,
                        resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE) -> Difference | None:
    """Compare two independent samples (two runs of a scenario): each resampled on its own."""
    spread_before, spread_after = describe(before, seed=seed), describe(after, seed=seed + 1)
    if spread_before is None or spread_after is None:
        return None
    low = high = None
    if min(spread_before.n, spread_after.n) >= MIN_VALUES_FOR_CI:
        rng = np.random.default_rng(seed)
        b = np.asarray([v for v in before if v is not None], dtype=float)
        a = np.asarray([v for v in after if v is not None], dtype=float)
        differences = (a[rng.integers(0, len(a), size=(resamples, len(a)))].mean(axis=1)
                       - b[rng.integers(0, len(b), size=(resamples, len(b)))].mean(axis=1))
        tail = (1.0 - confidence) / 2.0
        low, high = (float(q) for q in np.quantile(differences, [tail, 1.0 - tail]))
    return Difference(before=spread_before, after=spread_after, difference=spread_after.mean - spread_before.mean,
                      ci_low=low, ci_high=high)
