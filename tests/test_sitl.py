"""The SITL runtime: a fake `arducopter` for launching, stopping and orphans; the real one when it is there."""

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.runtime.sitl import JSON_QUADX_DEFAULTS, SITL_ENV, SitlOptions, run_sitl_trial
from preland_app.runtime.sitl_parm import read_parm_file
from preland_app.vehicle.lockstep_clock import MISSION_START_S

from .conftest import ROOT, THESIS_MISSION
from .ports import free_udp_port
from .procs import alive, children, cmdline
from .tools.fake_sitl import FRAME_RATE_HZ
from .tools.terminal import as_from_a_terminal
from .waiting import until


# The stand-in SITL's speed-up where a test is not about speed: 8x, what its 20x and 40x reached before the
# face kept to its clock (at 10x, one CI run ended a trial as a pilot takeover under load).
STAND_IN_SPEEDUP = 8.0


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


def _running(launch: dict) -> bool:
    """Whether the stand-in `launch` tells of still runs (its pid, given to no other process since)."""
    return alive(launch["pid"], launch["started"])


def test_a_trial_on_sitl_launches_a_fresh_instance_and_stops_it(fake_sitl, thesis_mission, tmp_path):
    from pymavlink import mavutil

    script, logs = fake_sitl
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=2),
                             options=SitlOptions(binary=script, tlog_dir=tmp_path / "tlogs",
                                                 log_dir=tmp_path / "dataflash"),
                             tlog_name="trial.tlog")
    assert outcome.outcome is Outcome.LANDED, outcome.message
    # SITL's own dataflash log outlives its temporary folder, named as the trial's telemetry log.
    kept = (tmp_path / "dataflash" / "trial.BIN").read_text()
    assert kept == f"stand-in dataflash log of instance {outcome.details['sitl_instance']}\n"
    # The stand-in's GPS error is its own simulator's, moved along in scaled wall time: the same seed has
    # missed by 12 to 37 cm from run to run, so only the bound of a GPS landing is checked here.
    assert outcome.details["runtime"] == "sitl" and 0.0 < outcome.landing_error_cm < 300.0
    (launch,) = _launches(logs)
    argv = launch["argv"]
    # No speedup given: 10x for a land mode that reads no camera frames (`normal`).
    assert argv[argv.index("--speedup") + 1] == "10" and outcome.details["sitl_speedup"] == 10.0
    assert argv[argv.index("-I") + 1] == str(outcome.details["sitl_instance"])
    assert any(a.startswith("--home=-35.363261,149.16523,584") for a in argv)
    assert argv[argv.index("--serial0") + 1].startswith("udpclient:127.0.0.1:")
    assert argv[argv.index("--model") + 1] == "+" and "--sim-port-out" not in argv
    assert outcome.details["sitl_physics"] == "ardupilot"
    assert not _running(launch)
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
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--sitl", str(script), "--sitl-speedup",
                                      f"{STAND_IN_SPEEDUP:g}", "--seed", "3", "--json"])
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


@pytest.mark.parametrize("command", [["fly", str(THESIS_MISSION)],
                                     ["campaign", "run", str(ROOT / "campaigns" / "smoke.yaml")]])
def test_a_speedup_out_of_range_gives_one_line(command, fake_sitl, tmp_path):
    script, logs = fake_sitl
    result = CliRunner().invoke(app, [*command, "--sitl", str(script), "--sitl-speedup", "0", "--db",
                                      str(tmp_path / "r.db")] if command[0] == "campaign" else
                                [*command, "--sitl", str(script), "--sitl-speedup", "0"])
    assert result.exit_code == 2 and result.stderr.strip() == \
        "preland: error: --sitl-speedup: must be within 0.1..1000, got 0"
    assert not list(logs.glob("*.json"))  # no SITL started


def _run_in_thread(function):
    import concurrent.futures

    pool = concurrent.futures.ThreadPoolExecutor(max_workers=1)
    return pool, pool.submit(function)


def _wait_for_launch(logs: Path, timeout_s: float = 30.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        launches = _launches(logs)
        if launches:
            return launches[0]
        time.sleep(0.05)
    raise AssertionError("SITL was not launched")


def _wait_airborne(logs: Path, launch: dict, timeout_s: float = 120.0) -> None:
    """Until the stand-in's vehicle is in the air (its PID.airborne file), however loaded the machine is."""
    until(lambda: (logs / f"{launch['pid']}.airborne").exists() or not _running(launch), timeout_s=timeout_s,
          what="the stand-in's vehicle to be airborne")
    assert _running(launch), "the stand-in ended before its vehicle was airborne"


def _bridge_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name == "sitl-json-bridge"]


def _children() -> list[int]:
    """The pids of this process's living SITL children, stand-in or real (a zombie not yet reaped is not
    one; children of other tests sharing the worker, such as a served simulator's tools, are not either)."""
    return [pid for pid in children(os.getpid()) if alive(pid) and _is_sitl(pid)]


def _is_sitl(pid: int) -> bool:
    command = cmdline(pid)
    return "fake_sitl.py" in command or "arducopter" in command


def _answers(logs: Path, launch: dict) -> int:
    """How many JSON physics answers the stand-in got (0: none noted)."""
    noted = logs / f"{launch['pid']}.json_answers"
    return int(noted.read_text()) if noted.exists() else 0


def _wait_dead(launch: dict, timeout_s: float = 30.0) -> None:
    until(lambda: not _running(launch), timeout_s=timeout_s, what=f"SITL process {launch['pid']} to end")


@pytest.mark.parametrize("physics", ["ardupilot", "preland"])
def test_without_copter_defaults_the_stand_in_refuses_to_arm_as_arducopter_does(fake_sitl, thesis_mission, tmp_path,
                                                                               monkeypatch, physics):
    """ArduCopter's FRAME_CLASS defaults to 0 and its motors refuse to arm; preland's packaged defaults set it.
    The refusal's reason (ArduPilot's STATUSTEXT beside the COMMAND_ACK) is told, in lock-step too."""
    script, logs = fake_sitl
    (tmp_path / "empty.parm").write_text("")
    from preland_app.runtime import sitl as sitl_module

    # The stand-in's face keeps to its clock: at 40x, the 5 vehicle s without a heartbeat that end a trial
    # are 0.125 wall s, which a loaded machine stalls a process for (it ran at about 8x before).
    options = SitlOptions(binary=script, speedup=STAND_IN_SPEEDUP, physics=physics)
    assert options.defaults_files()[0] == sitl_module.PACKAGED_DEFAULTS  # not in an ArduPilot tree
    packaged = sitl_module.PACKAGED_DEFAULTS.read_text()
    assert "FRAME_CLASS 1" in packaged and "FRAME_TYPE 0" in packaged
    monkeypatch.setattr(sitl_module, "PACKAGED_DEFAULTS", tmp_path / "empty.parm")
    monkeypatch.setattr(sitl_module, "JSON_QUADX_DEFAULTS", tmp_path / "empty.parm")
    mission = dataclasses.replace(thesis_mission, timeouts=dataclasses.replace(thesis_mission.timeouts, arm_s=5.0))
    outcome = run_sitl_trial(TrialRequest(mission=mission, seed=2), options=options)
    assert outcome.outcome is Outcome.ERROR and "Check frame class and type" in outcome.message


def test_copter_defaults_are_found_in_the_binarys_ardupilot_tree(tmp_path):
    from preland_app.runtime.sitl import find_copter_defaults

    binary = tmp_path / "ardupilot" / "build" / "sitl" / "bin" / "arducopter"
    binary.parent.mkdir(parents=True)
    binary.write_text("")
    assert find_copter_defaults(binary) is None
    parm = tmp_path / "ardupilot" / "Tools" / "autotest" / "default_params" / "copter.parm"
    parm.parent.mkdir(parents=True)
    parm.write_text("FRAME_CLASS 1\n")
    assert find_copter_defaults(binary) == parm
    extra = tmp_path / "mine.parm"
    assert SitlOptions(binary=binary, defaults=(extra,)).defaults_files() == (parm, extra)


def test_sitl_gets_a_rangefinder_and_a_per_trial_gps_error(fake_sitl, thesis_mission, tmp_path):
    from preland_app.runtime.sitl import GPS_UPDATE_PERIOD_S, GpsErrorDriver, rangefinder_params

    params = rangefinder_params(thesis_mission)
    assert params["RNGFND1_TYPE"] == 100 and params["RNGFND1_ORIENT"] == 25
    environment = thesis_mission.environment
    spec = environment.navigation
    first = GpsErrorDriver(environment=environment, seed=1, latitude_deg=-35.36).params()
    again = GpsErrorDriver(environment=environment, seed=1, latitude_deg=-35.36).params()
    other = GpsErrorDriver(environment=environment, seed=2, latitude_deg=-35.36).params()
    assert first == again and first != other
    # The drift's spread over many seeds is the embedded model's (degrees back to metres).
    norths = [GpsErrorDriver(environment=environment, seed=s, latitude_deg=0.0).params()["SIM_GPS_GLITCH_X"]
              * 111_319.49 for s in range(400)]
    import statistics

    assert abs(statistics.pstdev(norths) - spec.gps_drift_sigma_m) < 0.15 * spec.gps_drift_sigma_m
    script, logs = fake_sitl
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=4), options=SitlOptions(binary=script,
                                                                                             speedup=STAND_IN_SPEEDUP))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    (launch,) = _launches(logs)
    files = launch["argv"][launch["argv"].index("--defaults") + 1].split(",")
    assert files[0].endswith("sitl_copter.parm")
    # SITL's own wind blows from the embedded simulator's direction for the seed, and the trial says so.
    assert outcome.details["wind_from_deg"] == run_trial(TrialRequest(mission=thesis_mission, seed=4)
                                                         ).details["wind_from_deg"]
    # The GPS error started moving at the first update after arming, and SITL landed with the drift the
    # embedded estimate has that long after its own arming.
    armed_s = outcome.details["sitl_gps_armed_s"]
    assert armed_s is not None and armed_s % GPS_UPDATE_PERIOD_S == pytest.approx(0.0, abs=1e-6)
    at_arming_cm = [round(v * 100.0, 1) for v in GpsErrorDriver(environment=environment, seed=4,
                                                                 latitude_deg=0.0).error_ned_m]
    assert outcome.details["sitl_gps_error_cm"] != at_arming_cm


def test_sitl_gets_the_gps_drift_path_of_the_embedded_estimate_for_the_seed_aligned_at_arming(thesis_mission):
    from preland_app.runtime.sitl import GpsErrorDriver
    from preland_app.sim.simulator import Simulator

    environment = thesis_mission.environment
    for seed in (3, 8):
        simulator = Simulator(seed=seed, environment=environment)
        driver = GpsErrorDriver(environment=environment, seed=seed, latitude_deg=0.0)
        # Until SITL arms: the drift of the embedded simulator's arming time, when its fix arrives.
        for _ in range(round(environment.navigation.gps_fix_delay_s * environment.physics_rate_hz)):
            simulator.step()
        assert driver.error_ned_m == simulator.navigation.gps_drift_ne_m
        # 25 s after arming, on both.
        for _ in range(round(25.0 * environment.physics_rate_hz)):
            simulator.step()
        driver.at(25.0)
        assert driver.error_ned_m == simulator.navigation.gps_drift_ne_m
        moved = math.dist(driver.error_ned_m, GpsErrorDriver(environment=environment, seed=seed,
                                                             latitude_deg=0.0).error_ned_m)
        assert moved > 0.01  # the path moved on: the comparison is not between two start values


@pytest.mark.parametrize("usage, flag", [("--serial0 device  set device string for SERIAL0", "--serial0"),
                                         ("--uartA device  set device string for UARTA", "--uartA")])
def test_the_first_serial_port_is_named_as_the_binarys_help_names_it(tmp_path, usage, flag):
    # ArduPilot 4.5 renamed --uartA to --serial0; the 2020 ArduCopter's --help lists --uartA and exits 1.
    from preland_app.runtime.sitl import _serial0_flag

    binary = tmp_path / "arducopter"
    binary.write_text(f"#!/bin/sh\necho 'Options:'\necho '\t{usage}'\nexit 1\n")
    binary.chmod(0o755)
    assert _serial0_flag(str(binary), binary.stat().st_mtime_ns) == flag


def test_the_physics_ardupilot_or_preland_comes_from_the_url_or_the_options(tmp_path):
    from preland_app.runtime.base import RuntimeOptionError, open_runtime
    from preland_app.runtime.sitl import JSON_QUADX_DEFAULTS, PACKAGED_DEFAULTS

    assert open_runtime("sitl:x").options.physics == "ardupilot"
    assert open_runtime("sitl:x?physics=preland").options.physics == "preland"
    assert open_runtime("sitl:x?speedup=4&physics=ardupilot").options.physics == "ardupilot"
    assert open_runtime("sitl:x", {"physics": "preland"}).options.physics == "preland"
    assert open_runtime("sitl:x?physics=preland", {"physics": "ardupilot"}).options.physics == "ardupilot"
    for url, options in (("sitl:x?physics=bogus", {}), ("sitl:x", {"physics": "JSON"})):
        with pytest.raises(RuntimeOptionError) as refused:
            open_runtime(url, options)
        assert refused.value.option == "physics" and refused.value.runtime == "sitl:"
        assert "sitl:" in str(refused.value) and "ardupilot, preland" in str(refused.value)
    # preland's frame follows the copter defaults and comes before the user's files, which win.
    mine = tmp_path / "mine.parm"
    binary = tmp_path / "arducopter"
    assert SitlOptions(binary=binary, defaults=(mine,), physics="preland").defaults_files() == (
        PACKAGED_DEFAULTS, JSON_QUADX_DEFAULTS, mine)
    assert SitlOptions(binary=binary, defaults=(mine,)).defaults_files() == (PACKAGED_DEFAULTS, mine)
    lines = JSON_QUADX_DEFAULTS.read_text().splitlines()
    params = [line.split() for line in lines if line.strip() and not line.startswith("#")]
    assert ["FRAME_TYPE", "1"] in params
    for index, line in enumerate(lines):  # every parameter says why, on the comment line before it
        if line.strip() and not line.startswith("#"):
            assert lines[index - 1].startswith("#"), line


def test_a_physics_other_than_ardupilot_or_preland_is_refused_in_one_line(fake_sitl):
    script, logs = fake_sitl
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), "--runtime", f"sitl:{script}?physics=bogus"])
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.strip().splitlines()
    assert "physics" in line and "sitl:" in line and "ardupilot, preland" in line and "'bogus'" in line
    assert not list(logs.glob("*.json"))  # no SITL started


def test_a_defaults_file_is_read_as_sitl_reads_it(tmp_path):
    parm = tmp_path / "a.parm"
    parm.write_text("# a comment\nSIM_RATE_HZ 800\nFRAME_TYPE,1  # trailing comment\n\nSIM_RATE_HZ   400\nALONE\n")
    assert read_parm_file(parm) == {"SIM_RATE_HZ": 400.0, "FRAME_TYPE": 1.0}
    # preland's physics: one step per 400 Hz loop, and every Copter pre-arm check but INS (bit 4).
    frame = read_parm_file(JSON_QUADX_DEFAULTS)
    assert frame["SIM_RATE_HZ"] == 400 and frame["FRAME_TYPE"] == 1
    assert int(frame["ARMING_CHECK"]) == sum(1 << bit for bit in range(1, 20) if bit not in (4, 9))


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc")
def test_a_trial_on_preland_physics_runs_sitl_on_the_json_bridge(fake_sitl, thesis_mission):
    script, logs = fake_sitl
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=2),
                             options=SitlOptions(binary=script, speedup=STAND_IN_SPEEDUP, physics="preland"))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.details["sitl_physics"] == "preland"
    (launch,) = _launches(logs)
    argv = launch["argv"]
    assert argv[argv.index("--model") + 1] == "JSON:127.0.0.1"
    assert int(argv[argv.index("--sim-port-out") + 1]) > 0
    files = argv[argv.index("--defaults") + 1].split(",")
    assert files[0].endswith("sitl_copter.parm") and files[1].endswith("sitl_json_quadx.parm")
    # The air is preland's: the embedded simulator's wind for the same seed.
    assert outcome.details["wind_from_deg"] == run_trial(TrialRequest(mission=thesis_mission, seed=2)
                                                         ).details["wind_from_deg"]
    # The stand-in waits for an answer to every servo packet: it flew on answers from the bridge.
    answered = _answers(logs, launch)
    assert answered > 100 and outcome.details["sitl_json_packets"] >= answered
    # From the mission on, the ground station's HEARTBEAT reaches SITL once each whole vehicle second (the
    # companion's, in vehicle time from the connection on, the first at the mission's start), none between
    # (MAVSDK's own, sent each wall second, are held back from the connection on, also while the streams are
    # asked for again at the start).
    heard_s = [float(line.split()[0]) for line in (logs / f"{launch['pid']}.heartbeats").read_text().splitlines()]
    # (which needs the connection done before the mission's start: after it, the trial begins where it is)
    assert outcome.details["lockstep_connected_s"] < MISSION_START_S, heard_s
    in_mission_s = [t for t in heard_s if t >= MISSION_START_S - 1e-6]
    assert len(in_mission_s) >= 20
    first_s = int(MISSION_START_S)
    assert [math.floor(t + 1e-6) for t in in_mission_s] == list(range(first_s, first_s + len(in_mission_s)))
    # (read within the stand-in's next two physics frames, as it steps on from the held time)
    assert all(t - math.floor(t + 1e-6) < 2.5 / FRAME_RATE_HZ for t in in_mission_s), in_mission_s
    # SITL takes its SIGTERM at its next step: the physics the companion held at the trial's end was let go
    # for it, so it exited on its own (not killed after the grace).
    assert (logs / f"{launch['pid']}.exit").read_text() == "SIGTERM\n"
    assert not _running(launch) and _children() == []
    assert _bridge_threads() == []


REAL_SITL = os.environ.get(SITL_ENV)


needs_real_sitl = pytest.mark.skipif(not REAL_SITL,
                                     reason=f"set {SITL_ENV} to an arducopter SITL binary to run these")


def _real(**overrides) -> SitlOptions:
    return SitlOptions(binary=Path(REAL_SITL), **{"speedup": 10.0, **overrides})


@needs_real_sitl
@pytest.mark.parametrize("mode, sensor", [("irlock", None), ("marker", None), ("fused", None),
                                          ("cautious", "irlock"), ("cautious", "marker"), ("cautious", "fused")])
def test_every_precision_mode_lands_on_real_sitl(thesis_mission, mode, sensor):
    # At the speed-ups preland gives SITL's own physics (a camera land mode 2x, the others 10x): at 10x the
    # companion, rendering and detecting in wall time, sent 14 LANDING_TARGETs for the marker in a `make test`
    # run with PRELAND_SITL_BINARY set (its landing still within 20 cm).
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode=mode, sensor=sensor),
                             options=_real(speedup=None))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.details["landing_targets_sent"] > 50
    assert outcome.landing_error_cm < 20.0


@needs_real_sitl
@pytest.mark.parametrize("mode", ["paper_static", "paper_adaptive"])
def test_the_paper_algorithms_land_on_real_sitl(mode):
    from preland_app.config.mission import load_mission

    mission = load_mission(ROOT / "missions" / "paper_marker_land.yaml")
    outcome = run_sitl_trial(TrialRequest(mission=mission, seed=1, land_mode=mode), options=_real(speedup=None))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.landing_error_cm < 20.0


@needs_real_sitl
@pytest.mark.parametrize("mode", ["normal", "irlock"])
def test_the_thesis_mission_lands_on_preland_physics_on_real_sitl(thesis_mission, mode):
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode=mode),
                             options=_real(physics="preland"))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.details["sitl_physics"] == "preland" and outcome.details["sitl_json_packets"] > 10_000
    if mode == "irlock":
        assert outcome.details["landing_targets_sent"] > 50
        assert outcome.landing_error_cm < 15.0
    assert _bridge_threads() == [] and _children() == []


@needs_real_sitl
def test_a_seed_flown_twice_on_preland_physics_lands_on_the_same_point_on_real_sitl(thesis_mission):
    # In lock-step the companion's wall time decides nothing after the mission's start, which the connection
    # must reach first (at 400 Hz physics steps SITL ran 15 to 20 vehicle s while MAVSDK connected).
    first, second = (run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode="irlock"),
                                    options=_real(physics="preland")) for _ in range(2))
    for outcome in (first, second):
        assert outcome.outcome is Outcome.LANDED, outcome.message
        assert outcome.details["lockstep_connected_s"] < MISSION_START_S
    assert first.landing_error_cm == second.landing_error_cm and first.landing_time_s == second.landing_time_s
    assert [(e.kind, e.time_s) for e in first.events] == [(e.kind, e.time_s) for e in second.events]


@needs_real_sitl
def test_a_gyro_error_on_preland_physics_makes_arducopters_attitude_estimate_err(thesis_mission, tmp_path):
    from preland_app.runtime.sitl_log import attitude_estimate_errors_deg, rms

    estimate_error_deg = {}
    for gyro_error in (0.0, 0.43):
        outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode="irlock"),
                                 options=SitlOptions(binary=Path(REAL_SITL), physics="preland", gyro_error=gyro_error,
                                                     log_dir=tmp_path),
                                 tlog_name=f"gyro{gyro_error}.tlog")
        assert outcome.outcome is Outcome.LANDED, outcome.message
        errors = attitude_estimate_errors_deg(tmp_path / f"gyro{gyro_error}.BIN")
        assert len(errors) > 400  # ATT and SIM of every logged instant in the air (10 a vehicle second)
        estimate_error_deg[gyro_error] = rms(errors)
    # A true IMU: ArduCopter's EKF within about 0.1 degree (benchmarks/sitl_attitude_error.py: 0.09 to 0.12 a
    # trial); 0.43 of the mission's 0.7 degrees: about the mission's attitude error (0.49 to 0.79 a trial).
    assert estimate_error_deg[0.0] < 0.2
    assert 0.35 < estimate_error_deg[0.43] < 1.2


@needs_real_sitl
def test_arducopters_horizontal_estimate_errors_are_read_from_its_log(thesis_mission, tmp_path):
    from preland_app.runtime.sitl_log import horizontal_estimate_errors, rms

    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode="irlock"),
                             options=SitlOptions(binary=Path(REAL_SITL), physics="preland", log_dir=tmp_path),
                             tlog_name="nav.tlog")
    assert outcome.outcome is Outcome.LANDED, outcome.message
    velocity_m_s, position_m = horizontal_estimate_errors(tmp_path / "nav.BIN")
    # XKF1 of core 0 at 10 a vehicle second through some 40 s in the air; the high-pass leaves 2 s at each end.
    assert len(velocity_m_s) > 600 and 0 < len(position_m) < len(velocity_m_s)
    # On a true IMU and a GPS that only drifts: 2 to 3 cm/s, and about 1 cm from the GPS (the benchmark's trials).
    assert 0.005 < rms(velocity_m_s) < 0.08
    assert 0.002 < rms(position_m) < 0.05


@needs_real_sitl
def test_a_late_irlock_on_real_sitl_still_lands_on_the_beacon(thesis_mission):
    """Every IR-LOCK reading 400 ms late, in lock-step on preland's physics: ArduCopter 4.6 fuses each with
    the attitude and position of PLND_LAG (20 ms) before it arrives, yet lands on the beacon, since its
    velocity loop reads the EKF's velocity, not the precision-landing estimator's (as 3.6/4.0 did)."""
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode="irlock",
                                          faults={"irlock": "delay:400"}), options=_real(physics="preland"))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    details = outcome.details
    assert details["irlock_fault"] == "delay:400" and details["irlock_delay_mean_ms"] == 400.0
    assert details["landing_targets_sent"] > 500 and details["irlock_dropped"] == 0
    assert outcome.landing_error_cm < 15.0


@needs_real_sitl
@pytest.mark.parametrize("fault, counted, share", [("false:0.1:3", "irlock_false", (0.05, 0.15)),
                                                   ("stalestamp:0.5", "irlock_old_stamp", (0.4, 0.6))])
def test_false_or_old_timed_irlock_readings_on_real_sitl_still_land_on_the_beacon(thesis_mission, fault, counted,
                                                                                  share):
    """In lock-step on preland's physics. One IR-LOCK reading in ten pointing 3 m off the beacon: ArduCopter 4.6's
    outlier gate refuses them (a false one is fused only after three refused in a row). Half the readings
    carrying the time of the reading before: 4.6 takes a LANDING_TARGET whose (corrected) time equals the last
    one's as no new measurement (AC_PrecLand::retrieve_los_meas), so those are lost to it, as drops would be.
    Either way it lands on the beacon, and every reading is sent."""
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode="irlock",
                                          faults={"irlock": fault}), options=_real(physics="preland"))
    assert outcome.outcome is Outcome.LANDED, outcome.message
    details = outcome.details
    assert details["irlock_fault"] == fault and details["irlock_dropped"] == 0
    assert share[0] < details[counted] / details["irlock_produced"] < share[1]
    assert details["landing_targets_sent"] > 500
    assert outcome.landing_error_cm < 15.0


@needs_real_sitl
def test_normal_landings_on_real_sitl_miss_by_the_seeds_gps_error(thesis_mission):
    outcomes = [run_sitl_trial(TrialRequest(mission=thesis_mission, seed=seed), options=_real())
                for seed in (1, 2, 3)]
    errors = [o.landing_error_cm for o in outcomes]
    # Different seeds, different GPS errors: the touchdowns lie apart. (Their distances from the pad may
    # not: seeds 1 and 3 both miss by about 65 cm, in directions 90 degrees apart.)
    points = [(o.offset_north_cm, o.offset_east_cm) for o in outcomes]
    assert all(math.dist(a, b) > 10.0 for i, a in enumerate(points) for b in points[i + 1:]), points
    assert 5.0 < sum(errors) / len(errors) < 250.0


@needs_real_sitl
def test_the_table5_pair_on_real_sitl(thesis_mission):
    """Cautious against default with the marker lost below 3 m on the first attempt, over five seeds: on
    one seed a blind descent can land closer than a cautious one (seed 5: 1.7 against 6.1 cm), so the
    comparison is of the means, as the thesis' is.

    On preland's physics in lock-step (SITL's JSON interface): every camera frame is read at its own vehicle
    time however busy the machine is. On SITL's own physics at 10x the companion renders and detects in wall
    time, and four such flights at once on 2 cores (`pytest -n 4`) made a cautious landing lose the marker on
    its second attempt too (three attempts)."""
    faults = {"marker": "below:3:first-attempt"}
    lockstep = SitlOptions(binary=Path(REAL_SITL), physics="preland")  # the lock-step speed-up
    defaults, cautious = [], []
    for seed in range(1, 6):
        defaults.append(run_sitl_trial(TrialRequest(mission=thesis_mission, seed=seed, land_mode="marker",
                                                    faults=faults, takeoff_altitude_rel_m=6.0), options=lockstep))
        cautious.append(run_sitl_trial(TrialRequest(mission=thesis_mission, seed=seed, land_mode="cautious",
                                                    sensor="marker", faults=faults, takeoff_altitude_rel_m=6.0),
                                       options=lockstep))
    for default, careful in zip(defaults, cautious):
        assert default.outcome is careful.outcome is Outcome.LANDED, (default.message, careful.message)
        assert careful.details["attempts"] == 2 and careful.details["marker_dropped"] > 0
        assert careful.landing_time_s > default.landing_time_s  # the climb and the second attempt
        assert careful.landing_error_cm < 15.0  # the second attempt sees the marker to the ground
    default_mean = sum(t.landing_error_cm for t in defaults) / len(defaults)
    cautious_mean = sum(t.landing_error_cm for t in cautious) / len(cautious)
    assert cautious_mean < default_mean, ([t.landing_error_cm for t in defaults],
                                          [t.landing_error_cm for t in cautious])


@needs_real_sitl
def test_a_two_worker_campaign_on_real_sitl(tmp_path):
    from preland_app.campaign.store import ResultsStore

    campaign = tmp_path / "c.yaml"
    campaign.write_text(f"name: sitl_two\nmission: {THESIS_MISSION}\ntrials: 2\nbase_seed: 5\n"
                        "scenarios: [{label: gps, land: normal}, {label: marker, land: marker, initial_height_m: 6}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", str(campaign), "--db", str(tmp_path / "r.db"),
                                      "--workers", "2", "--quiet", "--sitl", REAL_SITL])
    assert result.exit_code == 0, result.output
    rows = ResultsStore(tmp_path / "r.db").trials("sitl_two")
    assert len(rows) == 4 and all(row["outcome"] == "landed" for row in rows)
    assert {row["runtime"] for row in rows} == {"sitl"}


@needs_real_sitl
def test_the_fault_command_reaches_a_sitl_flight(thesis_mission):
    import threading

    fault_port = free_udp_port()
    sent = threading.Event()

    def send_later():
        time.sleep(float(os.environ.get("PRELAND_TEST_FAULT_DELAY_S", "4")))
        result = CliRunner().invoke(app, ["fault", "send", "--connect", f"udp://127.0.0.1:{fault_port}",
                                          "--target", "marker", "--r-drop", "1.0"])
        sent.set()
        assert result.exit_code == 0, result.output

    sender = threading.Thread(target=send_later)
    sender.start()
    outcome = run_sitl_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode="marker"),
                             options=_real(fault_listen=f"udp://127.0.0.1:{fault_port}"))
    sender.join()
    assert sent.is_set() and outcome.outcome is Outcome.LANDED, outcome.message
    assert any(e.kind == "fault_command" for e in outcome.events)
    assert outcome.details["marker_fault"] == "permanent" and outcome.details["marker_dropped"] > 0


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


def test_sitl_wind_blows_as_the_embedded_models_at_every_height_and_from_its_direction(thesis_mission):
    """SITL's default wind profile (SIM_WIND_T 0) scales the mean wind by sqrt(h / 60 m) below 60 m: at 10 m
    a 3 m/s scenario would blow at 1.2 m/s. The embedded model's steady wind is the same at every height,
    so SITL gets SIM_WIND_T 1 (no profile); and a scenario without a direction blows from the direction
    the embedded simulator draws for the same seed."""
    from dataclasses import replace

    from preland_app.runtime.sitl import sim_params
    from preland_app.sim.simulator import Simulator

    wind = replace(thesis_mission.environment.wind, speed_m_s=3.0, direction_from_deg=None)
    windy = replace(thesis_mission, environment=replace(thesis_mission.environment, wind=wind))
    directions = set()
    for seed in (1, 2, 3):
        params = sim_params(windy, seed=seed)
        assert params["SIM_WIND_T"] == 1 and params["SIM_WIND_SPD"] == 3.0
        embedded = Simulator(seed=seed, environment=windy.environment).wind.direction_from_deg
        assert abs(params["SIM_WIND_DIR"] - embedded) < 1e-9
        directions.add(round(params["SIM_WIND_DIR"], 6))
    assert len(directions) == 3


def test_without_a_given_speedup_camera_land_modes_fly_sitl_at_2x_and_the_others_at_10x(thesis_mission):
    """The companion reads camera frames in wall time: at SITL 10x it processes about 9 of the camera's
    frames per vehicle second instead of 15, and marker landings with dropped values then miss
    (benchmarks/sitl_vs_embedded.py), so camera modes default to 2x."""
    from dataclasses import replace

    options = SitlOptions(binary=Path("arducopter"))
    chosen = {}
    for mode, sensor in (("normal", None), ("irlock", None), ("marker", None), ("fused", None),
                         ("cautious", "irlock"), ("cautious", "marker"), ("paper_adaptive", None)):
        request = TrialRequest(mission=thesis_mission, seed=1, land_mode=mode, sensor=sensor)
        uses_camera = request.resolved_mission().land.strategy().uses_marker
        chosen[(mode, sensor)] = options.speedup_for(uses_camera=uses_camera)
    assert chosen == {("normal", None): 10.0, ("irlock", None): 10.0, ("marker", None): 2.0, ("fused", None): 2.0,
                      ("cautious", "irlock"): 10.0, ("cautious", "marker"): 2.0, ("paper_adaptive", None): 2.0}
    assert replace(options, speedup=7.0).speedup_for(uses_camera=True) == 7.0
