"""Campaign reports: the thesis' table format with the published figures beside the simulated ones.

Per scenario: initial height, sensor(s), failure(s), average and maximum landing
error, average landing time, trials, landed/aborted, and, where the campaign
gives them, the published figures. Written as Markdown and CSV, with the PNG
figures of `figures.py`.
"""

from __future__ import annotations

import csv
import io
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..config.loader import build
from ..errors import PrelandError
from .spec import ReferenceSpec
from .store import ResultsStore


@dataclass
class PublishedTrial:
    error_cm: float
    x_cm: float | None
    y_cm: float | None
    landing_time_s: float | None


@dataclass(kw_only=True)
class ScenarioSummary:
    label: str
    index: int
    land_mode: str
    sensor: str
    failures: str
    initial_height_m: float | None
    trials: list[dict[str, Any]]
    reference: ReferenceSpec | None = None
    published: list[PublishedTrial] = field(default_factory=list)

    @property
    def landed(self) -> list[dict[str, Any]]:
        return [t for t in self.trials if t["outcome"] == "landed" and t["landing_error_cm"] is not None]

    @property
    def aborted(self) -> int:
        """Trials that did not land as planned: any outcome but landed, or a fall-back to a GPS landing."""
        return sum(1 for t in self.trials if t["outcome"] != "landed" or t["details"].get("aborted_to_gps"))

    def errors_cm(self) -> list[float]:
        return [t["landing_error_cm"] for t in self.landed]

    def avg_error_cm(self) -> float | None:
        errors = self.errors_cm()
        return statistics.mean(errors) if errors else None

    def max_error_cm(self) -> float | None:
        errors = self.errors_cm()
        return max(errors) if errors else None

    def avg_landing_time_s(self) -> float | None:
        times = [t["landing_time_s"] for t in self.landed if t["landing_time_s"] is not None]
        return statistics.mean(times) if times else None


class ReportError(PrelandError):
    """A report cannot be made from this store."""


def _references(store: ResultsStore, campaign: str) -> tuple[dict[str, ReferenceSpec], Path | None]:
    stored = store.campaign_text(campaign)
    if stored is None:
        return {}, None
    text, source_path = stored
    base = Path(source_path).parent if source_path else None
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError:
        return {}, base
    references = {}
    for scenario in data.get("scenarios", []) or []:
        if isinstance(scenario, dict) and isinstance(scenario.get("reference"), dict):
            references[str(scenario.get("label"))] = build(ReferenceSpec, scenario["reference"],
                                                           path=source_path or campaign, field="reference")
    return references, base


def _published_trials(reference: ReferenceSpec, base: Path | None) -> list[PublishedTrial]:
    if reference.trials_csv is None:
        return []
    path = Path(reference.trials_csv)
    if not path.is_absolute() and base is not None:
        path = base / path
    if not path.exists():
        return []

    def number(text: str | None) -> float | None:
        try:
            return float(text) if text not in (None, "", "-") else None
        except ValueError:
            return None

    with path.open(newline="", encoding="utf-8") as handle:
        return [PublishedTrial(error_cm=float(row["error_cm"]), x_cm=number(row.get("x_cm")),
                               y_cm=number(row.get("y_cm")), landing_time_s=number(row.get("landing_time_s")))
                for row in csv.DictReader(handle) if str(row.get("source_table")) == str(reference.source_table)]


def summarize(store: ResultsStore, campaign: str) -> list[ScenarioSummary]:
    trials = store.trials(campaign)
    if not trials:
        raise ReportError(f"{store.path}: no trials for campaign {campaign!r} "
                          f"(campaigns here: {', '.join(store.campaigns()) or 'none'})")
    references, base = _references(store, campaign)
    summaries: dict[tuple[str, str], ScenarioSummary] = {}
    for trial in trials:
        key = (trial["scenario"], trial["source"])
        summary = summaries.get(key)
        if summary is None:
            reference = references.get(trial["scenario"])
            label = trial["scenario"] if trial["source"] == "sim" else f"{trial['scenario']} [{trial['source']}]"
            summary = ScenarioSummary(
                label=label, index=trial["scenario_index"], land_mode=trial["land_mode"] or "",
                sensor=trial["sensor"] or "none", failures=trial["faults"] or "none",
                initial_height_m=trial["takeoff_altitude_m"], trials=[], reference=reference,
                published=_published_trials(reference, base) if reference else [])
            summaries[key] = summary
        summary.trials.append(trial)
    order = {"sim": 0, "sitl": 1, "field": 2}
    return sorted(summaries.values(), key=lambda s: (s.index, order.get(s.trials[0]["source"], 3)))


def _fmt(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


TABLE_HEADER = ("Scenario", "Initial height (m)", "Land mode", "Sensor(s)", "Failure(s)", "Avg error (cm)",
                "Published avg (cm)", "Max error (cm)", "Published max (cm)", "Avg landing time (s)",
                "Published time (s)", "Trials", "Landed", "Aborted")


def table_rows(summaries: list[ScenarioSummary]) -> list[tuple[str, ...]]:
    rows = []
    for s in summaries:
        ref = s.reference
        rows.append((s.label, _fmt(s.initial_height_m, 0), s.land_mode, s.sensor, s.failures,
                     _fmt(s.avg_error_cm(), 2), _fmt(ref.avg_error_cm if ref else None, 2),
                     _fmt(s.max_error_cm(), 2), _fmt(ref.max_error_cm if ref else None, 2),
                     _fmt(s.avg_landing_time_s(), 2), _fmt(ref.avg_landing_time_s if ref else None, 2),
                     str(len(s.trials)), str(len(s.landed)), str(s.aborted)))
    return rows


def markdown_table(campaign: str, summaries: list[ScenarioSummary]) -> str:
    lines = [f"# Campaign `{campaign}`", "",
             "Simulated figures beside the published ones (where the campaign gives them). Errors are the "
             "horizontal distance from the scoring reference at touchdown; times run from the hand-over to the "
             "land mode to touchdown.", "",
             "| " + " | ".join(TABLE_HEADER) + " |", "|" + "---|" * len(TABLE_HEADER)]
    for row in table_rows(summaries):
        lines.append("| " + " | ".join(row) + " |")
    sources = sorted({s.reference.source for s in summaries if s.reference and s.reference.source})
    if sources:
        lines += ["", "Published figures: " + "; ".join(sources) + "."]
    return "\n".join(lines) + "\n"


def csv_table(summaries: list[ScenarioSummary]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(TABLE_HEADER)
    writer.writerows(table_rows(summaries))
    return buffer.getvalue()


EXPORT_COLUMNS = ("campaign", "scenario", "scenario_index", "trial_index", "seed", "outcome", "message", "mission",
                  "land_mode", "sensor", "faults", "takeoff_altitude_m", "scoring_reference", "landing_error_cm",
                  "offset_north_cm", "offset_east_cm", "landing_time_s", "flight_time_s", "touchdown_speed_m_s",
                  "spec_hash", "software_version", "runtime", "source", "wall_time_s", "finished_at", "details")


def export_csv(store: ResultsStore, campaign: str | None = None) -> str:
    """Every stored trial (of one campaign, or all) as CSV, one row per trial."""
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(EXPORT_COLUMNS)
    import json

    for trial in store.trials(campaign):
        writer.writerow([json.dumps(trial[c], sort_keys=True) if c == "details" else trial[c]
                         for c in EXPORT_COLUMNS])
    return buffer.getvalue()


def write_report(store: ResultsStore, campaign: str, out_dir: Path) -> list[Path]:
    """Write report.md, report.csv and the PNG figures for a campaign; returns the files written."""
    from .figures import landing_error_boxplot, landing_positions_scatter, trajectory_plot

    summaries = summarize(store, campaign)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    markdown = out_dir / f"{campaign}.md"
    figures = [
        landing_error_boxplot(campaign, summaries, out_dir / f"{campaign}_errors.png"),
        landing_positions_scatter(campaign, summaries, out_dir / f"{campaign}_positions.png"),
    ]
    trajectory = trajectory_plot(store, campaign, summaries, out_dir / f"{campaign}_trajectory.png")
    if trajectory is not None:
        figures.append(trajectory)
    text = markdown_table(campaign, summaries)
    text += "\n" + "\n".join(f"![{path.stem}]({path.name})" for path in figures) + "\n"
    markdown.write_text(text, encoding="utf-8")
    table = out_dir / f"{campaign}.csv"
    table.write_text(csv_table(summaries), encoding="utf-8")
    written += [markdown, table, *figures]
    return written
