"""The 20-seed table of `normal` (GPS-only) landings on the thesis mission, beside the published figures.

Usage: python benchmarks/normal_landing_table.py [--seeds N]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preland_app.config.mission import load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    mission = load_mission(ROOT / "missions" / "thesis_square_land.yaml")
    print(f"{'seed':>4}  {'outcome':<8} {'error cm':>9} {'north cm':>9} {'east cm':>9} {'land s':>7}")
    errors, times = [], []
    for seed in range(args.seeds):
        o = run_trial(TrialRequest(mission=mission, seed=seed, land_mode="normal", record_trajectory=False))
        errors.append(o.landing_error_cm)
        times.append(o.landing_time_s)
        print(f"{seed:>4}  {o.outcome.value:<8} {o.landing_error_cm:9.1f} {o.offset_north_cm:9.1f} "
              f"{o.offset_east_cm:9.1f} {o.landing_time_s:7.1f}")
    print()
    print(f"simulated : mean {statistics.mean(errors):6.1f} cm, max {max(errors):6.1f} cm, "
          f"mean landing time {statistics.mean(times):5.1f} s  ({args.seeds} seeds)")
    print("thesis    : mean  67.2 cm, max  180.0 cm, mean landing time  12.6 s  (Table 3, 10 field trials)")
    print("paper     : mean  85.0 cm, range 51-144 cm                          (GPS-only, 10 flights)")


if __name__ == "__main__":
    main()
