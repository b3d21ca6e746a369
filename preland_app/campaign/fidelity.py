"""Fidelity to the field: how a scenario's simulated landings compare with measured ones.

The distance is the Wasserstein-1 (earth mover's) distance between the
simulated and the field landing errors (scipy.stats.wasserstein_distance): in
cm, how far the simulated distribution must move to become the field's. Beside
it, whether the simulated mean falls inside the field's min..max, and whether
the mean's 95 % confidence interval settles that. Used by
`preland sim calibrate` (its objective and the profile's scores) and by the
campaign report's fidelity section (`fidelity_section`), which also marks each
scenario as fitted or held out when the campaign ran with a fitted profile.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml

from ..sim.profile import ProfileSpec, ScenarioScore
from .fidelity_tests import WITNESSES, verdicts_section
from .stats import describe


def wasserstein(a: Sequence[float], b: Sequence[float]) -> float:
    from scipy.stats import wasserstein_distance

    return float(wasserstein_distance(list(a), list(b)))


def score_scenario(*, label: str, role: str, sim_errors_cm: Sequence[float], sim_times_s: Sequence[float],
                   field_errors_cm: Sequence[float], field_times_s: Sequence[float]) -> ScenarioScore | None:
    """The scenario's score, None when either side has no landing error."""
    if not sim_errors_cm or not field_errors_cm:
        return None
    mean = statistics.fmean(sim_errors_cm)
    timed = bool(sim_times_s) and bool(field_times_s)
    return ScenarioScore(
        label=label, role=role, wasserstein_cm=wasserstein(sim_errors_cm, field_errors_cm), sim_mean_cm=mean,
        field_mean_cm=statistics.fmean(field_errors_cm), field_min_cm=min(field_errors_cm),
        field_max_cm=max(field_errors_cm), inside=min(field_errors_cm) <= mean <= max(field_errors_cm),
        trials=len(sim_errors_cm), field_trials=len(field_errors_cm),
        time_wasserstein_s=wasserstein(sim_times_s, field_times_s) if timed else None,
        sim_time_mean_s=statistics.fmean(sim_times_s) if sim_times_s else None,
        field_time_mean_s=statistics.fmean(field_times_s) if field_times_s else None)


# ------------------------------------------------------------------ the report's section


@dataclass(frozen=True)
class ProfileUse:
    """The profile a stored campaign ran with, and which file named it."""

    profile: ProfileSpec | None
    named_by: str  # "campaign", "mission" or "" (defaults)
    problem: str = ""


def campaign_profile(spec_text: str, source_path: str) -> ProfileUse:
    """The profile named by a stored campaign's text (or by its mission file), loaded; a profile that can no
    longer be read is reported as a problem, not raised (the report still shows the trials)."""
    from ..errors import SpecError
    from ..sim.profile import load_profile, resolve_profile_path

    base = Path(source_path).parent if source_path else Path.cwd()
    try:
        data = yaml.safe_load(spec_text) or {}
    except yaml.YAMLError:
        return ProfileUse(None, "")
    named, where, relative_to = data.get("sim_profile"), "campaign", base
    if named is None and isinstance(data.get("mission"), str):
        mission_path = resolve_profile_path(data["mission"], relative_to=base)
        try:
            mission = yaml.safe_load(mission_path.read_text(encoding="utf-8")) or {}
        except (OSError, yaml.YAMLError):
            mission = {}
        named, where, relative_to = mission.get("sim_profile"), "mission", mission_path.parent
    if not isinstance(named, str):
        return ProfileUse(None, "")
    try:
        return ProfileUse(load_profile(resolve_profile_path(named, relative_to=relative_to)), where)
    except SpecError as error:
        return ProfileUse(None, where, problem=str(error))


def _role(profile: ProfileSpec | None, label: str) -> str:
    if profile is None:
        return "defaults"
    provenance = profile.provenance
    if provenance is None:
        return "profile (not fitted)"
    score = provenance.score_of(label)
    if score is not None:
        return "fitted" if score.role == "fitted" else "held out"
    if label in provenance.held_out:
        return "held out"
    return "not in the fit"


def _unsettled(spread, low: float | None, high: float | None, inside: str) -> str:
    """A note when the mean's 95 % confidence interval reaches across an end of the published range: the
    simulated trials do not settle on which side of it the model's mean lies."""
    if spread is None or spread.ci_low is None or low is None or high is None:
        return ""
    interval = f"{spread.ci_low:.1f}..{spread.ci_high:.1f}"
    if inside == "inside" and spread.ci_low < low:
        return f"its 95 % CI ({interval}) reaches below the published min"
    if inside == "inside" and spread.ci_high > high:
        return f"its 95 % CI ({interval}) reaches above the published max"
    if (inside == "below" and spread.ci_high >= low) or (inside == "above" and spread.ci_low <= high):
        return f"its 95 % CI ({interval}) reaches inside"
    return ""


def fidelity_rows(summaries, profile: ProfileSpec | None) -> list[tuple[str, ...]]:
    """One row per simulated scenario with published figures: role, simulated mean and its 95 % confidence
    interval (bootstrap, `stats.py`), the published mean and min..max (published trials, else a published
    range), inside or not, the Wasserstein distance to the published trials, the landing times, and notes:
    what the fit says about it, and whether the interval reaches across an end of the range."""
    rows = []
    for s in summaries:
        if s.source not in WITNESSES or s.reference is None:
            continue
        errors = s.errors_cm()
        published = [p.error_cm for p in s.published]
        low = min(published) if published else s.reference.min_error_cm
        high = max(published) if published else s.published_max_error_cm()
        spread = describe(errors)
        mean = spread.mean if spread else None
        inside = "" if mean is None or low is None or high is None else ("inside" if low <= mean <= high else
                                                                         ("below" if mean < low else "above"))
        interval = "" if spread is None or spread.ci_low is None else f"{spread.ci_low:.1f}..{spread.ci_high:.1f}"
        distance = f"{wasserstein(errors, published):.1f}" if errors and published else ""
        published_mean = s.published_avg_error_cm()
        sim_time, published_time = s.avg_landing_time_s(), s.published_avg_landing_time_s()
        role = _role(profile, s.scenario) if s.source == "sim" else WITNESSES[s.source]
        notes = []
        score = profile.provenance.score_of(s.scenario) if profile and profile.provenance and s.source == "sim" \
            else None
        if score is not None and not score.inside:
            fit_said = f"{score.sim_mean_cm:.1f} cm against {score.field_min_cm:.1f}..{score.field_max_cm:.1f}"
            notes.append(f"inside in this run, not in the fit's own scoring trials ({fit_said})"
                         if inside == "inside" else f"the fit could not bring it inside (profile: {fit_said})")
        unsettled = _unsettled(spread, low, high, inside)
        if unsettled:
            notes.append(unsettled)
        name = s.scenario if s.source == "sim" else f"{s.scenario} ({WITNESSES[s.source]})"
        rows.append((name, role, "" if mean is None else f"{mean:.1f}", interval,
                     "" if published_mean is None else f"{published_mean:.1f}",
                     "" if low is None or high is None else f"{low:.1f}..{high:.1f}", inside, distance,
                     "" if sim_time is None else f"{sim_time:.1f}",
                     "" if published_time is None else f"{published_time:.1f}", "; ".join(notes)))
    return rows


def fidelity_section(summaries, *, spec_text: str | None, source_path: str) -> str:
    """The report's 'Fidelity to the field' section (Markdown), empty when no scenario has published figures."""
    use = campaign_profile(spec_text, source_path) if spec_text else ProfileUse(None, "")
    rows = fidelity_rows(summaries, use.profile)
    if not rows:
        return ""
    if use.profile is not None:
        fitted = use.profile.provenance
        how = (f"simulated with profile `{use.profile.name}` (named by the {use.named_by})"
               + (f", fitted on {fitted.data} ({', '.join(f'{k} = {v:g}' for k, v in fitted.fitted.items())})"
                  if fitted else ", not fitted"))
    elif use.problem:
        how = f"the profile named by the {use.named_by} cannot be read now: {use.problem}"
    else:
        how = "simulated with the model's defaults (no profile)"
    header = ("Scenario", "Role", "Sim mean (cm)", "Sim mean 95 % CI (cm)", "Published mean (cm)", "Published min..max (cm)", "Mean",
              "Wasserstein-1 (cm)", "Sim time (s)", "Published time (s)", "Note")
    lines = ["## Fidelity to the field", "",
             f"Each scenario's simulated errors against the published ones: {how}. Role: fitted (the profile was "
             "fitted on its field trials), held out (scored only), not in the fit, or defaults; a row of ArduPilot "
             "SITL's trials (its runtime `sitl:`, on the same world) is the second witness, named in its scenario. "
             "Mean: where the "
             "simulated mean lies against the published min..max; where the mean's 95 % confidence interval (a "
             "bootstrap over the trials) reaches across an end of that range, the note says so: more trials "
             "would be needed to settle on which side the model lies. Wasserstein-1: the distance between the "
             "simulated and published error distributions (where the published trials are given).", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell or "-" for cell in row) + " |" for row in rows]
    inside = sum(1 for row in rows if row[6] == "inside")
    judged = sum(1 for row in rows if row[6])
    unsettled = sum(1 for row in rows if "95 % CI" in row[10])
    lines += ["", f"{inside} of {judged} simulated means inside the published min..max"
              + (f"; for {unsettled} of the {judged}, the mean's 95 % CI reaches across an end of the range."
                 if unsettled else ".") + " The range is a column, not a verdict: the tests below judge."]
    return "\n".join(lines) + "\n" + verdicts_section(summaries)
