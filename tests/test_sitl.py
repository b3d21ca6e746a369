"""The SITL runtime: a fake `arducopter` for launching, stopping and orphans; the real one when it is there."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest
from preland_app.runtime.sitl import SITL_ENV, SitlOptions, run_sitl_trial

from .conftest import ROOT, THESIS_MISSION


@pytest.fixture()
def fake_sitl(tmp_path, monkeypatch):
    """A stand-in `arducopter` (the embedded simulator behind SITL's command line), logging its launches."""
    logs = tmp_path / "launches"
    logs.mkdir()
    script = tmp_path / "arducopter"
    script.write_text(f"#!/bin/sh\nexec {sys.executable} {ROOT / 'tests' / 'tools' / 'fake_sitl.py'} \"$@\"\n")
    script.chmod(0o755)
    monkeypatch.setenv("FAKE_SITL_LOG_DIR", str(logs))
    return script, logs


def _launches(logs: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(logs.glob("*.json"))]


def _alive(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "State:\tZ" not in status


def test_a_trial_on_sitl_launches_a_fresh_instance_and_stops_it(fake_sitl, thesis_mission, tmp_path):
    from pymavlink import mavutil

    script, logs = fake_sitl
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=2),
                             options=SitlOptions(binary=script, speedup=8.0, tlog_dir=tmp_path / "tlogs"),
                             tlog_name="trial.tlog")
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.details["runtime"] == "sitl" and 20.0 < outcome.landing_error_cm < 300.0
    (launch,) = _launches(logs)
    argv = launch["argv"]
    assert argv[argv.index("--speedup") + 1] == "8" and argv[argv.index("-I") + 1] == str(outcome.details["sitl_instance"])
    assert any(a.startswith("--home=-35.363261,149.16523,584") for a in argv)
    assert argv[argv.index("--serial0") + 1].startswith("udpclient:127.0.0.1:")
    assert not _alive(launch["pid"])
    # The trial's telemetry log reads back with pymavlink's tools.
    log = mavutil.mavlink_connection(str(tmp_path / "tlogs" / "trial.tlog"))
    types = set()
    while (message := log.recv_match()) is not None:
        types.add(message.get_type())
    assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "COMMAND_ACK"} <= types
    assert outcome.details["tlog_messages"] > 500


def test_fly_on_sitl_from_the_cli(fake_sitl):
    import json as json_module

    script, _ = fake_sitl
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--sitl", str(script), "--sitl-speedup", "8",
                                      "--seed", "3", "--json"])
    assert result.exit_code == 0, result.output
    data = json_module.loads(result.stdout.strip().splitlines()[-1])
    assert data["outcome"] == "landed" and data["details"]["runtime"] == "sitl"


def test_a_missing_binary_gives_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv(SITL_ENV, raising=False)
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--sitl", str(tmp_path / "nope")])
    assert result.exit_code != 0 and "not found" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    result = CliRunner().invoke(app, ["campaign", "run", str(ROOT / "campaigns" / "smoke.yaml"), "--db",
                                      str(tmp_path / "r.db"), "--sitl", ""])
    assert result.exit_code == 2 and SITL_ENV in result.stderr


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc")
def test_an_interrupted_sitl_campaign_leaves_no_sitl_process(fake_sitl, tmp_path):
    script, logs = fake_sitl
    campaign = tmp_path / "c.yaml"
    campaign.write_text(f"name: sitl_orphans\nmission: {THESIS_MISSION}\ntrials: 4\n"
                        "scenarios: [{label: gps, land: normal}]\n")
    process = subprocess.Popen(
        [sys.executable, "-m", "preland_app.cli", "campaign", "run", str(campaign), "--db", str(tmp_path / "r.db"),
         "--workers", "2", "--quiet", "--sitl", str(script), "--sitl-speedup", "2"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env={**os.environ})
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(_launches(logs)) < 2:
        time.sleep(0.1)
    launches = _launches(logs)
    assert len(launches) >= 2, "two SITL processes should be running"
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 130, stderr
    time.sleep(1.0)
    assert [launch["pid"] for launch in _launches(logs) if _alive(launch["pid"])] == []


REAL_SITL = os.environ.get(SITL_ENV)


@pytest.mark.skipif(not REAL_SITL, reason=f"set {SITL_ENV} to an arducopter SITL binary to run these")
@pytest.mark.parametrize("mode", ["marker", "cautious"])
def test_the_thesis_mission_on_real_sitl(thesis_mission, mode):
    faults = {"marker": "below:3:first-attempt"} if mode == "cautious" else None
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode=mode, faults=faults),
                             options=SitlOptions(binary=Path(REAL_SITL), speedup=5.0))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.landing_error_cm < 30.0


def test_sitl_gusts_get_the_embedded_models_standard_deviation(thesis_mission):
    """SIM_WIND_TURB is the standard deviation of SITL's horizontal gust. Its update, per physics step
    (Aircraft::update_wind): speed = 0.98 * speed + 0.02 * (10 * SIM_WIND_TURB) * N(0, 1)."""
    from dataclasses import replace

    import numpy as np

    from preland_app.runtime.sitl import sim_params
    from preland_app.sim.environment import dryden_scales

    wind = replace(thesis_mission.environment.wind, speed_m_s=3.0, turbulence_w20_m_s=5.0, direction_from_deg=250.0)
    gusty = replace(thesis_mission, environment=replace(thesis_mission.environment, wind=wind))
    params = sim_params(gusty, seed=1)
    assert params["SIM_WIND_SPD"] == 3.0 and params["SIM_WIND_DIR"] == 250.0
    rng = np.random.default_rng(7)
    speed, samples = 0.0, np.empty(200_000)
    for i, draw in enumerate(rng.standard_normal(samples.size)):
        speed = 0.98 * speed + 0.02 * (10.0 * params["SIM_WIND_TURB"]) * draw
        samples[i] = speed
    _, _, sigma_u_m_s, _ = dryden_scales(altitude_m=10.0, w20_m_s=5.0)
    assert 0.9 < sigma_u_m_s < 1.1  # gusts of about 1 m/s at 10 m with W20 = 5 m/s
    assert abs(samples[1000:].std() / sigma_u_m_s - 1.0) < 0.03
