"""preland sim calibrate: fit declared simulator parameters to field trials, write a profile.
preland sim params: the calibratable parameters."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from typer.core import TyperCommand

from ..errors import PrelandError
from .app import EXIT_FAILED, columns, fail, progress_bar
from .sim import sim_app

MULTI_VALUE_OPTIONS = ("--params", "--holdout")


class MultiValueCommand(TyperCommand):
    """Lets `--params A B C` mean `--params A --params B --params C` (likewise --holdout): every word up to the
    next option belongs to the option before it."""

    def parse_args(self, ctx, args):
        expanded, current, last_was_option = [], None, False
        for word in args:
            if word.startswith("-"):
                current = word if word in MULTI_VALUE_OPTIONS else None
                expanded.append(word)
                last_was_option = True
                continue
            if current is not None and not last_was_option:
                expanded.append(current)
            expanded.append(word)
            last_was_option = False
        return super().parse_args(ctx, expanded)


@sim_app.command("calibrate", cls=MultiValueCommand)
def sim_calibrate(
    campaign_file: Path = typer.Argument(..., metavar="CAMPAIGN",
                                         help="Campaign file saying which scenario is which (labels, land modes, "
                                              "faults, weather, and each scenario's reference.source_table)."),
    field_csv: Optional[Path] = typer.Option(None, "--field-csv", help="Field trials as a CSV in the thesis "
                                             "reference's columns, matched to scenarios by source_table."),
    field_db: Optional[Path] = typer.Option(None, "--field-db", help="Field trials from a results store: the "
                                            "campaign's trials whose source is field."),
    params: list[str] = typer.Option([], "--params", metavar="NAME ...",
                                     help="Parameters to fit (declared calibratable: `preland sim params`)."),
    holdout: list[str] = typer.Option([], "--holdout", metavar="LABEL ...",
                                      help="Scenarios kept out of the fit, scored separately."),
    budget: int = typer.Option(20, "--budget", help="Objective evaluations (each flies every fitted scenario)."),
    seed: int = typer.Option(0, "--seed", help="Optimizer seed."),
    trials_per_scenario: int = typer.Option(6, "--trials-per-scenario",
                                            help="Simulated trials per fitted scenario and evaluation (the same "
                                                 "seeds at every evaluation)."),
    score_trials: int = typer.Option(10, "--score-trials", help="Trials per scenario when scoring the result."),
    time_weight: float = typer.Option(0.25, "--time-weight", help="Weight of the landing-time distance."),
    fresh_seed_sets: int = typer.Option(2, "--fresh-seed-sets",
                                        help="Sets of other seeds the best values are flown on again, to tell "
                                             "the fit from the seeds' luck (0: none)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes (default: number of cores)."),
    out: Path = typer.Option(Path("profile.yaml"), "--out", help="Profile YAML to write."),
    name: Optional[str] = typer.Option(None, "--name", help="The profile's name (default: the file's stem)."),
    quiet: bool = typer.Option(False, "--quiet", help="No progress bar."),
) -> None:
    """Fit the named parameters to recorded field trials and write a simulation profile with its provenance."""
    from ..campaign.calibrate import CalibrationRequest, calibrate
    from ..campaign.executors import ExecutorError
    from ..campaign.field_data import field_trials_from_csv, field_trials_from_store
    from ..campaign.spec import load_campaign
    from ..sim.calibratable import find_calibratable
    from ..sim.profile import write_profile

    for parameter in params:  # before anything else, so a misspelt name costs nothing
        try:
            find_calibratable(parameter)
        except PrelandError as error:
            raise fail(f"--params: {error}") from None
    if (field_csv is None) == (field_db is None):
        raise fail("give the field trials with exactly one of --field-csv and --field-db")
    if workers is not None and workers < 1:
        raise fail(f"--workers: must be >= 1, got {workers}")
    try:
        campaign = load_campaign(campaign_file)
        if field_csv is not None:
            field, data = field_trials_from_csv(field_csv, campaign), str(field_csv)
        else:
            from .app import open_store

            store = open_store(field_db, must_exist=True)
            field, data = field_trials_from_store(store, campaign), f"{field_db} (field trials of {campaign.name})"
            store.close()
        request = CalibrationRequest(campaign=campaign, field=field, data=data, params=tuple(params),
                                     holdout=tuple(holdout), budget=budget, seed=seed,
                                     trials_per_scenario=trials_per_scenario, score_trials=score_trials,
                                     time_weight=time_weight, fresh_seed_sets=fresh_seed_sets,
                                     name=name or out.stem)
        with progress_bar(enabled=not quiet) as advance:
            result = calibrate(request, workers=workers, progress=advance)
    except ExecutorError as error:
        raise fail(str(error), code=EXIT_FAILED) from None
    except KeyboardInterrupt:
        typer.echo("preland: calibration interrupted; no profile written", err=True)
        raise typer.Exit(130) from None
    except PrelandError as error:
        raise fail(str(error)) from None
    write_profile(result.profile, out)
    fitted = ", ".join(f"{k} = {v:g}" for k, v in result.best.items())
    typer.echo(f"fitted {fitted} (objective {result.objective:.3f}, {result.evaluations} evaluations, "
               f"{result.wall_time_s:.0f} s)")
    if result.fresh_seed_objectives:
        typer.echo(f"objective on {len(result.fresh_seed_objectives)} other seed set(s): "
                   + ", ".join(f"{value:.3f}" for value in result.fresh_seed_objectives)
                   + f" (on the fit's own seeds {result.objective:.3f})")
    rows = [(s.label, s.role.replace("_", " "), f"{s.sim_mean_cm:.1f}", f"{s.field_mean_cm:.1f}",
             f"{s.field_min_cm:.1f}..{s.field_max_cm:.1f}", "yes" if s.inside else "no", f"{s.wasserstein_cm:.1f}")
            for s in result.scores]
    typer.echo(columns(("scenario", "role", "sim mean cm", "field mean cm", "field min..max", "inside", "W1 cm"),
                       rows))
    typer.echo(f"wrote {out}")


@sim_app.command("params")
def sim_params() -> None:
    """The calibratable parameters: name, default, range, and where the default comes from."""
    from ..sim.calibratable import calibratable_parameters

    rows = [(p.name, f"{p.default():g}", f"{p.low:g}..{p.high:g}", p.unit, p.source)
            for p in sorted(calibratable_parameters().values(), key=lambda p: p.name)]
    typer.echo(columns(("parameter", "default", "range", "unit", "source of the default"), rows))
