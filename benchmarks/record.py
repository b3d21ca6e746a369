"""Run one benchmark script and keep what it printed as a JSON record, stamped with commit, date and machine.

The docs' benchmark pages are made from these records (`docs/benchmarks/build.py`), so a figure in the docs
is always a script's own output from a named run, never a number copied by hand.

Usage: python benchmarks/record.py SCRIPT.py [ARGS ...]
Writes benchmarks/results/SCRIPT.json (one record per script: the latest run) and echoes the output.
The exit code is the script's.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _git(*args: str) -> str:
    result = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False)
    return result.stdout.strip()


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine() -> dict[str, object]:
    """What ran it: enough to tell two machines apart, nothing that identifies a person."""
    return {"system": platform.system(), "machine": platform.machine(), "cpu": _cpu_model(),
            "cores": os.cpu_count(), "python": platform.python_version()}


def main(argv: list[str]) -> int:
    if not argv or not argv[0].endswith(".py"):
        print("record.py: usage: python benchmarks/record.py SCRIPT.py [ARGS ...]", file=sys.stderr)
        return 2
    script = Path(argv[0])
    if not script.is_absolute():
        script = (ROOT / "benchmarks" / script.name) if not script.exists() else script.resolve()
    if not script.is_file():
        print(f"record.py: {argv[0]}: no such benchmark script", file=sys.stderr)
        return 2
    # What ran is what was checked out when it started: a commit made while a long run goes on is not it.
    # Records written by earlier runs are not changes to what runs.
    commit = _git("rev-parse", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)benchmarks/results"))
    started = datetime.datetime.now(datetime.timezone.utc)
    t0 = time.perf_counter()
    process = subprocess.Popen([sys.executable, str(script), *argv[1:]], cwd=ROOT, stdout=subprocess.PIPE,
                               text=True)
    lines = []
    assert process.stdout is not None
    for line in process.stdout:
        sys.stdout.write(line)
        lines.append(line)
    code = process.wait()
    record = {
        "script": f"benchmarks/{script.name}",
        "args": argv[1:],
        "commit": commit,
        "dirty": dirty,
        "date_utc": started.replace(microsecond=0).isoformat(),
        "wall_time_s": round(time.perf_counter() - t0, 1),
        "machine": machine(),
        "exit_code": code,
        "output": "".join(lines),
    }
    if code == 0:
        RESULTS.mkdir(parents=True, exist_ok=True)
        out = RESULTS / f"{script.stem}.json"
        out.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        print(f"record.py: wrote {out.relative_to(ROOT)}", file=sys.stderr)
    else:
        print(f"record.py: {script.name} exited {code}; nothing recorded", file=sys.stderr)
    return code


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
