"""preland trial: field trials (record, amend, delete) and one stored trial in detail (show).

All four take the trial's place in the store as positional arguments, DB CAMPAIGN SCENARIO, and everything else
as options. show, amend and delete name an existing row, DB CAMPAIGN SCENARIO INDEX, as sqlite-utils names a
table's row by its database, table and key; record creates one, so it takes the same place without the INDEX,
which the store assigns (and record prints). The place is what every call needs and always in that order; the
measurements vary, most are optional, and read best named (--error-cm 6 --x-cm 3).
The earlier `trial record --db DB --campaign NAME --scenario LABEL` is refused in one line showing this form.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from typer.core import TyperCommand

from .app import DPI, app, choices, click_errors, fail
from .app import open_store
from .campaign_results import FIGURE_FORMATS


OutcomeName = choices("preland_app.outcome:Outcome")
Source = choices("preland_app.campaign.catalog:SOURCES")
OLD_RECORD_OPTIONS = ("--db", "--campaign", "--scenario")  # trial record's place, as it was given before


class _RecordCommand(TyperCommand):
    """trial record: the place given as options, the earlier form, is refused showing the present one."""

    def parse_args(self, ctx, args):
        for word in args:
            option = word.partition("=")[0]
            if option in OLD_RECORD_OPTIONS:
                raise click_errors.UsageError(f"{option}: trial record takes the database, campaign and scenario "
                                              "as arguments: preland trial record DB CAMPAIGN SCENARIO [OPTIONS]")
        return super().parse_args(ctx, args)


trial_app = typer.Typer(help="One trial: show any stored trial; record, amend or delete field trials.",
                         no_args_is_help=True)
app.add_typer(trial_app, name="trial")


@trial_app.command("record", cls=_RecordCommand)
def trial_record(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database (created if missing)."),
    campaign: str = typer.Argument(..., metavar="CAMPAIGN", help="Campaign the trial belongs to (as stored)."),
    scenario: str = typer.Argument(..., metavar="SCENARIO", help="Scenario label (as in the campaign file)."),
    error_cm: Optional[float] = typer.Option(None, "--error-cm", help="Tape-measured landing error in cm "
                                             "(needed when the outcome is landed)."),
    x_cm: Optional[float] = typer.Option(None, "--x-cm", help="Offset north (x) in cm; with --y-cm, within 1 cm "
                                         "of --error-cm."),
    y_cm: Optional[float] = typer.Option(None, "--y-cm", help="Offset east (y) in cm."),
    landing_time_s: Optional[float] = typer.Option(None, "--landing-time-s", help="Landing time in s."),
    outcome: OutcomeName = typer.Option("landed", "--outcome", help="How the trial ended."),
    land_mode: Optional[str] = typer.Option(None, "--land", help="Land mode flown (must be the scenario's)."),
    takeoff_altitude_m: Optional[float] = typer.Option(None, "--takeoff-altitude-m", help="Initial height in m."),
    note: str = typer.Option("", "--note", help="Free text."),
    new: bool = typer.Option(False, "--new", help="Start a campaign or scenario the store does not know yet."),
) -> None:
    """Store a field trial's measured outcome beside the simulated trials of the same scenario."""
    from ..campaign.field_records import FieldMeasurement, FieldRecordError, record

    measurement = FieldMeasurement(error_cm=error_cm, x_cm=x_cm, y_cm=y_cm, landing_time_s=landing_time_s,
                                   outcome=outcome, land_mode=land_mode, takeoff_altitude_m=takeoff_altitude_m,
                                   note=note)
    store = open_store(db, must_exist=False)
    try:
        index = record(store, campaign=campaign, scenario=scenario, measurement=measurement, new=new)
    except FieldRecordError as error:
        message = str(error)
        for option, argument in (("--campaign: ", "CAMPAIGN: "), ("--scenario: ", "SCENARIO: ")):
            if message.startswith(option):  # the names' checks are shared with fly --record-to's options
                message = argument + message[len(option):]
        raise fail(message) from None
    finally:
        store.close()
    shown = "no error measured" if error_cm is None else f"{error_cm:g} cm"
    typer.echo(f"recorded field trial {index} of {campaign} / {scenario}: {outcome}, {shown}")


@trial_app.command("amend")
def trial_amend(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    campaign: str = typer.Argument(..., metavar="CAMPAIGN"),
    scenario: str = typer.Argument(..., metavar="SCENARIO"),
    index: int = typer.Argument(..., metavar="INDEX", help="The field trial's index (as trial record printed)."),
    error_cm: Optional[float] = typer.Option(None, "--error-cm", help="Corrected landing error in cm."),
    x_cm: Optional[float] = typer.Option(None, "--x-cm", help="Corrected offset north (x) in cm."),
    y_cm: Optional[float] = typer.Option(None, "--y-cm", help="Corrected offset east (y) in cm."),
    landing_time_s: Optional[float] = typer.Option(None, "--landing-time-s", help="Corrected landing time in s."),
    outcome: Optional[OutcomeName] = typer.Option(None, "--outcome", help="Corrected outcome."),
    land_mode: Optional[str] = typer.Option(None, "--land", help="Corrected land mode."),
    takeoff_altitude_m: Optional[float] = typer.Option(None, "--takeoff-altitude-m", help="Corrected height in m."),
    note: Optional[str] = typer.Option(None, "--note", help="Corrected note."),
    reason: str = typer.Option("", "--reason", help="Why it changed (kept in the audit column)."),
) -> None:
    """Correct a field trial; the change, with when and why, is kept in its audit column."""
    from ..campaign.field_records import FieldRecordError, amend

    given = {"error_cm": error_cm, "x_cm": x_cm, "y_cm": y_cm, "landing_time_s": landing_time_s,
             "outcome": outcome, "land_mode": land_mode, "takeoff_altitude_m": takeoff_altitude_m, "note": note}
    changes = {name: value for name, value in given.items() if value is not None}
    store = open_store(db, must_exist=True)
    try:
        diff = amend(store, campaign=campaign, scenario=scenario, index=index, changes=changes, reason=reason)
    except FieldRecordError as error:
        raise fail(str(error)) from None
    finally:
        store.close()
    typer.echo(f"amended field trial {index} of {campaign} / {scenario}: "
               + ", ".join(f"{column} {old} -> {new}" for column, (old, new) in diff.items()))


@trial_app.command("delete")
def trial_delete(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    campaign: str = typer.Argument(..., metavar="CAMPAIGN"),
    scenario: str = typer.Argument(..., metavar="SCENARIO"),
    index: int = typer.Argument(..., metavar="INDEX", help="The field trial's index."),
    reason: str = typer.Option("", "--reason", help="Why (kept with the deleted row)."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask for confirmation."),
) -> None:
    """Delete a field trial (its row is kept in the table deleted_trials)."""
    from ..campaign.field_records import FieldRecordError, delete, field_trial

    store = open_store(db, must_exist=True)
    try:
        row = field_trial(store, campaign, scenario, index)
        if not yes:
            shown = "-" if row["landing_error_cm"] is None else f"{row['landing_error_cm']:g} cm"
            if not typer.confirm(f"delete field trial {index} of {campaign} / {scenario} ({row['outcome']}, "
                                 f"{shown}, recorded {row['finished_at']})?", default=False):
                typer.echo("nothing deleted")
                raise typer.Exit(1)
        delete(store, campaign=campaign, scenario=scenario, index=index, reason=reason)
    except FieldRecordError as error:
        raise fail(str(error)) from None
    finally:
        store.close()
    typer.echo(f"deleted field trial {index} of {campaign} / {scenario} (kept in deleted_trials)")


@trial_app.command("show")
def trial_show(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    campaign: str = typer.Argument(..., metavar="CAMPAIGN"),
    scenario: str = typer.Argument(..., metavar="SCENARIO"),
    index: int = typer.Argument(..., metavar="INDEX", help="Trial index within the scenario."),
    source: Optional[Source] = typer.Option(None, "--source", help="Where the trial ran (default: the simulated "
                                            "trial of that index, else the SITL one, else the field one)."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Also draw its path into this file ("
                                        + ", ".join(f".{suffix}" for suffix in FIGURE_FORMATS) + ")."),
    dpi: int = typer.Option(DPI, "--dpi", help="With --plot to PNG: dots per inch."),
) -> None:
    """One stored trial in full: its outcome, details, audit and event log; its path with --plot."""
    import json

    from ..campaign.catalog import find_trial
    from ..errors import PrelandError

    suffixes = [f".{suffix}" for suffix in FIGURE_FORMATS]
    if plot is not None and plot.suffix.lower() not in suffixes:
        raise fail(f"--plot: {plot} must end in {', '.join(suffixes[:-1])} or {suffixes[-1]}")
    store = open_store(db, must_exist=True)
    try:
        try:
            trial = find_trial(store, campaign, scenario, index, source)
        except PrelandError as error:
            raise fail(str(error)) from None
        events = store.events(trial["id"])
        written = None
        if plot is not None:
            from ..campaign.figure_trajectory import trajectory_figure

            written = trajectory_figure(store, trial, plot, dpi=dpi)
    finally:
        store.close()

    def show(value, unit: str = "") -> str:
        if value is None:
            return "-"
        return f"{value:.2f}{unit}" if isinstance(value, float) else f"{value}{unit}"

    rows = [("trial", f"{trial['campaign']} / {trial['scenario']} #{trial['trial_index']} ({trial['source']}, "
                      f"{trial['runtime']})"),
            ("outcome", f"{trial['outcome']} ({trial['message']})"), ("seed", str(trial["seed"])),
            ("land mode", show(trial["land_mode"])), ("sensor", show(trial["sensor"])),
            ("faults", show(trial["faults"])), ("take-off altitude", show(trial["takeoff_altitude_m"], " m")),
            ("landing error", show(trial["landing_error_cm"], " cm") + f"  (from the {trial['scoring_reference']})"),
            ("offset north", show(trial["offset_north_cm"], " cm")),
            ("offset east", show(trial["offset_east_cm"], " cm")),
            ("landing time", show(trial["landing_time_s"], " s")), ("flight time", show(trial["flight_time_s"], " s")),
            ("touchdown speed", show(trial["touchdown_speed_m_s"], " m/s")),
            ("software", f"{trial['software_version']}, spec {trial['spec_hash']}"),
            ("stored", f"{trial['finished_at']}" + (f" after {trial['wall_time_s']:.1f} s wall"
                                                    if trial["wall_time_s"] is not None else ""))]
    rows += [(key.replace("_", " "), json.dumps(value) if isinstance(value, (list, dict)) else show(value))
             for key, value in sorted(trial["details"].items())]
    for change in trial["audit"]:
        rows.append(("amended", f"{change['at']}: " + ", ".join(
            f"{column} {old} -> {new}" for column, (old, new) in change["changes"].items())
            + (f" ({change['reason']})" if change.get("reason") else "")))
    width = max(len(label) for label, _ in rows)
    typer.echo("\n".join(f"{label:<{width}}  {value}" for label, value in rows))
    if events:
        typer.echo("")
        for event in events:
            typer.echo(f"{event['time_s']:8.2f} s  {event['kind']:<13} {event['message']}")
    if plot is not None:
        typer.echo(f"wrote {written}" if written else "no trajectory stored for this trial (field trials have none)")
