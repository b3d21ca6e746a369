"""Field trials to compare simulated landings with: from a CSV in the thesis reference's columns, or from a
results store (trials whose source is `field`), matched to a campaign's scenarios.

CSV rows match a scenario through its `reference.source_table` (as the campaign
report does); stored field trials match by campaign name and scenario label.
Only trials with a landing error count.
"""

from __future__ import annotations

import csv
import statistics
from dataclasses import dataclass
from pathlib import Path

from ..errors import PrelandError
from .spec import CampaignSpec

CSV_COLUMNS = ("source_table", "error_cm", "landing_time_s")


class FieldDataError(PrelandError):
    """Field trials cannot be read as asked."""


@dataclass(frozen=True, kw_only=True)
class FieldTrials:
    """A scenario's field trials: landing errors (cm) and landing times (s, those recorded)."""

    label: str
    errors_cm: tuple[float, ...]
    times_s: tuple[float, ...] = ()

    @property
    def mean_cm(self) -> float:
        return statistics.fmean(self.errors_cm)

    @property
    def min_cm(self) -> float:
        return min(self.errors_cm)

    @property
    def max_cm(self) -> float:
        return max(self.errors_cm)


def _number(text: str | None) -> float | None:
    try:
        return float(text) if text not in (None, "", "-") else None
    except ValueError:
        return None


def field_trials_from_csv(path: Path, campaign: CampaignSpec) -> dict[str, FieldTrials]:
    """Each scenario's rows of the CSV, matched by its `reference.source_table` (scenarios without one
    have none)."""
    try:
        handle = path.open(newline="", encoding="utf-8")
    except OSError as error:
        raise FieldDataError(f"{path}: cannot read ({error.strerror})") from None
    with handle:
        reader = csv.DictReader(handle)
        missing = [c for c in CSV_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise FieldDataError(f"{path}: missing column(s) {', '.join(missing)} (expected the thesis reference's "
                                 f"columns: {', '.join(CSV_COLUMNS)}, ...)")
        rows = list(reader)
    by_table: dict[str, list[dict[str, str]]] = {}
    for line, row in enumerate(rows, start=2):
        if _number(row["error_cm"]) is None:
            raise FieldDataError(f"{path}: line {line}: error_cm: expected a number, got {row['error_cm']!r}")
        by_table.setdefault(str(row["source_table"]).strip(), []).append(row)
    found = {}
    for scenario in campaign.scenarios:
        reference = scenario.reference
        if reference is None or reference.source_table is None:
            continue
        table_rows = by_table.get(str(reference.source_table), [])
        if table_rows:
            found[scenario.label] = FieldTrials(
                label=scenario.label, errors_cm=tuple(float(r["error_cm"]) for r in table_rows),
                times_s=tuple(t for t in (_number(r.get("landing_time_s")) for r in table_rows) if t is not None))
    return found


def field_trials_from_store(store, campaign: CampaignSpec) -> dict[str, FieldTrials]:
    """The campaign's stored field trials, per scenario label."""
    errors: dict[str, list[float]] = {}
    times: dict[str, list[float]] = {}
    for trial in store.trials(campaign.name):
        if trial["source"] != "field" or trial["landing_error_cm"] is None:
            continue
        errors.setdefault(trial["scenario"], []).append(float(trial["landing_error_cm"]))
        if trial["landing_time_s"] is not None:
            times.setdefault(trial["scenario"], []).append(float(trial["landing_time_s"]))
    labels = {s.label for s in campaign.scenarios}
    return {label: FieldTrials(label=label, errors_cm=tuple(values), times_s=tuple(times.get(label, ())))
            for label, values in errors.items() if label in labels}
