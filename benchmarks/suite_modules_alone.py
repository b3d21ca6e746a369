"""Each test module run alone, with the CPU of everything it started: the suite's cost module by module.

`suite_time.py` counts a test's own process and the children it waited for; what a test starts and nobody
waits for (the daemons of a local Ray instance, a served vehicle killed in the background) falls outside
every test there. Here each module runs in a cgroup (v2) of its own, so its CPU (`cpu.stat`) is that of every
process it started, daemons included, read once the last of them has gone. Each module runs as
`python -m pytest -p no:xdist MODULE` with this interpreter (run it with the checkout's venv: `make test`
makes it), `--jobs` at a time (2: a module's wall time is then near the one it has in the suite).

Prints each module's CPU and wall seconds (the costliest first), the sum, and a reference workload's CPU
timed before and after (`suite_time.reference_cpu_s`, a fixed computation in plain Python), with the sum in
units of it. Needs a writable cgroup v2 hierarchy (root, and cgroup2 mounted); refuses in one line without.

Usage: python benchmarks/suite_modules_alone.py [--jobs 2] [--top 20] [MODULE ...]
"""

from __future__ import annotations

import argparse
import concurrent.futures
import os
import subprocess
import sys
import time
from pathlib import Path

from suite_time import REFERENCE_LOOPS, ROOT, reference_cpu_s

LEFT_WAIT_S = 30.0  # how long the processes a module leaves are waited for before they are killed


def cgroup2_root() -> Path | None:
    """Where cgroup v2 is mounted (/proc/mounts), or None."""
    for line in Path("/proc/mounts").read_text().splitlines():
        fields = line.split()
        if len(fields) > 2 and fields[2] == "cgroup2":
            return Path(fields[1])
    return None


def run_alone(root: Path, module: str) -> dict:
    """`module` run alone in a new cgroup under `root`: its CPU (s), wall (s), exit status, last line."""
    group = root / f"preland-alone-{os.getpid()}-{Path(module).stem}"
    group.mkdir()
    procs = group / "cgroup.procs"

    def enter() -> None:  # in the child, before exec: it and everything it starts are counted
        procs.write_text(str(os.getpid()))

    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": ""}  # as `make test` runs the suite
    started = time.monotonic()
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                             module], cwd=ROOT, env=env, capture_output=True, text=True, preexec_fn=enter)
    wall_s = time.monotonic() - started
    deadline = time.monotonic() + LEFT_WAIT_S
    while procs.read_text().split() and time.monotonic() < deadline:
        time.sleep(0.2)
    left = len(procs.read_text().split())
    usage_us = int(dict(line.split() for line in (group / "cpu.stat").read_text().splitlines())["usage_usec"])
    if left:
        (group / "cgroup.kill").write_text("1")
        while procs.read_text().split() and time.monotonic() < deadline + LEFT_WAIT_S:
            time.sleep(0.2)
    group.rmdir()
    lines = (result.stdout or result.stderr).strip().splitlines()
    return {"module": module, "cpu_s": usage_us / 1e6, "wall_s": wall_s, "returncode": result.returncode,
            "left": left, "last": lines[-1] if lines else ""}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=2, help="how many modules run at a time")
    parser.add_argument("--top", type=int, default=20, help="how many modules to list")
    parser.add_argument("modules", nargs="*", help="test modules (default: every tests/test_*.py)")
    args = parser.parse_args()
    if args.jobs < 1 or args.top < 1:
        print("suite_modules_alone.py: --jobs and --top must be >= 1", file=sys.stderr)
        return 2
    root = cgroup2_root()
    if root is None or not os.access(root, os.W_OK):
        print(f"suite_modules_alone.py: needs a writable cgroup v2 hierarchy (found {root or 'none'})",
              file=sys.stderr)
        return 2
    modules = args.modules or sorted(str(path.relative_to(ROOT)) for path in (ROOT / "tests").glob("test_*.py"))
    before_s = reference_cpu_s()
    started = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        runs = list(pool.map(lambda module: run_alone(root, module), modules))
    wall_s = time.monotonic() - started
    after_s = reference_cpu_s()
    total_s = sum(run["cpu_s"] for run in runs)
    print(f"{len(runs)} test modules alone, {args.jobs} at a time, in {wall_s:.0f} s: {total_s:.1f} CPU s in all; "
          f"reference workload ({REFERENCE_LOOPS:,} loops in plain Python) {before_s:.2f} s CPU before, "
          f"{after_s:.2f} s after; the sum is {total_s / ((before_s + after_s) / 2):.1f} x the reference")
    print(f"modules by CPU (the first {args.top}): CPU s, wall s, module, its last line")
    for run in sorted(runs, key=lambda run: -run["cpu_s"])[:args.top]:
        left = f" ({run['left']} processes left, killed)" if run["left"] else ""
        print(f"  {run['cpu_s']:7.1f} {run['wall_s']:7.1f}  {run['module']}  {run['last']}{left}")
    failed = [run for run in runs if run["returncode"] != 0]
    for run in failed:
        print(f"failed: {run['module']} (exit {run['returncode']}): {run['last']}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
