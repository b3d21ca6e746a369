"""The `preland` command line: a thin layer over the Python API.

Every user mistake ends in one line on stderr naming what is wrong and a
non-zero exit (2 for bad input, 1 for a failed run); never a traceback.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

from . import __version__
from .errors import PrelandError
from .landing.registry import LAND_MODES

app = typer.Typer(
    name="preland",
    help="Automated precision-landing missions for multirotor drones: fly, inject faults, measure.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def fail(message: str, *, code: int = EXIT_BAD_INPUT) -> typer.Exit:
    typer.echo(f"preland: error: {message}", err=True)
    return typer.Exit(code)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"preland {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version_callback, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Automated precision-landing missions for multirotor drones."""


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


def _parse_faults(values: list[str]) -> dict[str, str]:
    from .sensing.faults import SENSORS, FaultSpec, FaultSyntaxError

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
    sensor: Optional[str] = typer.Option(None, "--sensor", metavar="SENSOR",
                                         help="Precision sensor of the cautious mode: irlock, marker or fused."),
    fault: list[str] = typer.Option([], "--fault", metavar="SENSOR=FAULT",
                                    help="Drop a sensor's values (repeatable, one per sensor): none, random:P, "
                                         "periodic:KEEP:DROP, permanent, below:H, above:H; add :first-attempt "
                                         "to limit it to the first landing attempt. E.g. marker=below:3."),
    seed: int = typer.Option(1, "--seed", help="Trial seed: same seed, same outcome."),
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
    sitl_speedup: float = typer.Option(10.0, "--sitl-speedup", help="SITL --speedup."),
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
    fault_listen: Optional[str] = typer.Option(None, "--fault-listen", metavar="URL",
                                               help="With --connect or --sitl: take fault commands (preland fault send) "
                                                    "on this UDP address, e.g. udp://127.0.0.1:14560."),
) -> None:
    """Fly a mission once (on the embedded simulator, or over MAVLink) and print its outcome."""
    from .config.mission import load_mission
    from .errors import SpecValueError
    from .runtime.embedded import TrialRequest, run_trial

    try:
        mission = load_mission(mission_file)
    except PrelandError as error:
        raise fail(str(error)) from None
    if takeoff_altitude_m is not None and not 0.0 < takeoff_altitude_m <= 120.0:
        raise fail(f"--takeoff-altitude-m: must be > 0 and <= 120 m, got {takeoff_altitude_m:g}")
    if seed < 0:
        raise fail(f"--seed: must be >= 0, got {seed}")
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
        from .runtime.sitl import SitlOptions, resolve_sitl_binary, run_sitl_trial

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
        from .runtime.mavlink import run_mavlink_trial

        try:
            if record_to is not None and (not campaign_name or not scenario_label):
                raise fail("--record-to needs --campaign and --scenario")
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
                           outcome.takeoff_altitude_rel_m)
    if outcome.outcome.value != "landed":
        raise typer.Exit(EXIT_FAILED)


def _prompt_and_record(db: Path, campaign: str, scenario: str, land_mode: str, takeoff_altitude_m: float) -> None:
    """Ask for the tape-measured result and store it as a field trial (blank error: nothing stored)."""
    answer = typer.prompt("measured landing error in cm (blank to skip)", default="", show_default=False)
    if not answer.strip():
        typer.echo("nothing recorded")
        return
    try:
        error_cm = float(answer)
        x_cm = float(typer.prompt("offset north (x) in cm", default="0"))
        y_cm = float(typer.prompt("offset east (y) in cm", default="0"))
    except ValueError:
        raise fail("the measured values must be numbers") from None
    trial_record(db=db, campaign=campaign, scenario=scenario, error_cm=error_cm, x_cm=x_cm, y_cm=y_cm,
                 landing_time_s=None, outcome="landed", land_mode=land_mode, takeoff_altitude_m=takeoff_altitude_m,
                 note="recorded at the end of preland fly")


pad_app = typer.Typer(help="Landing pads: render printable pads.", no_args_is_help=True)
app.add_typer(pad_app, name="pad")


@pad_app.command("render")
def pad_render(
    out: Path = typer.Option(..., "--out", help="Output file: .png or .pdf."),
    preset: Optional[str] = typer.Option(None, "--preset", help="Pad preset: thesis or paper."),
    pad_file: Optional[Path] = typer.Option(None, "--pad", help="A pad YAML file instead of a preset."),
    dpi: int = typer.Option(100, "--dpi", help="Print resolution in dots per inch."),
) -> None:
    """Render a printable landing pad at true scale, with its dimensions annotated."""
    from .sensing.pad import PAD_PRESETS, load_pad
    from .sensing.pad_render import render_printable_pad

    if (preset is None) == (pad_file is None):
        raise fail("give exactly one of --preset or --pad")
    if out.suffix.lower() not in (".png", ".pdf"):
        raise fail(f"--out: {out} must end in .png or .pdf")
    if not 20 <= dpi <= 600:
        raise fail(f"--dpi: must be within 20..600, got {dpi}")
    if preset is not None and preset not in PAD_PRESETS:
        raise fail(f"--preset: unknown pad preset {preset!r} (expected one of: {', '.join(PAD_PRESETS)})")
    try:
        pad = load_pad(preset if preset is not None else str(pad_file))
    except PrelandError as error:
        raise fail(str(error)) from None
    path = render_printable_pad(pad, out, dpi=dpi)
    typer.echo(f"wrote {path} ({pad.name}: {pad.size_m * 100:.0f} cm sheet, "
               + ", ".join(f"id {m.id} {m.side_m * 100:.0f} cm" for m in pad.markers) + ")")


campaign_app = typer.Typer(help="Campaigns: repeated trials, a results store, reports.", no_args_is_help=True)
app.add_typer(campaign_app, name="campaign")


def _open_store(db: Path, *, must_exist: bool):
    from .campaign.store import ResultsStore

    if must_exist and not db.exists():
        raise fail(f"{db}: no such results database")
    try:
        return ResultsStore(db)
    except PrelandError as error:
        raise fail(str(error)) from None


@campaign_app.command("run")
def campaign_run(
    campaign_file: Path = typer.Argument(..., metavar="FILE", help="Campaign YAML file (see campaigns/)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes (default: number of cores)."),
    db: Path = typer.Option(Path("results.db"), "--db", help="SQLite results database (created if missing)."),
    resume: bool = typer.Option(False, "--resume", help="Finish a campaign already in --db; no trial runs twice."),
    report: Optional[Path] = typer.Option(None, "--report", help="Write the campaign's report to this folder."),
    quiet: bool = typer.Option(False, "--quiet", help="No progress bar."),
    sitl: Optional[str] = typer.Option(None, "--sitl", metavar="PATH",
                                       help="Run each trial on a fresh ArduPilot SITL process (arducopter binary, "
                                            "or $PRELAND_SITL_BINARY when given empty)."),
    sitl_speedup: float = typer.Option(10.0, "--sitl-speedup", help="SITL --speedup."),
    sitl_defaults: list[Path] = typer.Option([], "--sitl-defaults", help="More ArduPilot parameter defaults "
                                             "files, repeatable, applied after the copter defaults (copter.parm "
                                             "of the binary's ArduPilot tree, else preland's own)."),
    tlog_dir: Optional[Path] = typer.Option(None, "--tlog-dir", help="With --sitl: one MAVLink telemetry log "
                                            "(.tlog) per trial in this folder."),
) -> None:
    """Run every trial of a campaign (embedded simulator, or SITL with --sitl), storing each as it finishes."""
    import os
    import time

    from .campaign.executor import CampaignInterrupted, run_campaign
    from .campaign.report import write_report
    from .campaign.spec import load_campaign

    try:
        campaign = load_campaign(campaign_file)
    except PrelandError as error:
        raise fail(str(error)) from None
    if workers is not None and workers < 1:
        raise fail(f"--workers: must be >= 1, got {workers}")
    sitl_options = None
    if sitl is not None:
        from .runtime.sitl import SitlOptions, resolve_sitl_binary

        try:
            sitl_options = SitlOptions(binary=resolve_sitl_binary(sitl or None), speedup=sitl_speedup,
                                       defaults=tuple(p.resolve() for p in sitl_defaults),
                                       tlog_dir=tlog_dir.resolve() if tlog_dir else None)
        except PrelandError as error:
            raise fail(f"--sitl: {error}") from None
    store = _open_store(db, must_exist=False)
    started = time.perf_counter()
    failures: list[str] = []
    try:
        with _progress(enabled=not quiet) as advance:
            def progress(done: int, total: int, record) -> None:
                advance(done, total)
                if record is not None and record.result.get("outcome") == "error":
                    failures.append(f"{record.scenario} #{record.trial_index}: {record.result.get('message')}")

            ran, total = run_campaign(campaign, store, workers=workers or os.cpu_count() or 1, resume=resume,
                                      progress=progress, sitl=sitl_options)
    except CampaignInterrupted as error:
        store.close()
        typer.echo(f"preland: {error}", err=True)
        raise typer.Exit(130) from None
    except PrelandError as error:
        store.close()
        raise fail(str(error)) from None
    elapsed = time.perf_counter() - started
    typer.echo(f"campaign {campaign.name}: {ran} trial(s) run, {total} in {db} ({elapsed:.1f} s)")
    for line in failures:
        typer.echo(f"  trial failed: {line}", err=True)
    if report is not None:
        for path in write_report(store, campaign.name, report):
            typer.echo(f"wrote {path}")
    store.close()


def _progress(*, enabled: bool):
    """A progress bar with ETA on stderr (a no-op when disabled)."""
    from contextlib import contextmanager

    @contextmanager
    def bar():
        if not enabled:
            yield lambda done, total: None
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
        from rich.progress import TimeRemainingColumn

        with Progress(TextColumn("trials"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      TextColumn("ETA"), TimeRemainingColumn(), console=Console(stderr=True),
                      transient=False) as progress:
            task = progress.add_task("trials", total=None)

            def advance(done: int, total: int) -> None:
                progress.update(task, completed=done, total=total)

            yield advance

    return bar()


@campaign_app.command("report")
def campaign_report(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    campaign: Optional[str] = typer.Option(None, "--campaign", help="Campaign name (default: every campaign)."),
    out: Path = typer.Option(Path("report"), "--out", help="Folder for the Markdown, CSV and PNG files."),
) -> None:
    """Write each campaign's table (Markdown, CSV) and figures (PNG), published figures beside."""
    from .campaign.report import markdown_table, summarize, write_report

    store = _open_store(db, must_exist=True)
    names = [campaign] if campaign else store.campaigns()
    if not names:
        raise fail(f"{db}: no campaigns stored")
    try:
        for name in names:
            written = write_report(store, name, out)
            typer.echo(markdown_table(name, summarize(store, name)))
            for path in written:
                typer.echo(f"wrote {path}")
    except PrelandError as error:
        raise fail(str(error)) from None
    finally:
        store.close()


@campaign_app.command("export")
def campaign_export(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    export_format: str = typer.Option("csv", "--format", help="Export format: csv."),
    campaign: Optional[str] = typer.Option(None, "--campaign", help="Only this campaign."),
    out: Optional[Path] = typer.Option(None, "--out", help="Output file (default: standard output)."),
) -> None:
    """Export every stored trial, one row per trial."""
    from .campaign.report import export_csv

    if export_format != "csv":
        raise fail(f"--format: unknown format {export_format!r} (expected: csv)")
    store = _open_store(db, must_exist=True)
    try:
        text = export_csv(store, campaign)
    finally:
        store.close()
    if out is None:
        typer.echo(text, nl=False)
    else:
        out.write_text(text, encoding="utf-8")
        typer.echo(f"wrote {out}")


sim_app = typer.Typer(help="The embedded simulator as a MAVLink vehicle.", no_args_is_help=True)
app.add_typer(sim_app, name="sim")


@sim_app.command("serve")
def sim_serve(
    listen: list[str] = typer.Option(["udp:127.0.0.1:14550"], "--listen", metavar="UDP:HOST:PORT",
                                     help="UDP address to serve on (localhost unless told otherwise). Repeat it "
                                          "for more channels, as ArduPilot's serial ports: one for preland, "
                                          "one for a ground station."),
    speedup: float = typer.Option(1.0, "--speedup", help="Simulated seconds per wall second."),
    seed: int = typer.Option(1, "--seed", help="Simulator seed (wind, GPS error, noise)."),
    mission_file: Optional[Path] = typer.Option(None, "--mission",
                                                help="Take the environment and parameters from this mission."),
    param_values: list[str] = typer.Option([], "--param", metavar="NAME=VALUE",
                                           help="Set an ArduPilot parameter at start (repeatable; after the "
                                                "mission's), as a defaults file does: e.g. --param PLND_ENABLED=1 "
                                                "--param PLND_TYPE=1 for the precision land modes."),
) -> None:
    """Serve the embedded simulator over MAVLink, behaving like ArduCopter (Ctrl-C stops it)."""
    import asyncio
    import math

    from .clock_scaled import ScaledWallClock
    from .sim.mavlink_face import MavlinkFace
    from .sim.params import ARDUCOPTER_PARAMS, ParameterTable
    from .sim.simulator import Simulator

    if not 0.1 <= speedup <= 1000:
        raise fail(f"--speedup: must be within 0.1..1000, got {speedup:g}")
    environment, params, yaw = None, {}, 0.0
    if mission_file is not None:
        from .config.mission import load_mission

        try:
            mission = load_mission(mission_file)
        except PrelandError as error:
            raise fail(str(error)) from None
        environment, params, yaw = mission.environment, dict(mission.params), mission.initial_yaw_deg
    check = ParameterTable()
    for text in param_values:
        name, sep, value_text = text.partition("=")
        name = name.strip().upper()
        info = ARDUCOPTER_PARAMS.get(name)
        if not sep or not name:
            raise fail(f"--param {text!r}: expected NAME=VALUE, e.g. PLND_ENABLED=1")
        if info is None or not info.ardupilot:
            raise fail(f"--param {text!r}: {name} is not an ArduCopter parameter the simulator models")
        try:
            value = float(value_text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise fail(f"--param {text!r}: {value_text.strip()!r} is not a number")
        try:
            check.set(name, value)
        except ValueError as error:
            raise fail(f"--param {text!r}: {error}") from None
        params[name] = value

    async def main() -> None:
        simulator = Simulator(seed=seed, environment=environment, params=params, initial_yaw_deg=yaw)
        face = MavlinkFace(simulator=simulator, clock=ScaledWallClock(speedup=speedup), listen=listen)
        typer.echo(f"serving the embedded simulator on {', '.join(listen)} at {speedup:g}x (Ctrl-C to stop)")
        await face.run()

    try:
        asyncio.run(main())
    except PrelandError as error:
        raise fail(str(error)) from None
    except KeyboardInterrupt:
        typer.echo("stopped")


fault_app = typer.Typer(help="The thesis' fault command, as a MAVLink message.", no_args_is_help=True)
app.add_typer(fault_app, name="fault")


@fault_app.command("send")
def fault_send(
    connect: str = typer.Option(..., "--connect", metavar="URL",
                                help="Where the companion takes fault commands (its --fault-listen), "
                                     "e.g. udp://127.0.0.1:14560."),
    target: str = typer.Option(..., "--target", help="Sensor subsystem: irlock, marker or both."),
    r_drop: float = typer.Option(0.0, "--r-drop", help="Drop probability (random mode; 1.0: permanent)."),
    p_keep: int = typer.Option(0, "--p-keep", help="Values to keep (periodic mode)."),
    p_drop: int = typer.Option(0, "--p-drop", help="Values to drop (periodic mode)."),
) -> None:
    """Send a PRELAND_FAULT_INJECTION command (all zero: injection off for the target)."""
    from .mavlink.fault_message import send
    from .sensing.faults import FaultCommand, FaultSyntaxError, FaultTarget

    targets = {"irlock": FaultTarget.IRLOCK, "marker": FaultTarget.MARKER, "both": FaultTarget.BOTH}
    if target not in targets:
        raise fail(f"--target: expected irlock, marker or both, got {target!r}")
    try:
        command = FaultCommand(target=targets[target], r_drop=r_drop, p_keep=p_keep, p_drop=p_drop)
        send(command, url=connect)
    except (FaultSyntaxError, PrelandError) as error:
        raise fail(str(error)) from None
    faults = ", ".join(f"{sensor} {fault}" for sensor, fault in command.faults().items())
    typer.echo(f"sent PRELAND_FAULT_INJECTION to {connect}: {faults}")


@app.command("detect")
def detect(
    camera_source: Optional[str] = typer.Option(None, "--camera", metavar="SRC",
                                                help="Capture device: index (0), device path, or GStreamer pipeline."),
    video: Optional[Path] = typer.Option(None, "--video", help="A video file instead of a camera."),
    pad_name: str = typer.Option("thesis", "--pad", help="Pad preset (thesis, paper) or pad YAML file."),
    calibration: Optional[Path] = typer.Option(None, "--calibration", help="OpenCV calibration file."),
    out: Optional[Path] = typer.Option(None, "--out", help="Write the annotated frames to this video."),
    frames: int = typer.Option(0, "--frames", help="Stop after this many frames (0: the whole video, or Ctrl-C)."),
) -> None:
    """Detect the pad's markers live or in a video: overlays, detection rate and per-frame latency."""
    import asyncio
    import statistics
    import time

    from .clock import LoopClock
    from .sensing.camera import RPI_CAMERA_V2_640X480, load_calibration
    from .sensing.capture import CaptureDeviceSource, VideoFileSource, VideoRecorder
    from .sensing.marker import MarkerDetector
    from .sensing.overlay import draw_detections
    from .sensing.pad import load_pad

    if (camera_source is None) == (video is None):
        raise fail("give exactly one of --camera or --video")
    try:
        pad = load_pad(pad_name)
        camera = load_calibration(calibration) if calibration else RPI_CAMERA_V2_640X480
    except PrelandError as error:
        raise fail(str(error)) from None
    detector = MarkerDetector(pad=pad, camera=camera)

    async def main() -> tuple[int, int, list[float]]:
        clock = LoopClock()
        source = (VideoFileSource(path=video, clock=clock, camera=camera) if video is not None
                  else CaptureDeviceSource(source=camera_source, clock=clock, camera=camera))
        recorder = None
        seen = total = 0
        latencies: list[float] = []
        try:
            while frames <= 0 or total < frames:
                frame = await source.next_frame()
                if frame is None:
                    break
                started = time.perf_counter()
                detections = detector.detect(frame.image)
                latencies.append(time.perf_counter() - started)
                total += 1
                seen += bool(detections)
                if out is not None:
                    annotated = draw_detections(frame.image, detections, camera)
                    if recorder is None:
                        recorder = VideoRecorder(path=out, frame_rate_hz=camera.frame_rate_hz,
                                                 size=(annotated.shape[1], annotated.shape[0]), color=True)
                    recorder.write(annotated)
        finally:
            if recorder is not None:
                recorder.close()
        return seen, total, latencies

    try:
        seen, total, latencies = asyncio.run(main())
    except PrelandError as error:
        raise fail(str(error)) from None
    except KeyboardInterrupt:
        raise fail("interrupted", code=130) from None
    if total == 0:
        raise fail("no frames")
    latencies_ms = sorted(1000 * v for v in latencies)
    typer.echo(f"frames {total}, pad detected in {seen} ({100 * seen / total:.1f} %)")
    typer.echo(f"detection latency per frame: median {statistics.median(latencies_ms):.2f} ms, "
               f"p95 {latencies_ms[int(0.95 * (len(latencies_ms) - 1))]:.2f} ms")
    if out is not None:
        typer.echo(f"wrote {out}")


camera_app = typer.Typer(help="Cameras: calibration.", no_args_is_help=True)
app.add_typer(camera_app, name="camera")


@camera_app.command("calibrate")
def camera_calibrate(
    images: Optional[Path] = typer.Option(None, "--images", help="Folder of ChArUco board images (png, jpg)."),
    video: Optional[Path] = typer.Option(None, "--video", help="A video of the board (every 10th frame is used)."),
    out: Path = typer.Option(..., "--out", help="OpenCV calibration file to write (.yaml)."),
    squares_x: int = typer.Option(7, "--squares-x", help="Board squares across."),
    squares_y: int = typer.Option(5, "--squares-y", help="Board squares down."),
    square_m: float = typer.Option(0.04, "--square-m", help="Square side in m."),
    marker_m: float = typer.Option(0.03, "--marker-m", help="Marker side in m."),
    dictionary: str = typer.Option("DICT_4X4_50", "--dictionary", help="ArUco dictionary of the board."),
) -> None:
    """Calibrate a camera from views of a ChArUco board; writes a file the marker sensor reads."""
    from .sensing.calibration import CharucoBoardSpec, calibrate, read_images

    if images is None and video is None:
        raise fail("give --images or --video")
    try:
        result = calibrate(read_images(folder=images, video=video),
                           board_spec=CharucoBoardSpec(squares_x=squares_x, squares_y=squares_y, square_m=square_m,
                                                       marker_m=marker_m, dictionary=dictionary))
    except (PrelandError, KeyError) as error:
        raise fail(str(error)) from None
    result.write(out)
    typer.echo(f"wrote {out}: fx {result.fx_px:.1f} px, fy {result.fy_px:.1f} px, "
               f"{result.views_used} views, RMS reprojection error {result.rms_error_px:.3f} px")


trial_app = typer.Typer(help="Trials measured in the field.", no_args_is_help=True)
app.add_typer(trial_app, name="trial")


@trial_app.command("record")
def trial_record(
    db: Path = typer.Option(..., "--db", help="SQLite results database (created if missing)."),
    campaign: str = typer.Option(..., "--campaign", help="Campaign the trial belongs to."),
    scenario: str = typer.Option(..., "--scenario", help="Scenario label (as in the campaign file)."),
    error_cm: float = typer.Option(..., "--error-cm", help="Tape-measured landing error in cm."),
    x_cm: Optional[float] = typer.Option(None, "--x-cm", help="Offset north (x) in cm."),
    y_cm: Optional[float] = typer.Option(None, "--y-cm", help="Offset east (y) in cm."),
    landing_time_s: Optional[float] = typer.Option(None, "--landing-time-s", help="Landing time in s."),
    outcome: str = typer.Option("landed", "--outcome", help="landed, aborted, crashed..."),
    land_mode: Optional[str] = typer.Option(None, "--land", help="Land mode flown."),
    takeoff_altitude_m: Optional[float] = typer.Option(None, "--takeoff-altitude-m", help="Initial height in m."),
    note: str = typer.Option("", "--note", help="Free text."),
) -> None:
    """Store a field trial's measured outcome beside the simulated trials of the same scenario."""
    from .campaign.store import TrialRecord
    from .outcome import Outcome

    if error_cm < 0:
        raise fail(f"--error-cm: must be >= 0, got {error_cm:g}")
    if outcome not in {o.value for o in Outcome}:
        raise fail(f"--outcome: unknown outcome {outcome!r} (expected one of: "
                   f"{', '.join(o.value for o in Outcome)})")
    from .landing.registry import is_land_mode_name

    if land_mode is not None and not is_land_mode_name(land_mode):
        raise fail(f"--land: unknown land mode {land_mode!r}")
    store = _open_store(db, must_exist=False)
    try:
        known = next((t for t in store.trials(campaign) if t["scenario"] == scenario), None)
        index = store.next_trial_index(campaign, scenario, "field")
        result = {"outcome": outcome, "message": note or "measured in the field",
                  "land_mode": land_mode or (known["land_mode"] if known else None),
                  "sensor": known["sensor"] if known else None, "faults": known["faults"] if known else None,
                  "takeoff_altitude_m": takeoff_altitude_m if takeoff_altitude_m is not None
                  else (known["takeoff_altitude_m"] if known else None),
                  "scoring_reference": known["scoring_reference"] if known else "pad",
                  "landing_error_cm": error_cm, "offset_north_cm": x_cm, "offset_east_cm": y_cm,
                  "landing_time_s": landing_time_s, "details": {"note": note} if note else {}}
        store.add_trial(TrialRecord(campaign=campaign, scenario=scenario,
                                    scenario_index=store.scenario_index(campaign, scenario), trial_index=index,
                                    seed=0, result=result, spec_hash="field", runtime="field", source="field"))
    finally:
        store.close()
    typer.echo(f"recorded field trial {index} of {campaign} / {scenario}: {error_cm:g} cm")


def _columns(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    """Rows as text columns, each as wide as its widest cell (the last one left ragged)."""
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header) - 1)]
    return "\n".join("  ".join([*(cell.ljust(w) for cell, w in zip(row, widths)), row[-1]]).rstrip()
                     for row in (header, *rows))


@app.command("modes")
def modes() -> None:
    """List the land modes this version can fly: built-in ones and installed plugins (entry point group
    preland.land_modes). Any import path package.module:ClassName flies too."""
    from .landing.registry import catalog

    rows = [(row.name, row.origin, row.scored_from or "-", row.sensor or "-", row.description) for row in catalog()]
    typer.echo(_columns(("mode", "from", "scored from", "sensor", "description"), rows))


@app.command("schema")
def schema(kind: str = typer.Argument(..., metavar="mission|campaign|pad", help="Which file's schema.")) -> None:
    """Print the JSON Schema of mission, campaign or pad files (for editors: yaml-language-server)."""
    from .config.schema import SCHEMA_KINDS, schema_text

    if kind not in SCHEMA_KINDS:
        raise fail(f"schema: unknown kind {kind!r} (expected one of: {', '.join(SCHEMA_KINDS)})")
    typer.echo(schema_text(kind), nl=False)


def main() -> None:
    """Console entry point."""
    try:
        app()
    except PrelandError as error:  # anything a command did not catch itself
        typer.echo(f"preland: error: {error}", err=True)
        sys.exit(EXIT_FAILED)


if __name__ == "__main__":
    main()
