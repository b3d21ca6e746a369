"""Reading the results store: what campaigns and scenarios it holds, one trial in full, deletions.

The Python side of `preland campaign list`, `preland trial show` and `preland
campaign delete`; everything here takes an open `ResultsStore`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..errors import PrelandError
from .field_records import close_matches
from .references import stored_references
from .store import ResultsStore

SOURCES = ("sim", "sitl", "field")


class CatalogError(PrelandError):
    """A campaign, scenario or trial asked for is not in the store."""


@dataclass(frozen=True, kw_only=True)
class ScenarioCount:
    """One scenario of a campaign: trials per source (sim, sitl, field), how many landed, the land mode and
    the published source its reference names."""

    campaign: str
    scenario: str
    scenario_index: int
    land_mode: str
    counts: dict[str, int]
    landed: int
    published_source: str


@dataclass(frozen=True, kw_only=True)
class CampaignEntry:
    """A campaign: its file (as run), when it was first run, and its scenarios."""

    name: str
    source_path: str
    created_at: str
    scenarios: tuple[ScenarioCount, ...]

    @property
    def trials(self) -> int:
        return sum(sum(s.counts.values()) for s in self.scenarios)


def overview(store: ResultsStore) -> list[CampaignEntry]:
    """Every campaign in the store with its scenarios' trial counts."""
    entries = []
    for name in store.campaigns():
        row = store.db.execute("SELECT source_path, created_at FROM campaigns WHERE name = ?", (name,)).fetchone()
        references, _ = stored_references(store, name)
        scenarios: dict[str, dict[str, Any]] = {}
        for trial in store.db.execute(
                "SELECT scenario, MIN(scenario_index) AS idx, source, COUNT(*) AS n, "
                "SUM(outcome = 'landed') AS landed, MAX(land_mode) AS land_mode FROM trials WHERE campaign = ? "
                "GROUP BY scenario, source ORDER BY idx", (name,)):
            entry = scenarios.setdefault(trial["scenario"], {"index": trial["idx"], "counts": dict.fromkeys(SOURCES, 0),
                                                            "landed": 0, "land_mode": trial["land_mode"] or ""})
            entry["counts"][trial["source"]] = int(trial["n"])
            entry["landed"] += int(trial["landed"] or 0)
            entry["index"] = min(entry["index"], trial["idx"])
        entries.append(CampaignEntry(
            name=name, source_path=row["source_path"] if row else "", created_at=row["created_at"] if row else "",
            scenarios=tuple(ScenarioCount(campaign=name, scenario=label, scenario_index=data["index"],
                                          land_mode=data["land_mode"], counts=data["counts"], landed=data["landed"],
                                          published_source=references[label].source if label in references else "")
                            for label, data in sorted(scenarios.items(), key=lambda item: item[1]["index"]))))
    return entries


def require_campaign(store: ResultsStore, campaign: str) -> None:
    campaigns = store.campaigns()
    if campaign not in campaigns:
        hint = close_matches(campaign, campaigns)
        raise CatalogError(f"no campaign {campaign!r} in {store.path} ("
                           + (f"close: {', '.join(hint)}" if hint else f"campaigns: {', '.join(campaigns) or 'none'}")
                           + ")")


def require_scenario(store: ResultsStore, campaign: str, scenario: str) -> None:
    require_campaign(store, campaign)
    labels = [r[0] for r in store.db.execute("SELECT DISTINCT scenario FROM trials WHERE campaign = ?", (campaign,))]
    if scenario not in labels:
        hint = close_matches(scenario, labels)
        raise CatalogError(f"campaign {campaign!r} has no scenario {scenario!r} ("
                           + (f"close: {', '.join(repr(h) for h in hint)}" if hint
                              else f"scenarios: {', '.join(repr(s) for s in labels) or 'none'}") + ")")


def find_trial(store: ResultsStore, campaign: str, scenario: str, index: int,
               source: str | None = None) -> dict[str, Any]:
    """One trial's row (details and audit parsed). `source` None: the simulated trial of that index, else the
    SITL one, else the field one."""
    require_scenario(store, campaign, scenario)
    rows = {t["source"]: t for t in store.trials(campaign)
            if t["scenario"] == scenario and t["trial_index"] == index and (source is None or t["source"] == source)}
    for candidate in SOURCES:
        if candidate in rows:
            return rows[candidate]
    if rows:
        return next(iter(rows.values()))
    indices = sorted({(t["source"], t["trial_index"]) for t in store.trials(campaign) if t["scenario"] == scenario})
    shown = ", ".join(f"{s} {i}" for s, i in indices[:12]) + (" ..." if len(indices) > 12 else "")
    raise CatalogError(f"no {source + ' ' if source else ''}trial {index} of {campaign} / {scenario} "
                       f"(trials: {shown or 'none'})")


@dataclass(frozen=True)
class Deletion:
    """What a deletion removes: trials per source, and whether the campaign itself goes."""

    campaign: str
    scenarios: tuple[str, ...]
    counts: dict[str, int]
    whole_campaign: bool


def plan_deletion(store: ResultsStore, campaign: str, scenarios: list[str] | None = None) -> Deletion:
    """What deleting a campaign (or some of its scenarios) would remove; refuses unknown names."""
    require_campaign(store, campaign)
    for scenario in scenarios or []:
        require_scenario(store, campaign, scenario)
    labels = tuple(scenarios or [])
    query = "SELECT source, COUNT(*) AS n FROM trials WHERE campaign = ?"
    args: list[Any] = [campaign]
    if labels:
        query += f" AND scenario IN ({', '.join('?' * len(labels))})"
        args += labels
    counts = {row["source"]: int(row["n"]) for row in store.db.execute(query + " GROUP BY source", args)}
    return Deletion(campaign=campaign, scenarios=labels, counts=counts, whole_campaign=not labels)


def delete(store: ResultsStore, deletion: Deletion) -> int:
    """Carry out a planned deletion (events and trajectories go with their trials); returns trials deleted."""
    with store.db:
        if deletion.scenarios:
            cursor = store.db.execute(
                f"DELETE FROM trials WHERE campaign = ? AND scenario IN ({', '.join('?' * len(deletion.scenarios))})",
                (deletion.campaign, *deletion.scenarios))
        else:
            cursor = store.db.execute("DELETE FROM trials WHERE campaign = ?", (deletion.campaign,))
            store.db.execute("DELETE FROM campaigns WHERE name = ?", (deletion.campaign,))
    return cursor.rowcount
