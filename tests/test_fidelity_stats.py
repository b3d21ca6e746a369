"""The fidelity statistics, each against a case computed by hand, and the report's verdicts on seeded data."""

import math
from dataclasses import replace

import numpy as np
import pytest

from preland_app.campaign.fidelity import wasserstein
from preland_app.campaign.fidelity_tests import (Area, area_floor, area_metric, clopper_pearson, holm,
                                                 mann_whitney_p, scenario_tests, spearman, spearman_ceiling,
                                                 verdicts_section)
from preland_app.campaign.report import PublishedTrial, ScenarioSummary


def test_holm_steps_down_and_stays_monotone():
    # Sorted 0.01, 0.03, 0.04 times 3, 2, 1: 0.03, 0.06, 0.04 -> monotone: 0.03, 0.06, 0.06.
    assert holm({"a": 0.01, "b": 0.04, "c": 0.03}) == pytest.approx({"a": 0.03, "b": 0.06, "c": 0.06})
    assert holm({"a": 0.6, "b": 0.7}) == {"a": 1.0, "b": 1.0}  # capped at 1


def test_the_area_metric_splits_over_and_under_prediction_as_computed_by_hand():
    # Simulated 0.5, 7, 9 against field 1, 1, 2, 40. Between the sorted points the field's ECDF minus the
    # simulated: [0.5,1) -1/3 (width 0.5), [1,2) +1/6 (1), [2,7) +5/12 (5), [7,9) +1/12 (2), [9,40) -1/4 (31).
    # Over (simulated CDF below the field's: its errors larger): 1/6 + 25/12 + 1/6 = 29/12.
    # Under: 1/6 + 31/4 = 95/12. Total 124/12, which is the Wasserstein-1 distance.
    area = area_metric([0.5, 7, 9], [1, 1, 2, 40])
    assert area == Area(total=pytest.approx(124 / 12), over=pytest.approx(29 / 12), under=pytest.approx(95 / 12))
    assert area.total == pytest.approx(wasserstein([0.5, 7, 9], [1, 1, 2, 40]))
    assert area_metric([1, 2, 3], [2, 3, 4]) == Area(1.0, 0.0, 1.0)  # simulated one lower everywhere: under


def test_a_perfect_models_floor_is_what_sampling_alone_gives():
    assert area_floor([5.0, 5.0, 5.0], 10, np.random.default_rng(1)) == (0.0, 0.0)
    sim = np.random.default_rng(2).normal(10, 2, 400)
    median, p95 = area_floor(sim, 10, np.random.default_rng(3), draws=500)
    # A sample of 10 from a normal of sd 2: its ECDF lies about 0.5 cm (in area) from the parent's.
    assert 0.3 < median < 1.0 < p95 < 2.0
    # All draws at once give what area_metric gives draw by draw, on the same draws (ties included).
    tied = np.round(sim[:60], 0)
    rng = np.random.default_rng(4)
    one_by_one = [area_metric(tied, rng.choice(tied, size=7, replace=True)).total for _ in range(300)]
    assert area_floor(tied, 7, np.random.default_rng(4), draws=300) == pytest.approx(
        (np.median(one_by_one), np.percentile(one_by_one, 95)), rel=1e-12)


def test_mann_whitney_and_clopper_pearson_match_their_closed_forms():
    # U = 0 of 3 against 3: the exact two-sided p is 2 / C(6, 3) = 0.1.
    assert mann_whitney_p([1, 2, 3], [4, 5, 6]) == pytest.approx(0.1)
    assert mann_whitney_p([], [1.0]) is None
    # All of n: the lower end is (alpha / 2) ** (1 / n); none of n: the upper end is 1 minus that.
    assert clopper_pearson(10, 10) == pytest.approx((0.025 ** 0.1, 1.0))
    assert clopper_pearson(0, 10) == pytest.approx((0.0, 1 - 0.025 ** 0.1))
    low, high = clopper_pearson(5, 10)
    assert low == pytest.approx(0.1871, abs=1e-4) and high == pytest.approx(0.8129, abs=1e-4)


def test_spearman_and_its_ceiling():
    assert spearman([1, 2, 3, 4], [10, 30, 20, 40]) == pytest.approx(0.8)
    apart = [[1.0, 1.1, 0.9], [10.0, 10.5, 9.5], [100.0, 101.0, 99.0]]
    assert spearman_ceiling(apart, np.random.default_rng(0), draws=200) == (1.0, 1.0)  # means never swap
    close = [[1.0, 5.0, 9.0], [2.0, 6.0, 10.0], [3.0, 7.0, 11.0]]
    median, low = spearman_ceiling(close, np.random.default_rng(0), draws=500)
    assert low < median <= 1.0 and low < 0.5  # overlapping scenarios: resampled ranks often swap
    assert all(math.isnan(v) for v in spearman_ceiling([[5.0], [5.0], [5.0]], np.random.default_rng(0), draws=5))
    # All draws at once give what spearman gives draw by draw, on the same draws; a draw whose means tie
    # throughout has no ranking and is left out, as spearman's NaN is.
    groups = [[1.0, 5.0, 9.0], [2.0, 6.0, 10.0], [2.0, 6.0, 10.0], [4.0, 4.0, 4.0]]
    rng = np.random.default_rng(6)
    observed = [float(np.mean(g)) for g in groups]
    rhos = [spearman([float(rng.choice(np.asarray(g), size=3, replace=True).mean()) for g in groups], observed)
            for _ in range(400)]
    rhos = [r for r in rhos if not math.isnan(r)]
    assert spearman_ceiling(groups, np.random.default_rng(6), draws=400) == pytest.approx(
        (np.median(rhos), np.percentile(rhos, 5)), rel=1e-12)


def _summary(label: str, sim_cm, field_cm, *, sim_times=None, field_times=None) -> ScenarioSummary:
    trials = [{"outcome": "landed", "landing_error_cm": e, "landing_time_s": (sim_times or [20.0] * len(sim_cm))[i]}
              for i, e in enumerate(sim_cm)]
    published = [PublishedTrial(error_cm=e, x_cm=None, y_cm=None,
                                landing_time_s=(field_times or [20.0] * len(field_cm))[i])
                 for i, e in enumerate(field_cm)]
    return ScenarioSummary(label=label, index=0, land_mode="irlock", sensor="irlock", failures="none",
                           initial_height_m=10.0, trials=trials, scenario=label, published=published)


def test_the_section_rejects_the_scenario_that_differs_after_holms_correction():
    rng = np.random.default_rng(7)
    same = _summary("same", list(rng.normal(5, 1, 30)), list(rng.normal(5, 1, 10)))
    shifted = _summary("shifted", list(rng.normal(5, 1, 30)), list(rng.normal(15, 1, 10)),
                       field_times=[30.0] * 10)
    tests = {t.scenario: t for t in scenario_tests([same, shifted])}
    assert tests["same"].verdict == "consistent" and tests["shifted"].verdict == "rejected"
    assert tests["shifted"].holm_p == pytest.approx(min(1.0, 2 * tests["shifted"].p))  # the smaller of two
    assert tests["shifted"].area.under > 9.0 and tests["shifted"].area.over == 0.0
    assert tests["shifted"].time_verdict == "rejected" and tests["same"].time_verdict == "consistent"
    text = verdicts_section([same, shifted])
    assert "1 of 2 scenarios consistent with the field; rejected: shifted." in text
    assert "| shifted | 30 | 10 |" in text and "30/30 (88%..100%)" in text
    assert not math.isnan(tests["same"].floor_median)
    # A rejected scenario with random drops: the section says that no witness produces the field's cost.
    assert "Random drops" not in text
    dropping = replace(shifted, failures="irlock random:0.75")
    assert "Random drops: the field trials lost more" in verdicts_section([same, dropping])
    # ArduPilot SITL's trials of the same scenarios: a part of their own, corrected over their own scenarios.
    witness = [replace(same, source="sitl"), replace(shifted, source="sitl")]
    both = verdicts_section([same, shifted, *witness])
    assert both.count("1 of 2 scenarios consistent with the field; rejected: shifted.") == 2
    assert "### Tests per scenario: ArduPilot SITL" in both and both.index("ArduPilot SITL") > both.index("| same |")
    assert [t.scenario for t in scenario_tests([same, *witness], source="sitl")] == ["same", "shifted"]


def test_rejected_landing_times_on_both_sides_of_the_field_are_named_each_side():
    rng = np.random.default_rng(3)
    errors = lambda: (list(rng.normal(5, 1, 30)), list(rng.normal(5, 1, 10)))  # noqa: E731
    slower_field = _summary("slower field", *errors(), sim_times=list(rng.normal(20, 1, 30)),
                            field_times=list(rng.normal(30, 1, 10)))
    faster_field = _summary("faster field", *errors(), sim_times=list(rng.normal(20, 1, 30)),
                            field_times=list(rng.normal(12, 1, 10)))
    same = _summary("same", *errors())
    tests = {t.scenario: t for t in scenario_tests([slower_field, faster_field, same])}
    assert tests["slower field"].sim_time_median_s < tests["slower field"].field_time_median_s
    assert [tests[k].time_verdict for k in ("slower field", "faster field", "same")] == [
        "rejected", "rejected", "consistent"]
    text = verdicts_section([slower_field, faster_field, same])
    assert ("Landing times: rejected in 2 scenarios, shorter than the field's in 1 (slower field) and longer in 1 "
            "(faster field).") in text
    # All on one side: a descent speed could bring them in, and the section says nothing more.
    assert "Landing times:" not in verdicts_section([slower_field, same])

