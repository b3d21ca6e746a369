"""Printable landing pads at true scale, with their dimensions annotated.

The page is the pad's sheet plus a margin for the annotations; the figure is
sized in inches so that one metre on the sheet prints as one metre (print at
100 % / "actual size"). PNG pages carry their DPI; PDF pages are vector around
a raster of the markers at the chosen DPI.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .pad import PadSpec, render_pad_texture  # noqa: E402

_INCH_M = 0.0254
_MARGIN_M = 0.12


def render_printable_pad(pad: PadSpec, out: Path, *, dpi: int = 100) -> Path:
    """Write `out` (.png or .pdf) with the pad at true scale; returns the path."""
    suffix = out.suffix.lower()
    if suffix not in (".png", ".pdf"):
        raise ValueError(f"{out}: the output must end in .png or .pdf")
    size_m = pad.size_m
    page_m = size_m + 2 * _MARGIN_M
    texture = render_pad_texture(pad, pixels_per_m=dpi / _INCH_M)
    figure = plt.figure(figsize=(page_m / _INCH_M, page_m / _INCH_M), dpi=dpi)
    # Axes in metres, pad frame: x east (right), y north (up), centred on the pad.
    axes = figure.add_axes((_MARGIN_M / page_m, _MARGIN_M / page_m, size_m / page_m, size_m / page_m))
    half = size_m / 2.0
    axes.imshow(texture, cmap="gray", vmin=0, vmax=255, extent=(-half, half, -half, half),
                interpolation="nearest")
    axes.set_xlim(-half, half)
    axes.set_ylim(-half, half)
    axes.set_axis_off()
    font_pt = max(6.0, min(14.0, size_m * 12))
    for marker in pad.markers:
        corners = pad.marker_corners_pad_m(marker)
        top = corners[:, 0].max()
        left, right = corners[:, 1].min(), corners[:, 1].max()
        gap = marker.side_m * 0.04 + 0.004
        axes.annotate("", xy=(left, top + gap), xytext=(right, top + gap),
                      arrowprops={"arrowstyle": "<->", "color": "tab:red", "lw": 0.8})
        axes.text((left + right) / 2, top + gap * 1.4, f"id {marker.id}: {marker.side_m * 100:.1f} cm",
                  color="tab:red", ha="center", va="bottom", fontsize=font_pt * (0.6 if marker.side_m < 0.2 else 1))
    if pad.beacon_m is not None:
        axes.plot([pad.beacon_m[1]], [pad.beacon_m[0]], marker="+", color="tab:orange", markersize=font_pt)
    axes.plot([0], [0], marker="x", color="tab:blue", markersize=font_pt * 0.6)
    caption = (f"preland pad '{pad.name}' | {pad.dictionary} | sheet {size_m * 100:.0f} x {size_m * 100:.0f} cm | "
               "print at 100 % (actual size) | x: landing point" + (" | +: IR beacon" if pad.beacon_m else ""))
    figure.text(0.5, _MARGIN_M * 0.35 / page_m, caption, ha="center", va="center", fontsize=font_pt * 0.8)
    # A 10 cm scale bar to check the print.
    bar = figure.add_axes((_MARGIN_M / page_m, (_MARGIN_M + size_m + 0.03) / page_m, 0.10 / page_m, 0.01 / page_m))
    bar.set_facecolor("black")
    bar.set_xticks([])
    bar.set_yticks([])
    figure.text((_MARGIN_M + 0.105) / page_m, (_MARGIN_M + size_m + 0.035) / page_m, "10 cm", va="center",
                fontsize=font_pt * 0.8)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=dpi)
    plt.close(figure)
    return out
