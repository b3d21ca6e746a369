"""preland campaign run: repeated trials into the results store (reading them: campaign_results.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import PrelandError
from .app import EXIT_FAILED, app, choices, fail, progress_bar


# The executors are a registry (register_executor) with no entry point group: only Python code that runs
# before the app can add one, and the choices are read from the registry when --executor is shown or checked,
# so they are what it holds then.
Executor = choices("preland_app.campaign.executors:executor_names")

EXIT_PAUSED = 3  # a field campaign stopped at a pause: --resume goes on


def _field_options(runtime, *, measure: str | None, answers: Path | None, order: str | None, quiet: bool) -> dict:
    """The field campaign's options for `api.run_campaign` (none unless the runtime flies a vehicle): the
    operator at this terminal (or the answers file), the status lines, measure and order as given."""
    given = {"measure": measure, "answers": str(answers) if answers is not None else None, "order": order}
    if runtime is None or not getattr(runtime, "flies_a_vehicle", False):
        for name, value in given.items():
            if value is not None:
                raise fail(f"--{name}: only for a field campaign, on a vehicle (--runtime mavlink+...)")
        return {}
    import sys

    from ..field.operator import TerminalOperator

    options = {name: value for name, value in given.items() if value is not None}
    options["status"] = (lambda status: None) if quiet else (lambda status: typer.echo(status.line(), err=True))
    if answers is None and sys.stdin.isatty():
        options["operator"] = TerminalOperator(ask=lambda prompt: typer.prompt(prompt, default="",
                                                                                show_default=False),
                                               say=lambda line: typer.echo(line, err=True))
    return options


campaign_app = typer.Typer(help="Campaigns: run repeated trials into a results store; list, report, compare, "
                                "export, browse or delete what it holds.", no_args_is_help=True)
app.add_typer(campaign_app, name="campaign")


@campaign_app.command("run")
def campaign_run(
    campaign_file: Path = typer.Argument(..., metavar="FILE", help="Campaign YAML file (see campaigns/)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes (default: number of cores)."),
    db: Path = typer.Option(Path("results.db"), "--db", help="SQLite results database (created if missing)."),
    resume: bool = typer.Option(False, "--resume", help="Finish a campaign already in --db; no trial runs twice."),
    report: Optional[Path] = typer.Option(None, "--report", help="Write the campaign's report to this folder."),
    quiet: bool = typer.Option(False, "--quiet", help="No progress bar."),
    runtime: Optional[str] = typer.Option(
        None, "--runtime", metavar="URL",
        help="Where every trial flies (default: the campaign file's runtime:, else sim:): sim:, sitl:PATH "
             "(?speedup=X&defaults=A.parm), or a vehicle over MAVLink, mavlink+udp://:14550, "
             "mavlink+udpout://HOST:PORT, mavlink+tcp://HOST:PORT, mavlink+serial:///dev/DEVICE?baud=N "
             "(its trials one after another)."),
    sitl: Optional[str] = typer.Option(None, "--sitl", metavar="PATH",
                                       help="Shorthand for --runtime sitl:PATH: each trial on a fresh ArduPilot SITL "
                                            "process (given empty: $PRELAND_SITL_BINARY)."),
    sitl_speedup: Optional[float] = typer.Option(
        None, "--sitl-speedup", rich_help_panel="SITL runtime (sitl:PATH)",
        help="SITL --speedup (default: 2 for land modes that read camera frames, so the companion keeps the "
             "camera's rate; 10 for the others)."),
    sitl_physics: Optional[str] = typer.Option(
        None, "--sitl-physics", metavar="ardupilot|preland", rich_help_panel="SITL runtime (sitl:PATH)",
        help="SITL's physics: ardupilot (its own, the default) or preland (preland's motor-level quad X over "
             "SITL's JSON interface, flying in preland's wind, gusts and rotor wash)."),
    sitl_defaults: list[Path] = typer.Option([], "--sitl-defaults", rich_help_panel="SITL runtime (sitl:PATH)",
                                             help="More ArduPilot parameter defaults files, repeatable, applied "
                                                  "after the copter defaults (copter.parm of the binary's "
                                                  "ArduPilot tree, else preland's own)."),
    tlog_dir: Optional[Path] = typer.Option(None, "--tlog-dir", rich_help_panel="SITL runtime (sitl:PATH)",
                                            help="SITL and MAVLink: one MAVLink telemetry log (.tlog) per trial in "
                                                 "this folder."),
    no_truth: bool = typer.Option(False, "--no-truth", rich_help_panel="MAVLink runtime (mavlink+..., a vehicle)",
                                  help="The vehicle reports no ground truth (a real drone)."),
    no_preflight: bool = typer.Option(False, "--no-preflight",
                                      rich_help_panel="MAVLink runtime (mavlink+..., a vehicle)",
                                      help="Skip the preflight checks before each trial."),
    paced: bool = typer.Option(False, "--paced", rich_help_panel="MAVLink runtime (mavlink+..., a vehicle)",
                               help="The vehicle is preland sim serve: fly in lock-step with it (PRELAND_PACE), "
                                    "every sensor reading at its vehicle time however loaded the machine is."),
    camera_source: Optional[str] = typer.Option(
        None, "--camera", metavar="SRC", rich_help_panel="MAVLink runtime (mavlink+..., a vehicle)",
        help="A real camera (index, device, GStreamer pipeline) or a video file instead of the virtual camera."),
    fault_listen: Optional[str] = typer.Option(
        None, "--fault-listen", metavar="UDP:HOST:PORT", rich_help_panel="MAVLink runtime (mavlink+..., a vehicle)",
        help="Accept the thesis' fault command (preland fault send) here while each trial flies."),
    measure: Optional[str] = typer.Option(
        None, "--measure", metavar="operator|vehicle|truth", rich_help_panel="Field campaign (mavlink+..., a vehicle)",
        help="Where each landing's error comes from: operator (asked after each landing, or --answers), vehicle "
             "(its RTK position against the campaign's field.pad), truth (a simulated vehicle's ground truth). "
             "Default: truth on a vehicle that reports it (sim serve, SITL) unless --answers is given, else "
             "operator."),
    answers: Optional[Path] = typer.Option(
        None, "--answers", rich_help_panel="Field campaign (mavlink+..., a vehicle)",
        help="The operator's answers from a CSV file (scenario,trial,error_cm,x_cm,y_cm; error_cm a number, skip, "
             "redo or abort), for rehearsals: a pause then stops the campaign for --resume."),
    order: Optional[str] = typer.Option(
        None, "--order", metavar="campaign|shuffled", rich_help_panel="Field campaign (mavlink+..., a vehicle)",
        help="The trials in the campaign's order (default) or shuffled with its base seed (the same order on "
             "every --resume)."),
    executor: Executor = typer.Option("local", "--executor", help="Where trials run: local (worker processes "
                                      "on this machine), ray (tasks of a Ray cluster) or a registered one."),
    ray_address: Optional[str] = typer.Option(None, "--ray-address", metavar="ADDR",
                                              help="With --executor ray: the cluster to join (auto, "
                                                   "ray://host:10001, host:6379; default $RAY_ADDRESS, else a "
                                                   "local Ray instance of --workers CPUs)."),
    trial_cpus: float = typer.Option(1.0, "--trial-cpus", help="With --executor ray: CPUs each trial asks for."),
    outcomes_only: bool = typer.Option(False, "--outcomes-only", help="Store only each trial's outcome row: no "
                                       "event log, no trajectory (a much smaller store)."),
) -> None:
    """Run every trial of a campaign on its runtime (the embedded simulator by default, SITL, or one vehicle
    over MAVLink), storing each as it finishes."""
    import time

    from .. import api
    from ..campaign.driver import CampaignInterrupted
    from ..campaign.executors import ExecutorError, executor_factory
    from ..campaign.lease import CampaignBusy
    from ..campaign.spec import load_campaign
    from ..runtime.base import RuntimeOptionError
    from ..field.campaign import FieldCampaignPaused
    from .fly import choose_runtime, runtime_option_line

    try:
        campaign = load_campaign(campaign_file)
    except PrelandError as error:
        raise fail(str(error)) from None
    if workers is not None and workers < 1:
        raise fail(f"--workers: must be >= 1, got {workers}")
    if not trial_cpus > 0:
        raise fail(f"--trial-cpus: must be > 0, got {trial_cpus:g}")
    try:
        factory = executor_factory(executor)
    except ExecutorError as error:
        raise fail(f"--executor: {error}") from None
    if executor == "local" and (ray_address is not None or trial_cpus != 1.0):
        raise fail(f"--{'ray-address' if ray_address is not None else 'trial-cpus'}: needs --executor ray")
    given = {"speedup": sitl_speedup, "defaults": tuple(p.resolve() for p in sitl_defaults) or None,
             "physics": sitl_physics,
             "tlog_dir": str(tlog_dir.resolve()) if tlog_dir else None, "truth": False if no_truth else None,
             "preflight": False if no_preflight else None, "paced": True if paced else None,
             "fault_listen": fault_listen, "camera_source": camera_source}
    options = {name: value for name, value in given.items() if value is not None}
    chosen = choose_runtime(runtime if runtime is not None or sitl is not None else campaign.runtime,
                            connect=None, sitl=sitl, options=options) \
        if not getattr(factory, "runs_elsewhere", False) else None
    # On this machine the runtime is opened (and checked) here; on a cluster the nodes resolve it.
    target = chosen if chosen is not None else api.runtime_url(runtime, sitl=sitl)
    started = time.perf_counter()
    failures: list[str] = []
    field_options = _field_options(chosen, measure=measure, answers=answers, order=order, quiet=quiet)
    try:
        with progress_bar(enabled=not quiet and not field_options) as advance:
            def progress(done: int, total: int, record) -> None:
                advance(done, total)
                if record is not None and record.result.get("outcome") == "error":
                    failures.append(f"{record.scenario} #{record.trial_index}: {record.result.get('message')}")

            run = api.run_campaign(campaign, db=db, workers=workers, resume=resume, runtime=target,
                                   options=options if chosen is None else None,
                                   progress=progress, executor=executor, ray_address=ray_address,
                                   trial_cpus=trial_cpus, outcomes_only=outcomes_only, **field_options)
    except CampaignInterrupted as error:
        typer.echo(f"preland: {error}", err=True)
        raise typer.Exit(130) from None
    except FieldCampaignPaused as error:
        typer.echo(f"preland: {error}", err=True)
        raise typer.Exit(EXIT_PAUSED) from None
    except KeyboardInterrupt:  # a field campaign, between or during its flights: what is stored stays
        typer.echo("preland: interrupted; run again with --resume to go on", err=True)
        raise typer.Exit(130) from None
    except CampaignBusy as error:
        raise fail(str(error), code=EXIT_FAILED) from None
    except RuntimeOptionError as error:
        raise fail(runtime_option_line(error)) from None
    except ExecutorError as error:
        raise fail(f"--executor {executor}: {error}") from None
    except PrelandError as error:
        raise fail(str(error)) from None
    ran, total = run.ran, run.total
    elapsed = time.perf_counter() - started
    typer.echo(f"campaign {campaign.name}: {ran} trial(s) run, {total} in {db} ({elapsed:.1f} s)")
    for line in failures:
        typer.echo(f"  trial failed: {line}", err=True)
    if report is not None:
        for path in api.write_campaign_report(db, campaign.name, report):
            typer.echo(f"wrote {path}")