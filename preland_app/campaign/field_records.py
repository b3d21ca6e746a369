"""Field trials entered by hand (`preland trial record/amend/delete`): checked before they are stored.

A tape-measured result goes beside the simulated trials of the same campaign
and scenario, so a misspelt name would silently start a new campaign or
scenario: names must exist in the store (or in the campaign file it ran from)
unless the entry says it starts a new one (`new=True`), and a refusal lists the
close matches. The offsets must agree with the error (within 1 cm), and the land
mode with the scenario's. A record can be amended or deleted; each change is
appended to the trial's `audit` column and a deleted row is kept in
`deleted_trials` (see `migrations.py`), so nothing recorded is lost.

Errors name the command-line option they concern (`--x-cm/--y-cm`), as the CLI
prints them.
"""

from __future__ import annotations

import difflib
import json
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

import yaml

from ..errors import PrelandError
from ..outcome import Outcome
from .store import ResultsStore, TrialRecord

OFFSET_TOLERANCE_CM = 1.0  # the error and the length of its offsets may differ by this much (tape rounding)
FIELD = "field"


class FieldRecordError(PrelandError):
    """A field entry is refused; the message names the option and the problem."""


@dataclass(frozen=True, kw_only=True)
class FieldMeasurement:
    """What was measured in the field: the landing error in cm, optionally its offsets (north `x_cm`, east
    `y_cm`, cm), the landing time in s, the outcome, the land mode flown, the initial height in m, a note."""

    error_cm: float | None
    x_cm: float | None = None
    y_cm: float | None = None
    landing_time_s: float | None = None
    outcome: str = Outcome.LANDED.value
    land_mode: str | None = None
    takeoff_altitude_m: float | None = None
    note: str = ""


@dataclass(frozen=True, kw_only=True)
class ScenarioFacts:
    """What the store (or the campaign file) says about a scenario: its land mode, sensor, faults, height."""

    label: str
    land_mode: str | None = None
    sensor: str | None = None
    faults: str | None = None
    takeoff_altitude_m: float | None = None
    scoring_reference: str | None = None


def now_utc() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def close_matches(name: str, candidates: list[str]) -> list[str]:
    """Candidates that look like `name` (case and spacing ignored), best first."""
    folded = {" ".join(c.lower().split()): c for c in candidates}
    hits = difflib.get_close_matches(" ".join(name.lower().split()), list(folded), n=3, cutoff=0.6)
    return [folded[h] for h in hits]


def _spec_scenarios(store: ResultsStore, campaign: str) -> dict[str, ScenarioFacts]:
    stored = store.campaign_text(campaign)
    if stored is None:
        return {}
    try:
        data = yaml.safe_load(stored[0]) or {}
    except yaml.YAMLError:
        return {}
    facts = {}
    for scenario in data.get("scenarios") or []:
        if isinstance(scenario, dict) and scenario.get("label") is not None:
            label = str(scenario["label"])
            height = scenario.get("initial_height_m")
            facts[label] = ScenarioFacts(label=label, land_mode=scenario.get("land"),
                                         takeoff_altitude_m=float(height) if height is not None else None)
    return facts


def known_scenarios(store: ResultsStore, campaign: str) -> dict[str, ScenarioFacts]:
    """Every scenario of a campaign the store knows: from its trials (simulated first) and its campaign file."""
    facts = _spec_scenarios(store, campaign)
    rows = store.db.execute(
        "SELECT scenario, land_mode, sensor, faults, takeoff_altitude_m, scoring_reference, source FROM trials "
        "WHERE campaign = ? ORDER BY source = 'field', scenario_index, trial_index", (campaign,)).fetchall()
    for row in rows:
        if row["scenario"] in facts and facts[row["scenario"]].sensor is not None:
            continue
        spec = facts.get(row["scenario"])
        facts[row["scenario"]] = ScenarioFacts(
            label=row["scenario"], land_mode=row["land_mode"] or (spec.land_mode if spec else None),
            sensor=row["sensor"], faults=row["faults"], takeoff_altitude_m=row["takeoff_altitude_m"],
            scoring_reference=row["scoring_reference"])
    return facts


def check_names(store: ResultsStore, campaign: str, scenario: str, *, new: bool = False) -> ScenarioFacts | None:
    """The scenario's facts, or None for a new one; refuses unknown names unless `new`."""
    campaigns = store.campaigns()
    if campaign not in campaigns:
        if new:
            return None
        hint = close_matches(campaign, campaigns)
        raise FieldRecordError(
            f"--campaign: no campaign {campaign!r} in {store.path}"
            + (f" (close: {', '.join(hint)})" if hint else f" (campaigns: {', '.join(campaigns) or 'none'})")
            + "; add --new to start a new one")
    scenarios = known_scenarios(store, campaign)
    if scenario in scenarios:
        return scenarios[scenario]
    if new:
        return None
    hint = close_matches(scenario, list(scenarios))
    raise FieldRecordError(
        f"--scenario: campaign {campaign!r} has no scenario {scenario!r}"
        + (f" (close: {', '.join(repr(h) for h in hint)})" if hint
           else f" (scenarios: {', '.join(repr(s) for s in scenarios) or 'none'})")
        + "; add --new to start a new one")


def check_measurement(measurement: FieldMeasurement, facts: ScenarioFacts | None) -> None:
    """Refuse a measurement that contradicts itself or its scenario."""
    from ..landing.registry import is_land_mode_name

    m = measurement
    for option, value in (("--error-cm", m.error_cm), ("--x-cm", m.x_cm), ("--y-cm", m.y_cm),
                          ("--landing-time-s", m.landing_time_s), ("--takeoff-altitude-m", m.takeoff_altitude_m)):
        if value is not None and not math.isfinite(value):
            raise FieldRecordError(f"{option}: must be a number, got {value}")
    if m.error_cm is not None and m.error_cm < 0:
        raise FieldRecordError(f"--error-cm: must be >= 0, got {m.error_cm:g}")
    if m.landing_time_s is not None and m.landing_time_s < 0:
        raise FieldRecordError(f"--landing-time-s: must be >= 0, got {m.landing_time_s:g}")
    if m.takeoff_altitude_m is not None and not 0 < m.takeoff_altitude_m <= 120:
        raise FieldRecordError(f"--takeoff-altitude-m: must be > 0 and <= 120 m, got {m.takeoff_altitude_m:g}")
    if m.outcome not in {o.value for o in Outcome}:
        raise FieldRecordError(f"--outcome: unknown outcome {m.outcome!r} (expected one of: "
                               f"{', '.join(o.value for o in Outcome)})")
    if m.outcome == Outcome.LANDED.value and m.error_cm is None:
        raise FieldRecordError("--error-cm: a landed trial needs its measured error")
    if (m.x_cm is None) != (m.y_cm is None):
        raise FieldRecordError("--x-cm/--y-cm: give both offsets or neither")
    if m.x_cm is not None and m.y_cm is not None:
        if m.error_cm is None:
            raise FieldRecordError("--x-cm/--y-cm: offsets need --error-cm")
        length_cm = math.hypot(m.x_cm, m.y_cm)
        if abs(length_cm - m.error_cm) > OFFSET_TOLERANCE_CM:
            raise FieldRecordError(
                f"--x-cm/--y-cm: the offsets ({m.x_cm:g}, {m.y_cm:g}) make {length_cm:.1f} cm but --error-cm is "
                f"{m.error_cm:g} (more than {OFFSET_TOLERANCE_CM:g} cm apart)")
    if m.land_mode is not None:
        if not is_land_mode_name(m.land_mode):
            raise FieldRecordError(f"--land: unknown land mode {m.land_mode!r}")
        if facts is not None and facts.land_mode is not None and m.land_mode != facts.land_mode:
            raise FieldRecordError(f"--land: {m.land_mode} differs from scenario {facts.label!r}'s land mode "
                                   f"{facts.land_mode}")


def _next_index(store: ResultsStore, campaign: str, scenario: str) -> int:
    row = store.db.execute("SELECT MAX(trial_index) AS m FROM deleted_trials WHERE campaign = ? AND scenario = ? "
                           "AND source = ?", (campaign, scenario, FIELD)).fetchone()
    deleted = -1 if row["m"] is None else int(row["m"])
    return max(store.next_trial_index(campaign, scenario, FIELD), deleted + 1)  # a deleted index is not reused


def record(store: ResultsStore, *, campaign: str, scenario: str, measurement: FieldMeasurement,
           new: bool = False) -> int:
    """Check and store one field trial; returns its trial index (field trials count from 0 per scenario)."""
    facts = check_names(store, campaign, scenario, new=new)
    check_measurement(measurement, facts)
    m = measurement
    result = {"outcome": m.outcome, "message": m.note or "measured in the field",
              "land_mode": m.land_mode or (facts.land_mode if facts else None),
              "sensor": facts.sensor if facts else None, "faults": facts.faults if facts else None,
              "takeoff_altitude_m": m.takeoff_altitude_m if m.takeoff_altitude_m is not None
              else (facts.takeoff_altitude_m if facts else None),
              "scoring_reference": (facts.scoring_reference if facts else None) or "pad",
              "landing_error_cm": m.error_cm, "offset_north_cm": m.x_cm, "offset_east_cm": m.y_cm,
              "landing_time_s": m.landing_time_s, "details": {"note": m.note} if m.note else {}}
    index = _next_index(store, campaign, scenario)
    store.add_trial(TrialRecord(campaign=campaign, scenario=scenario,
                                scenario_index=store.scenario_index(campaign, scenario), trial_index=index,
                                seed=0, result=result, spec_hash=FIELD, runtime=FIELD, source=FIELD))
    return index


def field_trial(store: ResultsStore, campaign: str, scenario: str, index: int) -> dict[str, Any]:
    """One stored field trial's row; refuses an unknown one, naming the indices that exist."""
    row = store.db.execute("SELECT * FROM trials WHERE campaign = ? AND scenario = ? AND trial_index = ? AND "
                           "source = ?", (campaign, scenario, index, FIELD)).fetchone()
    if row is None:
        check_names(store, campaign, scenario)
        indices = [r[0] for r in store.db.execute(
            "SELECT trial_index FROM trials WHERE campaign = ? AND scenario = ? AND source = ? ORDER BY 1",
            (campaign, scenario, FIELD))]
        raise FieldRecordError(f"INDEX: no field trial {index} of {campaign} / {scenario} (field trials: "
                               f"{', '.join(map(str, indices)) or 'none'}; simulated trials cannot be changed)")
    return dict(row)


# The options `trial amend` takes -> the trials columns they change.
AMENDABLE = {"error_cm": "landing_error_cm", "x_cm": "offset_north_cm", "y_cm": "offset_east_cm",
             "landing_time_s": "landing_time_s", "outcome": "outcome", "land_mode": "land_mode",
             "takeoff_altitude_m": "takeoff_altitude_m", "note": "message"}


def amend(store: ResultsStore, *, campaign: str, scenario: str, index: int, changes: dict[str, Any],
          reason: str = "") -> dict[str, list[Any]]:
    """Correct a field trial: `changes` maps FieldMeasurement names to new values. The corrected record is
    checked as a new one would be; returns {column: [old, new]} as appended to its audit column."""
    unknown = sorted(set(changes) - set(AMENDABLE))
    if unknown:
        raise FieldRecordError(f"cannot amend {', '.join(unknown)} (amendable: {', '.join(AMENDABLE)})")
    row = field_trial(store, campaign, scenario, index)
    current = {name: row[column] for name, column in AMENDABLE.items()}
    if current["note"] == "measured in the field":
        current["note"] = ""
    merged = {**current, **changes}
    facts = known_scenarios(store, campaign).get(scenario)
    check_measurement(FieldMeasurement(**merged), facts)
    diff = {AMENDABLE[name]: [current[name], value] for name, value in changes.items() if current[name] != value}
    if not diff:
        raise FieldRecordError("nothing to change: give the corrected values (e.g. --error-cm)")
    audit = json.loads(row.get("audit") or "[]")
    audit.append({"at": now_utc(), "action": "amended", "changes": diff, "reason": reason})
    values = {column: new for column, (_, new) in diff.items()}
    if "message" in values:
        values["message"] = values["message"] or "measured in the field"
    details = json.loads(row["details"] or "{}")
    if "note" in changes:
        details = {**details, "note": changes["note"]} if changes["note"] else \
            {k: v for k, v in details.items() if k != "note"}
    assignments = ", ".join(f"{column} = ?" for column in values)
    with store.db:
        store.db.execute(f"UPDATE trials SET {assignments}, details = ?, audit = ? WHERE id = ?",
                         (*values.values(), json.dumps(details, sort_keys=True), json.dumps(audit), row["id"]))
    return diff


def delete(store: ResultsStore, *, campaign: str, scenario: str, index: int, reason: str = "") -> dict[str, Any]:
    """Delete a field trial, keeping its row in `deleted_trials`; returns the deleted row."""
    row = field_trial(store, campaign, scenario, index)
    with store.db:
        store.db.execute("INSERT INTO deleted_trials (campaign, scenario, trial_index, source, deleted_at, reason, "
                         "row) VALUES (?, ?, ?, ?, ?, ?, ?)",
                         (campaign, scenario, index, FIELD, now_utc(), reason, json.dumps(row, default=str)))
        store.db.execute("DELETE FROM trials WHERE id = ?", (row["id"],))
    return row
