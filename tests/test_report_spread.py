"""Reports with spread: mean, sd, median, a seeded bootstrap CI, the published figures with their spread."""

import csv
import statistics

import pytest

from preland_app.campaign.report import csv_table, markdown_table, summarize
from preland_app.campaign.stats import bootstrap_mean_ci, describe, difference_of_means
from preland_app.campaign.store import ResultsStore, TrialRecord

from .conftest import ROOT

REFERENCE_CSV = ROOT / "campaigns" / "reference" / "thesis_field_trials.csv"
SPEC = f"""name: spread
mission: ../missions/thesis_square_land.yaml
scenarios:
  - label: IRLock / none
    land: irlock
    reference: {{avg_error_cm: 5.79, max_error_cm: 13.86, source: "thesis Table 3 (Appendix B)",
                trials_csv: {REFERENCE_CSV}, source_table: 7}}
  - label: Algorithm 2
    land: paper_adaptive
    reference: {{avg_error_cm: 11.0, avg_landing_time_s: 55.0, source: "paper Section 6"}}
  - label: GPS
    land: normal
"""
ERRORS = {"IRLock / none": [1.0, 2.0, 3.0, 4.0, 10.0], "Algorithm 2": [8.0, 12.0, 9.5], "GPS": [60.0, 80.0]}


def published(table, column):
    with REFERENCE_CSV.open() as handle:
        return [float(r[column]) for r in csv.DictReader(handle) if r["source_table"] == str(table)]


def make_store():
    store = ResultsStore(":memory:")
    store.register_campaign(name="spread", spec_hash="h", spec_text=SPEC, source_path=str(ROOT / "campaigns" / "x.yaml"))
    for index, (label, errors) in enumerate(ERRORS.items()):
        mode = {"IRLock / none": "irlock", "Algorithm 2": "paper_adaptive", "GPS": "normal"}[label]
        for trial, error in enumerate(errors):
            details = {}
            if mode == "irlock":
                details = {"attempts": 1 + (trial == 4)}
            if mode == "paper_adaptive":
                details = {"marker_switches": 2 + trial, "recovery_climbs": trial, "aborted_to_gps": trial == 2,
                           "first_detection_altitude_m": 18.0 + trial}
            store.add_trial(TrialRecord(
                campaign="spread", scenario=label, scenario_index=index, trial_index=trial, seed=trial, spec_hash="h",
                result={"outcome": "landed", "message": "ok", "land_mode": mode, "takeoff_altitude_m": 10.0,
                        "landing_error_cm": error, "offset_north_cm": error, "offset_east_cm": 0.0,
                        "landing_time_s": 20.0 + trial, "details": details}))
    store.add_trial(TrialRecord(campaign="spread", scenario="IRLock / none", scenario_index=0, trial_index=0, seed=0,
                                spec_hash="field", source="field", runtime="field",
                                result={"outcome": "landed", "message": "tape", "land_mode": "irlock",
                                        "landing_error_cm": 7.0, "details": {}}))
    return store


def test_spread_numbers_and_a_seeded_interval():
    values = ERRORS["IRLock / none"]
    spread = describe(values)
    assert spread.n == 5 and spread.mean == pytest.approx(4.0) and spread.median == 3.0
    assert spread.sd == pytest.approx(statistics.stdev(values)) and spread.maximum == 10.0
    assert spread.ci_low < spread.mean < spread.ci_high and spread.ci_low >= 1.0 and spread.ci_high <= 10.0
    assert describe(values) == spread  # seeded: the same report every time
    assert describe([3.0]).sd is None and describe([3.0]).ci_low is None and describe([]) is None
    assert describe([3.0, 4.0, 5.0, 6.0]).ci_low is None and describe([3.0, 4.0]).sd is not None
    import numpy as np

    # A large sample's bootstrap interval is close to the normal one: mean +- 1.96 sd / sqrt(n).
    sample = list(np.random.default_rng(5).normal(10.0, 2.0, 400))
    low, high = bootstrap_mean_ci(sample, rng=np.random.default_rng(1))
    half = 1.96 * statistics.stdev(sample) / 20.0
    assert low == pytest.approx(statistics.fmean(sample) - half, abs=0.04)
    assert high == pytest.approx(statistics.fmean(sample) + half, abs=0.04)


def test_difference_of_means_interval():
    same = difference_of_means([1.0, 2.0, 3.0, 4.0, 2.5], [1.5, 2.5, 3.5, 2.0, 3.0])
    assert difference_of_means([1.0, 2.0], [1.0, 2.0, 3.0, 4.0, 5.0]).ci_low is None  # too few for an interval
    assert same.ci_low < 0 < same.ci_high and not same.significant and same.intervals_overlap
    apart = difference_of_means([1.0, 1.2, 0.9, 1.1, 1.0], [5.0, 5.3, 4.8, 5.1, 5.2])
    assert apart.difference == pytest.approx(4.04) and apart.significant and not apart.intervals_overlap


def test_the_table_has_spread_published_spread_times_attempts_and_paper_measures():
    store = make_store()
    summaries = summarize(store, "spread")
    assert [s.label for s in summaries] == ["IRLock / none", "IRLock / none [field]", "Algorithm 2", "GPS"]
    text = markdown_table("spread", summaries)
    header = text.splitlines()[4]
    for column in ("Error mean ± sd (cm)", "Error median (cm)", "95 % CI of mean (cm)", "Published mean ± sd (cm)",
                   "Published time (s)", "Attempts mean (max)", "Marker switches (mean)", "Recovery climbs (mean)",
                   "Abort to GPS", "First detection (m)", "Published source"):
        assert column in header, column
    rows = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("| ")}
    irlock = rows["IRLock / none"]
    table7 = published(7, "error_cm")
    sd7 = statistics.stdev(table7)
    assert f"| 4.00 ± {statistics.stdev(ERRORS['IRLock / none']):.2f} |" in irlock
    assert f"| 5.79 ± {sd7:.2f} (n=10) |" in irlock  # published mean with the published trials' spread
    times7 = published(7, "landing_time_s")
    assert f"| {statistics.fmean(times7):.2f} ± {statistics.stdev(times7):.2f} |" in irlock  # from the trials
    assert "| 1.20 (max 2) |" in irlock and irlock.endswith("| [1] |")
    paper = rows["Algorithm 2"]
    assert "| 3.00 |" in paper and "| 1.00 |" in paper and "| 1/3 |" in paper and "| 19.0 |" in paper
    assert "| 55.00 |" in paper and paper.endswith("| [2] |")  # the summary's time, with no trials to spread
    # The field row is a measurement: no published figures, no source note.
    field = rows["IRLock / none [field]"]
    assert "5.79" not in field and "13.86" not in field and field.endswith("| - |")
    assert "[1] thesis Table 3 (Appendix B)" in text and "[2] paper Section 6" in text


def test_columns_empty_in_every_row_are_left_out():
    store = make_store()
    gps_only = [s for s in summarize(store, "spread") if s.label == "GPS"]
    text = markdown_table("spread", gps_only)
    header = text.splitlines()[4]
    for absent in ("Published", "Attempts", "Marker switches", "Abort to GPS", "First detection"):
        assert absent not in header, absent
    rows = list(csv.reader(csv_table(gps_only).splitlines()))
    assert all(any(row[i] for row in rows[1:]) for i in range(len(rows[0])))
    assert "error_sd_cm" in rows[0] and "published_error_mean_cm" not in rows[0]
    assert "error_ci95_low_cm" not in rows[0]  # two trials: too few for an interval in any row


def _summary_with(errors_cm, published_cm):
    from preland_app.campaign.report import PublishedTrial, ScenarioSummary

    trials = [{"outcome": "landed", "landing_error_cm": e, "landing_time_s": 20.0, "details": {}} for e in errors_cm]
    return ScenarioSummary(label="s", index=0, land_mode="irlock", sensor="irlock", failures="", initial_height_m=10,
                           trials=trials, published=[PublishedTrial(error_cm=p, x_cm=None, y_cm=None,
                                                                    landing_time_s=22.0) for p in published_cm])


def test_a_match_is_only_a_mean_inside_the_published_min_to_max():
    from preland_app.campaign.report import COLUMNS

    column = next(c for c in COLUMNS if c.name == "inside_published_range")
    published = [1.8, 5.0, 13.9]
    assert column.cell(_summary_with([2.0, 3.0], published)) == "yes"
    assert column.cell(_summary_with([1.0, 1.5], published)) == "no"  # more precise than any field trial
    assert column.cell(_summary_with([20.0, 30.0], published)) == "no"
    assert column.cell(_summary_with([2.0], [])) == ""
    shown = next(c for c in COLUMNS if c.name == "published_range").cell(_summary_with([2.0], published))
    assert shown == "1.80 to 13.90"
