"""Field entries: names checked with close matches, offsets and land mode checked, amend and delete audited."""

import json
import sqlite3

import pytest
from typer.testing import CliRunner

from preland_app.campaign.report import summarize, write_report
from preland_app.campaign.store import ResultsStore, TrialRecord
from preland_app.cli import app

from .conftest import ROOT

TABLE3 = ROOT / "campaigns" / "thesis_table3.yaml"


def seeded_store(path):
    """thesis_table3 registered with two simulated trials of two scenarios (made-up values, no flight)."""
    with ResultsStore(path) as store:
        store.register_campaign(name="thesis_table3", spec_hash="h", spec_text=TABLE3.read_text(),
                                source_path=str(TABLE3))
        for index, (label, mode, sensor) in enumerate((("None / none", "normal", None),
                                                       ("IRLock / none", "irlock", "irlock"))):
            for trial in range(2):
                store.add_trial(TrialRecord(
                    campaign="thesis_table3", scenario=label, scenario_index=index, trial_index=trial, seed=trial,
                    spec_hash="h", result={"outcome": "landed", "message": "ok", "land_mode": mode, "sensor": sensor,
                                           "faults": "none", "takeoff_altitude_m": 10.0,
                                           "scoring_reference": "pad" if sensor else "takeoff",
                                           "landing_error_cm": 3.0 + trial, "offset_north_cm": 3.0 + trial,
                                           "offset_east_cm": 0.0, "landing_time_s": 20.0, "details": {}}))
    return path


def record(db, campaign, scenario, *options):
    return CliRunner().invoke(app, ["trial", "record", str(db), campaign, scenario, *options])


def test_a_misspelt_campaign_or_scenario_is_refused_with_close_matches(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    result = record(db, "thesis_tabel3", "IRLock / none", "--error-cm", "4")
    assert result.exit_code == 2 and "CAMPAIGN: " in result.stderr and "'thesis_tabel3'" in result.stderr
    assert "close: thesis_table3" in result.stderr and "--new" in result.stderr
    result = record(db, "thesis_table3", "IRlock / nne", "--error-cm", "4")
    assert result.exit_code == 2 and "SCENARIO: " in result.stderr and "'IRLock / none'" in result.stderr
    # A scenario of the campaign file that has not run yet is known too.
    assert record(db, "thesis_table3", "Marker / none", "--error-cm", "4").exit_code == 0
    with ResultsStore(db) as store:
        assert {t["campaign"] for t in store.trials()} == {"thesis_table3"}
        assert len(store.trials()) == 5
    result = record(db, "field_day", "IRlock / nne", "--error-cm", "4", "--new")
    assert result.exit_code == 0, result.output
    assert "recorded field trial 0 of field_day / IRlock / nne" in result.stdout


def test_offsets_must_make_the_error_within_a_centimetre(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    base = ["thesis_table3", "IRLock / none"]
    result = record(db, *base, "--error-cm", "5", "--x-cm", "30", "--y-cm", "40")
    assert result.exit_code == 2 and "--x-cm/--y-cm" in result.stderr and "50.0 cm" in result.stderr
    result = record(db, *base, "--error-cm", "5", "--x-cm", "3")
    assert result.exit_code == 2 and "both offsets or neither" in result.stderr
    assert record(db, *base, "--error-cm", "50.9", "--x-cm", "30", "--y-cm", "40").exit_code == 0
    with ResultsStore(db) as store:
        assert len([t for t in store.trials() if t["source"] == "field"]) == 1


def test_a_land_mode_other_than_the_scenarios_is_refused(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    result = record(db, "thesis_table3", "IRLock / none", "--error-cm", "4",
                    "--land", "marker")
    assert result.exit_code == 2 and "--land: marker differs" in result.stderr and "irlock" in result.stderr
    result = record(db, "thesis_table3", "IRLock / none", "--error-cm", "4",
                    "--land", "irlock")
    assert result.exit_code == 0


def test_amend_keeps_an_audit_of_what_changed_and_delete_asks_and_keeps_the_row(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    base = ["thesis_table3", "IRLock / none"]
    assert record(db, *base, "--error-cm", "5", "--x-cm", "3", "--y-cm", "4").exit_code == 0
    assert record(db, *base, "--error-cm", "7").exit_code == 0
    runner = CliRunner()
    where = [str(db), "thesis_table3", "IRLock / none"]
    result = runner.invoke(app, ["trial", "amend", *where, "0", "--error-cm", "12"])
    assert result.exit_code == 2 and "make 5.0 cm" in result.stderr  # the stored offsets no longer fit
    result = runner.invoke(app, ["trial", "amend", *where, "0", "--error-cm", "13", "--x-cm", "5", "--y-cm", "12",
                                 "--reason", "re-measured from the photo"])
    assert result.exit_code == 0, result.output
    assert "landing_error_cm 5.0 -> 13.0" in result.stdout
    with ResultsStore(db) as store:
        (amended,) = [t for t in store.trials() if t["source"] == "field" and t["trial_index"] == 0]
    assert amended["landing_error_cm"] == 13.0 and amended["offset_east_cm"] == 12.0
    (entry,) = amended["audit"]
    assert entry["action"] == "amended" and entry["reason"] == "re-measured from the photo"
    assert entry["changes"] == {"landing_error_cm": [5.0, 13.0], "offset_north_cm": [3.0, 5.0],
                                "offset_east_cm": [4.0, 12.0]}
    assert entry["at"].endswith("Z")
    result = runner.invoke(app, ["trial", "amend", *where, "0", "--error-cm", "13"])
    assert result.exit_code == 2 and "nothing to change" in result.stderr
    result = runner.invoke(app, ["trial", "amend", *where, "0", "--land", "marker"])
    assert result.exit_code == 2 and "--land: marker differs" in result.stderr
    result = runner.invoke(app, ["trial", "amend", str(db), "thesis_table3", "None / none", "0", "--error-cm", "1"])
    assert result.exit_code == 2 and "no field trial 0" in result.stderr  # simulated trials are not edited

    result = runner.invoke(app, ["trial", "delete", *where, "1"], input="n\n")
    assert result.exit_code == 1 and "nothing deleted" in result.stdout
    result = runner.invoke(app, ["trial", "delete", *where, "1", "--reason", "wrong pad"], input="y\n")
    assert result.exit_code == 0, result.output
    with ResultsStore(db) as store:
        assert [t["trial_index"] for t in store.trials() if t["source"] == "field"] == [0]
        (kept,) = store.db.execute("SELECT * FROM deleted_trials").fetchall()
        assert kept["reason"] == "wrong pad" and json.loads(kept["row"])["landing_error_cm"] == 7.0
    assert record(db, *base, "--error-cm", "8").exit_code == 0
    with ResultsStore(db) as store:  # a deleted index is not reused
        assert [t["trial_index"] for t in store.trials() if t["source"] == "field"] == [0, 2]
    result = runner.invoke(app, ["trial", "delete", *where, "7", "--yes"])
    assert result.exit_code == 2 and "field trials: 0, 2" in result.stderr


def test_a_store_from_before_the_audit_column_opens_and_gains_it(tmp_path):
    path = tmp_path / "old.db"
    db = sqlite3.connect(path)
    from preland_app.campaign import store as store_module

    db.executescript(store_module.SCHEMA)  # the schema as it was: no audit column, no deleted_trials
    db.execute("INSERT INTO trials (campaign, scenario, scenario_index, trial_index, seed, outcome, message, "
               "spec_hash, software_version, runtime) VALUES ('c', 's', 0, 0, 1, 'landed', 'ok', 'h', '0.1', 'e')")
    db.commit()
    assert "audit" not in {row[1] for row in db.execute("PRAGMA table_info(trials)")}
    db.close()
    with ResultsStore(path) as store:
        (trial,) = store.trials()
        assert trial["audit"] == [] and trial["outcome"] == "landed"
        assert store.db.execute("SELECT COUNT(*) FROM deleted_trials").fetchone()[0] == 0
    with ResultsStore(path) as store:  # opening again changes nothing
        assert len(store.trials()) == 1


def test_the_report_works_with_any_mix_of_optional_fields(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    base = ["thesis_table3", "IRLock / none"]
    for extra in (["--error-cm", "4"], ["--error-cm", "5", "--x-cm", "3", "--y-cm", "4"],
                  ["--error-cm", "6", "--landing-time-s", "21"], ["--outcome", "aborted"],
                  ["--error-cm", "9", "--outcome", "crashed", "--takeoff-altitude-m", "8"]):
        assert record(db, *base, *extra).exit_code == 0
    assert record(db, "new_day", "only field", "--new", "--outcome", "aborted").exit_code == 0
    with ResultsStore(db) as store:
        summaries = summarize(store, "thesis_table3")
        field = next(s for s in summaries if s.label == "IRLock / none [field]")
        assert field.errors_cm() == [4.0, 5.0, 6.0] and field.aborted == 2
        for campaign in ("thesis_table3", "new_day"):
            files = write_report(store, campaign, tmp_path / "rep")
            assert any(f.suffix == ".md" for f in files)
    text = (tmp_path / "rep" / "new_day.md").read_text()
    assert "only field [field]" in text
