"""preland campaign list, report, compare, export, delete and browse: reading the results store."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import PrelandError
from .app import DPI, EXIT_FAILED, choices, columns, fail, open_store
from .campaign import campaign_app

FIGURE_FORMATS = ("png", "pdf", "svg")
FigureFormat = choices(lambda: FIGURE_FORMATS)


ExportFormat = choices("preland_app.campaign.export:FORMATS")
ExportTable = choices("preland_app.campaign.export:TABLES")
Measure = choices("preland_app.campaign.compare:MEASURES")


def parse_trial(text: str | None) -> tuple[str, int] | None:
    """`SCENARIO:INDEX` (the label may itself hold colons: the index is after the last one)."""
    if text is None:
        return None
    label, sep, index = text.rpartition(":")
    if not sep or not label or not index.strip().isdigit():
        raise fail(f"--trial: expected SCENARIO:INDEX (e.g. 'IRLock / none:3'), got {text!r}")
    return label, int(index)


@campaign_app.command("report")
def campaign_report(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    campaign: Optional[str] = typer.Option(None, "--campaign", help="Campaign name (default: every campaign)."),
    out: Path = typer.Option(Path("report"), "--out", help="Folder for the Markdown, CSV and figure files."),
    figure_format: FigureFormat = typer.Option("png", "--format", help="Figure format."),
    dpi: int = typer.Option(DPI, "--dpi", help="PNG resolution in dots per inch (PDF and SVG are vector)."),
    trial: Optional[str] = typer.Option(None, "--trial", metavar="SCENARIO:INDEX",
                                        help="The trial the trajectory figure shows (default: the first landed "
                                             "trial of the first precision scenario)."),
) -> None:
    """Write each campaign's table (Markdown, CSV: spread, confidence intervals, published figures beside)
    and its figures."""
    from ..campaign.catalog import require_campaign
    from ..campaign.report import markdown_table, summarize, write_report

    if not 50 <= dpi <= 1200:
        raise fail(f"--dpi: must be within 50..1200, got {dpi}")
    chosen = parse_trial(trial)
    store = open_store(db, must_exist=True)
    try:
        names = [campaign] if campaign else store.campaigns()
        if not names:
            raise fail(f"{db}: no campaigns stored")
        if campaign:
            require_campaign(store, campaign)
        if chosen is not None and len(names) != 1:
            raise fail("--trial: give --campaign too (a trial belongs to one campaign)")
        for name in names:
            written = write_report(store, name, out, figure_format=figure_format, dpi=dpi, trial=chosen)
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
    export_format: ExportFormat = typer.Option("csv", "--format", help="jsonl is JSON Lines; parquet needs the "
                                               "parquet extra: pip install 'preland\\[parquet]'."),
    table: ExportTable = typer.Option("trials", "--table", help="trials: one row per trial, events: one per event, "
                                      "trajectories: one per 2 Hz sample; trial_id joins them."),
    campaign: Optional[str] = typer.Option(None, "--campaign", help="Only this campaign."),
    out: Optional[Path] = typer.Option(None, "--out", help="Output file (default: standard output; Parquet "
                                       "needs a file)."),
) -> None:
    """Export stored trials, events or trajectories for pandas, R or polars."""
    from ..campaign.catalog import require_campaign
    from ..campaign.export import export

    store = open_store(db, must_exist=True)
    try:
        if campaign is not None:
            require_campaign(store, campaign)
        text = export(store, table=table, export_format=export_format, campaign=campaign, out=out)
    except PrelandError as error:
        raise fail(f"--campaign: {error}" if campaign and "no campaign" in str(error) else str(error)) from None
    finally:
        store.close()
    if text is not None:
        typer.echo(text, nl=False)
    else:
        typer.echo(f"wrote {out}", err=True)


@campaign_app.command("list")
def campaign_list(db: Path = typer.Argument(..., metavar="DB", help="SQLite results database.")) -> None:
    """List the campaigns in a store: scenarios, trials per source (sim, sitl, field), landed, sources."""
    from ..campaign.catalog import overview

    store = open_store(db, must_exist=True)
    try:
        entries = overview(store)
    finally:
        store.close()
    if not entries:
        typer.echo(f"{db}: no campaigns")
        return
    for number, entry in enumerate(entries):
        if number:
            typer.echo("")
        where = f", from {entry.source_path}" if entry.source_path else " (field records only)"
        when = f", first run {entry.created_at}" if entry.created_at else ""
        typer.echo(f"{entry.name}: {len(entry.scenarios)} scenario(s), {entry.trials} trial(s){where}{when}")
        rows = [(s.scenario, s.land_mode, str(s.counts["sim"]), str(s.counts["sitl"]), str(s.counts["field"]),
                 str(s.landed), s.published_source or "-") for s in entry.scenarios]
        text = columns(("  scenario", "land mode", "sim", "sitl", "field", "landed", "published source"),
                       [("  " + r[0], *r[1:]) for r in rows])
        typer.echo(text)


def _db_campaign(text: str) -> tuple[Path, str | None]:
    """`DB` or `DB:CAMPAIGN`."""
    if Path(text).exists():
        return Path(text), None
    path, sep, name = text.rpartition(":")
    if sep and path and Path(path).exists():
        return Path(path), name or None
    raise fail(f"{text}: no such results database")


def _one_campaign(store, db: Path, name: str | None) -> str:
    from ..campaign.catalog import require_campaign

    if name is not None:
        try:
            require_campaign(store, name)
        except PrelandError as error:
            raise fail(str(error)) from None
        return name
    names = store.campaigns()
    if len(names) != 1:
        raise fail(f"{db}: holds {len(names)} campaigns ({', '.join(names) or 'none'}); name one as DB:CAMPAIGN")
    return names[0]


@campaign_app.command("compare")
def campaign_compare(
    before: str = typer.Argument(..., metavar="DB[:CAMPAIGN]", help="The reference run."),
    after: str = typer.Argument(..., metavar="DB[:CAMPAIGN]", help="The run to compare with it."),
    measure: Measure = typer.Option("landing_error_cm", "--measure", help="The measure compared."),
) -> None:
    """Per-scenario difference of the means (after - before) with bootstrap 95 % confidence intervals."""
    from ..campaign.compare import MEASURES, compare

    (db_b, name_b), (db_a, name_a) = _db_campaign(before), _db_campaign(after)
    store_b, store_a = open_store(db_b, must_exist=True), open_store(db_a, must_exist=True)
    try:
        campaign_b, campaign_a = _one_campaign(store_b, db_b, name_b), _one_campaign(store_a, db_a, name_a)
        rows = compare((store_b, campaign_b), (store_a, campaign_a), measure=measure)
    finally:
        store_b.close()
        store_a.close()

    def mean_ci(spread) -> str:
        if spread is None:
            return "-"
        if spread.ci_low is None:
            return f"{spread.mean:.2f}"
        return f"{spread.mean:.2f} [{spread.ci_low:.2f}, {spread.ci_high:.2f}]"

    table = []
    for row in rows:
        d = row.difference
        label = row.scenario if row.source == "sim" else f"{row.scenario} [{row.source}]"
        if d is None:
            table.append((label, f"{row.before_n}", "-", f"{row.after_n}", "-", "-", "one side only"))
            continue
        diff = f"{d.difference:+.2f}" + (f" [{d.ci_low:+.2f}, {d.ci_high:+.2f}]" if d.ci_low is not None else "")
        verdict = ("difference CI excludes 0" if d.significant else "difference CI includes 0") + \
            ("; means' CIs overlap" if d.intervals_overlap else "; means' CIs apart")
        table.append((label, str(d.before.n), mean_ci(d.before), str(d.after.n), mean_ci(d.after), diff, verdict))
    typer.echo(f"{MEASURES[measure]}: {before} ({campaign_b}) -> {after} ({campaign_a}); mean [95 % CI], "
               "landed trials only")
    typer.echo(columns(("scenario", "n", "before", "n", "after", "after - before [95 % CI]", "verdict"), table))


@campaign_app.command("delete")
def campaign_delete(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    campaign: str = typer.Argument(..., metavar="CAMPAIGN"),
    scenario: list[str] = typer.Option([], "--scenario", help="Delete only this scenario (repeatable)."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask for confirmation."),
) -> None:
    """Delete a campaign's trials (or some scenarios'), with their events and trajectories."""
    from ..campaign.catalog import delete, plan_deletion

    store = open_store(db, must_exist=True)
    try:
        try:
            plan = plan_deletion(store, campaign, scenario)
        except PrelandError as error:
            raise fail(str(error)) from None
        what = (f"campaign {campaign}" if plan.whole_campaign
                else f"{', '.join(repr(s) for s in plan.scenarios)} of campaign {campaign}")
        counts = ", ".join(f"{n} {source}" for source, n in sorted(plan.counts.items())) or "no trials"
        if not yes:
            warning = " (field trials are measurements: they cannot be re-run)" if plan.counts.get("field") else ""
            if not typer.confirm(f"delete {what}: {counts} trial(s){warning}?", default=False):
                typer.echo("nothing deleted")
                raise typer.Exit(EXIT_FAILED)
        removed = delete(store, plan)
    finally:
        store.close()
    typer.echo(f"deleted {what}: {removed} trial(s)")


@campaign_app.command("browse")
def campaign_browse(
    db: Path = typer.Argument(..., metavar="DB", help="SQLite results database."),
    port: int = typer.Option(8001, "--port", help="Port to serve on (localhost)."),
    metadata_out: Optional[Path] = typer.Option(None, "--metadata", help="Only write Datasette's metadata file "
                                                "(units, descriptions, canned queries) here and exit."),
) -> None:
    r"""Browse the store in Datasette (optional: pip install 'preland\[browse]'), with units, descriptions and
    canned queries for the thesis' tables; Ctrl-C stops it."""
    import tempfile

    from ..campaign.browse import BrowseError, start, write_metadata

    if not db.exists():
        raise fail(f"{db}: no such results database")
    if metadata_out is not None:
        typer.echo(f"wrote {write_metadata(db, metadata_out)}")
        return
    if not 1024 <= port <= 65535:
        raise fail(f"--port: must be within 1024..65535, got {port}")
    store = open_store(db, must_exist=True)  # migrates an older store before Datasette reads it
    store.close()
    with tempfile.TemporaryDirectory() as folder:
        try:
            process = start(db, Path(folder) / "metadata.json", port=port)
        except BrowseError as error:
            raise fail(str(error)) from None
        typer.echo(f"Datasette on http://127.0.0.1:{port}/{db.stem} (canned queries: thesis_table, "
                   "field_beside_simulated, paper_measures, campaigns_overview); Ctrl-C stops it")
        try:
            code = process.wait()
        except KeyboardInterrupt:
            process.terminate()
            process.wait(timeout=10)
            raise typer.Exit(130) from None
    if code != 0:
        raise fail(f"Datasette stopped with exit code {code}", code=EXIT_FAILED)
