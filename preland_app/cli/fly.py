"""preland fly: one mission, on the embedded simulator, SITL or a vehicle over MAVLink."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from ..errors import PrelandError
from .app import EXIT_FAILED, app, check_sitl_speedup, choices, fail
from ..landing.registry import LAND_MODES, PRECISION_SENSORS

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


def _with_wind(mission, *, wind_m_s: float | None, wind_from_deg: float | None, connect: str | None):
    """The mission with the command line's wind; refused over MAVLink, where the weather is the real one."""
    import math
    from dataclasses import replace

    if wind_m_s is None and wind_from_deg is None:
        return mission
    option = "--wind-m-s" if wind_m_s is not None else "--wind-from-deg"
    if connect is not None:
        raise fail(f"{option}: only for the embedded simulator and SITL (with --connect the wind is the real one)")
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
                                    help="Drop a sensor's values (repeatable, one per sensor): none, random:P, "
                                         "periodic:KEEP:DROP, permanent, below:H, above:H; add :first-attempt "
                                         "to limit it to the first landing attempt. E.g. marker=below:3."),
    seed: int = typer.Option(1, "--seed", help="Trial seed: same seed, same outcome."),
    wind_m_s: Optional[float] = typer.Option(None, "--wind-m-s", help="Steady wind speed in m/s, overriding the "
                                             "mission's environment (embedded simulator and SITL)."),
    wind_from_deg: Optional[float] = typer.Option(None, "--wind-from-deg", help="Where the wind blows from, deg "
                                                  "clockwise from north (default: the mission's, else drawn per "
                                                  "seed)."),
    takeoff_altitude_m: Optional[float] = typer.Option(
        None, "--takeoff-altitude-m", help="Take-off altitude above home in m, overriding the mission's."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
    events: bool = typer.Option(False, "--events", help="Include the mission's event log."),
    connect: Optional[str] = typer.Option(
        None, "--connect", metavar="URL",
        help="Fly over MAVLink instead of the embedded simulator: udp://:14550, udpout://127.0.0.1:14550, "
             "tcp://127.0.0.1:5760, serial:///dev/ttyAMA0:921600."),
    no_truth: bool = typer.Option(False, "--no-truth",
                                  help="With --connect: the vehicle reports no ground truth (a real drone)."),
    sitl: Optional[str] = typer.Option(None, "--sitl", metavar="PATH",
                                       help="Fly on a fresh ArduPilot SITL process (arducopter binary; "
                                            "default $PRELAND_SITL_BINARY when --sitl is given empty)."),
    sitl_speedup: Optional[float] = typer.Option(
        None, "--sitl-speedup", help="SITL --speedup (default: 2 for land modes that read camera frames, so the "
                                     "companion keeps the camera's rate; 10 for the others)."),
    sitl_defaults: list[Path] = typer.Option([], "--sitl-defaults", help="More ArduPilot parameter defaults "
                                             "files, repeatable, applied after the copter defaults (copter.parm "
                                             "of the binary's ArduPilot tree, else preland's own)."),
    tlog: Optional[Path] = typer.Option(None, "--tlog", help="With --connect or --sitl: write a MAVLink "
                                        "telemetry log (.tlog) of the trial."),
    camera_source: Optional[str] = typer.Option(None, "--camera", metavar="SRC",
                                                help="With --connect: a real camera (index, device, GStreamer "
                                                     "pipeline) or a video file instead of the virtual camera."),
    no_preflight: bool = typer.Option(False, "--no-preflight", help="With --connect: skip the preflight checks."),
    detections_log: Optional[Path] = typer.Option(None, "--detections-log",
                                                  help="With --connect: keep every detection in this CSV."),
    record_video: Optional[Path] = typer.Option(None, "--record-video",
                                                help="With --connect: keep the camera's frames in this video."),
    record_to: Optional[Path] = typer.Option(None, "--record-to", metavar="DB",
                                             help="With --connect: after landing, ask for the measured result and "
                                                  "store it (as `preland trial record`) in this results database."),
    campaign_name: Optional[str] = typer.Option(None, "--campaign", help="With --record-to: the campaign."),
    scenario_label: Optional[str] = typer.Option(None, "--scenario", help="With --record-to: the scenario."),
    record_new: bool = typer.Option(False, "--new", help="With --record-to: the campaign or scenario may be new "
                                    "(else it must be in the database, checked before take-off)."),
    fault_listen: Optional[str] = typer.Option(None, "--fault-listen", metavar="URL",
                                               help="With --connect or --sitl: take fault commands (preland fault send) "
                                                    "on this UDP address, e.g. udp://127.0.0.1:14560."),
) -> None:
    """Fly a mission once (on the embedded simulator, or over MAVLink) and print its outcome."""
    from ..config.mission import load_mission
    from ..errors import SpecValueError
    from ..runtime.embedded import TrialRequest, run_trial

    try:
        mission = load_mission(mission_file)
    except PrelandError as error:
        raise fail(str(error)) from None
    if takeoff_altitude_m is not None and not 0.0 < takeoff_altitude_m <= 120.0:
        raise fail(f"--takeoff-altitude-m: must be > 0 and <= 120 m, got {takeoff_altitude_m:g}")
    check_sitl_speedup(sitl_speedup)
    if seed < 0:
        raise fail(f"--seed: must be >= 0, got {seed}")
    mission = _with_wind(mission, wind_m_s=wind_m_s, wind_from_deg=wind_from_deg, connect=connect)
    faults = _parse_faults(fault) if fault else None
    request = TrialRequest(mission=mission, seed=seed, land_mode=land, sensor=sensor, faults=faults,
                           takeoff_altitude_rel_m=takeoff_altitude_m, record_trajectory=False)
    try:
        request.resolved_mission()
    except SpecValueError as error:
        option = {"sensor": "--sensor", "mode": "--land"}.get(error.field.split(".")[0], "--fault")
        if error.field.startswith("params"):  # a plugin's options: the mission's land.params do not fit it
            raise fail(f"--land {land}: land.{error.field}: {error.problem}") from None
        raise fail(f"{option}: {error.problem}") from None

    if sitl is not None:
        from ..runtime.sitl import SitlOptions, resolve_sitl_binary, run_sitl_trial

        try:
            binary = resolve_sitl_binary(sitl or None)
        except PrelandError as error:  # a missing binary is bad input, as for `campaign run --sitl`
            raise fail(f"--sitl: {error}") from None
        options = SitlOptions(binary=binary, speedup=sitl_speedup, defaults=tuple(sitl_defaults),
                              tlog_dir=tlog.parent if tlog else None, fault_listen=fault_listen)
        try:
            outcome = run_sitl_trial(request, options=options, tlog_name=tlog.name if tlog else None)
        except PrelandError as error:
            raise fail(f"--sitl: {error}", code=EXIT_FAILED) from None
        except KeyboardInterrupt:
            raise fail("interrupted", code=130) from None
    elif connect is not None:
        from ..runtime.mavlink import run_mavlink_trial

        try:
            if record_to is not None and (not campaign_name or not scenario_label):
                raise fail("--record-to needs --campaign and --scenario")
            if record_to is not None and not record_new:
                _check_record_target(record_to, campaign_name, scenario_label)
            outcome = run_mavlink_trial(request, url=connect, truth=not no_truth,
                                        tlog_path=str(tlog) if tlog else None, fault_listen=fault_listen,
                                        preflight=not no_preflight, camera_source=camera_source,
                                        detection_log=str(detections_log) if detections_log else None,
                                        video_path=str(record_video) if record_video else None)
        except PrelandError as error:
            raise fail(f"--connect {connect}: {error}", code=EXIT_FAILED) from None
        except KeyboardInterrupt:
            raise fail("interrupted", code=130) from None
    else:
        outcome = run_trial(request)
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
    if connect is not None and record_to is not None and outcome.outcome.value == "landed":
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
