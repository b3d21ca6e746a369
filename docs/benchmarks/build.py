"""The benchmark page, made at build time from the benchmark scripts' own records (mkdocs-gen-files script).

Each script in benchmarks/ is described by its own docstring; its figures are the output of its latest
recorded run (`python benchmarks/record.py SCRIPT.py`, kept in benchmarks/results/SCRIPT.json with the
commit, date and machine it ran on). Nothing here is typed by hand, so the page cannot drift from the runs.
"""

from __future__ import annotations

import ast
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
RESULTS = BENCHMARKS / "results"
# The scripts that run the project's tooling rather than measure it.
NOT_BENCHMARKS = {"record.py"}
# Figures about results first (they are what a reader compares with the sources), then speed.
RESULT_SCRIPTS = ("fault_scenarios_table.py", "land_modes_table.py", "normal_landing_table.py", "paper_table.py",
                  "error_budget.py", "drop_rate_sensitivity.py", "drop_cost_witnesses.py", "sitl_witness.py",
                  "fault_kinds.py",
                  "detector_variants.py",
                  "sitl_vs_embedded.py",
                  "json_bridge_hover.py", "sitl_air.py", "sitl_attitude_error.py", "sitl_lockstep.py")


def _summary(script: Path) -> str:
    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))) or ""
    return doc.split("\n\n")[0].replace("\n", " ").strip()


def _usage(script: Path) -> str:
    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))) or ""
    for line in doc.splitlines():
        if line.startswith("Usage:"):
            return line.removeprefix("Usage:").strip()
    return f"python benchmarks/{script.name}"


def _stamp(record: dict) -> str:
    machine = record.get("machine", {})
    commit = record.get("commit", "")[:10] + (" (with uncommitted changes)" if record.get("dirty") else "")
    args = " ".join(record.get("args", ())) or "(defaults)"
    return (f"Run `{args}` at commit `{commit}` on {record.get('date_utc', '?')}, "
            f"{machine.get('cores', '?')} cores ({machine.get('cpu', '?')}, {machine.get('system', '')} "
            f"{machine.get('machine', '')}, Python {machine.get('python', '?')}), {record.get('wall_time_s', '?')} s.")


def page() -> str:
    scripts = sorted((p for p in BENCHMARKS.glob("*.py") if p.name not in NOT_BENCHMARKS),
                     key=lambda p: (p.name not in RESULT_SCRIPTS,
                                    RESULT_SCRIPTS.index(p.name) if p.name in RESULT_SCRIPTS else 0, p.name))
    out = ["# Benchmarks\n",
           "Each section is one script in `benchmarks/`: what it measures (its own docstring), how to run it, "
           "and the output of its latest recorded run with the commit, date and machine. Record a run with "
           "`python benchmarks/record.py SCRIPT.py [ARGS]`; `make bench` records them all. Speeds depend on "
           "the machine and its load: compare runs of one machine, side by side.\n"]
    out.append("| script | measures | recorded |\n|---|---|---|")
    records = {}
    for script in scripts:
        path = RESULTS / f"{script.stem}.json"
        records[script.name] = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None
        record = records[script.name]
        when = record["date_utc"][:10] if record else "not recorded"
        anchor = script.stem.replace("_", "-")
        out.append(f"| [`{script.name}`](#{anchor}) | {_summary(script).split('. ')[0].rstrip('.')} | {when} |")
    out.append("")
    for script in scripts:
        anchor = script.stem.replace("_", "-")
        out.append(f"## `{script.name}` {{ #{anchor} }}\n")
        out.append(_summary(script) + "\n")
        out.append(f"```sh\n{_usage(script)}\n```\n")
        record = records[script.name]
        if record is None:
            out.append(f"No run recorded: `python benchmarks/record.py {script.name}` records one.\n")
            continue
        out.append(_stamp(record) + "\n")
        out.append("```text\n" + record["output"].rstrip("\n") + "\n```\n")
    return "\n".join(out)


def publish(open_file) -> None:
    with open_file("benchmarks/index.md", "w") as handle:
        handle.write(page())


try:
    import mkdocs_gen_files
except ImportError:  # run by hand: print the page
    mkdocs_gen_files = None

if mkdocs_gen_files is not None and __name__ != "__main__":
    publish(mkdocs_gen_files.open)
elif __name__ == "__main__":
    sys.stdout.write(page())
