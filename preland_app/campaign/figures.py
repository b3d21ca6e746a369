"""Report figures like the thesis': landing error per scenario (its Figures 16a-18a), landing positions
around the pad (16b-18b), and the path of one trial (15b, `figure_trajectory.py`).

Written as PNG (at `dpi`, 300 by default), PDF or SVG. Each figure's legend says
what every mark means and sits outside the data. When the landing errors span
two orders of magnitude (GPS-only landings beside precision ones), the error
axis is logarithmic and the positions get a second, zoomed panel, so centimetre
differences stay visible beside metre ones.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
# Text stays text: editable in SVG, embedded TrueType in PDF (what journals ask for).
matplotlib.rcParams["svg.fonttype"] = "none"
matplotlib.rcParams["pdf.fonttype"] = 42
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from .figure_trajectory import choose_trial, trajectory_figure  # noqa: E402
from .store import ResultsStore  # noqa: E402

if TYPE_CHECKING:  # the report writes the figures: only its summaries' type is needed here
    from .report import ScenarioSummary

DEFAULT_PNG_DPI = 300
SOURCE_MARKERS = {"sim": "o", "sitl": "s", "field": "^"}
SOURCE_COLORS = {"sim": "tab:blue", "sitl": "tab:purple", "field": "tab:orange"}
PUBLISHED_MARKER = "D"
RINGS_CM = (1, 2, 5, 10, 25, 50, 100, 200, 500)


def spans_two_orders(values: list[float]) -> bool:
    """Whether the positive values span a factor of 100 or more."""
    positive = [v for v in values if v is not None and v > 0]
    return len(positive) > 1 and max(positive) / min(positive) >= 100.0


def scenario_colors(summaries: list[ScenarioSummary]) -> dict[str, tuple]:
    """One colour per scenario label (its simulated and field rows share it; the marker tells them apart)."""
    labels = list(dict.fromkeys(s.scenario or s.label for s in summaries))
    palette = plt.get_cmap("tab10" if len(labels) <= 10 else "tab20")
    return {label: palette(i % palette.N) for i, label in enumerate(labels)}


def _title(axes_or_figure, text: str, width: int) -> None:
    """A title wrapped to fit the figure's width (in characters)."""
    import textwrap

    wrapped = "\n".join(textwrap.wrap(text, width=max(30, width)))
    if hasattr(axes_or_figure, "suptitle"):
        axes_or_figure.suptitle(wrapped, fontsize=10)
    else:
        axes_or_figure.set_title(wrapped, fontsize=10)


def landing_error_boxplot(campaign: str, summaries: list[ScenarioSummary], out: Path, *,
                          dpi: int | None = None) -> Path:
    """Box plot of the landing error per scenario and source (box: middle half; line: median; whiskers:
    min to max; diamond: mean), with the published trials (dots) and published mean (bar) beside each
    simulated box where the campaign gives them."""
    width_in = max(7.5, 1.05 * len(summaries) + 4.5)
    figure, axes = plt.subplots(figsize=(width_in, 5.0))
    positions = list(range(1, len(summaries) + 1))
    all_errors = [e for s in summaries for e in s.errors_cm()] + [p.error_cm for s in summaries for p in s.published]
    log_axis = spans_two_orders(all_errors)
    floor = 0.1  # cm: a zero error on a log axis
    for position, summary in zip(positions, summaries):
        errors = summary.errors_cm()
        if log_axis:
            errors = [max(e, floor) for e in errors]
        color = SOURCE_COLORS.get(summary.source, "tab:gray")
        if errors:
            axes.boxplot([errors], positions=[position], widths=0.38, whis=(0, 100), showmeans=True,
                         patch_artist=True, manage_ticks=False,
                         boxprops={"facecolor": color, "alpha": 0.35, "edgecolor": color},
                         medianprops={"color": "black", "lw": 1.6},
                         whiskerprops={"color": color}, capprops={"color": color},
                         meanprops={"marker": "D", "markerfacecolor": "white", "markeredgecolor": "black",
                                    "markersize": 5})
        else:
            axes.text(position, 0.5, "no landing", transform=axes.get_xaxis_transform(), ha="center", fontsize=7,
                      rotation=90, color="gray")
        if summary.published:
            published = [max(p.error_cm, floor) if log_axis else p.error_cm for p in summary.published]
            axes.scatter([position + 0.33] * len(published), published, s=12, color="black", alpha=0.55,
                         zorder=3)
        mean = summary.published_avg_error_cm()
        if mean is not None:
            axes.plot([position + 0.22, position + 0.44], [mean] * 2, color="black", lw=2.2, zorder=4)
    axes.set_xticks(positions)
    axes.set_xticklabels([s.label for s in summaries], rotation=25, ha="right", fontsize=8)
    axes.set_xlim(0.4, len(summaries) + 0.7)
    if log_axis:
        from matplotlib.ticker import FuncFormatter

        axes.set_yscale("log")
        axes.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        axes.set_ylabel("landing error (cm, log scale)")
    else:
        axes.set_ylim(bottom=0)
        axes.set_ylabel("landing error (cm)")
    axes.grid(axis="y", which="both", alpha=0.25)
    sources = list(dict.fromkeys(s.source for s in summaries))
    handles = [Patch(facecolor=SOURCE_COLORS.get(source, "tab:gray"), alpha=0.35,
                     edgecolor=SOURCE_COLORS.get(source, "tab:gray"),
                     label={"sim": "box: middle 50 % of simulated trials", "sitl": "box: middle 50 % of SITL trials",
                            "field": "box: middle 50 % of field trials"}.get(source, source)) for source in sources]
    handles += [Line2D([], [], color="black", lw=1.6, label="line in box: median"),
                Line2D([], [], color=SOURCE_COLORS.get(sources[0], "gray"), lw=1.0,
                       label="whiskers: minimum to maximum"),
                Line2D([], [], marker="D", ls="none", markerfacecolor="white", markeredgecolor="black",
                       label="diamond: mean (the table's figure)")]
    if any(s.published for s in summaries):
        handles.append(Line2D([], [], marker="o", ls="none", color="black", alpha=0.55, markersize=4,
                              label="dot: one published trial"))
    if any(s.published_avg_error_cm() is not None for s in summaries):
        handles.append(Line2D([], [], color="black", lw=2.2, label="bar: published mean"))
    axes.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    _title(axes, f"{campaign}: landing error per scenario", int(width_in * 9))
    figure.tight_layout()
    figure.savefig(out, dpi=dpi)
    plt.close(figure)
    return out


def _zoom_radius_cm(radii: list[float]) -> float | None:
    """The zoomed panel's radius: the smallest ring holding at least half the landings, when the landings
    span two orders of magnitude."""
    if not spans_two_orders(radii):
        return None
    ordered = sorted(radii)
    median = ordered[len(ordered) // 2]
    ring = next((r for r in RINGS_CM if r >= median * 1.2), None)
    return ring if ring is not None and ring * 3 < max(radii) else None


def landing_positions_scatter(campaign: str, summaries: list[ScenarioSummary], out: Path, *,
                              dpi: int | None = None) -> Path:
    """Landing positions relative to the scoring reference (pad centre or take-off point), in cm: one colour
    per scenario, one marker per source (circle simulated, square SITL, triangle field, diamond published)."""
    colors = scenario_colors(summaries)
    series = []  # (label, color, marker, hollow, east, north)
    for summary in summaries:
        color = colors[summary.scenario or summary.label]
        placed = [t for t in summary.landed if t["offset_east_cm"] is not None and t["offset_north_cm"] is not None]
        if placed:
            series.append((f"{summary.label} (n={len(placed)})", color, SOURCE_MARKERS.get(summary.source, "P"),
                           False, [t["offset_east_cm"] for t in placed], [t["offset_north_cm"] for t in placed]))
        published = [p for p in summary.published if p.x_cm is not None and p.y_cm is not None]
        if published:
            # Drawn as the thesis' figures draw them: x across, y up.
            series.append((f"{summary.label}, published (n={len(published)})", color, PUBLISHED_MARKER, True,
                           [p.x_cm for p in published], [p.y_cm for p in published]))
    radii = [math.hypot(e, n) for *_, east, north in series for e, n in zip(east, north)]
    zoom = _zoom_radius_cm(radii) if radii else None
    panels = 2 if zoom else 1
    figure, axes_list = plt.subplots(1, panels, figsize=(5.6 * panels + 3.6, 5.6), squeeze=False)
    extent = max([10.0, *radii]) * 1.12
    for axes, limit in zip(axes_list[0], [extent, zoom * 1.05] if zoom else [extent]):
        for label, color, marker, hollow, east, north in series:
            axes.scatter(east, north, marker=marker, s=30 if not hollow else 26, label=label,
                         facecolors="none" if hollow else [color], edgecolors=[color], linewidths=1.0,
                         alpha=0.9)
        for ring in RINGS_CM:
            if limit / 12 <= ring <= limit:
                axes.add_patch(plt.Circle((0, 0), ring, fill=False, color="gray", lw=0.5, ls="--"))
                axes.annotate(f"{ring:g} cm", (ring * 0.7071, ring * 0.7071), fontsize=6, color="gray")
        axes.plot([0], [0], marker="+", color="black", markersize=14, mew=1.3)
        axes.set_xlim(-limit, limit)
        axes.set_ylim(-limit, limit)
        axes.set_aspect("equal")
        axes.set_xlabel("east (cm)")
        axes.set_ylabel("north (cm)")
        axes.grid(alpha=0.2)
    if zoom:
        axes_list[0][0].set_title("all landings", fontsize=9)
        axes_list[0][1].set_title(f"within {zoom:g} cm of the reference", fontsize=9)
    handles, labels = axes_list[0][0].get_legend_handles_labels()
    handles.append(Line2D([], [], marker="+", color="black", ls="none", markersize=10))
    labels.append("reference: pad centre (take-off point for GPS-only)")
    width_in = 5.6 * panels + 3.6
    legend_share = 3.4 / width_in
    figure.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0 - legend_share + 0.01, 0.5), fontsize=7,
                  frameon=False)
    kinds = {"sim": "filled circle: simulated", "sitl": "square: SITL", "field": "triangle: field"}
    shown = [kinds[s.source] for s in summaries if s.source in kinds]
    if any(s.published for s in summaries):
        shown.append("hollow diamond: published")
    _title(figure, f"{campaign}: landing positions around the reference ({'; '.join(dict.fromkeys(shown))})",
           int(width_in * 9))
    figure.tight_layout(rect=(0, 0, 1.0 - legend_share, 0.95))
    figure.savefig(out, dpi=dpi)
    plt.close(figure)
    return out


def error_ecdfs(campaign: str, summaries: list[ScenarioSummary], out: Path, *, dpi: int) -> Path | None:
    """One panel per simulated scenario with published trials: the simulated landing errors' empirical CDF
    (a step curve) and the field trials as points on their own ECDF; None when no scenario has field trials."""
    import numpy as np

    chosen = [s for s in summaries if s.source == "sim" and s.published and s.errors_cm()]
    if not chosen:
        return None
    columns = min(3, len(chosen))
    rows = math.ceil(len(chosen) / columns)
    figure, axes = plt.subplots(rows, columns, figsize=(3.6 * columns, 2.7 * rows), squeeze=False)
    for ax, summary in zip(axes.flat, chosen):
        simulated = np.sort(summary.errors_cm())
        field = np.sort([p.error_cm for p in summary.published])
        ax.step(np.concatenate([[0.0], simulated]), np.arange(len(simulated) + 1) / len(simulated), where="post",
                color="tab:blue", lw=1.2, label=f"simulated ({len(simulated)})")
        ax.plot(field, np.arange(1, len(field) + 1) / len(field), "^", color="tab:orange", ms=5,
                label=f"field ({len(field)})")
        ax.set_title(summary.scenario, fontsize=9)
        ax.set_xlabel("landing error (cm)", fontsize=8)
        ax.set_ylabel("fraction of trials", fontsize=8)
        ax.set_ylim(0, 1.02)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, loc="lower right")
    for ax in list(axes.flat)[len(chosen):]:
        ax.set_visible(False)
    figure.suptitle(f"{campaign}: landing errors, simulated (step curve) against the field trials (points)",
                    fontsize=10)
    figure.tight_layout(rect=(0, 0, 1, 0.95))
    figure.savefig(out, dpi=dpi)
    plt.close(figure)
    return out


def write_figures(store: ResultsStore, campaign: str, summaries: list[ScenarioSummary], out_dir: Path, *,
                  figure_format: str = "png", dpi: int | None = None,
                  trial: tuple[str, int] | None = None) -> list[Path]:
    """Every figure of a campaign's report, as `figure_format` (png, pdf, svg) files in `out_dir`; PNG at
    `dpi` (default 300). `trial` = (scenario, index) chooses the trajectory figure's trial."""
    suffix = "." + figure_format
    dpi = dpi if dpi is not None else DEFAULT_PNG_DPI
    chosen = choose_trial(store, campaign, summaries, trial)  # first: a trial that is not there draws nothing
    figures = [landing_error_boxplot(campaign, summaries, out_dir / f"{campaign}_errors{suffix}", dpi=dpi),
               landing_positions_scatter(campaign, summaries, out_dir / f"{campaign}_positions{suffix}", dpi=dpi)]
    if chosen is not None:
        path = trajectory_figure(store, chosen, out_dir / f"{campaign}_trajectory{suffix}", dpi=dpi)
        if path is not None:
            figures.append(path)
    ecdfs = error_ecdfs(campaign, summaries, out_dir / f"{campaign}_ecdf{suffix}", dpi=dpi)
    return figures + ([ecdfs] if ecdfs is not None else [])
