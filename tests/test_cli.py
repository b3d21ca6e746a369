"""The CLI, in-process."""

import json

from typer.testing import CliRunner

from preland_app.cli import app

from .conftest import THESIS_MISSION

REQUIRED = {"outcome", "landing_error_cm", "offset_north_cm", "offset_east_cm", "landing_time_s", "seed"}


def test_fly_json_prints_one_object_with_the_outcome_keys():
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--seed", "5", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert REQUIRED <= set(data)
    assert data["outcome"] == "landed" and data["seed"] == 5
    assert 0 < data["landing_error_cm"] < 300
    assert abs((data["offset_north_cm"] ** 2 + data["offset_east_cm"] ** 2) ** 0.5 - data["landing_error_cm"]) < 0.05


def test_fly_table_and_takeoff_override():
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--seed", "5", "--takeoff-altitude-m", "6",
                                      "--events"])
    assert result.exit_code == 0, result.output
    assert "landing error" in result.stdout and "6.0 m" in result.stdout
    assert "waypoint 4 reached" in result.stdout


def test_every_command_has_help():
    runner = CliRunner()
    for args in ([], ["fly"], ["modes"], ["pad"], ["pad", "render"]):
        result = runner.invoke(app, [*args, "--help"])
        assert result.exit_code == 0
        assert "Usage" in result.stdout


def test_modes_lists_every_land_mode_with_its_scoring_reference():
    result = CliRunner().invoke(app, ["modes"])
    assert result.exit_code == 0
    header, *rows = result.stdout.splitlines()
    assert header.split() == ["mode", "from", "scored", "from", "sensor", "description"]
    lines = {line.split()[0]: line.split() for line in rows}
    precision = ("irlock", "marker", "fused", "cautious", "paper_static", "paper_adaptive")
    assert {"normal", *precision} <= set(lines)  # and any plugin installed here
    assert lines["normal"][1:4] == ["built-in", "takeoff", "GPS"]
    assert all(lines[m][1:3] == ["built-in", "pad"] for m in precision)
    assert lines["fused"][3] == "fused" and lines["paper_static"][3] == "marker"


def test_fly_wind_overrides():
    import json

    runner = CliRunner()
    mission = str(THESIS_MISSION)
    calm = runner.invoke(app, ["fly", mission, "--json", "--seed", "4", "--wind-m-s", "0", "--wind-from-deg", "90"])
    assert calm.exit_code == 0, calm.output
    windy = runner.invoke(app, ["fly", mission, "--json", "--seed", "4", "--wind-m-s", "8", "--wind-from-deg", "90"])
    calm, windy = json.loads(calm.stdout), json.loads(windy.stdout)
    assert calm["details"]["wind_from_deg"] == windy["details"]["wind_from_deg"] == 90.0
    assert calm["landing_error_cm"] != windy["landing_error_cm"]
    result = runner.invoke(app, ["fly", mission, "--wind-m-s", "-1"])
    assert result.exit_code == 2 and "--wind-m-s" in result.stderr
    result = runner.invoke(app, ["fly", mission, "--wind-from-deg", "400"])
    assert result.exit_code == 2 and "--wind-from-deg" in result.stderr
    result = runner.invoke(app, ["fly", mission, "--wind-m-s", "3", "--connect", "udp://:14550"])
    assert result.exit_code == 2 and "real one" in result.stderr
