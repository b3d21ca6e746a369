"""One runtime interface, chosen by URL: every entry point (fly, campaigns, the Python API) flies through the
same object; a runtime's options are its own; an installed package adds a runtime by entry point."""

from __future__ import annotations

import json
import sqlite3
import textwrap

import pytest
from typer.testing import CliRunner

import preland_app as preland
from preland_app.campaign.trials import derive_seed
from preland_app.cli import app
from preland_app.runtime.base import RuntimeOptionError, RuntimeUrlError, open_runtime, split_url
from preland_app.runtime.embedded import EmbeddedRuntime
from preland_app.runtime.mavlink import MavlinkRuntime
from preland_app.runtime.sitl import SitlOptions, SitlRuntime

from .conftest import THESIS_MISSION
from .test_mavlink_runtime import ServedSimulator


def _campaign(tmp_path, body: str, name: str = "rt") -> str:
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"name: {name}\nmission: {THESIS_MISSION}\nbase_seed: 5\n" + textwrap.dedent(body))
    return str(path)


def _rows(db) -> list[dict]:
    with sqlite3.connect(db) as connection:
        connection.row_factory = sqlite3.Row
        return [dict(r) for r in connection.execute(
            "SELECT scenario, trial_index, seed, outcome, landing_error_cm, landing_time_s, runtime, source "
            "FROM trials ORDER BY scenario, trial_index")]


@pytest.mark.parametrize("url, scheme, target, query", [
    ("sim:", "sim", "", {}),
    ("sitl:/opt/ardupilot/arducopter?speedup=5&defaults=a.parm,b.parm", "sitl", "/opt/ardupilot/arducopter",
     {"speedup": "5", "defaults": "a.parm,b.parm"}),
    ("sitl:", "sitl", "", {}),
    ("mavlink+udpout://127.0.0.1:14550", "mavlink", "mavlink+udpout://127.0.0.1:14550", {}),
    ("mavlink+serial:///dev/ttyAMA0?baud=921600", "mavlink", "mavlink+serial:///dev/ttyAMA0?baud=921600", {}),
    ("udpout://127.0.0.1:14550", "mavlink", "udpout://127.0.0.1:14550", {}),
])
def test_one_parser_reads_every_runtime_url(url, scheme, target, query):
    assert split_url(url) == (scheme, target, query)


def test_each_url_opens_its_runtime_with_its_own_options(tmp_path):
    assert isinstance(open_runtime(None), EmbeddedRuntime) and open_runtime("sim:").url == "sim:"
    sitl = open_runtime(f"sitl:{tmp_path}/arducopter?speedup=5&defaults=a.parm", {"tlog_dir": str(tmp_path)})
    assert isinstance(sitl, SitlRuntime) and sitl.options.speedup == 5.0
    assert sitl.options.defaults[0].name == "a.parm" and sitl.options.tlog_dir == tmp_path
    vehicle = open_runtime("mavlink+udpout://127.0.0.1:14550", {"truth": False})
    assert isinstance(vehicle, MavlinkRuntime) and vehicle.source == "field" and vehicle.max_workers == 1
    assert open_runtime("tcp://127.0.0.1:5760").url == "mavlink+tcp://127.0.0.1:5760"
    with pytest.raises(RuntimeUrlError, match="no runtime for bogus: URLs"):
        open_runtime("bogus:x")
    with pytest.raises(RuntimeUrlError, match="must be NAME=VALUE"):
        open_runtime("sitl:x?speedup")
    with pytest.raises(RuntimeOptionError, match="speedup: does not apply to the sim: runtime"):
        open_runtime("sim:", {"speedup": 3.0})
    with pytest.raises(RuntimeOptionError, match="must be within 0.1..1000"):
        open_runtime("sitl:x?speedup=0")
    with pytest.raises(RuntimeOptionError, match="rate: not an option of a sitl: URL"):
        open_runtime("sitl:x?rate=3")


def test_the_same_seed_stores_the_same_outcome_whichever_entry_point_flies_it(tmp_path):
    campaign = _campaign(tmp_path, "trials: 2\nscenarios: [{label: ir, land: irlock}]\n")
    run = preland.run_campaign(campaign, db=tmp_path / "c.db", workers=1, runtime="sim:")
    assert (run.ran, run.total) == (2, 2)
    stored = _rows(tmp_path / "c.db")
    assert {row["runtime"] for row in stored} == {"embedded"} and {row["source"] for row in stored} == {"sim"}
    for row in stored:
        assert row["seed"] == derive_seed(5, "ir", row["trial_index"])
        api = preland.fly(str(THESIS_MISSION), land="irlock", seed=row["seed"], runtime="sim:")
        cli = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--land", "irlock", "--seed", str(row["seed"]),
                                       "--runtime", "sim:", "--json"])
        assert cli.exit_code == 0, cli.output
        data, from_api = json.loads(cli.stdout), api.to_dict()  # as printed and stored: rounded alike
        assert from_api["outcome"] == data["outcome"] == row["outcome"] == "landed"
        assert from_api["landing_error_cm"] == data["landing_error_cm"] == row["landing_error_cm"]
        assert from_api["landing_time_s"] == data["landing_time_s"] == row["landing_time_s"]
        assert abs(api.landing_error_cm - row["landing_error_cm"]) < 0.01


def test_a_campaign_file_names_its_runtime_and_the_command_line_overrides_it(tmp_path):
    campaign = _campaign(tmp_path, "trials: 1\nruntime: bogus:here\nscenarios: [{label: gps, land: normal}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "a.db"), "--quiet"])
    assert result.exit_code == 2 and "no runtime for bogus: URLs" in result.stderr
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "a.db"), "--quiet",
                                      "--runtime", "sim:"])
    assert result.exit_code == 0, result.output
    assert [row["runtime"] for row in _rows(tmp_path / "a.db")] == ["embedded"]
    bad = _campaign(tmp_path, "trials: 1\nruntime: 'no scheme'\nscenarios: [{label: gps, land: normal}]\n", "bad")
    result = CliRunner().invoke(app, ["campaign", "run", bad, "--db", str(tmp_path / "b.db")])
    assert result.exit_code == 2 and "bad.yaml: runtime:" in result.stderr and len(result.stderr.splitlines()) == 1


FLY_REFUSALS = [
    (["--sitl-speedup", "3"], "sim:", "--sitl-speedup: does not apply to the sim: runtime"),
    (["--sitl-defaults", "x.parm"], "sim:", "--sitl-defaults: does not apply to the sim: runtime"),
    (["--tlog", "t.tlog"], "sim:", "--tlog: does not apply to the sim: runtime"),
    (["--fault-listen", "udp://127.0.0.1:14560"], "sim:", "--fault-listen: does not apply to the sim: runtime"),
    (["--no-truth"], "sim:", "--no-truth: does not apply to the sim: runtime"),
    (["--camera", "0"], "sim:", "--camera: does not apply to the sim: runtime"),
    (["--no-preflight"], "sim:", "--no-preflight: does not apply to the sim: runtime"),
    (["--detections-log", "d.csv"], "sim:", "--detections-log: does not apply to the sim: runtime"),
    (["--record-video", "v.mkv"], "sim:", "--record-video: does not apply to the sim: runtime"),
    (["--paced"], "sim:", "--paced: does not apply to the sim: runtime"),
    (["--paced"], "sitl:{sitl}", "--paced: does not apply to the sitl: runtime"),
    (["--sitl-physics", "preland"], "sim:", "--sitl-physics: does not apply to the sim: runtime"),
    (["--sitl-physics", "preland"], "mavlink+udp://:14550", "--sitl-physics: does not apply to the mavlink+"),
    (["--record-to", "r.db", "--campaign", "c", "--scenario", "s"], "sim:", "--record-to: only for a vehicle"),
    (["--campaign", "c"], "sim:", "--campaign: only with --record-to"),
    (["--camera", "0"], "sitl:{sitl}", "--camera: does not apply to the sitl: runtime"),
    (["--no-truth"], "sitl:{sitl}", "--no-truth: does not apply to the sitl: runtime"),
    (["--no-preflight"], "sitl:{sitl}", "--no-preflight: does not apply to the sitl: runtime"),
    (["--record-to", "r.db", "--campaign", "c", "--scenario", "s"], "sitl:{sitl}", "--record-to: only for a vehicle"),
    (["--sitl-speedup", "3"], "mavlink+udp://:14550", "--sitl-speedup: does not apply to the mavlink+ runtime"),
    (["--sitl-defaults", "x.parm"], "mavlink+udp://:14550", "--sitl-defaults: does not apply to the mavlink+"),
    (["--wind-m-s", "3"], "mavlink+udp://:14550", "--wind-m-s: only where preland simulates the world"),
    (["--wind-from-deg", "30"], "mavlink+udp://:14550", "--wind-from-deg: only where preland simulates the world"),
]


@pytest.fixture
def sitl_stand_in(tmp_path):
    binary = tmp_path / "arducopter"
    binary.write_text("#!/bin/sh\nexit 0\n")
    binary.chmod(0o755)
    return binary


@pytest.mark.parametrize("options, url, line", FLY_REFUSALS)
def test_a_runtime_option_given_to_another_runtime_is_refused_in_one_line(options, url, line, sitl_stand_in):
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--runtime", url.format(sitl=sitl_stand_in),
                                      *options])
    assert result.exit_code == 2, result.output
    assert result.stderr.startswith(f"preland: error: {line}") and len(result.stderr.splitlines()) == 1


CAMPAIGN_REFUSALS = [
    (["--sitl-speedup", "3"], "sim:", "--sitl-speedup: does not apply to the sim: runtime"),
    (["--sitl-defaults", "x.parm"], "sim:", "--sitl-defaults: does not apply to the sim: runtime"),
    (["--tlog-dir", "tlogs"], "sim:", "--tlog: does not apply to the sim: runtime"),
    (["--no-truth"], "sim:", "--no-truth: does not apply to the sim: runtime"),
    (["--no-preflight"], "sitl:{sitl}", "--no-preflight: does not apply to the sitl: runtime"),
    (["--paced"], "sim:", "--paced: does not apply to the sim: runtime"),
    (["--workers", "2"], "mavlink+udpout://127.0.0.1:14550", "--workers: mavlink+udpout://127.0.0.1:14550 is one "
                                                             "vehicle: its trials fly one at a time"),
]


@pytest.mark.parametrize("options, url, line", CAMPAIGN_REFUSALS)
def test_a_campaign_refuses_an_option_of_another_runtime_in_one_line(options, url, line, tmp_path, sitl_stand_in):
    campaign = _campaign(tmp_path, "trials: 1\nscenarios: [{label: gps, land: normal}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "r.db"), "--quiet",
                                      "--runtime", url.format(sitl=sitl_stand_in), *options])
    assert result.exit_code == 2, result.output
    assert line in result.stderr and len(result.stderr.splitlines()) == 1
    assert not (tmp_path / "r.db").exists() or _rows(tmp_path / "r.db") == []


def test_a_runtime_from_an_installed_package_flies_a_campaign(tmp_path, monkeypatch):
    site = tmp_path / "site"
    (site / "replay_runtime").mkdir(parents=True)
    (site / "replay_runtime" / "__init__.py").write_text(textwrap.dedent('''
        from dataclasses import dataclass
        from typing import ClassVar

        from preland_app.runtime.base import no_options
        from preland_app.runtime.embedded import run_trial


        @dataclass(frozen=True)
        class ReplayRuntime:
            """The embedded simulator under another name: what a package's own runtime looks like."""

            scheme: ClassVar[str] = "replay"
            name: ClassVar[str] = "replay"
            source: ClassVar[str] = "sim"
            simulated_world: ClassVar[bool] = True
            max_workers: ClassVar = None
            cluster_resource: ClassVar = None
            url: ClassVar[str] = "replay:"

            @classmethod
            def from_url(cls, *, target, query, options):
                no_options(options, runtime="replay:")
                return cls()

            def fly(self, request, *, tlog_name=None):
                outcome = run_trial(request)
                outcome.details["replayed"] = True
                return outcome

            def on_this_machine(self):
                return self
        '''))
    dist = site / "replay_runtime-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: replay-runtime\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[preland.runtimes]\nreplay = replay_runtime:ReplayRuntime\n")
    monkeypatch.syspath_prepend(str(site))
    campaign = _campaign(tmp_path, "trials: 2\nruntime: 'replay:'\nscenarios: [{label: gps, land: normal}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "p.db"), "--quiet",
                                      "--workers", "1"])
    assert result.exit_code == 0, result.output
    rows = _rows(tmp_path / "p.db")
    assert [row["runtime"] for row in rows] == ["replay", "replay"]
    assert all(row["outcome"] == "landed" for row in rows)
    with sqlite3.connect(tmp_path / "p.db") as connection:
        details = [json.loads(d) for (d,) in connection.execute("SELECT details FROM trials")]
    assert all(d["replayed"] is True for d in details)


def test_fly_the_api_and_a_campaign_fly_over_mavlink_against_sim_serve(thesis_mission, tmp_path):
    served = ServedSimulator(thesis_mission, seed=4, paced=True)
    url = f"mavlink+udpout://127.0.0.1:{served.port}"
    paced = {"preflight": False, "paced": True}
    try:
        cli = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--land", "irlock", "--runtime", url,
                                       "--no-preflight", "--paced", "--json"])
        assert cli.exit_code == 0, cli.output
        data = json.loads(cli.stdout)
        assert data["outcome"] == "landed" and data["landing_error_cm"] < 15.0, data.get("message")
        assert data["details"]["runtime"] == "mavlink" and data["details"]["paced_grants"] > 1000
        api = preland.fly(thesis_mission, land="irlock", runtime=url, options=paced)
        assert api.outcome.value == "landed" and api.landing_error_cm < 15.0, api.message
        campaign = _campaign(tmp_path, "trials: 2\nscenarios: [{label: ir, land: irlock}]\n")
        run = preland.run_campaign(campaign, db=tmp_path / "m.db", runtime=url, options=paced)
        assert (run.ran, run.total) == (2, 2)
    finally:
        served.stop()
    rows = _rows(tmp_path / "m.db")
    assert [(row["runtime"], row["source"], row["outcome"]) for row in rows] == [("mavlink", "sim", "landed")] * 2
    assert all(row["landing_error_cm"] < 15.0 for row in rows)


def test_a_runtime_urls_own_options_reach_the_trial_from_fly_and_a_campaign(tmp_path, sitl_stand_in, monkeypatch):
    # The command line opens the runtime to check it; the trial must fly on that object, query options kept.
    import preland_app.runtime.sitl as sitl
    from preland_app.outcome import Outcome, TrialOutcome

    flown = []

    def fake_trial(request, *, options, tlog_name=None):
        flown.append(options)
        return TrialOutcome(outcome=Outcome.LANDED, message="landed", seed=request.seed, mission="m",
                            land_mode="normal", takeoff_altitude_rel_m=10.0, scoring_reference="takeoff")

    monkeypatch.setattr(sitl, "run_sitl_trial", fake_trial)
    url = f"sitl:{sitl_stand_in}?speedup=3.5&defaults={tmp_path / 'extra.parm'}"
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--runtime", url, "--json"])
    assert result.exit_code == 0, result.output
    campaign = _campaign(tmp_path, "trials: 1\nscenarios: [{label: gps, land: normal}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", campaign, "--db", str(tmp_path / "s.db"), "--quiet",
                                      "--workers", "1", "--runtime", url])
    assert result.exit_code == 0, result.output
    assert [(o.speedup, o.defaults) for o in flown] == [(3.5, ((tmp_path / "extra.parm").resolve(),))] * 2


def test_the_gyro_error_is_a_sitl_option_of_preland_physics_only(tmp_path):
    sitl = open_runtime(f"sitl:{tmp_path}/arducopter?physics=preland&gyro_error=0.43")
    assert sitl.options.gyro_error == 0.43 and sitl.options.physics == "preland"
    assert open_runtime(f"sitl:{tmp_path}/arducopter").options.gyro_error == 0.0
    with pytest.raises(RuntimeOptionError, match="gyro_error: applies to preland's physics only"):
        open_runtime(f"sitl:{tmp_path}/arducopter?gyro_error=0.43")
    with pytest.raises(RuntimeOptionError, match="gyro_error: must be a number, got 'much'"):
        open_runtime(f"sitl:{tmp_path}/arducopter?physics=preland&gyro_error=much")
    with pytest.raises(RuntimeOptionError, match="gyro_error: must be a number >= 0, got -1"):
        open_runtime(f"sitl:{tmp_path}/arducopter?physics=preland&gyro_error=-1")
    with pytest.raises(RuntimeOptionError, match="gyro_error: does not apply to the sim: runtime"):
        open_runtime("sim:", {"gyro_error": 0.43})
    with pytest.raises(RuntimeOptionError, match="gyro_error: applies to preland's physics only"):
        SitlOptions(binary=None, gyro_error=0.43)  # the Python API checks as the URL does
