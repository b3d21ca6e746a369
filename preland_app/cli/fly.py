"""preland fly: one mission, on any runtime (the embedded simulator, SITL, a vehicle over MAVLink), through the
Python API's `fly`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from ..errors import PrelandError
from .app import EXIT_FAILED, app, choices, fail
from ..landing.registry import LAND_MODES, PRECISION_SENSORS
from ..sensing.faults import FAULT_SYNTAX

PrecisionSensor = choices(lambda: PRECISION_SENSORS)


def _format_outcome_table(data: dict) -> str:
    def show(value, unit: str = "", digits: int = 1) -> str:
        if value is None:
            return "-"
        if isinstance(value, float):
            return f"{value:.{digits}f}{unit}"
        return f"{value}{unit}"

    rows = [
        ("outcome", f"{data['outcome']} ({data['message']})"),
        ("mission", data["mission"]),
        ("land mode", data["land_mode"]),
        ("seed", str(data["seed"])),
        ("take-off altitude", show(data["takeoff_altitude_rel_m"], " m")),
        ("landing error", show(data["landing_error_cm"], " cm") + f"  (from the {data['scoring_reference']})"),
        ("offset north", show(data["offset_north_cm"], " cm")),
        ("offset east", show(data["offset_east_cm"], " cm")),
        ("landing time", show(data["landing_time_s"], " s")),
        ("flight time", show(data["flight_time_s"], " s")),
        ("touchdown speed", show(data["touchdown_speed_m_s"], " m/s", 2)),
    ]
    for key, value in sorted(data.get("details", {}).items()):
        rows.append((key.replace("_", " "), show(value)))
    width = max(len(label) for label, _ in rows)
    return "\n".join(f"{label:<{width}}  {value}" for label, value in rows)


def _with_wind(mission, *, wind_m_s: float | None, wind_from_deg: float | None, runtime):
    """The mission with the command line's wind; refused where the weather is the real one (a vehicle)."""
    import math
    from dataclasses import replace

    if wind_m_s is None and wind_from_deg is None:
        return mission
    option = "--wind-m-s" if wind_m_s is not None else "--wind-from-deg"
    if not runtime.simulated_world:
        raise fail(f"{option}: only where preland simulates the world (sim:, sitl:), not on {runtime.url}, "
                   "where the wind is the real one")
    if wind_m_s is not None and not (math.isfinite(wind_m_s) and 0.0 <= wind_m_s <= 30.0):
        raise fail(f"--wind-m-s: must be within 0..30 m/s, got {wind_m_s:g}")
    if wind_from_deg is not None and not (math.isfinite(wind_from_deg) and 0.0 <= wind_from_deg <= 360.0):
        raise fail(f"--wind-from-deg: must be within 0..360 deg, got {wind_from_deg:g}")
    wind = mission.environment.wind
    wind = replace(wind, speed_m_s=wind.speed_m_s if wind_m_s is None else wind_m_s,
                   direction_from_deg=wind.direction_from_deg if wind_from_deg is None else wind_from_deg % 360.0)
    return replace(mission, environment=replace(mission.environment, wind=wind))


def _parse_faults(values: list[str]) -> dict[str, str]:
    from ..sensing.faults import SENSORS, FaultSpec, FaultSyntaxError

    faults: dict[str, str] = {}
    for value in values:
        sensor, sep, text = value.partition("=")
        sensor = sensor.strip().lower()
        if not sep or sensor not in SENSORS:
            raise fail(f"--fault {value!r}: expected SENSOR=FAULT with SENSOR one of {', '.join(SENSORS)}")
        if sensor in faults:
            raise fail(f"--fault: {sensor} given twice (one fault per sensor)")
        try:
            FaultSpec.parse(text)
        except FaultSyntaxError as error:
            raise fail(f"--fault {value!r}: {error}") from None
        faults[sensor] = text
    return faults


SIM_PANEL = "Embedded simulator and SITL (simulated world)"
SITL_PANEL = "SITL runtime (sitl:PATH)"
MAVLINK_PANEL = "MAVLink runtime (mavlink+..., a vehicle)"
# The command line's name of each runtime option, for one-line refusals.
OPTION_FLAGS = {"speedup": "--sitl-speedup", "defaults": "--sitl-defaults", "tlog_dir": "--tlog",
                "fault_listen": "--fault-listen", "truth": "--no-truth", "preflight": "--no-preflight",
                "camera_source": "--camera", "detection_log": "--detections-log", "video_path": "--record-video",
                "paced": "--paced", "physics": "--sitl-physics"}


def runtime_option_line(error) -> str:
    """A RuntimeOptionError as the command line names the option."""
    return f"{OPTION_FLAGS.get(error.option, '--' + error.option.replace('_', '-'))}: {error.problem}"


def choose_runtime(runtime: str | None, *, connect: str | None, sitl: str | None, options: dict):
    """The runtime the command line names (`--runtime`, or a shorthand), with the options given; one line
    and exit 2 for an unknown URL or an option that does not apply."""
    from ..api import runtime_url
    from ..runtime.base import RuntimeOptionError, open_runtime

    given = [flag for flag, value in (("--runtime", runtime), ("--connect", connect), ("--sitl", sitl))
             if value is not None]
    if len(given) > 1:
        raise fail(f"{given[1]}: give one of --runtime, --connect and --sitl (got {' and '.join(given)})")
    try:
        # On this machine: a SITL binary that cannot be run is bad input, refused before anything flies.
        return open_runtime(runtime_url(runtime, connect=connect, sitl=sitl), options).on_this_machine()
    except RuntimeOptionError as error:
        raise fail(runtime_option_line(error)) from None
    except PrelandError as error:
        raise fail(f"{given[0] if given else '--runtime'}: {error}") from None


@app.command()
def fly(
    mission_file: Path = typer.Argument(..., metavar="MISSION", help="Mission YAML file (see missions/)."),
    land: Optional[str] = typer.Option(None, "--land", metavar="MODE",
                                       help=f"Land mode, overriding the mission's: {', '.join(LAND_MODES)}, an "
                                            "installed plugin's name (preland modes), or an import path "
                                            "package.module:ClassName (its folder on PYTHONPATH)."),
    sensor: Optional[PrecisionSensor] = typer.Option(None, "--sensor", help="Precision sensor of the cautious "
                                                     "mode."),
    fault: list[str] = typer.Option([], "--fault", metavar="SENSOR=FAULT",
                                    help="A fault on a sensor's values (repeatable, one per sensor; the how-to on "
                                         f"faults says what each does): {FAULT_SYNTAX} (to limit it to the first "
                                         "landing attempt). E.g. marker=below:3."),
    seed: int = typer.Option(1, "--seed", help="Trial seed: same seed, same outcome."),
    takeoff_altitude_m: Optional[float] = typer.Option(
        None, "--takeoff-altitude-m", help="Take-off altitude above home in m, overriding the mission's."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
    events: bool = typer.Option(False, "--events", help="Include the mission's event log."),
    runtime: Optional[str] = typer.Option(
        None, "--runtime", metavar="URL",
        help="Where to fly: sim: (default, the embedded simulator), sitl:PATH (sitl: for $PRELAND_SITL_BINARY; "
             "?speedup=X&defaults=A.parm), mavlink+udp://:14550, mavlink+udpout://HOST:PORT, "
             "mavlink+tcp://HOST:PORT, mavlink+serial:///dev/ttyAMA0?baud=921600."),
    connect: Optional[str] = typer.Option(
        None, "--connect", metavar="URL",
        help="Shorthand for --runtime mavlink+URL: udp://:14550, udpout://127.0.0.1:14550, tcp://127.0.0.1:5760, "
             "serial:///dev/ttyAMA0:921600."),
    sitl: Optional[str] = typer.Option(None, "--sitl", metavar="PATH",
                                       help="Shorthand for --runtime sitl:PATH (a fresh ArduPilot SITL process; "
                                            "given empty: $PRELAND_SITL_BINARY)."),
    wind_m_s: Optional[float] = typer.Option(None, "--wind-m-s", rich_help_panel=SIM_PANEL,
                                             help="Steady wind speed in m/s, overriding the mission's environment."),
    wind_from_deg: Optional[float] = typer.Option(None, "--wind-from-deg", rich_help_panel=SIM_PANEL,
                                                  help="Where the wind blows from, deg clockwise from north "
                                                       "(default: the mission's, else drawn per seed)."),
    sitl_speedup: Optional[float] = typer.Option(
        None, "--sitl-speedup", rich_help_panel=SITL_PANEL,
        help="SITL --speedup (default: 2 for land modes that read camera frames, so the companion keeps the "
             "camera's rate; 10 for the others)."),
    sitl_physics: Optional[str] = typer.Option(
        None, "--sitl-physics", metavar="ardupilot|preland", rich_help_panel=SITL_PANEL,
        help="SITL's physics: ardupilot (its own, the default) or preland (preland's motor-level quad X over "
             "SITL's JSON interface, flying in preland's wind, gusts and rotor wash)."),
    sitl_defaults: list[Path] = typer.Option([], "--sitl-defaults", rich_help_panel=SITL_PANEL,
                                             help="More ArduPilot parameter defaults files, repeatable, applied "
                                                  "after the copter defaults (copter.parm of the binary's ArduPilot "
                                                  "tree, else preland's own)."),
    tlog: Optional[Path] = typer.Option(None, "--tlog", rich_help_panel=SITL_PANEL,
                                        help="SITL and MAVLink: write a MAVLink telemetry log (.tlog) of the trial."),
    fault_listen: Optional[str] = typer.Option(None, "--fault-listen", metavar="URL", rich_help_panel=SITL_PANEL,
                                               help="SITL and MAVLink: take fault commands (preland fault send) "
                                                    "on this UDP address, e.g. udp://127.0.0.1:14560."),
    no_truth: bool = typer.Option(False, "--no-truth", rich_help_panel=MAVLINK_PANEL,
                                  help="The vehicle reports no ground truth (a real drone)."),
    camera_source: Optional[str] = typer.Option(None, "--camera", metavar="SRC", rich_help_panel=MAVLINK_PANEL,
                                                help="A real camera (index, device, GStreamer pipeline) or a video "
                                                     "file instead of the virtual camera."),
    no_preflight: bool = typer.Option(False, "--no-preflight", rich_help_panel=MAVLINK_PANEL,
                                      help="Skip the preflight checks."),
    paced: bool = typer.Option(False, "--paced", rich_help_panel=MAVLINK_PANEL,
                               help="The vehicle is preland sim serve: fly in lock-step with it (PRELAND_PACE), "
                                    "every sensor reading at its vehicle time however loaded the machine is."),
    detections_log: Optional[Path] = typer.Option(None, "--detections-log", rich_help_panel=MAVLINK_PANEL,
                                                  help="Keep every detection in this CSV."),
    record_video: Optional[Path] = typer.Option(None, "--record-video", rich_help_panel=MAVLINK_PANEL,
                                                help="Keep the camera's frames in this video."),
    record_to: Optional[Path] = typer.Option(None, "--record-to", metavar="DB", rich_help_panel=MAVLINK_PANEL,
                                             help="After landing, ask for the measured result and store it (as "
                                                  "`preland trial record`) in this results database."),
    campaign_name: Optional[str] = typer.Option(None, "--campaign", rich_help_panel=MAVLINK_PANEL,
                                                help="With --record-to: the campaign."),
    scenario_label: Optional[str] = typer.Option(None, "--scenario", rich_help_panel=MAVLINK_PANEL,
                                                 help="With --record-to: the scenario."),
    record_new: bool = typer.Option(False, "--new", rich_help_panel=MAVLINK_PANEL,
                                    help="With --record-to: the campaign or scenario may be new (else it must be "
                                         "in the database, checked before take-off)."),
) -> None:
    """Fly a mission once (on the embedded simulator, ArduPilot SITL or a vehicle over MAVLink) and print its
    outcome."""
    from .. import api
    from ..config.mission import load_mission
    from ..errors import SpecValueError
    from ..runtime.base import RuntimeOptionError

    try:
        mission = load_mission(mission_file)
    except PrelandError as error:
        raise fail(str(error)) from None
    if takeoff_altitude_m is not None and not 0.0 < takeoff_altitude_m <= 120.0:
        raise fail(f"--takeoff-altitude-m: must be > 0 and <= 120 m, got {takeoff_altitude_m:g}")
    if seed < 0:
        raise fail(f"--seed: must be >= 0, got {seed}")
    given = {"speedup": sitl_speedup, "defaults": tuple(p.resolve() for p in sitl_defaults) or None,
             "physics": sitl_physics,
             "tlog_dir": str(tlog.parent) if tlog else None, "fault_listen": fault_listen,
             "truth": False if no_truth else None, "preflight": False if no_preflight else None,
             "camera_source": camera_source, "detection_log": str(detections_log) if detections_log else None,
             "video_path": str(record_video) if record_video else None, "paced": True if paced else None}
    chosen = choose_runtime(runtime, connect=connect, sitl=sitl,
                            options={name: value for name, value in given.items() if value is not None})
    mission = _with_wind(mission, wind_m_s=wind_m_s, wind_from_deg=wind_from_deg, runtime=chosen)
    if record_to is not None and chosen.name != "mavlink":
        raise fail(f"--record-to: only for a vehicle over MAVLink (mavlink+... runtimes), not {chosen.url}")
    for flag, value in (("--campaign", campaign_name), ("--scenario", scenario_label), ("--new", record_new or None)):
        if value is not None and record_to is None:
            raise fail(f"{flag}: only with --record-to")
    faults = _parse_faults(fault) if fault else None
    try:
        api.trial_request(mission, seed=seed, land=land, sensor=sensor, faults=faults,
                          takeoff_altitude_m=takeoff_altitude_m, record_trajectory=False)
    except SpecValueError as error:
        option = {"sensor": "--sensor", "mode": "--land"}.get(error.field.split(".")[0], "--fault")
        if error.field.startswith("params"):  # a plugin's options: the mission's land.params do not fit it
            raise fail(f"--land {land}: land.{error.field}: {error.problem}") from None
        raise fail(f"{option}: {error.problem}") from None
    if record_to is not None and (not campaign_name or not scenario_label):
        raise fail("--record-to needs --campaign and --scenario")
    if record_to is not None and not record_new:
        _check_record_target(record_to, campaign_name, scenario_label)
    try:
        outcome = api.fly(mission, seed=seed, land=land, sensor=sensor, faults=faults,
                          takeoff_altitude_m=takeoff_altitude_m, record_trajectory=False, runtime=chosen,
                          tlog_name=tlog.name if tlog else None)
    except RuntimeOptionError as error:
        raise fail(runtime_option_line(error)) from None
    except PrelandError as error:
        raise fail(f"{chosen.url}: {error}", code=EXIT_FAILED) from None
    except KeyboardInterrupt:
        raise fail("interrupted", code=130) from None
    data = outcome.to_dict(include_events=events)
    failures = outcome.details.get("preflight_failures") or []
    if failures:
        for line in failures:
            typer.echo(f"preland: preflight: {line}", err=True)
        raise typer.Exit(EXIT_FAILED)
    if as_json:
        typer.echo(json.dumps(data, sort_keys=True))
    else:
        typer.echo(_format_outcome_table(data))
        if events:
            typer.echo("")
            for event in data["events"]:
                typer.echo(f"{event['time_s']:8.2f} s  {event['kind']:<13} {event['message']}")
    if record_to is not None and outcome.outcome.value == "landed":
        _prompt_and_record(record_to, campaign_name, scenario_label, outcome.land_mode,
                           outcome.takeoff_altitude_rel_m, new=record_new)
    if outcome.outcome.value != "landed":
        raise typer.Exit(EXIT_FAILED)


def _check_record_target(db: Path, campaign: str, scenario: str) -> None:
    """Before the flight: the campaign and scenario a measured result will be stored under must exist."""
    from ..campaign.field_records import FieldRecordError, check_names
    from .app import open_store

    store = open_store(db, must_exist=False)
    try:
        check_names(store, campaign, scenario)
    except FieldRecordError as error:
        raise fail(f"--record-to {db}: {error} (record a new one's first trial with preland trial record DB "
                   "CAMPAIGN SCENARIO --new, or fly with --new)") from None
    finally:
        store.close()


def _prompt_and_record(db: Path, campaign: str, scenario: str, land_mode: str, takeoff_altitude_m: float, *,
                       new: bool = False) -> None:
    """Ask for the tape-measured result and store it as a field trial (blank error: nothing stored). A
    measurement the store refuses (offsets that do not make the error) is asked for again."""
    from ..campaign.field_records import FieldMeasurement, FieldRecordError, record
    from .app import open_store

    def number(text: str) -> float | None:
        return float(text) if text.strip() else None

    for _ in range(3):
        answer = typer.prompt("measured landing error in cm (blank to skip)", default="", show_default=False)
        if not answer.strip():
            typer.echo("nothing recorded")
            return
        try:
            measurement = FieldMeasurement(
                error_cm=float(answer),
                x_cm=number(typer.prompt("offset north (x) in cm (blank: not measured)", default="",
                                         show_default=False)),
                y_cm=number(typer.prompt("offset east (y) in cm (blank: not measured)", default="",
                                         show_default=False)),
                land_mode=land_mode, takeoff_altitude_m=takeoff_altitude_m, note="recorded at the end of preland fly")
        except ValueError:
            typer.echo("preland: the measured values must be numbers", err=True)
            continue
        store = open_store(db, must_exist=False)
        try:
            index = record(store, campaign=campaign, scenario=scenario, measurement=measurement, new=new)
        except FieldRecordError as error:
            typer.echo(f"preland: {error}", err=True)
            continue
        finally:
            store.close()
        typer.echo(f"recorded field trial {index} of {campaign} / {scenario}: {measurement.error_cm:g} cm")
        return
    raise fail("nothing recorded: the measured values were refused three times")
