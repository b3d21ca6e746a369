"""Bad mission files: one line naming the file and the field, exit code 2, no traceback."""

from pathlib import Path

import pytest
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.config.mission import load_mission
from preland_app.errors import SpecError

from .conftest import THESIS_MISSION

GOOD = THESIS_MISSION.read_text()


def _variant(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return path


CASES = {
    "malformed_yaml": (GOOD.replace("  altitude_rel_m: 10.0", "  altitude_rel_m: [10.0"), "", "malformed YAML"),
    "missing_field": (GOOD.replace("  altitude_rel_m: 10.0\n", ""), "takeoff.altitude_rel_m", "missing required field"),
    "wrong_type": (GOOD.replace("altitude_rel_m: 10.0", "altitude_rel_m: ten"), "takeoff.altitude_rel_m",
                   "expected a number"),
    "unknown_land_mode": (GOOD.replace("mode: normal", "mode: teleport"), "land.mode", "unknown land mode 'teleport'"),
    "negative_altitude": (GOOD.replace("altitude_rel_m: 10.0", "altitude_rel_m: -5"), "takeoff.altitude_rel_m",
                          "must be > 0"),
    "unknown_key": (GOOD.replace("land:\n", "land:\n  speeed: 3\n"), "land.speeed", "unknown key"),
    "bad_waypoint": (GOOD.replace("- [-2.0, 2.0]", "- [-2.0]"), "path.waypoints_rel_ned_m[1]",
                     "expected a list of 2 values"),
    "unknown_param": (GOOD + "params:\n  LAND_SPEEED: 30\n", "params.LAND_SPEEED", "unknown autopilot parameter"),
    "top_level_list": ("- 1\n- 2\n", "", "expected a mapping at the top level"),
    # the take-off and target-shaping parameters only the embedded copter-4.6 model uses
    "param_of_another_firmware": (GOOD + "params:\n  TKOFF_SLEW_TIME: 3\n", "params.TKOFF_SLEW_TIME",
                                  "used only with `environment.autopilot.firmware: copter-4.6`; this mission's is "
                                  "copter-4.0"),
    # YAML reads an unquoted 4.6 as a number, which names no release: the line says which names do.
    "firmware_as_number": (GOOD + "environment:\n  autopilot:\n    firmware: 4.6\n", "environment.autopilot.firmware",
                           "one of copter-4.0, copter-4.6"),
    "misspelt_detector_parameter": (GOOD + "sensors:\n  marker:\n    detector: {adaptivethreshwinsizemax: 13}\n",
                                    "sensors.marker.detector.adaptivethreshwinsizemax",
                                    "did you mean adaptiveThreshWinSizeMax?"),
    "detector_parameter_type": (GOOD + "sensors:\n  marker:\n    detector: {useAruco3Detection: 1}\n",
                                "sensors.marker.detector.useAruco3Detection", "expected true or false"),
    "detector_refused_by_opencv": (GOOD + "sensors:\n  marker:\n    detector: {adaptiveThreshWinSizeStep: 0}\n",
                                   "sensors.marker.detector", "OpenCV refuses them"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_mission_file_gives_one_clear_line(tmp_path, case):
    text, field, problem = CASES[case]
    path = _variant(tmp_path, text)
    result = CliRunner().invoke(app, ["fly", str(path)])
    assert result.exit_code == 2
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1, message
    assert "Traceback" not in result.output
    assert str(path) in message
    assert field in message
    assert problem in message


@pytest.mark.parametrize("case", sorted(CASES))
def test_loader_raises_spec_error_with_field(tmp_path, case):
    text, field, _ = CASES[case]
    with pytest.raises(SpecError) as info:
        load_mission(_variant(tmp_path, text))
    assert info.value.field.startswith(field) if field else True
    assert info.value.path.endswith("mission.yaml")


def test_missing_file_and_bad_options(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["fly", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 2 and "file not found" in result.stderr
    result = runner.invoke(app, ["fly", str(THESIS_MISSION), "--land", "teleport"])
    assert result.exit_code == 2 and "--land" in result.stderr and "normal" in result.stderr
    result = runner.invoke(app, ["fly", str(THESIS_MISSION), "--takeoff-altitude-m", "-3"])
    assert result.exit_code == 2 and "--takeoff-altitude-m" in result.stderr


def test_thesis_mission_loads_with_the_sources_numbers():
    mission = load_mission(THESIS_MISSION)
    assert mission.takeoff.altitude_rel_m == 10.0
    assert mission.pad.offset_from_start_ned_m == (2.0, 0.0)
    legs = [mission.path.waypoints_rel_ned_m[0]] + [
        (b[0] - a[0], b[1] - a[1]) for a, b in zip(mission.path.waypoints_rel_ned_m, mission.path.waypoints_rel_ned_m[1:])
    ]
    assert [abs(n) + abs(e) for n, e in legs] == [2.0, 2.0, 2.0, 2.0]
    assert mission.path.waypoints_rel_ned_m[-1] == (0.0, 0.0)


@pytest.mark.parametrize("content, problem", [
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xd8", "not a UTF-8 text file (byte 0x89 at offset 0)"),
    ("name: x\n".encode("utf-16"), "not a UTF-8 text file"),
    (b"name: x\x00\x01\x02\n", "character #x0000 is not allowed in YAML text"),
])
def test_a_binary_mission_or_campaign_file_gives_one_line(tmp_path, content, problem):
    path = tmp_path / "binary.yaml"
    path.write_bytes(content)
    runner = CliRunner()
    for args in (["fly", str(path)], ["campaign", "run", str(path), "--db", str(tmp_path / "r.db")],
                 ["sim", "serve", "--mission", str(path)]):
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        message = result.stderr.strip()
        assert len(message.splitlines()) == 1 and "Traceback" not in result.output, message
        assert message.startswith(f"preland: error: {path}: ") and problem in message, message


def test_a_copter_4_6_parameter_loads_when_the_mission_flies_copter_4_6(tmp_path):
    text = GOOD + "params:\n  PSC_JERK_XY: 8\nenvironment:\n  autopilot:\n    firmware: copter-4.6\n"
    mission = load_mission(_variant(tmp_path, text))
    assert mission.params == {"PSC_JERK_XY": 8.0}
