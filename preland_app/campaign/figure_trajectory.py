"""The path of one trial, as the thesis' Figure 15b: take-off (green), path (blue), landing (red), seen from
above and as height over time, with a zoom on the touchdown around the scoring reference (in cm) when the
path is long beside the landing error."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .store import ResultsStore  # noqa: E402

ZOOM_RATIO = 5.0  # a touchdown zoom when the path spans this many times the area the zoom shows
ZOOM_HEIGHT_M = 2.0  # the zoom draws the path below this height: the end of the descent


def choose_trial(store: ResultsStore, campaign: str, summaries: list, chosen: tuple[str, int] | None = None
                 ) -> dict[str, Any] | None:
    """The trial to draw: `chosen` (scenario, index; simulated first, else SITL, else field), or the first
    landed trial of the first precision scenario (else of the first scenario) that has a trajectory."""
    if chosen is not None:
        from .catalog import find_trial

        return find_trial(store, campaign, chosen[0], chosen[1])
    for summary in sorted(summaries, key=lambda s: (s.land_mode == "normal", s.source != "sim", s.index)):
        for trial in summary.landed:
            if store.trajectory(trial["id"]) is not None:
                return trial
    return None


def _segments(rows: list[list[float]], time_index: int, marks: tuple[float, float]) -> list[list[list[float]]]:
    """Rows split at the two times, each part sharing its first sample with the end of the one before, so the
    drawn segments join."""
    recorded_s, land_s = marks
    parts: list[list[list[float]]] = [[], [], []]
    for row in rows:
        t = row[time_index]
        parts[0 if t <= recorded_s else 1 if t <= land_s else 2].append(row)
    for i in (1, 2):
        previous = next((p for p in reversed(parts[:i]) if p), None)
        if previous and parts[i]:
            parts[i].insert(0, previous[-1])
    return parts


def trajectory_figure(store: ResultsStore, trial: dict[str, Any], out: Path, *, dpi: int | None = None,
                      title: str | None = None) -> Path | None:
    """Draw `trial`'s stored path into `out` (png, pdf or svg by its suffix); None when it has none. Ground
    truth where the runtime recorded it, else the vehicle's estimate. Positions in m from the start."""
    stored = store.trajectory(trial["id"])
    if stored is None:
        return None
    columns, rows = stored
    col = {name: i for i, name in enumerate(columns)}
    events = {e["kind"]: e["time_s"] for e in reversed(store.events(trial["id"]))}
    recorded_s = events.get("recorded", 0.0)
    land_s = events.get("land_handover", events.get("land_command", math.inf))  # stores before 0.2: land_command
    truth = "true_north_m" in col and rows and rows[0][col["true_north_m"]] is not None
    north, east, up = (("true_north_m", "true_east_m", "true_altitude_m") if truth
                       else ("est_north_m", "est_east_m", "est_altitude_rel_m"))
    rows = [r for r in rows if r[col[north]] is not None and r[col[east]] is not None]
    if not rows:
        return None
    last = rows[-1]
    touchdown = (last[col[north]], last[col[east]])
    reference = None
    if trial.get("offset_north_cm") is not None and trial.get("offset_east_cm") is not None:
        reference = (touchdown[0] - trial["offset_north_cm"] / 100.0, touchdown[1] - trial["offset_east_cm"] / 100.0)
    zoom_half_m = _zoom_half_m(rows, col, north, east, trial)
    if zoom_half_m is not None:
        figure, (top, zoom, side) = plt.subplots(1, 3, figsize=(13.0, 4.9),
                                                 gridspec_kw={"width_ratios": [1.15, 0.85, 1.0]})
    else:
        figure, (top, side) = plt.subplots(1, 2, figsize=(10.0, 4.9), gridspec_kw={"width_ratios": [1.1, 1.0]})
    phases = (("take-off", "tab:green"), ("path", "tab:blue"), ("landing", "tab:red"))
    for (label, color), part in zip(phases, _segments(rows, col["time_s"], (recorded_s, land_s))):
        if part:
            top.plot([r[col[east]] for r in part], [r[col[north]] for r in part], color=color, lw=1.4, label=label)
            side.plot([r[col["time_s"]] for r in part], [r[col[up]] for r in part], color=color, lw=1.4)
    top.plot([0], [0], marker="o", color="black", markersize=5, ls="none", label="start")
    top.plot([touchdown[1]], [touchdown[0]], marker="x", color="tab:red", markersize=8, ls="none",
             label="touchdown")
    if reference is not None:
        name = "pad centre" if trial.get("scoring_reference") == "pad" else "take-off point (reference)"
        top.plot([reference[1]], [reference[0]], marker="+", color="black", markersize=14, mew=1.5, ls="none",
                 label=name)
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("east (m)")
    top.set_ylabel("north (m)")
    top.set_title("seen from above", fontsize=9)
    top.grid(alpha=0.3)
    side.set_xlabel("time (s)")
    side.set_ylabel("height (m)")
    side.set_title("height over time", fontsize=9)
    side.grid(alpha=0.3)
    if zoom_half_m is not None:
        _touchdown_zoom(top, zoom, [r for r in rows if r[col[up]] is not None and r[col[up]] <= ZOOM_HEIGHT_M],
                        col, north, east, touchdown, reference, zoom_half_m)
    handles, labels = top.get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    error = trial.get("landing_error_cm")
    figure.suptitle(title or (f"{trial['campaign']}: {trial['scenario']}, {trial['source']} trial "
                              f"{trial['trial_index']} ({'true' if truth else 'estimated'} path"
                              + (f", landing error {error:.1f} cm)" if error is not None else ")")), fontsize=10)
    figure.tight_layout(rect=(0, 0.07, 1, 0.96))
    figure.savefig(out, dpi=dpi)
    plt.close(figure)
    return out


def _zoom_half_m(rows, col, north, east, trial) -> float | None:
    """Half the side of the touchdown zoom in m, or None when the path is short enough to show it."""
    norths = [r[col[north]] for r in rows]
    easts = [r[col[east]] for r in rows]
    extent_m = max(max(norths) - min(norths), max(easts) - min(easts))
    half_m = max(1.6 * (trial.get("landing_error_cm") or 0.0) / 100.0, 0.10)
    return half_m if extent_m >= ZOOM_RATIO * 2 * half_m else None


def _touchdown_zoom(top, zoom, rows, col, north, east, touchdown, reference, half_m: float) -> None:
    """The last metres of the landing, in cm around the reference (else the touchdown), and its frame on the
    view from above."""
    from matplotlib.patches import Rectangle

    centre = reference or touchdown
    to_cm = 100.0
    near = [r for r in rows if abs(r[col[north]] - centre[0]) <= 3 * half_m and abs(r[col[east]] - centre[1]) <= 3 * half_m]
    zoom.plot([(r[col[east]] - centre[1]) * to_cm for r in near], [(r[col[north]] - centre[0]) * to_cm for r in near],
              color="tab:red", lw=1.2)
    zoom.plot([(touchdown[1] - centre[1]) * to_cm], [(touchdown[0] - centre[0]) * to_cm], marker="x",
              color="tab:red", markersize=9, ls="none")
    if reference is not None:
        zoom.plot([0], [0], marker="+", color="black", markersize=16, mew=1.5, ls="none")
    limit = half_m * to_cm
    zoom.set_xlim(-limit, limit)
    zoom.set_ylim(-limit, limit)
    zoom.set_aspect("equal")
    zoom.set_xlabel("east (cm)")
    zoom.set_ylabel("north (cm)")
    zoom.set_title(f"last {ZOOM_HEIGHT_M:g} m of the descent, from the reference", fontsize=9)
    zoom.grid(alpha=0.3)
    top.add_patch(Rectangle((centre[1] - half_m, centre[0] - half_m), 2 * half_m, 2 * half_m, fill=False,
                            edgecolor="gray", lw=0.8, ls="--"))
