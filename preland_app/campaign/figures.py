"""Report figures like the thesis': landing error per scenario (its Figures 16a-18a), landing positions
around the pad (16b-18b), and the path of one trial (15b)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .report import ScenarioSummary  # noqa: E402
from .store import ResultsStore  # noqa: E402

_MARKERS = "os^Dv<>Ph*Xd"


def landing_error_boxplot(campaign: str, summaries: list[ScenarioSummary], out: Path) -> Path:
    """Box plot of the landing error per scenario (median line, IQR box, min/max whiskers), with the
    published trials beside each box where the campaign gives them."""
    figure, axes = plt.subplots(figsize=(max(6.0, 1.3 * len(summaries) + 2), 4.8), dpi=110)
    positions = list(range(1, len(summaries) + 1))
    data = [s.errors_cm() or [math.nan] for s in summaries]
    axes.boxplot(data, positions=positions, widths=0.35, whis=(0, 100),
                 medianprops={"color": "red"}, boxprops={"color": "tab:blue"})
    for position, summary in zip(positions, summaries):
        if summary.published:
            xs = [position + 0.32] * len(summary.published)
            axes.scatter(xs, [p.error_cm for p in summary.published], s=14, color="black", alpha=0.6,
                         label="published trials" if position == positions[0] or not axes.get_legend() else None)
        if summary.reference and summary.reference.avg_error_cm is not None:
            axes.plot([position + 0.2, position + 0.44], [summary.reference.avg_error_cm] * 2, color="black", lw=2)
    axes.set_xticks(positions)
    axes.set_xticklabels([s.label for s in summaries], rotation=25, ha="right", fontsize=8)
    axes.set_ylabel("landing error (cm)")
    axes.set_title(f"{campaign}: landing error per scenario (boxes: simulated; dots, bars: published)")
    axes.grid(axis="y", alpha=0.3)
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)
    return out


def landing_positions_scatter(campaign: str, summaries: list[ScenarioSummary], out: Path) -> Path:
    """Landing positions relative to the scoring reference (pad centre or take-off point), in cm."""
    figure, axes = plt.subplots(figsize=(6.4, 6.0), dpi=110)
    radius = 10.0
    for index, summary in enumerate(summaries):
        east = [t["offset_east_cm"] for t in summary.landed]
        north = [t["offset_north_cm"] for t in summary.landed]
        marker = _MARKERS[index % len(_MARKERS)]
        axes.scatter(east, north, marker=marker, s=28, label=f"{summary.label} (n={len(east)})")
        radius = max([radius, *[math.hypot(e, n) for e, n in zip(east, north)]])
        published = [p for p in summary.published if p.x_cm is not None and p.y_cm is not None]
        if published:
            axes.scatter([p.x_cm for p in published], [p.y_cm for p in published], marker=marker, s=28,
                         facecolors="none", edgecolors="gray", label=f"{summary.label}, published")
    for ring in (5, 10, 25, 50, 100, 200):
        if ring <= radius * 1.2:
            axes.add_patch(plt.Circle((0, 0), ring, fill=False, color="gray", lw=0.5, ls="--"))
    axes.plot([0], [0], marker="+", color="black", markersize=14)
    limit = radius * 1.15
    axes.set_xlim(-limit, limit)
    axes.set_ylim(-limit, limit)
    axes.set_aspect("equal")
    axes.set_xlabel("east (cm)")
    axes.set_ylabel("north (cm)")
    axes.set_title(f"{campaign}: landing positions around the reference")
    axes.legend(fontsize=7, loc="upper right")
    axes.grid(alpha=0.2)
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)
    return out


def trajectory_plot(store: ResultsStore, campaign: str, summaries: list[ScenarioSummary], out: Path) -> Path | None:
    """The path of one trial, as the thesis' Figure 15b: take-off (green), path (blue), landing (red), seen
    from above and as height over time. The trial is the first landed trial of the first precision scenario
    (else of the first scenario). Ground truth where the runtime has it, else the vehicle's estimate."""
    chosen = None
    for summary in sorted(summaries, key=lambda s: (s.land_mode == "normal", s.index)):
        if summary.landed:
            chosen = summary.landed[0]
            break
    if chosen is None:
        return None
    stored = store.trajectory(chosen["id"])
    if stored is None:
        return None
    columns, rows = stored
    col = {name: i for i, name in enumerate(columns)}
    events = {e["kind"]: e["time_s"] for e in reversed(store.events(chosen["id"]))}
    recorded_s = events.get("recorded", 0.0)
    land_s = events.get("land_handover", events.get("land_command", math.inf))  # stores before 0.2: land_command
    truth = "true_north_m" in col and rows and rows[0][col["true_north_m"]] is not None
    north, east, up = (("true_north_m", "true_east_m", "true_altitude_m") if truth
                       else ("est_north_m", "est_east_m", "est_altitude_rel_m"))
    figure, (top, side) = plt.subplots(1, 2, figsize=(10.0, 4.6), dpi=110)
    phases = (("take-off", "tab:green", lambda t: t <= recorded_s),
              ("path", "tab:blue", lambda t: recorded_s <= t <= land_s),
              ("landing", "tab:red", lambda t: t >= land_s))
    for label, color, keep in phases:
        part = [r for r in rows if keep(r[col["time_s"]])]
        if part:
            top.plot([r[col[east]] for r in part], [r[col[north]] for r in part], color=color, label=label)
            side.plot([r[col["time_s"]] for r in part], [r[col[up]] for r in part], color=color, label=label)
    top.plot([0], [0], marker="o", color="black", markersize=5, label="start")
    if chosen.get("scoring_reference") == "pad" and chosen["offset_north_cm"] is not None:
        last = rows[-1]
        pad = (last[col[north]] - chosen["offset_north_cm"] / 100.0, last[col[east]] - chosen["offset_east_cm"] / 100.0)
        top.plot([pad[1]], [pad[0]], marker="+", color="black", markersize=14, label="pad centre")
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("east (m)")
    top.set_ylabel("north (m)")
    top.set_title("seen from above", fontsize=9)
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    side.set_xlabel("time (s)")
    side.set_ylabel("height (m)")
    side.set_title("height", fontsize=9)
    side.grid(alpha=0.3)
    figure.suptitle(f"{campaign}: {chosen['scenario']}, trial {chosen['trial_index']} "
                    f"({'true' if truth else 'estimated'} path)", fontsize=10)
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)
    return out
