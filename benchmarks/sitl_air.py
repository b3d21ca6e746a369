"""IR-LOCK landings in the thesis' Table 4 air (a 3 m/s wind, W20 5 m/s gusts; thesis Table 4's test site
had regular gusts) on three worlds side by side, the same seeds on each:

- the embedded simulator (`sim:`);
- ArduCopter SITL on its own physics (`sitl:BIN`), the wind given as SIM_WIND_* (SITL's gust model);
- ArduCopter SITL on preland's quad X (`sitl:BIN?physics=preland`), flying in the embedded simulator's air
  (`sim/air.py`: its wind, Dryden gusts and rotor wash, from each trial seed's own streams).

Each column is one campaign (`--workers 2` on SITL), one trial per seed; the table gives the mean, median
and largest landing error (cm) of the trials that touched down, the landings, the wall time per trial, and
how the others ended.

Usage: python benchmarks/sitl_air.py [--binary PATH] [--trials N] [--workers N]
       (binary: $PRELAND_SITL_BINARY)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import preland_app as preland  # noqa: E402

CAMPAIGN = """name: table4_air_irlock
mission: {mission}
trials: {trials}
base_seed: 2004
scenarios:
  - label: IR-LOCK in Table 4 air
    land: irlock
    initial_height_m: 10
    environment: {{wind: {{speed_m_s: 3.0, turbulence_w20_m_s: 5.0}}}}
"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.environ.get("PRELAND_SITL_BINARY"))
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if not args.binary:
        print("set PRELAND_SITL_BINARY (or --binary) to an arducopter SITL binary")
        return 2
    columns = [("embedded simulator", "sim:", 2),
               ("SITL, ArduPilot physics", f"sitl:{args.binary}", args.workers),
               ("SITL, preland physics", f"sitl:{args.binary}?physics=preland", args.workers)]
    print(f"IR-LOCK, thesis mission, Table 4 air (3 m/s, W20 5 m/s), {args.trials} seeds from 2004")
    print(f"  {'world':<26} {'mean cm':>8} {'median':>7} {'max':>7} {'landed':>7} {'wall s/trial':>13}")
    with tempfile.TemporaryDirectory() as folder:
        campaign = Path(folder) / "c.yaml"
        campaign.write_text(CAMPAIGN.format(mission=ROOT / "missions" / "thesis_square_land.yaml",
                                            trials=args.trials))
        for number, (label, url, workers) in enumerate(columns):
            db = Path(folder) / f"{number}.db"
            started = time.perf_counter()
            preland.run_campaign(campaign, db=db, runtime=url, workers=workers)
            wall_s = time.perf_counter() - started
            rows = preland.read_results(db)
            errors = [r["landing_error_cm"] for r in rows if r["landing_error_cm"] is not None]
            landed = sum(r["outcome"] == "landed" for r in rows)
            if not errors:
                print(f"  {label:<26} no landing error: {sorted({r['message'] for r in rows})}")
                continue
            print(f"  {label:<26} {statistics.mean(errors):8.1f} {statistics.median(errors):7.1f} "
                  f"{max(errors):7.1f} {landed:>4}/{len(rows):<2} {wall_s * workers / len(rows):13.1f}")
            print(f"  {'':<26} per seed: {', '.join(f'{e:.1f}' for e in errors)}")
            others = sorted({(r["outcome"], r["message"][:110]) for r in rows if r["outcome"] != "landed"})
            for outcome, message in others:
                print(f"  {'':<26} {outcome}: {message}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
