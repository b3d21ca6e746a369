"""Campaign reports: the thesis' table format with spread, and the published figures beside.

Per scenario and source (simulated, SITL, field): initial height, land mode,
sensor(s), failure(s), trials, landed, aborted, landing attempts; the landing
error's mean, standard deviation, median, bootstrap 95 % confidence interval of
the mean (`stats.py`, seeded) and maximum; the landing time's mean and standard
deviation; the paper algorithms' measures (marker switches, recovery climbs,
aborts to a GPS landing, first-detection altitude) where a land mode reports
them. Beside a simulated row: the published mean, spread and maximum, from the
published trials where the campaign gives them (else the published summary),
with the published landing time, and the source as a numbered note. A field row
is measured, so it carries no published figures. Columns empty in every row are
left out. Written as Markdown and CSV (one column per number), with the figures
of `figures.py`.
"""

from __future__ import annotations

import csv
import io
import statistics
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from ..errors import PrelandError
from .references import stored_references
from .spec import ReferenceSpec
from .stats import Spread, describe
from .store import ResultsStore

SOURCE_ORDER = {"sim": 0, "sitl": 1, "field": 2}


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
    source: str = "sim"
    scenario: str = ""
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

    def error_spread(self) -> Spread | None:
        return describe(self.errors_cm())

    def landing_time_spread(self) -> Spread | None:
        return describe([t["landing_time_s"] for t in self.landed if t["landing_time_s"] is not None])

    def avg_error_cm(self) -> float | None:
        errors = self.errors_cm()
        return statistics.mean(errors) if errors else None

    def max_error_cm(self) -> float | None:
        errors = self.errors_cm()
        return max(errors) if errors else None

    def avg_landing_time_s(self) -> float | None:
        spread = self.landing_time_spread()
        return spread.mean if spread else None

    def detail_values(self, key: str) -> list[Any]:
        """A `details` key's values over the trials that report it."""
        return [t["details"][key] for t in self.trials if t["details"].get(key) is not None]

    # Published figures: the published trials' spread where the campaign gives them, the summary otherwise.

    def published_error_spread(self) -> Spread | None:
        return describe([p.error_cm for p in self.published])

    def published_avg_error_cm(self) -> float | None:
        if self.reference and self.reference.avg_error_cm is not None:
            return self.reference.avg_error_cm
        spread = self.published_error_spread()
        return spread.mean if spread else None

    def published_max_error_cm(self) -> float | None:
        if self.reference and self.reference.max_error_cm is not None:
            return self.reference.max_error_cm
        spread = self.published_error_spread()
        return spread.maximum if spread else None

    def published_time_spread(self) -> Spread | None:
        return describe([p.landing_time_s for p in self.published if p.landing_time_s is not None])

    def published_avg_landing_time_s(self) -> float | None:
        if self.reference and self.reference.avg_landing_time_s is not None:
            return self.reference.avg_landing_time_s
        spread = self.published_time_spread()
        return spread.mean if spread else None


class ReportError(PrelandError):
    """A report cannot be made from this store."""


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
    """One summary per scenario and source, in the campaign's scenario order (simulated, SITL, field)."""
    trials = store.trials(campaign)
    if not trials:
        raise ReportError(f"{store.path}: no trials for campaign {campaign!r} "
                          f"(campaigns here: {', '.join(store.campaigns()) or 'none'})")
    references, base = stored_references(store, campaign)
    summaries: dict[tuple[str, str], ScenarioSummary] = {}
    for trial in trials:
        key = (trial["scenario"], trial["source"])
        summary = summaries.get(key)
        if summary is None:
            # Published figures go beside simulated rows only: a field row is itself a measurement.
            reference = references.get(trial["scenario"]) if trial["source"] != "field" else None
            label = trial["scenario"] if trial["source"] == "sim" else f"{trial['scenario']} [{trial['source']}]"
            summary = ScenarioSummary(
                label=label, scenario=trial["scenario"], source=trial["source"], index=trial["scenario_index"],
                land_mode=trial["land_mode"] or "", sensor=trial["sensor"] or "none",
                failures=trial["faults"] or "none", initial_height_m=trial["takeoff_altitude_m"], trials=[],
                reference=reference, published=_published_trials(reference, base) if reference else [])
            summaries[key] = summary
        summary.trials.append(trial)
    return sorted(summaries.values(), key=lambda s: (s.index, SOURCE_ORDER.get(s.source, 3)))


# ---------------------------------------------------------------- the table

def _fmt(value: float | None, digits: int = 1) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def _mean_of(values: list[Any]) -> float | None:
    numbers = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return statistics.fmean(numbers) if numbers else None


@dataclass(frozen=True)
class Column:
    """A report column: its Markdown header, its CSV name, and its cell for a summary (text, "" when none)."""

    header: str
    name: str
    cell: Callable[[ScenarioSummary], str]
    markdown: bool = True
    csv: bool = True


def _spread_cell(spread: Callable[[ScenarioSummary], Spread | None], attribute: str, digits: int = 2):
    def cell(s: ScenarioSummary) -> str:
        value = spread(s)
        return _fmt(getattr(value, attribute) if value else None, digits)
    return cell


def _mean_sd(spread: Callable[[ScenarioSummary], Spread | None], digits: int = 2):
    def cell(s: ScenarioSummary) -> str:
        value = spread(s)
        if value is None:
            return ""
        return _fmt(value.mean, digits) + ("" if value.sd is None else f" ± {value.sd:.{digits}f}")
    return cell


def _ci(s: ScenarioSummary) -> str:
    spread = s.error_spread()
    if spread is None or spread.ci_low is None:
        return ""
    return f"{spread.ci_low:.2f} to {spread.ci_high:.2f}"


def _published_mean_sd(s: ScenarioSummary) -> str:
    mean = s.published_avg_error_cm()
    if mean is None:
        return ""
    spread = s.published_error_spread()
    text = f"{mean:.2f}"
    if spread is not None and spread.sd is not None:
        text += f" ± {spread.sd:.2f} (n={spread.n})"
    return text


def _published_range(s: ScenarioSummary) -> str:
    spread = s.published_error_spread()
    return "" if spread is None else f"{spread.minimum:.2f} to {spread.maximum:.2f}"


def _inside_published_range(s: ScenarioSummary) -> str:
    """"yes" only when the simulated mean lies within the published trials' min..max; "no" otherwise."""
    published, simulated = s.published_error_spread(), s.error_spread()
    if published is None or simulated is None:
        return ""
    return "yes" if published.minimum <= simulated.mean <= published.maximum else "no"


def _published_time(s: ScenarioSummary) -> str:
    mean = s.published_avg_landing_time_s()
    if mean is None:
        return ""
    spread = s.published_time_spread()
    return f"{mean:.2f}" + (f" ± {spread.sd:.2f}" if spread is not None and spread.sd is not None else "")


def _attempts(s: ScenarioSummary) -> str:
    values = s.detail_values("attempts")
    if not values:
        return ""
    return f"{_mean_of(values):.2f} (max {max(values)})"


def _count_true(key: str):
    def cell(s: ScenarioSummary) -> str:
        values = s.detail_values(key)
        return f"{sum(bool(v) for v in values)}/{len(values)}" if values else ""
    return cell


def _detail_mean(key: str, digits: int = 2):
    def cell(s: ScenarioSummary) -> str:
        return _fmt(_mean_of(s.detail_values(key)), digits)
    return cell


def _ref(attribute: str, digits: int = 2):
    def cell(s: ScenarioSummary) -> str:
        return _fmt(getattr(s, attribute)(), digits)
    return cell


COLUMNS: tuple[Column, ...] = (
    Column("Scenario", "scenario", lambda s: s.label),
    Column("Source", "source", lambda s: s.source, markdown=False),
    Column("Initial height (m)", "initial_height_m", lambda s: _fmt(s.initial_height_m, 0)),
    Column("Land mode", "land_mode", lambda s: s.land_mode),
    Column("Sensor(s)", "sensor", lambda s: s.sensor),
    Column("Failure(s)", "failures", lambda s: s.failures),
    Column("Trials", "trials", lambda s: str(len(s.trials))),
    Column("Landed", "landed", lambda s: str(len(s.landed))),
    Column("Aborted", "aborted", lambda s: str(s.aborted)),
    Column("Attempts mean (max)", "attempts", _attempts, csv=False),
    Column("", "attempts_mean", lambda s: _fmt(_mean_of(s.detail_values("attempts")), 3), markdown=False),
    Column("", "attempts_max", lambda s: str(max(s.detail_values("attempts"))) if s.detail_values("attempts")
           else "", markdown=False),
    Column("Error mean ± sd (cm)", "error_mean_sd", _mean_sd(ScenarioSummary.error_spread), csv=False),
    Column("", "error_mean_cm", _spread_cell(ScenarioSummary.error_spread, "mean", 3), markdown=False),
    Column("", "error_sd_cm", _spread_cell(ScenarioSummary.error_spread, "sd", 3), markdown=False),
    Column("Error median (cm)", "error_median_cm", _spread_cell(ScenarioSummary.error_spread, "median")),
    Column("95 % CI of mean (cm)", "error_ci", _ci, csv=False),
    Column("", "error_ci95_low_cm", _spread_cell(ScenarioSummary.error_spread, "ci_low", 3), markdown=False),
    Column("", "error_ci95_high_cm", _spread_cell(ScenarioSummary.error_spread, "ci_high", 3), markdown=False),
    Column("Max error (cm)", "error_max_cm", _spread_cell(ScenarioSummary.error_spread, "maximum")),
    Column("Published mean ± sd (cm)", "published", _published_mean_sd, csv=False),
    Column("", "published_error_mean_cm", _ref("published_avg_error_cm", 3), markdown=False),
    Column("", "published_error_sd_cm", _spread_cell(ScenarioSummary.published_error_spread, "sd", 3),
           markdown=False),
    Column("", "published_error_median_cm", _spread_cell(ScenarioSummary.published_error_spread, "median", 3),
           markdown=False),
    Column("", "published_trials", lambda s: str(len(s.published)) if s.published else "", markdown=False),
    Column("Published max (cm)", "published_error_max_cm", _ref("published_max_error_cm")),
    Column("Published min to max (cm)", "published_range", _published_range, csv=False),
    Column("", "published_error_min_cm", _spread_cell(ScenarioSummary.published_error_spread, "minimum", 3),
           markdown=False),
    Column("Mean inside published range", "inside_published_range", _inside_published_range),
    Column("Landing time mean ± sd (s)", "time", _mean_sd(ScenarioSummary.landing_time_spread), csv=False),
    Column("", "landing_time_mean_s", _spread_cell(ScenarioSummary.landing_time_spread, "mean", 3), markdown=False),
    Column("", "landing_time_sd_s", _spread_cell(ScenarioSummary.landing_time_spread, "sd", 3), markdown=False),
    Column("Published time (s)", "published_time", _published_time, csv=False),
    Column("", "published_landing_time_mean_s", _ref("published_avg_landing_time_s", 3), markdown=False),
    Column("", "published_landing_time_sd_s", _spread_cell(ScenarioSummary.published_time_spread, "sd", 3),
           markdown=False),
    Column("Marker switches (mean)", "marker_switches_mean", _detail_mean("marker_switches")),
    Column("Recovery climbs (mean)", "recovery_climbs_mean", _detail_mean("recovery_climbs")),
    Column("Abort to GPS", "aborted_to_gps", _count_true("aborted_to_gps")),
    Column("First detection (m)", "first_detection_altitude_mean_m", _detail_mean("first_detection_altitude_m", 1)),
)


def _table(summaries: list[ScenarioSummary], *, markdown: bool,
           notes: dict[str, int] | None = None) -> tuple[list[str], list[list[str]]]:
    """Header and rows, without the columns that are empty in every row."""
    columns = [c for c in COLUMNS if (c.markdown if markdown else c.csv)]
    cells = [[c.cell(s) for c in columns] for s in summaries]
    keep = [i for i, c in enumerate(columns) if i == 0 or any(row[i] for row in cells)]
    header = [(columns[i].header if markdown else columns[i].name) for i in keep]
    rows = [[row[i] for i in keep] for row in cells]
    if notes is not None and notes:
        header.append("Published source")
        rows = [row + [f"[{notes[s.reference.source]}]" if s.reference and s.reference.source in notes else ""]
                for row, s in zip(rows, summaries)]
    elif not markdown and any(s.reference and s.reference.source for s in summaries):
        header.append("published_source")
        rows = [row + [s.reference.source if s.reference else ""] for row, s in zip(rows, summaries)]
    return header, rows


def source_notes(summaries: list[ScenarioSummary]) -> dict[str, int]:
    """Each published source, numbered in the order its rows appear."""
    notes: dict[str, int] = {}
    for s in summaries:
        if s.reference and s.reference.source and s.reference.source not in notes:
            notes[s.reference.source] = len(notes) + 1
    return notes


def table_rows(summaries: list[ScenarioSummary]) -> list[tuple[str, ...]]:
    """The Markdown table's rows (after its header)."""
    _, rows = _table(summaries, markdown=True, notes=source_notes(summaries))
    return [tuple(row) for row in rows]


def markdown_table(campaign: str, summaries: list[ScenarioSummary]) -> str:
    notes = source_notes(summaries)
    header, rows = _table(summaries, markdown=True, notes=notes)
    lines = [f"# Campaign `{campaign}`", "",
             "Simulated trials beside the published ones (where the campaign gives them). Errors are the "
             "horizontal distance from the scoring reference at touchdown, over the trials that landed; times "
             "run from the hand-over to the land mode to touchdown. Mean ± sample standard deviation; the 95 % "
             "confidence interval of the mean is a seeded bootstrap (4000 resamples), given from 5 trials up. "
             "Published spread is that of the published trials (n of them); a simulated mean is inside the "
             "published range only when it lies between the published trials' smallest and largest error. "
             "Rows marked [field] are measured, not simulated.", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell or "-" for cell in row) + " |" for row in rows]
    if notes:
        lines += [""] + [f"[{number}] {source}" for source, number in notes.items()]
    return "\n".join(lines) + "\n"


def csv_table(summaries: list[ScenarioSummary]) -> str:
    header, rows = _table(summaries, markdown=False)
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(header)
    writer.writerows(rows)
    return buffer.getvalue()


def write_report(store: ResultsStore, campaign: str, out_dir: Path, *, figure_format: str = "png",
                 dpi: int | None = None, trial: tuple[str, int] | None = None) -> list[Path]:
    """Write the campaign's table (`CAMPAIGN.md`, `CAMPAIGN.csv`) and figures (`figure_format`: png, pdf or
    svg; `dpi` for PNG, default 300) into `out_dir`; `trial` = (scenario, index) chooses the trajectory
    figure's trial. Returns the files written."""
    from .figures import write_figures

    summaries = summarize(store, campaign)
    out_dir.mkdir(parents=True, exist_ok=True)
    figures = write_figures(store, campaign, summaries, out_dir, figure_format=figure_format, dpi=dpi, trial=trial)
    markdown = out_dir / f"{campaign}.md"
    text = markdown_table(campaign, summaries)
    text += _fidelity(store, campaign, summaries)
    text += "\n" + "\n".join(f"![{path.stem}]({path.name})" for path in figures) + "\n"
    markdown.write_text(text, encoding="utf-8")
    table = out_dir / f"{campaign}.csv"
    table.write_text(csv_table(summaries), encoding="utf-8")
    return [markdown, table, *figures]


def _fidelity(store: ResultsStore, campaign: str, summaries: list[ScenarioSummary]) -> str:
    """The fidelity section (`fidelity.py`), after a blank line; empty when there is nothing to compare."""
    from .fidelity import fidelity_section

    stored = store.campaign_text(campaign)
    section = fidelity_section(summaries, spec_text=stored[0] if stored else None,
                               source_path=stored[1] if stored else "")
    return "\n" + section if section else ""
