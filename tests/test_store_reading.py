"""Reading the store: campaign list, trial show, campaign compare and campaign delete."""

from typer.testing import CliRunner

from preland_app.campaign.compare import compare
from preland_app.campaign.store import ResultsStore, TrialRecord
from preland_app.cli import app

from .test_field_records import seeded_store


def run(*args, input=None):
    return CliRunner().invoke(app, [str(a) for a in args], input=input)


def add_events_and_path(db):
    with ResultsStore(db) as store:
        store.add_trial(TrialRecord(
            campaign="thesis_table3", scenario="IRLock / none", scenario_index=1, trial_index=2, seed=9,
            spec_hash="h", result={"outcome": "landed", "message": "landed and disarmed", "land_mode": "irlock",
                                   "scoring_reference": "pad", "landing_error_cm": 5.0, "offset_north_cm": 3.0,
                                   "offset_east_cm": 4.0, "landing_time_s": 25.0, "details": {"attempts": 2}},
            events=({"time_s": 3.0, "kind": "armed", "message": "armed in GUIDED"},
                    {"time_s": 9.0, "kind": "recorded", "message": "position recorded"},
                    {"time_s": 20.0, "kind": "land_handover", "message": "hand-over to land mode irlock"}),
            trajectory_columns=("time_s", "est_north_m", "est_east_m", "est_altitude_rel_m", "true_north_m",
                                "true_east_m", "true_altitude_m"),
            trajectory_rows=tuple((t, 0.0, 0.1 * t, min(t, 10.0), 0.08 * t, 0.0, min(t, 10.0) if t < 25 else 0.0)
                                  for t in range(0, 30))))


def test_campaign_list_shows_campaigns_scenarios_counts_and_sources(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    assert run("trial", "record", db, "thesis_table3", "IRLock / none", "--error-cm", "4").exit_code == 0
    assert run("trial", "record", db, "day2", "hover", "--error-cm", "4", "--new").exit_code == 0
    result = run("campaign", "list", db)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("day2: 1 scenario(s), 1 trial(s) (field records only)")
    table3 = next(i for i, line in enumerate(lines) if line.startswith("thesis_table3: 2 scenario(s), 5 trial(s)"))
    assert "campaigns/thesis_table3.yaml" in lines[table3]
    assert lines[table3 + 1].split() == ["scenario", "land", "mode", "sim", "sitl", "field", "landed",
                                         "published", "source"]
    assert lines[table3 + 3].split()[:7] == ["IRLock", "/", "none", "irlock", "2", "0", "1"]
    assert lines[table3 + 3].endswith("thesis Table 3 (Appendix B)")
    assert run("campaign", "list", tmp_path / "none.db").exit_code == 2


def test_trial_show_prints_outcome_details_events_and_plots_the_path(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    add_events_and_path(db)
    plot = tmp_path / "path.png"
    result = run("trial", "show", db, "thesis_table3", "IRLock / none", "2", "--plot", plot, "--dpi", "60")
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "outcome            landed (landed and disarmed)" in out and "landing error      5.00 cm" in out
    assert "attempts           2" in out and "hand-over to land mode irlock" in out and "20.00 s" in out
    assert plot.read_bytes()[:4] == b"\x89PNG" and f"wrote {plot}" in out
    # A field trial of the same index is reached with --source; its corrections are shown.
    assert run("trial", "record", db, "thesis_table3", "IRLock / none", "--error-cm", "4").exit_code == 0
    assert run("trial", "amend", db, "thesis_table3", "IRLock / none", "0", "--error-cm", "4.5",
               "--reason", "tape slipped").exit_code == 0
    result = run("trial", "show", db, "thesis_table3", "IRLock / none", "0", "--source", "field")
    assert result.exit_code == 0 and "(field, field)" in result.stdout
    assert "landing_error_cm 4.0 -> 4.5 (tape slipped)" in result.stdout
    result = run("trial", "show", db, "thesis_table3", "IRLock / none", "9")
    assert result.exit_code == 2 and "no trial 9" in result.stderr and "sim 0" in result.stderr
    result = run("trial", "show", db, "thesis_tabel3", "IRLock / none", "0")
    assert result.exit_code == 2 and "close: thesis_table3" in result.stderr


def two_runs(tmp_path, shift_cm):
    paths = []
    for name, shift in (("before", 0.0), ("after", shift_cm)):
        db = tmp_path / f"{name}.db"
        with ResultsStore(db) as store:
            for index, (label, base) in enumerate((("near", 3.0), ("far", 60.0))):
                for trial in range(10):
                    error = base + shift + (trial % 5) * 0.5 * (1 + index * 10)
                    store.add_trial(TrialRecord(campaign="c", scenario=label, scenario_index=index, trial_index=trial,
                                                seed=trial, spec_hash="h",
                                                result={"outcome": "landed", "message": "ok",
                                                        "landing_error_cm": error, "landing_time_s": 20.0 + trial % 3,
                                                        "details": {}}))
        paths.append(db)
    return paths


def test_compare_gives_differences_with_intervals(tmp_path):
    before, after = two_runs(tmp_path, shift_cm=5.0)
    with ResultsStore(before) as b, ResultsStore(after) as a:
        near, far = compare((b, "c"), (a, "c"))
        assert near.difference.difference == 5.0 and near.difference.significant
        assert far.difference.ci_low < 5.0 < far.difference.ci_high
        same = compare((b, "c"), (b, "c"))
        assert all(row.difference.difference == 0 and row.difference.intervals_overlap for row in same)
    result = run("campaign", "compare", f"{before}:c", after)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("landing error (cm):")
    near_line = next(line for line in lines if line.startswith("near"))
    assert "+5.00 [" in near_line and "difference CI excludes 0; means' CIs apart" in near_line
    result = run("campaign", "compare", before, after, "--measure", "landing_time_s")
    assert result.exit_code == 0 and "difference CI includes 0; means' CIs overlap" in result.stdout
    result = run("campaign", "compare", f"{before}:nope", after)
    assert result.exit_code == 2 and "no campaign 'nope'" in result.stderr
    assert run("campaign", "compare", tmp_path / "x.db", after).exit_code == 2


def test_delete_asks_then_removes_trials_with_their_events(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    add_events_and_path(db)
    result = run("campaign", "delete", db, "thesis_table3", "--scenario", "IRLock / none", input="n\n")
    assert result.exit_code == 1 and "nothing deleted" in result.stdout and "3 sim trial(s)" in result.stdout
    with ResultsStore(db) as store:
        assert len(store.trials()) == 5
    result = run("campaign", "delete", db, "thesis_table3", "--scenario", "IRLock / none", input="y\n")
    assert result.exit_code == 0 and "3 trial(s)" in result.stdout
    with ResultsStore(db) as store:
        assert {t["scenario"] for t in store.trials()} == {"None / none"}
        assert store.db.execute("SELECT COUNT(*) FROM events").fetchone()[0] == 0
        assert store.db.execute("SELECT COUNT(*) FROM trajectories").fetchone()[0] == 0
    result = run("campaign", "delete", db, "thesis_tabel3", "--yes")
    assert result.exit_code == 2 and "close: thesis_table3" in result.stderr
    result = run("campaign", "delete", db, "thesis_table3", "--yes")
    assert result.exit_code == 0
    with ResultsStore(db) as store:
        assert store.campaigns() == [] and store.trials() == []
