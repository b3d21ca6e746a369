"""Land-mode plugins: by import path and by entry point, with options, in campaigns, and when they fail."""

import asyncio
import json
import sys
import textwrap

import pytest
from typer.testing import CliRunner

from preland_app.campaign.driver import run_campaign
from preland_app.campaign.spec import load_campaign
from preland_app.campaign.store import ResultsStore
from preland_app.cli import app
from preland_app.config.mission import load_mission
from preland_app.errors import SpecError
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial

from .conftest import ROOT, THESIS_MISSION

MODULE = "preland_test_plugins"
PLUGINS = '''
"""Test plugins: a GPS landing of their own, one that needs an option, one that raises, one that never returns."""

from preland_app.clock import wait_until
from preland_app.landing import LandingReport, ScoringReference
from preland_app.vehicle.types import FlightMode


class GpsLand:
    """LAND on GPS, after `settle_s` vehicle seconds of hover; scored from the pad."""

    name = "gps_land"
    scoring_reference = ScoringReference.PAD
    uses_irlock = False
    uses_marker = False

    def __init__(self, *, settle_s: float = 0.0, note: str = "") -> None:
        if settle_s < 0:
            raise ValueError("settle_s must be >= 0")
        self.settle_s, self.note = settle_s, note

    async def land(self, context):
        if self.settle_s > 0:
            await context.clock.sleep(self.settle_s)
        await context.vehicle.set_mode(FlightMode.LAND)

        async def disarmed():
            return not (await context.vehicle.telemetry()).armed

        await wait_until(disarmed, clock=context.clock, timeout_s=context.timeout_s, operation="land")
        return LandingReport(details={"settle_s": self.settle_s, "note": self.note})


class NeedsGain(GpsLand):
    """Needs its gain."""

    def __init__(self, *, gain: float) -> None:
        super().__init__()
        self.gain = gain


class Raises(GpsLand):
    """Fails half-way down."""

    name = "raises"

    async def land(self, context):
        await context.vehicle.set_mode(FlightMode.LAND)
        await context.clock.sleep(2.0)
        raise RuntimeError("the plugin broke")


class Never(GpsLand):
    """Hovers for ever."""

    name = "never"

    async def land(self, context):
        while True:
            await context.clock.sleep(1.0)


class NotAStrategy:
    """Has no land()."""

    name = "not_a_strategy"
'''


@pytest.fixture(scope="module")
def plugins(tmp_path_factory):
    """A plugin module on sys.path (campaign workers get the parent's sys.path as it is when they start)."""
    folder = tmp_path_factory.mktemp("plugins")
    (folder / f"{MODULE}.py").write_text(PLUGINS)
    (folder / "preland_broken_plugin.py").write_text("RATE = 1 / 0\n")
    sys.path.insert(0, str(folder))
    yield folder
    sys.path.remove(str(folder))
    for name in (MODULE, "preland_broken_plugin"):
        sys.modules.pop(name, None)


def fly_cli(*args: str):
    return CliRunner().invoke(app, ["fly", *args])


def test_a_plugin_by_import_path_lands_as_the_built_in_mode_it_copies(plugins, thesis_mission):
    """GpsLand does what `normal` does: same seed, same touchdown, same landing time; scored from the pad."""
    result = fly_cli(str(THESIS_MISSION), "--land", f"{MODULE}:GpsLand", "--seed", "4", "--json")
    assert result.exit_code == 0, result.output
    plugin = json.loads(result.stdout)
    normal = run_trial(TrialRequest(mission=thesis_mission, seed=4)).to_dict()
    assert plugin["outcome"] == "landed" and plugin["land_mode"] == f"{MODULE}:GpsLand"
    assert plugin["scoring_reference"] == "pad" and normal["scoring_reference"] == "takeoff"
    # The pad is 2 m north of the take-off point.
    assert plugin["offset_north_cm"] == pytest.approx(normal["offset_north_cm"] - 200.0, abs=0.02)
    assert plugin["offset_east_cm"] == pytest.approx(normal["offset_east_cm"], abs=0.02)
    # Landing time runs from the hand-over the mission runner records, for a plugin as for a built-in.
    assert plugin["landing_time_s"] == normal["landing_time_s"] and 15 < plugin["landing_time_s"] < 30
    assert plugin["details"]["settle_s"] == 0.0


def _mission_with_land(tmp_path, land: str, *, land_s: float = 240) -> str:
    text = THESIS_MISSION.read_text().replace("land:\n  mode: normal\n", land).replace("land_s: 240",
                                                                                        f"land_s: {land_s:g}")
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return str(path)


def test_land_params_from_a_mission_file_reach_the_class(plugins, tmp_path, thesis_mission):
    land = f"land:\n  mode: {MODULE}:GpsLand\n  params: {{settle_s: 3, note: hovered}}\n"
    path = _mission_with_land(tmp_path, land)
    result = fly_cli(path, "--seed", "4", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["details"]["settle_s"] == 3.0 and data["details"]["note"] == "hovered"  # 3 became a float
    normal = run_trial(TrialRequest(mission=thesis_mission, seed=4))
    assert data["landing_time_s"] > normal.landing_time_s + 2.5  # the hover counts: it is the land mode's time


@pytest.mark.parametrize("land, field, problem", [
    ("  mode: {m}:GpsLand\n  params: {{setle_s: 3}}\n", "land.params.setle_s", "unknown keyword"),
    ("  mode: {m}:GpsLand\n  params: {{settle_s: soon}}\n", "land.params.settle_s", "expected a number, got 'soon'"),
    ("  mode: {m}:NeedsGain\n", "land.params.gain", "missing"),
    ("  mode: {m}:GpsLand\n  params: {{settle_s: -1}}\n", "land.params", "ValueError: settle_s must be >= 0"),
    ("  mode: {m}:NotAStrategy\n", "land.mode", "is not a LandStrategy"),
    ("  mode: {m}:Nope\n", "land.mode", f"module '{MODULE}' has no 'Nope'"),
    ("  mode: preland_no_such_module:Landing\n", "land.mode", "no module named 'preland_no_such_module'"),
    ("  mode: preland_broken_plugin:Landing\n", "land.mode", "ZeroDivisionError: division by zero"),
    ("  mode: proportionl\n", "land.mode", "unknown land mode 'proportionl'"),
    ("  mode: marker\n  params: {{gain: 1}}\n", "land.params", "takes no params"),
])
def test_a_bad_plugin_or_bad_options_give_one_line_and_exit_2(plugins, tmp_path, land, field, problem):
    path = _mission_with_land(tmp_path, "land:\n" + land.format(m=MODULE))
    result = fly_cli(path)
    assert result.exit_code == 2, result.output
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in result.output, message
    assert f"{path}: {field}" in message and problem in message, message


def test_land_option_errors_name_the_option(plugins):
    for land, problem in ((f"{MODULE}:Nope", "has no 'Nope'"), ("preland_no_such_module:X", "no module named"),
                          (f"{MODULE}:NeedsGain", "land.params.gain: missing")):
        result = fly_cli(str(THESIS_MISSION), "--land", land)
        assert result.exit_code == 2, result.output
        assert result.stderr.count("\n") == 1 and "--land" in result.stderr and problem in result.stderr


def test_an_exception_in_land_ends_the_trial_as_error(plugins):
    result = fly_cli(str(THESIS_MISSION), "--land", f"{MODULE}:Raises", "--json")
    assert result.exit_code == 1
    data = json.loads(result.stdout)
    assert data["outcome"] == "error"
    assert data["message"].startswith("land mode 'raises' raised RuntimeError: the plugin broke (at ")
    assert f"{MODULE}.py:" in data["message"]


def test_a_land_that_never_returns_ends_at_the_land_timeout(plugins, tmp_path):
    mission = load_mission(_mission_with_land(tmp_path, "land:\n  mode: normal\n", land_s=30))
    outcome = run_trial(TrialRequest(mission=mission, seed=2, land_mode=f"{MODULE}:Never"))
    assert outcome.outcome is Outcome.TIMED_OUT
    assert outcome.message.startswith("land: not done after 30 s (land mode never still running; mode GUIDED")
    handover = next(e for e in outcome.events if e.kind == "land_handover")
    assert outcome.trajectory[-1][0] - handover.time_s == pytest.approx(30.0, abs=0.2)


def test_a_plugin_campaign_on_two_workers(plugins, tmp_path):
    """Spawned workers import the plugin; land_params reach it; a raising plugin is that trial's error and the
    campaign goes on."""
    mission = _mission_with_land(tmp_path, "land:\n  mode: normal\n", land_s=60)
    path = tmp_path / "campaign.yaml"
    path.write_text(textwrap.dedent(f"""\
        name: plugins
        mission: {mission}
        trials: 2
        base_seed: 5
        scenarios:
          - {{label: settled, land: "{MODULE}:GpsLand", land_params: {{settle_s: 2, note: w}}}}
          - {{label: broken, land: "{MODULE}:Raises", trials: 1}}
          - {{label: gps, land: normal, trials: 1}}
        """))
    campaign = load_campaign(path)
    with ResultsStore(tmp_path / "results.db") as store:
        ran, total = run_campaign(campaign, store, workers=2)
        rows = {(row["scenario"], row["trial_index"]): row for row in store.trials("plugins")}
    assert ran == total == 4
    settled = [rows["settled", 0], rows["settled", 1]]
    assert all(row["outcome"] == "landed" and row["land_mode"] == f"{MODULE}:GpsLand" for row in settled)
    assert all(row["details"]["settle_s"] == 2.0 and row["details"]["note"] == "w" for row in settled)
    assert all(row["scoring_reference"] == "pad" and 100 < row["landing_error_cm"] < 400 for row in settled)
    broken = rows["broken", 0]
    assert broken["outcome"] == "error" and "raised RuntimeError: the plugin broke" in broken["message"]
    assert rows["gps", 0]["outcome"] == "landed"
    # The same trial in this process, from the same seed: the workers flew it exactly so.
    again = run_trial(TrialRequest(mission=campaign_mission(campaign, 0), seed=settled[0]["seed"]))
    assert round(again.landing_error_cm, 2) == settled[0]["landing_error_cm"]


def campaign_mission(campaign, index):
    from preland_app.campaign.spec import resolve_scenarios

    return resolve_scenarios(campaign)[index].mission


@pytest.mark.parametrize("scenario, field, problem", [
    (f'{{label: a, land: "{MODULE}:GpsLand", land_params: {{settle: 2}}}}', "scenarios[0].land_params.settle",
     "unknown keyword"),
    (f'{{label: a, land: "{MODULE}:NeedsGain"}}', "scenarios[0].land_params.gain", "missing"),
    ('{label: a, land: "preland_no_such_module:X"}', "scenarios[0].land", "no module named"),
])
def test_bad_plugin_scenarios_give_one_line_and_exit_2(plugins, tmp_path, scenario, field, problem):
    path = tmp_path / "campaign.yaml"
    path.write_text(f"name: bad\nmission: {THESIS_MISSION}\nscenarios:\n  - {scenario}\n")
    with pytest.raises(SpecError) as info:
        load_campaign(path)
    assert info.value.field == field and problem in info.value.problem
    result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(tmp_path / "r.db")])
    assert result.exit_code == 2 and f"{path}: {field}" in result.stderr and result.stderr.count("\n") == 1


# --- the example package, found by its entry point ------------------------------------------------

EXAMPLE = ROOT / "examples" / "preland-proportional"


@pytest.fixture
def proportional_installed(tmp_path, monkeypatch):
    """What `pip install examples/preland-proportional` leaves for importlib.metadata: a dist-info with the
    entry point (the package itself from the source folder)."""
    dist = tmp_path / "preland_proportional-0.1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: preland-proportional\nVersion: 0.1.0\n")
    entry_points = (EXAMPLE / "pyproject.toml").read_text().split('[project.entry-points."preland.land_modes"]\n')[1]
    entry_point = entry_points.split("\n\n")[0].replace('"', "")  # TOML's quotes: entry_points.txt has none
    (dist / "entry_points.txt").write_text(f"[preland.land_modes]\n{entry_point}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLE))
    yield
    sys.modules.pop("preland_proportional", None)


def test_the_example_plugin_lands_by_its_short_name(proportional_installed):
    result = fly_cli(str(THESIS_MISSION), "--land", "proportional", "--seed", "1", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["outcome"] == "landed" and data["scoring_reference"] == "pad"
    assert data["landing_error_cm"] < 30.0 and 10.0 < data["landing_time_s"] < 30.0
    assert data["takeoff_altitude_rel_m"] == 6.0  # it uses the marker: the thesis' marker altitude
    assert data["details"]["frames_with_marker"] > 0.9 * data["details"]["frames"]


def test_the_example_plugin_applies_the_missions_faults(proportional_installed, thesis_mission):
    """The sensor suite drops a plugin's readings as the mission's faults say (the built-ins apply their own)."""
    outcome = run_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode="proportional",
                                     faults={"marker": "random:0.5"}))
    assert outcome.outcome is Outcome.LANDED and outcome.landing_error_cm < 30.0
    details = outcome.details
    assert details["marker_fault"] == "random:0.5" and 0.4 < details["marker_dropped"] / details["marker_produced"] < 0.6
    assert details["frames_with_marker"] == details["marker_produced"] - details["marker_dropped"]


def test_modes_lists_installed_plugins_in_aligned_columns(proportional_installed, tmp_path):
    broken = tmp_path / "preland_broken-1.0.dist-info"  # an installed plugin whose module is gone
    broken.mkdir()
    (broken / "METADATA").write_text("Metadata-Version: 2.1\nName: preland-broken\nVersion: 1.0\n")
    (broken / "entry_points.txt").write_text("[preland.land_modes]\nbroken = preland_gone:Landing\n")
    result = CliRunner().invoke(app, ["modes"])
    assert result.exit_code == 0
    lines = result.stdout.splitlines()
    assert lines[0].split()[:2] == ["mode", "from"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert "proportional" in rows and "preland-proportional 0.1.0" in rows["proportional"]
    assert rows["normal"].split()[1] == "built-in"
    for column in ("from", "scored from", "sensor", "description"):
        start = lines[0].index(column)
        assert all(line[start - 2:start] == "  " and line[start] != " " for line in lines[1:]), column
    assert rows["proportional"].split("  ")[-1].startswith("Proportional centring")
    assert "preland-broken 1.0" in rows["broken"] and "cannot be loaded: cannot import 'preland_gone'" in rows["broken"]


def test_the_example_plugin_lands_through_the_mavlink_face(proportional_installed, thesis_mission):
    from .test_mavlink_runtime import fly_paced

    # In lock-step: the plugin's camera frames at their vehicle times however loaded the machine is.
    outcome, served = fly_paced(thesis_mission, seed=1, land_mode="proportional")
    assert outcome.outcome is Outcome.LANDED, outcome.message
    truth = served.simulator.touchdowns()[-1]
    expected_cm = 100 * ((truth.north_m - 2.0) ** 2 + truth.east_m ** 2) ** 0.5  # from SIM_STATE, as in-process
    assert outcome.landing_error_cm == pytest.approx(expected_cm, abs=3.0) and outcome.landing_error_cm < 30.0
    assert outcome.details["frames_with_marker"] > 50
    assert outcome.landing_time_s is not None and 10.0 < outcome.landing_time_s < 40.0


def test_a_plugins_views_give_a_stale_value_again_as_the_built_in_modes_do():
    """Under `stale:1` every value after the first is the first one again: the IR-LOCK view's with the new
    reading's capture time, the detector view's as the detections of that first frame."""
    import numpy as np

    from preland_app.landing.boundary import DetectorView, IrLockView, SensorFaults
    from preland_app.sensing.faults import FaultSpec
    from preland_app.sensing.readings import TargetReading

    class FixedClock:
        def now_s(self) -> float:
            return 0.0

    faults = SensorFaults(faults={"irlock": FaultSpec.parse("stale:1"), "marker": FaultSpec.parse("stale:1")},
                          rng=np.random.default_rng(0), clock=FixedClock())

    class Beacon:
        def __init__(self) -> None:
            self.k = 0

        async def next_reading(self) -> TargetReading:
            self.k += 1
            return TargetReading(sensor="irlock", capture_time_s=0.02 * self.k, angle_x_rad=0.01 * self.k,
                                 angle_y_rad=0.0)

    view = IrLockView(Beacon(), faults)
    first, second, third = (asyncio.run(view.next_reading()) for _ in range(3))
    assert (first.capture_time_s, first.angle_x_rad) == (0.02, 0.01)
    assert (second.capture_time_s, second.angle_x_rad) == (0.04, 0.01)
    assert (third.capture_time_s, third.angle_x_rad) == pytest.approx((0.06, 0.01))

    class Detector:
        def __init__(self) -> None:
            self.k = 0

        def detect(self, image):
            self.k += 1
            return [f"marker seen in frame {self.k}"]

    detector = DetectorView(Detector(), faults)
    assert [detector.detect(None) for _ in range(3)] == [["marker seen in frame 1"]] * 3
    assert faults.details()["irlock_repeated"] == 2 and faults.details()["marker_repeated"] == 2
