"""Field campaigns: a campaign's trials flown back to back on one vehicle (the simulator's MAVLink face here),
with the vehicle brought back to its start, the measurement after each landing, battery swaps, pilot takeover
and resume after a kill mid-flight."""

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import threading

import pytest
from typer.testing import CliRunner

import preland_app as preland
from preland_app.campaign.store import ResultsStore
from preland_app.cli.app import app
from preland_app.field.operator import AnswersError, Measurement, Pause, Verdict, load_answers
from preland_app.vehicle.types import FlightMode

from .conftest import SHORT_MISSION
from .test_mavlink_runtime import PATIENCE_S, ServedSimulator
from .waiting import until

TWO_SCENARIOS = """\
    trials: 2
    field: {between_trials: reposition}
    scenarios:
      - {label: gps, land: normal}
      - {label: ir, land: irlock}
"""


def _campaign(tmp_path, body: str = TWO_SCENARIOS, name: str = "fc") -> str:
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"name: {name}\nmission: {SHORT_MISSION}\nbase_seed: 7\n" + textwrap.dedent(body))
    return str(path)


def _answers(tmp_path, text: str) -> str:
    path = tmp_path / "answers.csv"
    path.write_text("scenario,trial,error_cm,x_cm,y_cm\n" + textwrap.dedent(text))
    return str(path)


def _served(*, paced: bool, seed: int = 2, speedup: float = 10.0) -> ServedSimulator:
    served = ServedSimulator(preland.load_mission(SHORT_MISSION), seed=seed, paced=paced, speedup=speedup)
    served.simulator.params.set("PLND_ENABLED", 1)  # set on the vehicle, as before a field day (PLND_TYPE
    served.simulator.params.set("PLND_TYPE", 1)  # takes a reboot), so the preflight checks pass
    return served


def _url(served: ServedSimulator) -> str:
    return "mavlink+" + served.url


def _on_face(served: ServedSimulator, action) -> None:
    """Run `action(simulator)` on the face's own thread and wait (bounded) until it ran."""
    done = threading.Event()

    def run():
        action(served.simulator)
        done.set()

    served.loop.call_soon_threadsafe(run)
    assert done.wait(PATIENCE_S), "the MAVLink face did not run the action"


def _land_on_face(served: ServedSimulator) -> None:
    """The pilot lands the vehicle: LAND, then wait (bounded) for the disarm."""
    _on_face(served, lambda simulator: simulator.autopilot.set_mode(FlightMode.LAND))
    until(lambda: not served.simulator.autopilot.armed, timeout_s=PATIENCE_S, what="the pilot's landing")


def _trials(db) -> list[dict]:
    return sorted(preland.read_results(db), key=lambda r: (r["scenario"], r["trial_index"]))


def _journal(db, campaign: str = "fc") -> list[dict]:
    with ResultsStore(db) as store:
        return store.field_log(campaign)


# ---------------------------------------------------------------- the answers file


@pytest.mark.parametrize("body, line", [
    ("scenario,trial,error\n", "answers.csv line 1: the header must be scenario,trial,error_cm,x_cm,y_cm (x_cm, "
                                "y_cm optional); unknown column 'error'"),
    ("scenario,trial,error_cm\nGPS,0,3\n", "answers.csv line 2, scenario: 'GPS' is not a scenario of the campaign "
                                           "(it has: gps, ir)"),
    ("scenario,trial,error_cm\ngps,2,3\n", "answers.csv line 2, trial: 2 is out of range (scenario 'gps' has trials "
                                           "0..1)"),
    ("scenario,trial,error_cm\ngps,0,3\nir,1,again\n", "answers.csv line 3, error_cm: 'again' is not a number, "
                                                       "skip, redo or abort"),
    ("scenario,trial,error_cm\ngps,0,-2\n", "answers.csv line 2, error_cm: -2 cm is negative (a distance is >= 0)"),
    ("scenario,trial,error_cm,x_cm,y_cm\ngps,0,5,3,\n", "answers.csv line 2, x_cm/y_cm: give both offsets or "
                                                        "neither"),
    ("scenario,trial,error_cm,x_cm,y_cm\ngps,0,5,3,2\n", "answers.csv line 2, x_cm/y_cm: their length 3.6 cm is "
                                                         "not error_cm 5 cm (within 1 cm)"),
    ("scenario,trial,error_cm,x_cm,y_cm\ngps,0,skip,3,4\n", "answers.csv line 2, x_cm/y_cm: offsets only with a "
                                                            "measured error_cm"),
])
def test_an_answers_file_is_checked_line_by_line(tmp_path, body, line):
    path = tmp_path / "answers.csv"
    path.write_text(body)
    with pytest.raises(AnswersError) as refused:
        load_answers(path, trials={"gps": 2, "ir": 2})
    assert str(refused.value) == f"{path.parent}/{line}"


def test_answers_keep_their_order_for_a_redone_trial(tmp_path):
    path = tmp_path / "answers.csv"
    path.write_text("scenario,trial,error_cm,x_cm,y_cm\ngps,1,redo,,\nir,0,skip,,\ngps,1,5,3,4\n")
    answers = load_answers(path, trials={"gps": 2, "ir": 2})
    assert list(answers[("gps", 1)]) == [Measurement(verdict=Verdict.REDO),
                                         Measurement(verdict=Verdict.MEASURED, error_cm=5.0, x_cm=3.0, y_cm=4.0)]
    assert list(answers[("ir", 0)]) == [Measurement(verdict=Verdict.SKIP)]


def test_field_options_are_refused_off_a_vehicle_and_a_bad_answers_file_in_one_line(tmp_path):
    campaign = _campaign(tmp_path)
    answers = _answers(tmp_path, "gps,0,3,,\n")
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "x.db"), "--quiet",
                                      "--answers", answers])
    assert result.exit_code == 2
    assert result.output.strip() == ("preland: error: --answers: only for a field campaign, on a vehicle "
                                     "(--runtime mavlink+...)")
    bad = _answers(tmp_path, "gps,0,far,,\n")
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "x.db"), "--quiet",
                                      "--runtime", "mavlink+udpout://127.0.0.1:9", "--answers", bad])
    assert result.exit_code == 2
    assert result.output.strip() == (f"preland: error: {bad} line 2, error_cm: 'far' is not a number, skip, redo "
                                     "or abort")
    assert not os.path.exists(tmp_path / "x.db") or not _trials(tmp_path / "x.db")


# ---------------------------------------------------------------- flying a field campaign


def test_a_field_campaign_repositions_measures_redoes_and_sits_beside_the_simulated_trials(tmp_path):
    campaign = _campaign(tmp_path)
    answers = _answers(tmp_path, """\
        gps,0,48.5,,
        gps,1,redo,,
        gps,1,61,60,11
        ir,0,skip,,
        ir,1,3.5,,
    """)
    db = tmp_path / "field.db"
    served = _served(paced=True)
    try:
        result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(db), "--runtime", _url(served),
                                          "--paced", "--answers", answers])
    finally:
        served.stop()
    assert result.exit_code == 0, result.output
    assert "[5/4]" not in result.output and "gps #1 · repositioning to the start" in result.output
    rows = _trials(db)
    assert [(r["scenario"], r["trial_index"], r["source"], r["runtime"], r["outcome"]) for r in rows] == [
        ("gps", 0, "field", "mavlink", "landed"), ("gps", 1, "field", "mavlink", "landed"),
        ("ir", 0, "field", "mavlink", "landed"), ("ir", 1, "field", "mavlink", "landed")], [r["message"] for r in rows]
    assert [r["landing_error_cm"] for r in rows] == [48.5, 61.0, None, 3.5]
    assert (rows[1]["offset_north_cm"], rows[1]["offset_east_cm"]) == (60.0, 11.0)
    assert rows[2]["details"]["measured"] is False
    assert all(r["details"]["measured_by"] == "operator" and r["details"]["truth_error_cm"] >= 0 for r in rows)
    # The redone trial is stored once, from its second flight; the first is kept in the journal.
    assert rows[1]["details"]["attempt"] == 2 and rows[1]["details"]["reflown_after"] == ["redo"]
    journal = _journal(db)
    (redo,) = [e for e in journal if e["kind"] == "redo"]
    assert (redo["scenario"], redo["trial_index"], redo["data"]["record"]["outcome"]) == ("gps", 1, "landed")
    assert [e["kind"] for e in journal].count("flight") == 5 and journal[0]["kind"] == "start"
    # The IR-LOCK trials land on the pad, 2 m north of the start: the next trial first flies back.
    hops = [e for e in journal if e["kind"] == "reposition"]
    after_ir = [h for h in hops if (h["scenario"], h["trial_index"]) == ("ir", 1)]
    assert after_ir[0]["data"]["flown"] and 1.5 <= after_ir[0]["data"]["before_m"] <= 2.5
    assert after_ir[0]["data"]["after_m"] <= 0.5
    # The report's table shows the field rows beside the simulated ones of the same campaign.
    from preland_app.campaign.report import markdown_table, summarize

    assert preland.run_campaign(campaign, db=db, workers=1).ran == 4
    with ResultsStore(db) as store:
        table = markdown_table("fc", summarize(store, "fc"))
    rows_shown = [line.split(" | ")[0] for line in table.splitlines() if line.startswith("| gps") or
                  line.startswith("| ir")]
    assert rows_shown == ["| gps", "| gps [field]", "| ir", "| ir [field]"]


class SwappingOperator:
    """An operator who swaps the face's battery when asked to."""

    def __init__(self, served):
        self.served = served
        self.pauses = []

    def confirm(self, pause, message):
        self.pauses.append((pause, message))
        if pause is Pause.BATTERY:
            _on_face(self.served, lambda simulator: setattr(simulator, "battery_used_mah", 0.0))
        return True

    def measure(self, *, scenario, trial_index):
        raise AssertionError("measured by truth in this test")


def test_a_low_battery_pauses_at_the_next_landing_and_the_campaign_goes_on_after_the_swap(tmp_path):
    campaign = _campaign(tmp_path, "trials: 2\nfield: {battery_swap_pct: 35, between_trials: operator}\n"
                                   "scenarios: [{label: gps, land: normal}]\n")
    db = tmp_path / "battery.db"
    served = _served(paced=True)
    capacity_mah = served.simulator.environment.airframe.battery_capacity_mah
    served.simulator.battery_used_mah = 0.64 * capacity_mah  # 36 %: one flight takes it below 35 %
    operator = SwappingOperator(served)
    try:
        run = preland.run_campaign(campaign, db=db, runtime=_url(served), options={"paced": True},
                                   operator=operator)
    finally:
        served.stop()
    assert (run.ran, run.total) == (2, 2)
    # The swap first, then the operator carries the vehicle back for the next trial.
    assert [pause for pause, _ in operator.pauses] == [Pause.BATTERY, Pause.CARRY_BACK]
    assert operator.pauses[0][1].endswith("% is below the swap threshold 35 %: swap it")
    assert operator.pauses[1][1] == "carry the vehicle back to the start for gps #1"
    first, second = _trials(db)
    assert first["details"]["battery_remaining_pct"] < 35 <= second["details"]["battery_remaining_pct"]
    assert all(r["source"] == "sim" and r["details"]["measured_by"] == "truth" for r in (first, second))
    kinds = [(e["kind"], e["data"].get("pause")) for e in _journal(db)]
    assert ("paused", "battery") in kinds and ("resumed", "battery") in kinds


def test_a_low_battery_stops_a_rehearsal_that_resumes_after_the_swap(tmp_path):
    campaign = _campaign(tmp_path, "trials: 2\nfield: {battery_swap_pct: 35}\n"
                                   "scenarios: [{label: gps, land: normal}]\n")
    answers = _answers(tmp_path, "gps,0,12,,\ngps,1,14,,\n")
    db = tmp_path / "rehearsal.db"
    served = _served(paced=True)
    served.simulator.battery_used_mah = 0.64 * served.simulator.environment.airframe.battery_capacity_mah
    args = ["campaign", "run", campaign, "--db", str(db), "--runtime", _url(served), "--paced", "--answers", answers]
    try:
        paused = CliRunner().invoke(app, args)
        _on_face(served, lambda simulator: setattr(simulator, "battery_used_mah", 0.0))
        resumed = CliRunner().invoke(app, [*args, "--resume"])
    finally:
        served.stop()
    assert paused.exit_code == 3, paused.output
    assert "preland: paused: battery" in paused.output and "1 of 2 trials stored: run again with --resume" \
        in paused.output
    assert resumed.exit_code == 0, resumed.output
    assert [r["landing_error_cm"] for r in _trials(db)] == [12.0, 14.0]


def test_a_pilot_takeover_ends_that_trial_and_pauses_and_the_campaign_resumes(tmp_path):
    campaign = _campaign(tmp_path, "trials: 3\nscenarios: [{label: gps, land: normal}]\n")
    db = tmp_path / "takeover.db"
    served = _served(paced=False)
    flown = threading.Event()

    def pilot():
        # Two vehicle seconds into the first flight the pilot flips the mode switch.
        until(lambda: served.simulator.autopilot.landed_state().name == "IN_AIR", timeout_s=PATIENCE_S,
              what="the first take-off")
        take_off_s = served.simulator.time_s
        until(lambda: served.simulator.time_s > take_off_s + 2.0, timeout_s=PATIENCE_S, what="two seconds of flight")
        _on_face(served, lambda simulator: simulator.autopilot.set_mode(FlightMode.LOITER))
        flown.set()

    watcher = threading.Thread(target=pilot, daemon=True)
    watcher.start()
    args = ["campaign", "run", campaign, "--db", str(db), "--runtime", _url(served), "--quiet"]
    try:
        paused = CliRunner().invoke(app, args)
        assert flown.wait(PATIENCE_S)
        _land_on_face(served)
        resumed = CliRunner().invoke(app, [*args, "--resume"])
    finally:
        served.stop()
    assert paused.exit_code == 3, paused.output
    assert "preland: paused: pilot_takeover (pilot takeover: mode LOITER" in paused.output
    assert resumed.exit_code == 0, resumed.output
    rows = _trials(db)
    assert [r["outcome"] for r in rows] == ["pilot_takeover", "landed", "landed"]
    assert rows[0]["landing_error_cm"] is None and all(r["landing_error_cm"] is not None for r in rows[1:])


def test_a_campaign_killed_mid_flight_resumes_without_losing_or_repeating_a_trial(tmp_path):
    campaign = _campaign(tmp_path, "trials: 3\nscenarios: [{label: gps, land: normal}]\n")
    answers = _answers(tmp_path, "gps,0,10,,\ngps,1,11,,\ngps,2,12,,\n")
    db = tmp_path / "killed.db"
    served = _served(paced=False)
    args = ["campaign", "run", campaign, "--db", str(db), "--runtime", _url(served), "--answers", answers]

    def second_flight_in_the_air() -> bool:
        if not db.exists():
            return False
        try:
            with sqlite3.connect(db) as connection:
                flights = connection.execute("SELECT COUNT(*) FROM field_log WHERE kind = 'flight'").fetchone()[0]
        except sqlite3.OperationalError:  # the campaign has not made its tables yet
            return False
        return flights == 2 and served.simulator.autopilot.landed_state().name == "IN_AIR"

    try:
        process = subprocess.Popen([sys.executable, "-m", "preland_app.cli", *args, "--quiet"],
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            until(second_flight_in_the_air, timeout_s=PATIENCE_S, what="the second flight to take off")
        finally:
            process.send_signal(signal.SIGKILL)
            process.wait(timeout=PATIENCE_S)
        _land_on_face(served)  # the pilot lands the vehicle the dead laptop left hovering
        resumed = CliRunner().invoke(app, [*args, "--resume"])
    finally:
        served.stop()
    assert resumed.exit_code == 0, resumed.output
    rows = _trials(db)
    assert [(r["trial_index"], r["landing_error_cm"]) for r in rows] == [(0, 10.0), (1, 11.0), (2, 12.0)]
    assert rows[1]["details"]["reflown_after"] == ["interrupted"] and rows[1]["details"]["attempt"] == 2
    assert "reflown_after" not in rows[0]["details"] and "reflown_after" not in rows[2]["details"]
    interrupted = [e for e in _journal(db) if e["kind"] == "interrupted"]
    assert [(e["trial_index"], e["data"]["attempt"]) for e in interrupted] == [(1, 1)]


# ---------------------------------------------------------------- the parts, without a vehicle


def test_the_terminal_operator_asks_again_until_an_answer_is_usable():
    from preland_app.field.operator import TerminalOperator

    typed = iter(["far", "12.5", "10 5", "12 3", "redo", "abort"])
    said = []
    operator = TerminalOperator(ask=lambda prompt: next(typed), say=said.append)
    assert operator.measure(scenario="gps", trial_index=0) == Measurement(verdict=Verdict.MEASURED, error_cm=12.5,
                                                                          x_cm=12.0, y_cm=3.0)
    assert said == ["error: 'far' is not a number, skip, redo or abort",
                    "offsets: their length 11.2 cm is not the error 12.5 cm; measure again"]
    assert operator.measure(scenario="gps", trial_index=1).verdict is Verdict.REDO
    assert operator.confirm(Pause.BATTERY, "battery 30 % is below the swap threshold 35 %: swap it") is False


def test_a_shuffled_order_is_drawn_from_the_campaigns_seed_and_keeps_every_trial_once(tmp_path):
    from preland_app.campaign.spec import load_campaign, resolve_scenarios
    from preland_app.campaign.trials import plan_trials
    from preland_app.field.campaign import Order, trial_order

    campaign = load_campaign(_campaign(tmp_path, "trials: 5\nscenarios: [{label: a, land: normal}, "
                                                  "{label: b, land: irlock}]\n"))
    plan = list(plan_trials(campaign, resolve_scenarios(campaign)))
    shuffled = trial_order(plan, order=Order.SHUFFLED, seed=campaign.base_seed)
    assert [j.key for j in trial_order(plan, order=Order.CAMPAIGN, seed=7)] == [j.key for j in plan]
    assert sorted(j.key for j in shuffled) == sorted(j.key for j in plan)
    assert [j.key for j in shuffled] != [j.key for j in plan]
    assert [j.key for j in trial_order(plan, order=Order.SHUFFLED, seed=7)] == [j.key for j in shuffled]
    assert [j.key for j in trial_order(plan, order=Order.SHUFFLED, seed=8)] != [j.key for j in shuffled]


def test_measure_vehicle_takes_the_final_position_against_the_surveyed_pad(tmp_path):
    from preland_app.campaign.field_spec import SurveyedPoint
    from preland_app.field.campaign import vehicle_measurement
    from preland_app.geo import GeoPoint, LocalTangentPlane
    from preland_app.outcome import Outcome, TrialOutcome

    pad = SurveyedPoint(latitude_deg=-35.3632621, longitude_deg=149.1652374)
    landed = LocalTangentPlane(GeoPoint(pad.latitude_deg, pad.longitude_deg, 0.0)).to_geodetic(
        north_m=0.03, east_m=-0.04, down_m=0.0)
    outcome = TrialOutcome(outcome=Outcome.LANDED, message="", seed=1, mission="m", land_mode="marker",
                           takeoff_altitude_rel_m=10.0, scoring_reference="pad",
                           details={"final_latitude_deg": landed.latitude_deg,
                                    "final_longitude_deg": landed.longitude_deg})
    measured = vehicle_measurement(outcome, pad=pad)
    assert measured.verdict is Verdict.MEASURED
    assert measured.error_cm == pytest.approx(5.0, abs=0.01)
    assert (measured.x_cm, measured.y_cm) == (pytest.approx(3.0, abs=0.01), pytest.approx(-4.0, abs=0.01))
    silent = TrialOutcome(outcome=Outcome.LANDED, message="", seed=1, mission="m", land_mode="marker",
                          takeoff_altitude_rel_m=10.0, scoring_reference="pad")
    assert vehicle_measurement(silent, pad=pad).verdict is Verdict.SKIP


@pytest.mark.parametrize("body, args, line", [
    ("scenarios: [{label: gps, land: normal}]\n", ["--measure", "vehicle"],
     "{campaign}, field.pad: --measure vehicle needs the pad's surveyed position (latitude_deg, longitude_deg)"),
    ("scenarios: [{label: ir, land: irlock}]\n", ["--no-truth", "--answers", "{answers}"],
     "{campaign}, scenario 'ir': land mode 'irlock' reads preland's IR-LOCK model, which needs a simulated "
     "vehicle's ground truth (fly its marker scenarios on a drone)"),
    ("scenarios: [{label: mk, land: marker}]\n", ["--no-truth", "--answers", "{answers}"],
     "{campaign}, scenario 'mk': land mode 'marker' reads camera frames: give the drone's camera with --camera"),
    ("scenarios: [{label: gps, land: normal}]\n", ["--no-truth"],
     "--answers: needed to measure by operator with nobody to ask (no terminal)"),
    ("scenarios: [{label: gps, land: normal}]\n", ["--measure", "truth", "--answers", "{answers}"],
     "--answers: answers are the operator's measurements, not with --measure truth"),
    ("scenarios: [{label: gps, land: normal}]\n", ["--order", "random"],
     "--order: 'random' is not one of campaign, shuffled"),
])
def test_a_field_campaign_that_cannot_fly_as_asked_is_refused_before_it_connects(tmp_path, body, args, line):
    campaign = _campaign(tmp_path, "trials: 1\n" + body)
    answers = _answers(tmp_path, "")
    args = [a.format(answers=answers) for a in args]
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "r.db"),
                                      "--runtime", "mavlink+udpout://127.0.0.1:9", *args])
    assert result.exit_code == 2, result.output
    assert result.output.strip() == "preland: error: " + line.format(campaign=campaign)


def test_a_preflight_refusal_pauses_without_a_trial_and_the_trial_flies_after_the_fix(tmp_path):
    campaign = _campaign(tmp_path, "trials: 1\nscenarios: [{label: ir, land: irlock}]\n")
    db = tmp_path / "refused.db"
    served = ServedSimulator(preland.load_mission(SHORT_MISSION), seed=2, paced=True)  # PLND_* still 0
    args = ["campaign", "run", campaign, "--db", str(db), "--runtime", _url(served), "--paced", "--quiet"]
    try:
        paused = CliRunner().invoke(app, args)
        stored_while_paused = _trials(db)

        def set_plnd(simulator):
            simulator.params.set("PLND_ENABLED", 1)
            simulator.params.set("PLND_TYPE", 1)

        _on_face(served, set_plnd)
        resumed = CliRunner().invoke(app, [*args, "--resume"])
    finally:
        served.stop()
    assert paused.exit_code == 3, paused.output
    assert "preland: paused: preflight: PLND_ENABLED is 0, must be 1" in paused.output
    assert stored_while_paused == []
    assert resumed.exit_code == 0, resumed.output
    (row,) = _trials(db)
    assert row["outcome"] == "landed" and row["details"]["attempt"] == 1 and "reflown_after" not in row["details"]
    assert [e["kind"] for e in _journal(db)] == ["start", "flight", "refused", "paused", "flight"]


def test_abort_keeps_the_landed_trial_as_not_measured_and_stops_until_resumed(tmp_path):
    campaign = _campaign(tmp_path, "trials: 2\nscenarios: [{label: gps, land: normal}]\n")
    answers = _answers(tmp_path, "gps,0,abort,,\ngps,1,7.5,,\n")
    db = tmp_path / "abort.db"
    served = _served(paced=True)
    args = ["campaign", "run", campaign, "--db", str(db), "--runtime", _url(served), "--paced", "--quiet",
            "--answers", answers]
    try:
        aborted = CliRunner().invoke(app, args)
        resumed = CliRunner().invoke(app, [*args, "--resume"])
    finally:
        served.stop()
    assert aborted.exit_code == 3, aborted.output
    assert "preland: aborted by the operator after the landing (stored as not measured); 1 of 2" \
        in aborted.output
    assert resumed.exit_code == 0, resumed.output
    first, second = _trials(db)
    assert (first["outcome"], first["landing_error_cm"], first["details"]["measured"]) == ("landed", None, False)
    assert first["details"]["not_measured_because"] == "aborted" and second["landing_error_cm"] == 7.5
