"""Calibration against field trials: profiles, `preland sim calibrate`, and the report's fidelity section."""

from __future__ import annotations

import csv
import functools
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from preland_app.campaign.calibrate import Flyer, run_jobs
from preland_app.campaign.driver import run_campaign
from preland_app.campaign.executors import ExecutorOptions, create_executor
from preland_app.campaign.fidelity import fidelity_section
from preland_app.campaign.report import summarize, write_report
from preland_app.campaign.spec import load_campaign, resolve_scenarios
from preland_app.campaign.store import ResultsStore
from preland_app.campaign.trials import plan_trials
from preland_app.cli import app
from preland_app.config.mission import load_mission
from preland_app.errors import SpecError
from preland_app.sim.calibratable import CalibratableError, CalibratableParameter, calibratable_parameters, \
    find_calibratable, register_calibratable
from preland_app.sim.profile import load_profile

# A mission of a few seconds: take off to 3 m over the pad, land (physics at 50 Hz to keep it quick).
TINY_MISSION = """
name: tiny
pad: {preset: thesis, offset_from_start_ned_m: [0.0, 0.0]}
takeoff: {altitude_rel_m: 3.0}
path: {waypoints_rel_ned_m: [[0.0, 0.0]]}
environment: {physics_rate_hz: 50}
timeouts: {position_fix_s: 30, arm_s: 30, takeoff_s: 30, waypoint_s: 30, land_s: 60}
"""

TINY_CAMPAIGN = """
name: tiny_cal
mission: tiny.yaml
trials: 5
base_seed: 11
scenarios:
  - label: gps
    land: normal
    reference: {trials_csv: field.csv, source_table: 1}
  - label: irlock
    land: irlock
    reference: {trials_csv: field.csv, source_table: 2}
  - label: irlock random
    land: irlock
    faults: {irlock: "random:0.75"}
    reference: {trials_csv: field.csv, source_table: 3}
"""

TABLES = {"gps": 1, "irlock": 2, "irlock random": 3}


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def one_line_error(result) -> str:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1, message
    return message


# ------------------------------------------------------------------ calibratable parameters


def test_declared_parameters_have_their_spec_defaults_inside_their_ranges():
    parameters = calibratable_parameters()
    assert {"navigation.gps_drift_sigma_m", "navigation.attitude_noise_sigma_deg", "wind.turbulence_w20_m_s",
            "sensors.irlock.noise_sigma_deg", "sensors.camera.noise_sigma"} <= set(parameters)
    gps = parameters["navigation.gps_drift_sigma_m"]
    assert gps.default() == 0.75 and gps.contains(gps.default()) and gps.source
    with pytest.raises(CalibratableError, match="not a calibratable parameter"):
        find_calibratable("navigation.gps_drift_tau_s")


def test_a_package_registers_a_parameter_and_a_wrong_one_is_refused():
    register_calibratable(CalibratableParameter(name="navigation.gps_drift_tau_s", low=30.0, high=600.0,
                                                source="a test"))
    try:
        assert find_calibratable("navigation.gps_drift_tau_s").default() == 120.0
    finally:
        from preland_app.sim import calibratable

        del calibratable._REGISTRY["navigation.gps_drift_tau_s"]
    with pytest.raises(CalibratableError, match="no such field"):
        register_calibratable(CalibratableParameter(name="navigation.nope", low=0.0, high=1.0, source=""))
    with pytest.raises(CalibratableError, match="outside the declared range"):
        register_calibratable(CalibratableParameter(name="wind.speed_m_s", low=5.0, high=9.0, source=""))


# ------------------------------------------------------------------ profiles


def test_a_profile_fills_the_mission_and_the_missions_and_scenarios_own_overrides_win(tmp_path):
    write(tmp_path, "p.yaml", "name: p\nenvironment: {navigation: {gps_drift_sigma_m: 1.2, "
                              "attitude_noise_sigma_deg: 1.0}, wind: {speed_m_s: 4.0}}\n"
                              "sensors: {camera: {noise_sigma: 6.0}}\n")
    write(tmp_path, "q.yaml", "name: q\nenvironment: {navigation: {gps_drift_sigma_m: 2.0}}\n")
    mission_path = write(tmp_path, "tiny.yaml", TINY_MISSION + "sim_profile: p.yaml\n"
                         "environment: {physics_rate_hz: 50, navigation: {attitude_noise_sigma_deg: 0.3}}\n")
    mission = load_mission(mission_path)
    navigation = mission.environment.navigation
    assert (navigation.gps_drift_sigma_m, navigation.attitude_noise_sigma_deg) == (1.2, 0.3)
    assert mission.environment.wind.speed_m_s == 4.0 and mission.sensors.camera.noise_sigma == 6.0
    assert mission.environment.physics_rate_hz == 50

    # A campaign's profile takes the mission's place; a scenario's environment goes on top.
    campaign_path = write(tmp_path, "c.yaml", "name: c\nmission: tiny.yaml\nsim_profile: q.yaml\nscenarios:\n"
                          "  - {label: a, land: normal}\n"
                          "  - {label: b, land: normal, environment: {navigation: {gps_drift_sigma_m: 0.5}}}\n")
    a, b = resolve_scenarios(load_campaign(campaign_path))
    assert a.mission.environment.navigation.gps_drift_sigma_m == 2.0
    assert a.mission.environment.wind.speed_m_s == 1.5  # the mission's profile p is replaced, not merged
    assert a.mission.environment.navigation.attitude_noise_sigma_deg == 0.3  # the mission's own override
    assert b.mission.environment.navigation.gps_drift_sigma_m == 0.5
    assert a.spec_hash != b.spec_hash


@pytest.mark.parametrize("body, field, problem", [
    ("name: p\nenvironment: {navigation: {gps_drift_sigma_m: 9.0}}\n", "environment.navigation.gps_drift_sigma_m",
     "outside the calibratable range 0.2..2.5"),
    ("name: p\nenvironment: {navigaton: {gps_drift_sigma_m: 1.0}}\n", "environment.navigaton", "unknown key"),
    ("name: p\nsensors: {irlock: {noise_sigma_deg: high}}\n", "sensors.irlock.noise_sigma_deg", "expected a number"),
    ("name: p\nsensor: {}\n", "sensor", "unknown key"),
    ("name: p\nenvironment: {wind: {speed_m_s: 2.0}}\nprovenance: {data: x.csv, campaign: c.yaml, "
     "fitted: {wind.speed_m_s: 3.0}}\n", "provenance.fitted.wind.speed_m_s", "is not the profile's override"),
    ("name: p\nenvironment: {navigation: {gps_drift_tau_s: 60.0}}\nprovenance: {data: x.csv, campaign: c.yaml, "
     "fitted: {navigation.gps_drift_tau_s: 60.0}}\n", "provenance.fitted.navigation.gps_drift_tau_s",
     "not a calibratable parameter"),
])
def test_a_bad_profile_is_one_line_naming_file_and_field(tmp_path, body, field, problem):
    profile_path = write(tmp_path, "p.yaml", body)
    with pytest.raises(SpecError) as caught:
        load_profile(profile_path)
    message = str(caught.value)
    assert str(profile_path) in message and field in message and problem in message
    # Named by a mission flown from the command line: one line, exit 2, naming both files.
    mission_path = write(tmp_path, "tiny.yaml", TINY_MISSION + "sim_profile: p.yaml\n")
    result = CliRunner().invoke(app, ["fly", str(mission_path)])
    message = one_line_error(result)
    assert str(mission_path) in message and "sim_profile" in message and field in message


# ------------------------------------------------------------------ calibrate


def make_field_trials(tmp_path: Path, truth: dict[str, float]) -> Path:
    """Field trials flown by the simulator with `truth` (5 per scenario), as a CSV in the thesis' columns."""
    campaign = load_campaign(tmp_path / "c.yaml")
    flyer = Flyer(campaign)
    records = []
    with create_executor("local", ExecutorOptions(workers=1)) as executor:
        jobs = list(plan_trials(campaign, flyer.scenarios(truth, list(TABLES), 5), outcomes_only=True))
        run_jobs(executor, jobs, records.append)
    path = tmp_path / "field.csv"
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["source_table", "error_cm", "landing_time_s"])
        for record in records:
            assert record.result["outcome"] == "landed"
            writer.writerow([TABLES[record.scenario], record.result["landing_error_cm"],
                             record.result["landing_time_s"]])
    return path


def test_calibrate_recovers_the_parameters_that_made_synthetic_field_trials(tmp_path):
    """Field trials flown with known values (GPS drift 1.5 m, attitude noise 1.6 deg; the defaults are 0.75 and
    0.7) and with the fit's own seeds, so the truth scores 0: the fit, started from the defaults with 20
    evaluations, must land within 10 % of each value. The held-out scenario is scored, not fitted."""
    write(tmp_path, "tiny.yaml", TINY_MISSION)
    write(tmp_path, "c.yaml", TINY_CAMPAIGN)
    truth = {"navigation.gps_drift_sigma_m": 1.5, "navigation.attitude_noise_sigma_deg": 1.6}
    field_csv = make_field_trials(tmp_path, truth)
    out = tmp_path / "fitted.yaml"
    result = CliRunner().invoke(app, [
        "sim", "calibrate", str(tmp_path / "c.yaml"), "--field-csv", str(field_csv),
        "--params", *truth, "--holdout", "irlock random", "--budget", "20", "--seed", "1",
        "--trials-per-scenario", "5", "--score-trials", "5", "--workers", "1", "--quiet", "--out", str(out)])
    assert result.exit_code == 0, result.output
    profile = load_profile(out)
    provenance = profile.provenance
    for name, value in truth.items():
        assert provenance.fitted[name] == pytest.approx(value, rel=0.10), provenance.fitted
        assert profile.value_of(name) == provenance.fitted[name]
    assert provenance.start == {"navigation.gps_drift_sigma_m": 0.75, "navigation.attitude_noise_sigma_deg": 0.7}
    assert provenance.held_out == ("irlock random",) and provenance.data == str(field_csv)
    assert provenance.optimizer.budget == 20 and provenance.optimizer.seed == 1
    assert provenance.optimizer.evaluations <= 20 and provenance.optimizer.trials_per_scenario == 5
    roles = {s.label: s.role for s in provenance.scores}
    assert roles == {"gps": "fitted", "irlock": "fitted", "irlock random": "held_out"}
    gps = provenance.score_of("gps")
    assert gps.field_trials == 5 and gps.trials == 5 and gps.wasserstein_cm < 0.2 * gps.field_mean_cm
    assert "gps" in result.stdout and "held out" in result.stdout and f"wrote {out}" in result.stdout
    # The field trials were flown on the fit's own seeds, so there the fit scores nearly 0; on other seeds
    # (base seed 11 + 1 and + 2) the same values meet other draws, and the objective says how far apart
    # two draws of the same model lie.
    optimizer = provenance.optimizer
    assert optimizer.fresh_base_seeds == (12, 13) and len(optimizer.fresh_seed_objectives) == 2
    assert min(optimizer.fresh_seed_objectives) > optimizer.objective
    assert f"objective on 2 other seed set(s): {optimizer.fresh_seed_objectives[0]:.3f}" in result.stdout


def test_calibrate_refuses_what_it_cannot_fit_in_one_line(tmp_path):
    write(tmp_path, "tiny.yaml", TINY_MISSION)
    campaign = write(tmp_path, "c.yaml", TINY_CAMPAIGN)
    csv_path = write(tmp_path, "field.csv", "source_table,error_cm,landing_time_s\n1,40,7\n2,3,12\n")
    runner = CliRunner()
    base = ["sim", "calibrate", str(campaign), "--field-csv", str(csv_path), "--quiet", "--workers", "1"]
    message = one_line_error(runner.invoke(app, [*base, "--params", "navigation.gps_drift_sigma_m",
                                                 "navigation.gps_drift_tau_s"]))
    assert "--params" in message and "navigation.gps_drift_tau_s" in message and "not a calibratable" in message
    message = one_line_error(runner.invoke(app, [*base, "--params", "navigation.gps_drift_sigma_m",
                                                 "--holdout", "nope"]))
    assert "--holdout" in message and "'nope'" in message
    # Every scenario's own environment (here the mission's) sets it: a profile could not change it.
    message = one_line_error(runner.invoke(app, [*base, "--params", "navigation.gps_drift_sigma_m",
                                                 "navigation.attitude_noise_sigma_deg", "--budget", "2"]))
    assert "--budget" in message
    message = one_line_error(runner.invoke(app, [*base, "--params", "navigation.gps_drift_sigma_m",
                                                 "--fresh-seed-sets", "-1"]))
    assert "--fresh-seed-sets" in message and "must be >= 0" in message
    write(tmp_path, "tiny.yaml", TINY_MISSION.replace("physics_rate_hz: 50", "physics_rate_hz: 50, wind: {speed_m_s: 1}"))
    message = one_line_error(runner.invoke(app, [*base, "--params", "wind.speed_m_s"]))
    assert "wind.speed_m_s" in message and "cannot change it" in message
    message = one_line_error(runner.invoke(app, [*base, "--params", "navigation.gps_drift_sigma_m",
                                                 "--holdout", "gps", "irlock"]))
    assert "no scenario left to fit" in message


# ------------------------------------------------------------------ the report


def test_the_report_marks_fitted_and_held_out_scenarios_and_what_the_fit_could_not_reach(tmp_path):
    from scipy.stats import wasserstein_distance  # here: SciPy takes a second to import

    write(tmp_path, "tiny.yaml", TINY_MISSION)
    write(tmp_path, "field.csv", "source_table,error_cm,landing_time_s\n"
                                 "1,30,7\n1,50,7.5\n1,70,6.5\n2,20,12\n2,25,13\n2,30,14\n")
    profile = {"name": "fit", "environment": {"navigation": {"gps_drift_sigma_m": 1.5}},
               "provenance": {"data": "field.csv", "campaign": "c.yaml", "fitted": {"navigation.gps_drift_sigma_m": 1.5},
                              "held_out": ["irlock"],
                              "scores": [{"label": "gps", "role": "fitted", "wasserstein_cm": 4.0, "sim_mean_cm": 45.0,
                                          "field_mean_cm": 50.0, "field_min_cm": 30.0, "field_max_cm": 70.0,
                                          "inside": True, "trials": 3, "field_trials": 3},
                                         {"label": "irlock", "role": "held_out", "wasserstein_cm": 22.0,
                                          "sim_mean_cm": 3.0, "field_mean_cm": 25.0, "field_min_cm": 20.0,
                                          "field_max_cm": 30.0, "inside": False, "trials": 3, "field_trials": 3}]}}
    write(tmp_path, "fit.yaml", yaml.safe_dump(profile))
    load_profile(tmp_path / "fit.yaml")
    campaign_path = write(tmp_path, "c.yaml", TINY_CAMPAIGN.replace("trials: 5", "trials: 3")
                          .replace("mission: tiny.yaml", "mission: tiny.yaml\nsim_profile: fit.yaml")
                          .split("  - label: irlock random")[0])
    campaign = load_campaign(campaign_path)
    with ResultsStore(tmp_path / "r.db") as store:
        run_campaign(campaign, store, workers=1)
        summaries = summarize(store, "tiny_cal")
        stored_text, source = store.campaign_text("tiny_cal")
        section = fidelity_section(summaries, spec_text=stored_text, source_path=source)
        write_report(store, "tiny_cal", tmp_path / "report")
    assert "profile `fit` (named by the campaign)" in section
    table = section.split("### Tests per scenario")[0]  # the fidelity table, before the tests' own
    rows = {line.split(" | ")[0].strip("| "): line.split(" | ") for line in table.splitlines()
            if line.startswith("| gps") or line.startswith("| irlock")}
    assert rows["gps"][1] == "fitted" and rows["irlock"][1] == "held out"
    gps_errors = summaries[0].errors_cm()
    assert rows["gps"][7] == f"{wasserstein_distance(gps_errors, [30.0, 50.0, 70.0]):.1f}"
    assert rows["gps"][5] == "30.0..70.0"
    irlock_mean = sum(summaries[1].errors_cm()) / 3
    assert rows["irlock"][6] == ("inside" if 20 <= irlock_mean <= 30 else "below" if irlock_mean < 20 else "above")
    expected_note = ("inside in this run, not in the fit's own scoring trials (3.0 cm against 20.0..30.0)"
                     if rows["irlock"][6] == "inside" else "the fit could not bring it inside (profile: 3.0 cm")
    assert expected_note in rows["irlock"][10] and "could not" not in rows["gps"][10]
    assert "## Fidelity to the field" in (tmp_path / "report" / "tiny_cal.md").read_text()


def test_the_report_compares_with_a_published_range_and_says_when_defaults_were_used(tmp_path):
    write(tmp_path, "tiny.yaml", TINY_MISSION)
    campaign_path = write(tmp_path, "c.yaml", "name: paperish\nmission: tiny.yaml\ntrials: 2\nscenarios:\n"
                          "  - {label: gps, land: normal, reference: {avg_error_cm: 85, min_error_cm: 51, "
                          "max_error_cm: 144, avg_landing_time_s: 28.5, source: paper}}\n")
    with ResultsStore(tmp_path / "r.db") as store:
        run_campaign(load_campaign(campaign_path), store, workers=1)
        summaries = summarize(store, "paperish")
        section = fidelity_section(summaries, spec_text=store.campaign_text("paperish")[0],
                                   source_path=str(campaign_path))
    row = next(line for line in section.splitlines() if line.startswith("| gps")).split(" | ")
    mean = summaries[0].avg_error_cm()
    assert "model's defaults" in section and row[1] == "defaults" and row[5] == "51.0..144.0"
    assert row[6] == ("inside" if 51 <= mean <= 144 else "below" if mean < 51 else "above")
    assert row[7] == "-"  # no published trials: no distance
    assert row[3] == "-"  # 2 trials: no confidence interval


def _summary(label, errors_cm, *, published_cm):
    """A simulated scenario's summary as the fidelity section reads it: `errors_cm` against published trials."""
    from types import SimpleNamespace

    return SimpleNamespace(
        scenario=label, source="sim", failures="none", reference=SimpleNamespace(min_error_cm=None),
        published=[SimpleNamespace(error_cm=e, landing_time_s=22.0) for e in published_cm],
        errors_cm=lambda: errors_cm,
        trials=[{"outcome": "landed", "landing_error_cm": e, "landing_time_s": 20.0} for e in errors_cm],
        landed=[{"outcome": "landed", "landing_error_cm": e, "landing_time_s": 20.0} for e in errors_cm],
        published_max_error_cm=lambda: max(published_cm),
        published_avg_error_cm=lambda: sum(published_cm) / len(published_cm),
        avg_landing_time_s=lambda: 20.0, published_avg_landing_time_s=lambda: 22.0)


def test_the_fit_note_tells_a_run_inside_from_a_fit_that_could_not_reach_it(tmp_path):
    """Where the profile's own scoring trials were outside the published range, the note says whether this
    run's mean is inside anyway or still outside; where they were inside, there is no note."""
    from scipy.stats import wasserstein_distance  # here: SciPy takes a second to import

    from preland_app.campaign.fidelity import fidelity_rows

    def score(label, *, inside, sim_mean_cm):
        return {"label": label, "role": "fitted", "wasserstein_cm": 5.0, "sim_mean_cm": sim_mean_cm,
                "field_mean_cm": 25.0, "field_min_cm": 20.0, "field_max_cm": 30.0, "inside": inside,
                "trials": 3, "field_trials": 3}

    profile = {"name": "fit", "environment": {"navigation": {"gps_drift_sigma_m": 1.5}},
               "provenance": {"data": "field.csv", "campaign": "c.yaml",
                              "fitted": {"navigation.gps_drift_sigma_m": 1.5}, "held_out": [],
                              "scores": [score("now inside", inside=False, sim_mean_cm=12.0),
                                         score("still below", inside=False, sim_mean_cm=11.0),
                                         score("was inside", inside=True, sim_mean_cm=24.0)]}}
    write(tmp_path, "fit.yaml", yaml.safe_dump(profile))

    summary = functools.partial(_summary, published_cm=(20.0, 25.0, 30.0))

    rows = {row[0]: row for row in fidelity_rows(
        [summary("now inside", [22.0, 24.0, 26.0]), summary("still below", [10.0, 12.0, 14.0]),
         summary("was inside", [40.0, 44.0, 48.0])], load_profile(tmp_path / "fit.yaml"))}
    assert rows["now inside"][6] == "inside"
    assert rows["now inside"][10] == "inside in this run, not in the fit's own scoring trials (12.0 cm against 20.0..30.0)"
    assert rows["still below"][6] == "below"
    assert rows["still below"][10] == "the fit could not bring it inside (profile: 11.0 cm against 20.0..30.0)"
    # The fit's own trials were inside: no note, even though this run's mean is above.
    assert rows["was inside"][6] == "above" and rows["was inside"][10] == ""
    assert rows["now inside"][7] == f"{wasserstein_distance([22.0, 24.0, 26.0], [20.0, 25.0, 30.0]):.1f}"


def test_the_fidelity_note_says_when_the_means_interval_reaches_across_the_published_range():
    """A mean inside the range whose 95 % CI reaches below its min, one below whose CI reaches inside, and
    one whose CI lies wholly inside (no note); the summary line counts the unsettled ones."""
    from preland_app.campaign.fidelity import fidelity_rows, fidelity_section
    from preland_app.campaign.stats import describe

    summary = functools.partial(_summary, published_cm=(10.0, 20.0, 30.0))

    wide_inside = [2.0, 3.0, 4.0, 25.0, 30.0, 6.0]  # mean 11.7, inside 10..30
    near_below = [6.0, 7.0, 8.0, 9.0, 14.0, 9.5]  # mean 8.9, below 10
    settled = [19.0, 20.0, 21.0, 20.5, 19.5]
    summaries = [summary("wide", wide_inside), summary("near", near_below), summary("settled", settled)]
    rows = {row[0]: row for row in fidelity_rows(summaries, None)}
    wide, near = describe(wide_inside), describe(near_below)
    assert wide.ci_low < 10.0 and near.ci_high >= 10.0  # the premise of the cases
    assert rows["wide"][6] == "inside" and rows["wide"][3] == f"{wide.ci_low:.1f}..{wide.ci_high:.1f}"
    assert rows["wide"][10] == f"its 95 % CI ({wide.ci_low:.1f}..{wide.ci_high:.1f}) reaches below the published min"
    assert rows["near"][6] == "below"
    assert rows["near"][10] == f"its 95 % CI ({near.ci_low:.1f}..{near.ci_high:.1f}) reaches inside"
    assert rows["settled"][6] == "inside" and rows["settled"][10] == ""
    section = fidelity_section(summaries, spec_text=None, source_path="c.yaml")
    assert "2 of 3 simulated means inside the published min..max; for 2 of the 3, the mean's 95 % CI reaches " \
           "across an end of the range." in section
    # ArduPilot SITL's trials of a scenario: a row of their own, named so, beside the simulator's.
    sitl = summary("settled", [40.0, 41.0, 42.0])
    sitl.source = "sitl"
    rows = {row[0]: row for row in fidelity_rows([*summaries, sitl], None)}
    assert rows["settled (ArduPilot SITL)"][1] == "ArduPilot SITL" and rows["settled (ArduPilot SITL)"][6] == "above"
    assert rows["settled"][6] == "inside"
