"""figures/mission.png: the thesis mission in plan view, from `missions/thesis_square_land.yaml` itself, with
the true paths of seeded trials flown on the embedded simulator over it.

Plan view in the mission's frame: NED from the start position (the take-off spot), north up, east right, as
`pad.offset_from_start_ned_m` and the trajectory's `true_north_m` / `true_east_m` are.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

if __name__ == "__main__":  # run alone: no __pycache__ in docs/, the site's source
    sys.dont_write_bytecode = True
import _figkit  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Polygon  # noqa: E402

from preland_app.config.mission import MissionSpec, load_mission  # noqa: E402
from preland_app.outcome import TRAJECTORY_COLUMNS  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402
from preland_app.sensing.pad import render_pad_texture  # noqa: E402

MISSION = _figkit.ROOT / "missions" / "thesis_square_land.yaml"
SEED = 1  # `preland fly missions/thesis_square_land.yaml` flies seed 1 by default
REFERENCE_NAMES = {"pad": "pad's centre", "takeoff": "take-off point"}  # ScoringReference values
# The mission's own land mode, and a precision one so the pad is where a landing ends; (mode, colour, width).
# Drawn wide first, thin over it: with one seed both fly the same square until the hand-over.
TRIALS = ((None, "#1565c0", 1.3), ("irlock", "#ef6c00", 3.2))


def fly(mission: MissionSpec, land_mode: str | None):
    """One seeded trial: (land mode flown, true north m, true east m, outcome)."""
    outcome = run_trial(TrialRequest(mission=mission, seed=SEED, land_mode=land_mode))
    columns = {name: i for i, name in enumerate(TRAJECTORY_COLUMNS)}
    path = outcome.trajectory
    return outcome.land_mode, path[:, columns["true_north_m"]], path[:, columns["true_east_m"]], outcome


def _draw_pad(axes, mission: MissionSpec) -> None:
    pad = mission.pad_spec()
    north, east = mission.pad.offset_from_start_ned_m
    half = pad.size_m / 2
    # The texture is north up, east right: as the axes, so a yawed pad needs only its outline turned.
    texture = render_pad_texture(pad, pixels_per_m=250)
    yaw = math.radians(mission.pad.yaw_deg)
    if abs(yaw) < 1e-9:
        axes.imshow(texture, cmap="gray", vmin=0, vmax=255, extent=(east - half, east + half, north - half,
                    north + half), zorder=1, interpolation="antialiased")
    corners = np.array([[-half, -half], [-half, half], [half, half], [half, -half]])  # (north, east)
    turned = np.stack([corners[:, 0] * math.cos(yaw) - corners[:, 1] * math.sin(yaw),
                       corners[:, 0] * math.sin(yaw) + corners[:, 1] * math.cos(yaw)], axis=1)
    axes.add_patch(Polygon(np.stack([east + turned[:, 1], north + turned[:, 0]], axis=1), closed=True,
                           fill=False, edgecolor="#455a64", lw=1.0, zorder=2))
    axes.annotate(f"pad '{mission.pad.preset}' ({pad.size_m * 100:.0f} cm sheet)\n"
                  f"pad.offset_from_start_ned_m: [{north:g}, {east:g}]",
                  xy=(east + half, north), xytext=(east + half + 0.45, north + 0.55), fontsize=9,
                  arrowprops=dict(arrowstyle="-", color="#455a64", lw=0.8), va="center")


def _draw_plan(axes, mission: MissionSpec) -> None:
    waypoints = mission.path.waypoints_rel_ned_m
    # Planned legs from the take-off point: the waypoints are relative to the position recorded after take-off,
    # which is the take-off point up to the estimate's error.
    north = [0.0] + [w[0] for w in waypoints]
    east = [0.0] + [w[1] for w in waypoints]
    axes.plot(east, north, color="#757575", lw=1.4, ls=(0, (5, 4)), zorder=3,
              label=f"path.waypoints_rel_ned_m (circles: {mission.path.acceptance_radius_m:g} m acceptance)")
    radius = mission.path.acceptance_radius_m
    for index, (n, e) in enumerate(waypoints, start=1):
        axes.add_patch(plt.Circle((e, n), radius, fill=False, ec="#757575", lw=0.8, zorder=3))
        # Labels outside the square, away from the paths drawn over its corners.
        dn = 0.32 if n >= -1e-9 else -0.32
        de = 0.32 if e >= 1.0 else -0.32
        if index == len(waypoints) and n == 0 and e == 0:
            dn, de = -0.34, -0.5
        axes.text(e + de, n + dn, f"wp {index}\n[{n:g}, {e:g}]", ha="center", va="center", fontsize=8.5,
                  color="#424242", zorder=6)
    axes.plot([0], [0], marker="^", ms=11, color="#2e7d32", zorder=7, ls="none",
              label=f"take-off (NED origin), to {mission.takeoff.altitude_rel_m:g} m")


def _draw_ned_axes(axes, origin: tuple[float, float]) -> None:
    east, north = origin
    for (de, dn), text, offset in (((0, 0.7), "N  north_m", (0.0, 0.86)), ((0.7, 0), "E  east_m", (1.12, 0.0))):
        axes.annotate("", xy=(east + de, north + dn), xytext=(east, north),
                      arrowprops=dict(arrowstyle="-|>", color="black", lw=1.4), zorder=8)
        axes.text(east + offset[0], north + offset[1], text, ha="center", va="center", fontsize=9.5,
                  fontweight="bold")
    axes.plot([east], [north], marker="o", ms=7, mfc="white", mec="black", zorder=9)
    axes.plot([east], [north], marker=".", ms=3, color="black", zorder=10)
    axes.text(east, north - 0.3, "D  down_m: into the page", ha="left", va="center", fontsize=8.5)


def make(out_dir: Path) -> list[Path]:
    mission = load_mission(MISSION)
    figure, axes = plt.subplots(figsize=(8.4, 9.0), layout="constrained")
    _draw_pad(axes, mission)
    _draw_plan(axes, mission)
    entries = {}
    for land_mode, color, width in sorted(TRIALS, key=lambda trial: -trial[2]):
        mode, north, east, outcome = fly(mission, land_mode)
        error = f"{outcome.landing_error_cm:.0f} cm from the {REFERENCE_NAMES[outcome.scoring_reference]}" \
            if outcome.landing_error_cm is not None else outcome.outcome.value
        option = "" if land_mode is None else f" --land {land_mode}"
        path, = axes.plot(east, north, color=color, lw=width, zorder=4 if width > 2 else 5,
                          alpha=0.8 if width > 2 else 1, label=f"true path: fly{option} --seed {SEED} ({mode})")
        touchdown, = axes.plot([east[-1]], [north[-1]], marker="X", ms=10, color=color, mec="white", zorder=8,
                               ls="none", label=f"touchdown ({mode}): {error}")
        entries[land_mode] = (path, touchdown)
    _draw_ned_axes(axes, (-1.55, -3.1))
    axes.set_aspect("equal")
    axes.set_xlim(-2.0, 3.6)
    axes.set_ylim(-3.6, 3.1)
    axes.set_xlabel("east_m: east of the start position (m)")
    axes.set_ylabel("north_m: north of the start position (m)")
    axes.grid(True, color="#eeeeee", zorder=0)
    axes.set_axisbelow(True)
    axes.set_title(f"{MISSION.relative_to(_figkit.ROOT)} in plan view (NED from the start position)",
                   fontsize=11)
    # Below the axes: inside, it would cover the pad or the square.
    handles, _ = axes.get_legend_handles_labels()
    handles = handles[:2] + [h for trial in TRIALS for h in entries[trial[0]]]  # planned first, then each trial
    axes.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=2, fontsize=8.5, frameon=False)
    return [_figkit.save(figure, out_dir / "mission.png")]


if __name__ == "__main__":
    _figkit.run_alone(make)
