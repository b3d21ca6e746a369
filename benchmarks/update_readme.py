"""Rewrite the README's simulated figures from fresh benchmark runs, so they cannot go stale.

Each generated part of README.md sits between `<!-- BEGIN generated: NAME -->` and
`<!-- END generated: NAME -->`; this script recomputes every such part and rewrites only those lines:

* `make-fly`: the first lines `preland fly missions/thesis_square_land.yaml` prints (seed 1);
* `fault-scenarios`: `benchmarks/fault_scenarios_table.py` (the thesis' scenarios beside the field
  trials, with spread, 95 % CI and whether each mean falls inside the published min..max) and the
  sentences that quote it;
* `land-modes`: `benchmarks/land_modes_table.py`'s means with their spread;
* `error-budget`: with `--budget FILE`, the table `benchmarks/error_budget.py --out FILE` wrote
  (without it, that block is left as it is).

Usage: python benchmarks/update_readme.py [--seeds N] [--workers W] [--from-json FILE] [--budget FILE] [--check]
`--from-json` reuses a `fault_scenarios_table.py --json` file instead of flying the scenarios again;
`--check` rewrites nothing and exits 1 when the README differs from what the benchmarks print now.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import fault_scenarios_table as faults  # noqa: E402
import land_modes_table as modes  # noqa: E402

README = ROOT / "README.md"
_BLOCK = re.compile(r"(<!-- BEGIN generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- END generated: (?P=name) -->)",
                    re.DOTALL)


def make_fly_block() -> str:
    from typer.testing import CliRunner

    from preland_app.cli import app

    result = CliRunner().invoke(app, ["fly", str(ROOT / "missions" / "thesis_square_land.yaml")])
    if result.exit_code != 0:
        raise SystemExit(f"update_readme.py: preland fly failed: {result.output.strip()}")
    lines = [line.rstrip() for line in result.output.splitlines() if line.strip()][:6]
    return "```\n" + "\n".join(lines) + "\n...\n```\n"


def fault_block(data: dict) -> str:
    rows = data["rows"]
    seeds = data["seeds"]
    lines = ["```", *_captured(lambda: faults.print_table(rows, seeds)), "```", ""]
    by = {r["scenario"]: r for r in rows}
    compared = [r for r in rows if r["inside"] is not None and r["scenario"] != "T5 default as flown"]
    inside = [r["scenario"] for r in compared if r["inside"]]
    outside = [r["scenario"] for r in compared if not r["inside"]]
    lines.append(f"Over {seeds} seeds per scenario, {len(inside)} of the {len(compared)} scenarios with field "
                 f"trials in the same weather have their simulated mean inside the published min..max "
                 f"({', '.join(inside) or 'none'}); outside: {', '.join(outside) or 'none'}. "
                 f"Means are given ± their seed-to-seed sd, with the 95 % confidence interval of the mean.")
    if {"T5 default", "T5 default as flown", "T5 cautious"} <= set(by):
        thesis_ratio = 39.32 / 14.37
        gusty = by["T5 default"]["mean_cm"] / by["T5 cautious"]["mean_cm"]
        as_flown = by["T5 default as flown"]["mean_cm"] / by["T5 cautious"]["mean_cm"]
        lines += ["", f"Cautious against default landing (Table 5): the thesis' ratio of mean errors is "
                      f"{thesis_ratio:.1f}x, its default being Table 3's calm-air trials; the simulated ratio is "
                      f"{as_flown:.1f}x with the default flown as the thesis flew it (near-calm) and {gusty:.1f}x "
                      f"with both in gusts. Landing times: cautious "
                      f"{by['T5 cautious']['mean_s']:.1f} s simulated against "
                      f"{by['T5 cautious']['field_mean_s']:.1f} s in the field."]
    return "\n".join(lines) + "\n"


def land_modes_block(seeds: int, workers: int) -> str:
    jobs = [(mode, seed) for mode in modes.THESIS for seed in range(seeds)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(modes._one, jobs))
    lines = []
    for mode, (thesis_mean, thesis_max, _) in modes.THESIS.items():
        errors = [r[3] for r in results if r[0] == mode and r[3] is not None]
        times = [r[4] for r in results if r[0] == mode and r[4] is not None]
        mean, sd, ci = faults.mean_sd_ci(errors)
        lines.append(f"- `{mode}`: {mean:.1f} ± {sd:.1f} cm (95 % CI of the mean ± {ci:.1f} cm, max "
                     f"{max(errors):.1f} cm), {statistics.mean(times):.1f} s, over {seeds} seeds "
                     f"(thesis field trials: mean {thesis_mean:.1f} cm, max {thesis_max:.1f} cm)")
    return "\n".join(lines) + "\n"


def _captured(function) -> list[str]:
    import contextlib
    import io

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        function()
    return buffer.getvalue().rstrip("\n").splitlines()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--from-json", default="", help="a fault_scenarios_table.py --json file to reuse")
    parser.add_argument("--budget", default="", help="an error_budget.py --out file for the error-budget block")
    parser.add_argument("--check", action="store_true", help="exit 1 if the README is not up to date")
    args = parser.parse_args()
    if args.from_json:
        data = json.loads(Path(args.from_json).read_text(encoding="utf-8"))
    else:
        labels = list(faults.SCENARIOS)
        jobs = [(label, seed) for label in labels for seed in range(args.seeds)]
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            results = list(pool.map(faults._one, jobs, chunksize=1))
        data = {"seeds": args.seeds, "rows": faults.summarize(results, labels)}
    blocks = {"make-fly": make_fly_block(), "fault-scenarios": fault_block(data),
              "land-modes": land_modes_block(data["seeds"], args.workers)}
    text = README.read_text(encoding="utf-8")
    found = {m.group("name") for m in _BLOCK.finditer(text)}
    if args.budget:
        blocks["error-budget"] = "```\n" + Path(args.budget).read_text(encoding="utf-8") + "```\n"
    else:  # keep what is there
        blocks["error-budget"] = next((m.group("body") for m in _BLOCK.finditer(text)
                                       if m.group("name") == "error-budget"), "")
    missing = sorted(set(blocks) - found)
    if missing:
        raise SystemExit(f"update_readme.py: README.md has no generated block {missing[0]!r}")
    updated = _BLOCK.sub(lambda m: m.group(1) + blocks[m.group("name")] + m.group(4), text)
    if args.check:
        raise SystemExit(0 if updated == text else 1)
    README.write_text(updated, encoding="utf-8")
    print(f"README.md: rewrote {', '.join(sorted(blocks))}")


if __name__ == "__main__":
    main()
