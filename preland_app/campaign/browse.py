"""The results store in Datasette (the sqlite-utils family's browser), as it is: a metadata file and a server.

`metadata(db_name)` gives Datasette the store's title, each column's
description and unit (Datasette shows `landing_error_cm` values as cm and lets
filters take units), and canned queries for the thesis' tables: per-scenario
figures of a campaign, field rows beside simulated ones, the paper
algorithms' measures, and the campaigns with their trial counts.
`serve(db, ...)` starts `datasette serve` on it (the optional `browse` extra:
`pip install 'preland[browse]'`).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from ..errors import PrelandError


class BrowseError(PrelandError):
    """The store cannot be browsed as asked."""


TRIAL_COLUMNS = {
    "id": "Trial id (joins events.trial_id and trajectories.trial_id)",
    "campaign": "Campaign name (campaigns.name)",
    "scenario": "Scenario label, as in the campaign file",
    "scenario_index": "Scenario's position in the campaign file (from 0)",
    "trial_index": "Trial's index within its scenario and source (from 0)",
    "seed": "Trial seed: same seed, same outcome on the embedded simulator",
    "outcome": "landed, aborted, timed_out, crashed, link_lost, pilot_takeover or error",
    "message": "Readable account of the outcome",
    "mission": "Mission name",
    "land_mode": "Land mode flown (normal, irlock, marker, fused, cautious, paper_static, paper_adaptive, ...)",
    "sensor": "Precision sensor (irlock, marker, fused) or empty for GPS-only",
    "faults": "Injected sensor faults (e.g. 'irlock random:0.75') or 'none'",
    "takeoff_altitude_m": "Initial height above home",
    "scoring_reference": "What the error is measured from: pad (its centre) or takeoff (the take-off point)",
    "landing_error_cm": "Horizontal distance of the touchdown from the scoring reference",
    "offset_north_cm": "Touchdown north of the reference",
    "offset_east_cm": "Touchdown east of the reference",
    "landing_time_s": "From the hand-over to the land mode to touchdown",
    "flight_time_s": "From arming to disarming",
    "touchdown_speed_m_s": "Vertical speed at touchdown",
    "details": "JSON: the land mode's and runtime's measures (attempts, marker_switches, recovery_climbs, ...)",
    "spec_hash": "Hash of the scenario's resolved spec ('field' for field trials)",
    "software_version": "preland version that stored the trial",
    "runtime": "embedded, sitl or field",
    "source": "sim (embedded simulator), sitl or field (measured by hand)",
    "wall_time_s": "Wall-clock time the trial took to run",
    "finished_at": "When the trial was stored (UTC)",
    "audit": "JSON list of corrections: when, what changed (old, new), why",
}
TRIAL_UNITS = {"takeoff_altitude_m": "m", "landing_error_cm": "cm", "offset_north_cm": "cm", "offset_east_cm": "cm",
               "landing_time_s": "s", "flight_time_s": "s", "touchdown_speed_m_s": "m/s", "wall_time_s": "s"}

# SQLite has no standard-deviation function; the report (`preland campaign report`) gives the spread.
QUERIES = {
    "thesis_table": {
        "title": "Thesis table: per-scenario figures of a campaign",
        "description": "The thesis' table format: initial height, land mode, sensor, failures, trials, landed, "
                       "aborted, mean and maximum error (cm, landed trials), mean landing time (s); simulated "
                       "and field rows apart.",
        "sql": """SELECT scenario, source, MIN(takeoff_altitude_m) AS initial_height_m, MIN(land_mode) AS land_mode,
  COALESCE(MIN(sensor), 'none') AS sensor, MIN(faults) AS failures, COUNT(*) AS trials,
  SUM(outcome = 'landed') AS landed,
  SUM(outcome != 'landed' OR COALESCE(json_extract(details, '$.aborted_to_gps'), 0)) AS aborted,
  ROUND(AVG(CASE WHEN outcome = 'landed' THEN landing_error_cm END), 2) AS avg_error_cm,
  ROUND(MAX(CASE WHEN outcome = 'landed' THEN landing_error_cm END), 2) AS max_error_cm,
  ROUND(AVG(CASE WHEN outcome = 'landed' THEN landing_time_s END), 2) AS avg_landing_time_s,
  ROUND(AVG(json_extract(details, '$.attempts')), 2) AS attempts_mean
FROM trials WHERE campaign = :campaign
GROUP BY scenario, source ORDER BY MIN(scenario_index), source = 'field', source""",
    },
    "field_beside_simulated": {
        "title": "Field trials beside simulated ones",
        "description": "Per scenario of a campaign: the simulated and the field mean error side by side.",
        "sql": """SELECT scenario,
  SUM(source = 'sim') AS sim_trials,
  ROUND(AVG(CASE WHEN source = 'sim' AND outcome = 'landed' THEN landing_error_cm END), 2) AS sim_avg_error_cm,
  SUM(source = 'field') AS field_trials,
  ROUND(AVG(CASE WHEN source = 'field' AND outcome = 'landed' THEN landing_error_cm END), 2) AS field_avg_error_cm
FROM trials WHERE campaign = :campaign GROUP BY scenario ORDER BY MIN(scenario_index)""",
    },
    "paper_measures": {
        "title": "The paper's algorithms: marker switches, recovery climbs, aborts, first detection",
        "description": "Per scenario of a campaign, from each trial's details (paper_static, paper_adaptive).",
        "sql": """SELECT scenario, COUNT(*) AS trials,
  ROUND(AVG(json_extract(details, '$.marker_switches')), 2) AS marker_switches_mean,
  ROUND(AVG(json_extract(details, '$.recovery_climbs')), 2) AS recovery_climbs_mean,
  SUM(COALESCE(json_extract(details, '$.aborted_to_gps'), 0)) AS aborted_to_gps,
  ROUND(AVG(json_extract(details, '$.first_detection_altitude_m')), 1) AS first_detection_altitude_m
FROM trials WHERE campaign = :campaign AND json_extract(details, '$.marker_switches') IS NOT NULL
GROUP BY scenario ORDER BY MIN(scenario_index)""",
    },
    "campaigns_overview": {
        "title": "Campaigns: scenarios and trials per source",
        "description": "Every campaign in the store with its scenarios and trial counts.",
        "sql": """SELECT campaign, COUNT(DISTINCT scenario) AS scenarios, SUM(source = 'sim') AS sim,
  SUM(source = 'sitl') AS sitl, SUM(source = 'field') AS field, SUM(outcome = 'landed') AS landed,
  MAX(finished_at) AS last_stored
FROM trials GROUP BY campaign ORDER BY campaign""",
    },
}


def metadata(db_name: str) -> dict[str, Any]:
    """Datasette metadata for a results store opened under the name `db_name` (its file's stem)."""
    return {
        "title": "preland results",
        "description": "Precision-landing trials: one row per trial in trials, its event log in events, its "
                       "2 Hz path in trajectories. Canned queries give the thesis' tables.",
        "databases": {db_name: {
            "tables": {
                "trials": {"description": "One row per stored trial (simulated, SITL or field).",
                           "columns": TRIAL_COLUMNS, "units": TRIAL_UNITS, "sort": "id"},
                "campaigns": {"description": "Each campaign run into the store: its file's text, hash and path.",
                              "columns": {"name": "Campaign name", "spec_hash": "Hash of the campaign spec",
                                          "spec_text": "The campaign file as it ran", "source_path": "Its path",
                                          "created_at": "When it first ran (UTC)"}},
                "events": {"description": "Each trial's event log, on the vehicle clock.",
                           "columns": {"trial_id": "trials.id", "time_s": "Vehicle time", "kind": "Event kind",
                                       "message": "What happened", "data": "JSON: the event's numbers"},
                           "units": {"time_s": "s"}},
                "trajectories": {"description": "Each trial's path at 2 Hz: JSON column names and rows (see "
                                                "`preland campaign export --table trajectories`).",
                                 "columns": {"trial_id": "trials.id", "columns": "JSON list of column names",
                                             "rows": "JSON rows (s, m)"}},
                "deleted_trials": {"description": "Deleted field trials, kept whole: when, why, the row as JSON."},
            },
            "queries": QUERIES,
        }},
    }


def write_metadata(db: Path, out: Path) -> Path:
    out.write_text(json.dumps(metadata(db.stem), indent=2), encoding="utf-8")
    return out


def datasette_available() -> bool:
    try:
        import datasette  # noqa: F401
    except ImportError:
        return False
    return True


def serve_command(db: Path, metadata_file: Path, *, host: str = "127.0.0.1", port: int = 8001) -> list[str]:
    """The `datasette serve` command line for a store (run with this Python)."""
    return [sys.executable, "-m", "datasette", "serve", str(db), "--metadata", str(metadata_file), "--host", host,
            "--port", str(port), "--setting", "sql_time_limit_ms", "5000"]


def start(db: Path, metadata_file: Path, *, host: str = "127.0.0.1", port: int = 8001) -> subprocess.Popen:
    """Start Datasette on the store in a child process (the caller stops it)."""
    if not datasette_available():
        raise BrowseError("Datasette is not installed: pip install 'preland[browse]'")
    write_metadata(db, metadata_file)
    return subprocess.Popen(serve_command(db, metadata_file, host=host, port=port))
