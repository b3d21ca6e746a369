"""Fidelity judged by sound statistics: per scenario, a two-sample test of the simulated against the field
landing errors, corrected for the number of scenarios, and the area validation metric beside its sampling
floor; over the scenarios, Spearman's rank correlation of the means beside its noise ceiling.

- **Test:** Mann-Whitney U, two-sided (scipy), of the simulated against the field errors (and landing times);
  Holm's step-down correction across the scenarios keeps the family-wise error at `ALPHA`. A scenario is
  "rejected" when its adjusted p is below `ALPHA`, else "consistent".
- **Area metric** (Ferson, Oberkampf and Ginzburg 2008): the area between the two empirical CDFs, in cm (for
  one dimension the Wasserstein-1 distance), split into over-prediction (where the simulated errors lie
  above the field's: the simulation is pessimistic) and under-prediction.
- **Its sampling floor:** what a perfect model scores against as many field draws: the area between the
  simulated ECDF and that of `n_field` values drawn from the simulated trials themselves, median and 95th
  percentile over `FLOOR_DRAWS` seeded draws.
- **Spearman's rho** over the scenarios' mean errors, beside its noise ceiling: each scenario's field
  trials resampled against the observed field means (what a simulator whose means were the field's true
  means would reach), median and 5th percentile over `CEILING_DRAWS` seeded resamples.
- **Success rates** with Clopper-Pearson 95 % intervals.

The min..max of the field trials stays a column of the fidelity table, not a verdict: with ten field trials
a scenario's range says little about a model either way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

ALPHA = 0.05  # family-wise error across the scenarios of one report
FLOOR_DRAWS = 2000
CEILING_DRAWS = 2000
SEED = 2020  # the floors and ceilings are resampled with a fixed seed: a report is the same every time
# The sources judged against the field, each in a section of its own, and how its section names it.
WITNESSES = {"sim": "the embedded simulator", "sitl": "ArduPilot SITL"}


def mann_whitney_p(a: Sequence[float], b: Sequence[float]) -> float | None:
    """Two-sided Mann-Whitney U p-value of `a` against `b`; None when either has no values."""
    if not a or not b:
        return None
    from scipy.stats import mannwhitneyu

    return float(mannwhitneyu(list(a), list(b), alternative="two-sided").pvalue)


def holm(pvalues: Mapping[str, float]) -> dict[str, float]:
    """Holm's step-down adjusted p-values (monotone, at most 1), by the same keys."""
    ordered = sorted(pvalues.items(), key=lambda item: item[1])
    m, running, adjusted = len(ordered), 0.0, {}
    for rank, (key, p) in enumerate(ordered):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[key] = running
    return adjusted


@dataclass(frozen=True)
class Area:
    """The area between two ECDFs (cm): `total` = `over` + `under`; `over`: where the simulated errors lie
    above the field's (its CDF below theirs), `under`: where they lie below."""

    total: float
    over: float
    under: float


def _ecdf(values: np.ndarray, at: np.ndarray) -> np.ndarray:
    return np.searchsorted(np.sort(values), at, side="right") / len(values)


def area_metric(simulated: Sequence[float], field: Sequence[float]) -> Area:
    """The area validation metric between the simulated and the field values (exact: the ECDFs are steps)."""
    sim, obs = np.asarray(simulated, float), np.asarray(field, float)
    points = np.unique(np.concatenate([sim, obs]))
    if len(points) < 2:
        return Area(0.0, 0.0, 0.0)
    widths = np.diff(points)
    gap = _ecdf(obs, points[:-1]) - _ecdf(sim, points[:-1])  # > 0: the simulated CDF lags, its errors larger
    over, under = (float(side) for side in _over_under(gap, widths))
    return Area(over + under, over, under)


def _over_under(gap: np.ndarray, widths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The areas where `gap` (field ECDF minus simulated, over the last axis) is positive and negative."""
    return np.sum(np.clip(gap, 0, None) * widths, axis=-1), np.sum(np.clip(-gap, 0, None) * widths, axis=-1)


def area_floor(simulated: Sequence[float], n_field: int, rng: np.random.Generator,
               draws: int = FLOOR_DRAWS) -> tuple[float, float]:
    """(median, 95th percentile) of the area a perfect model scores against `n_field` field values."""
    sim = np.asarray(simulated, float)
    resampled = np.array([rng.choice(sim, size=n_field, replace=True) for _ in range(draws)])
    areas = _areas_against_resamples(sim, resampled)
    return float(np.median(areas)), float(np.percentile(areas, 95))


def _areas_against_resamples(sim: np.ndarray, resampled: np.ndarray) -> np.ndarray:
    """`area_metric(sim, row).total` for each row of `resampled` (values drawn from `sim`), all at once: the
    rows' values are among `sim`'s, so every ECDF steps at `sim`'s distinct values."""
    points = np.unique(sim)
    if len(points) < 2:
        return np.zeros(len(resampled))
    widths = np.diff(points)
    rows, n = resampled.shape
    at = np.searchsorted(points, resampled)  # each value's step
    counts = np.bincount((np.arange(rows)[:, None] * len(points) + at).ravel(), minlength=rows * len(points))
    ecdf_rows = np.cumsum(counts.reshape(rows, len(points)), axis=1)[:, :-1] / n
    over, under = _over_under(ecdf_rows - _ecdf(sim, points[:-1]), widths)
    return over + under


def spearman(a: Sequence[float], b: Sequence[float]) -> float:
    """Spearman's rho; NaN when either side is constant (no ranking to compare)."""
    from scipy.stats import spearmanr

    if len(set(a)) < 2 or len(set(b)) < 2:
        return math.nan
    return float(spearmanr(list(a), list(b)).statistic)


def spearman_ceiling(field_groups: Sequence[Sequence[float]], rng: np.random.Generator,
                     draws: int = CEILING_DRAWS) -> tuple[float, float]:
    """(median, 5th percentile) of Spearman's rho between resampled and observed field means: the most a
    simulator can reach against these field trials, however right it is."""
    from scipy.stats import rankdata

    groups = [np.asarray(g, float) for g in field_groups]
    observed = np.array([float(g.mean()) for g in groups])
    means = np.array([[float(rng.choice(g, size=len(g), replace=True).mean()) for g in groups]
                      for _ in range(draws)])
    if len(set(observed)) < 2:
        return math.nan, math.nan
    varying = np.ptp(means, axis=1) > 0  # a constant row has no ranking (spearman's NaN)
    if not varying.any():  # the field means tie whatever is resampled: no ranking to reach
        return math.nan, math.nan
    # Spearman's rho is Pearson's r of the average ranks, row by row.
    ranks = rankdata(means[varying], axis=1)
    ranked = rankdata(observed)
    ranks -= ranks.mean(axis=1, keepdims=True)
    ranked -= ranked.mean()
    rhos = ranks @ ranked / np.sqrt(np.sum(ranks ** 2, axis=1) * np.sum(ranked ** 2))
    return float(np.median(rhos)), float(np.percentile(rhos, 5))


def clopper_pearson(successes: int, trials: int, *, confidence: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) interval of a success rate."""
    from scipy.stats import beta

    tail = (1.0 - confidence) / 2.0
    low = 0.0 if successes == 0 else float(beta.ppf(tail, successes, trials - successes + 1))
    high = 1.0 if successes == trials else float(beta.ppf(1.0 - tail, successes + 1, trials - successes))
    return low, high


@dataclass(frozen=True, kw_only=True)
class ScenarioTest:
    """One scenario's verdicts and measures (see the module)."""

    scenario: str
    sim_n: int
    field_n: int
    p: float
    holm_p: float
    area: Area
    floor_median: float
    floor_p95: float
    time_p: float | None
    time_holm_p: float | None
    sim_time_median_s: float | None  # the landed trials' median landing time (s); None without times
    field_time_median_s: float | None
    sim_landed: int
    sim_trials: int

    @property
    def verdict(self) -> str:
        return "rejected" if self.holm_p < ALPHA else "consistent"

    @property
    def time_verdict(self) -> str:
        return "" if self.time_holm_p is None else ("rejected" if self.time_holm_p < ALPHA else "consistent")


def scenario_tests(summaries, *, source: str = "sim") -> list[ScenarioTest]:
    """The tests of every scenario of `source` (sim, sitl) with published trials (`report.ScenarioSummary`), in
    order; Holm's correction runs over that source's scenarios."""
    rng = np.random.default_rng(SEED)
    chosen = [s for s in summaries if s.source == source and s.published and s.errors_cm()]
    ps = {s.scenario: mann_whitney_p(s.errors_cm(), [p.error_cm for p in s.published]) for s in chosen}
    times, medians = {}, {}
    for s in chosen:
        field_times = [p.landing_time_s for p in s.published if p.landing_time_s is not None]
        sim_times = [t["landing_time_s"] for t in s.landed if t.get("landing_time_s") is not None]
        times[s.scenario] = mann_whitney_p(sim_times, field_times)
        medians[s.scenario] = (float(np.median(sim_times)) if sim_times else None,
                               float(np.median(field_times)) if field_times else None)
    adjusted = holm(ps)
    time_adjusted = holm({k: v for k, v in times.items() if v is not None})
    tests = []
    for s in chosen:
        field = [p.error_cm for p in s.published]
        floor = area_floor(s.errors_cm(), len(field), rng)
        tests.append(ScenarioTest(scenario=s.scenario, sim_n=len(s.errors_cm()), field_n=len(field),
                                  p=ps[s.scenario], holm_p=adjusted[s.scenario],
                                  area=area_metric(s.errors_cm(), field), floor_median=floor[0], floor_p95=floor[1],
                                  time_p=times[s.scenario], time_holm_p=time_adjusted.get(s.scenario),
                                  sim_time_median_s=medians[s.scenario][0],
                                  field_time_median_s=medians[s.scenario][1], sim_landed=len(s.landed),
                                  sim_trials=len(s.trials)))
    return tests


def verdicts_section(summaries) -> str:
    """The report's per-scenario tests and the rank correlation (Markdown), one part per witness with trials
    (the embedded simulator, ArduPilot SITL); empty without published trials."""
    return "".join(_verdicts(summaries, source) for source in WITNESSES)


def _verdicts(summaries, source: str) -> str:
    tests = scenario_tests(summaries, source=source)
    if not tests:
        return ""

    def p(value: float | None) -> str:
        return "-" if value is None else (f"{value:.3f}" if value >= 0.001 else "<0.001")

    header = ("Scenario", "Sim n", "Field n", "Error p (MWU)", "Holm p", "Verdict", "Area (cm)",
              "Over / under (cm)", "Perfect model's area: median (95th) (cm)", "Time Holm p", "Time verdict",
              "Sim landed (95 % CI)")
    title = "### Tests per scenario" + ("" if source == "sim" else f": {WITNESSES[source]}")
    lines = ["", title, "",
             f"Each scenario's landing errors on {WITNESSES[source]} against its published trials: a two-sided "
             f"Mann-Whitney U test, Holm-corrected across these {len(tests)} scenarios to a {ALPHA:.0%} "
             "family-wise error (rejected: the adjusted p is below that). Area: the area between the two "
             "empirical CDFs (over: the simulated errors lie above the field's), beside what a perfect model "
             "scores against as many field draws. Landing times are tested the same way. Landed: the simulated "
             "trials that landed, with the Clopper-Pearson 95 % interval.", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for t in tests:
        low, high = clopper_pearson(t.sim_landed, t.sim_trials)
        lines.append("| " + " | ".join((
            t.scenario, str(t.sim_n), str(t.field_n), p(t.p), p(t.holm_p), t.verdict, f"{t.area.total:.1f}",
            f"{t.area.over:.1f} / {t.area.under:.1f}", f"{t.floor_median:.1f} ({t.floor_p95:.1f})",
            p(t.time_holm_p), t.time_verdict or "-",
            f"{t.sim_landed}/{t.sim_trials} ({low:.0%}..{high:.0%})")) + " |")
    rejected = [t.scenario for t in tests if t.verdict == "rejected"]
    lines += ["", f"{len(tests) - len(rejected)} of {len(tests)} scenarios consistent with the field"
              + (f"; rejected: {'; '.join(rejected)}." if rejected else ".")]
    failures = {s.scenario: s.failures for s in summaries if s.source == source}
    if source == "sim" and any("random:" in failures.get(scenario, "") for scenario in rejected):
        lines += ["", "Random drops: the field trials lost more to them than the embedded autopilot does, and "
                      "neither ArduCopter 4.6.3 nor a 2020 ArduCopter (master of 15 October 2020) flying the same "
                      "world on SITL loses as much (`benchmarks/drop_cost_witnesses.py`). What made the "
                      "thesis' drone lose more has no source; it is not modelled, and nothing is fitted to it."]
    lines += _time_directions(tests)
    chosen = [s for s in summaries if s.source == source and s.published and s.errors_cm()]
    if len(chosen) >= 3:
        rho = spearman([float(np.mean(s.errors_cm())) for s in chosen],
                       [float(np.mean([p.error_cm for p in s.published])) for s in chosen])
        median, low = spearman_ceiling([[p.error_cm for p in s.published] for s in chosen],
                                       np.random.default_rng(SEED))
        if math.isnan(rho) or math.isnan(median):
            lines += ["", f"Spearman's rank correlation of the {len(chosen)} scenarios' mean errors: undefined "
                          "(the means tie)."]
        else:
            lines += ["", f"Spearman's rank correlation of the {len(chosen)} scenarios' mean errors, simulated "
                          f"against field: {rho:.3f}; its noise ceiling (the field's trials resampled against their "
                          f"own means): median {median:.3f}, 5th percentile {low:.3f}."]
    return "\n".join(lines) + "\n"


def _time_directions(tests: Sequence[ScenarioTest]) -> list[str]:
    """A paragraph when the rejected landing times lie on both sides of the field's: a descent speed
    (LAND_SPEED) moves every land mode's time the same way, so it cannot bring both sides in."""
    rejected = [t for t in tests if t.time_verdict == "rejected"]
    shorter = [t.scenario for t in rejected if t.sim_time_median_s < t.field_time_median_s]
    longer = [t.scenario for t in rejected if t.sim_time_median_s > t.field_time_median_s]
    if not (shorter and longer):
        return []
    return ["", f"Landing times: rejected in {len(rejected)} scenarios, shorter than the field's in "
                f"{len(shorter)} ({'; '.join(shorter)}) and longer in {len(longer)} ({'; '.join(longer)}). A "
                "descent speed (LAND_SPEED) moves every land mode's time the same way, so none brings both "
                "sides in; where the source does not say where its landing time starts and stops (the thesis "
                "does not), the times are compared as given, and nothing is fitted to them (docs: departures)."]
