"""The public Python API, used through `preland_app` alone."""

import preland_app as preland

from .conftest import ROOT


def test_the_public_api_flies_runs_a_campaign_and_reads_it_back(tmp_path):
    mission = preland.load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    outcome = preland.fly(mission, seed=8, land="irlock", faults={"irlock": "random:0.5"})
    assert isinstance(outcome, preland.TrialOutcome) and outcome.outcome is preland.Outcome.LANDED
    assert outcome.scoring_reference == "pad" and outcome.landing_error_cm < 20.0
    assert outcome.details["irlock_dropped"] > 0 and outcome.landing_time_s > 10.0

    campaign = tmp_path / "campaign.yaml"
    campaign.write_text(f"name: api\nmission: {ROOT / 'missions' / 'thesis_square_land.yaml'}\ntrials: 2\n"
                        "base_seed: 3\nscenarios:\n  - {label: gps, land: normal}\n")
    run = preland.run_campaign(campaign, db=tmp_path / "results.db", workers=1)
    assert (run.name, run.ran, run.total) == ("api", 2, 2)
    rows = preland.read_results(run.db, campaign="api")
    assert [row["trial_index"] for row in rows] == [0, 1] and all(row["outcome"] == "landed" for row in rows)
    # What the store holds is what fly() gives for the same seed.
    again = preland.fly(mission, seed=rows[1]["seed"], record_trajectory=False)
    assert round(again.landing_error_cm, 2) == rows[1]["landing_error_cm"]
    assert rows[1]["details"]["wind_from_deg"] == again.details["wind_from_deg"]

    assert {row.name for row in preland.land_modes()} >= {"normal", "marker", "paper_adaptive"}
    assert preland.schema("pad")["additionalProperties"] is False
    try:
        preland.fly(mission, land="preland_no_such_module:Landing")
    except preland.SpecError as error:
        assert error.field == "land.mode" and "no module named" in error.problem
    else:
        raise AssertionError("an unknown land mode must raise SpecError")


def test_reading_functions_of_the_api(tmp_path):
    import json

    import pytest

    import preland_app

    from .test_field_records import seeded_store
    from .test_store_reading import add_events_and_path

    db = seeded_store(tmp_path / "r.db")
    add_events_and_path(db)
    (entry,) = preland_app.list_campaigns(db)
    assert entry.name == "thesis_table3" and entry.trials == 5
    trial = preland_app.read_trial(db, campaign="thesis_table3", scenario="IRLock / none", index=2)
    assert trial["landing_error_cm"] == 5.0 and trial["events"][0]["kind"] == "armed"
    assert trial["trajectory"][0][0] == "time_s" and len(trial["trajectory"][1]) == 30
    summaries = preland_app.summarize_campaign(db, "thesis_table3")
    assert summaries[1].error_spread().n == 3 and summaries[1].published_avg_error_cm() == 5.79
    (gps, irlock) = preland_app.compare_runs((db, "thesis_table3"), (db, "thesis_table3"))
    assert gps.difference.difference == 0.0 and irlock.before_n == 3
    lines = preland_app.export_results(db, export_format="jsonl").splitlines()
    assert len(lines) == 5 and json.loads(lines[0])["campaign"] == "thesis_table3"
    files = preland_app.write_campaign_report(db, "thesis_table3", tmp_path / "rep", figure_format="svg")
    assert {f.suffix for f in files} == {".md", ".csv", ".svg"}
    with pytest.raises(preland_app.PrelandError):
        preland_app.list_campaigns(tmp_path / "missing.db")
