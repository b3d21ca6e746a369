"""The test suite's time as `make test` runs it: wall time, the CPU the whole machine spent meanwhile, and where.

The suite keeps every core busy from start to end (six xdist workers on two cores), so its wall time is the
CPU it needs divided by the cores: the figure to cut is CPU. Each run prints:

* wall time (the command's, and the one pytest reports), and the CPU seconds every process on the machine
  used meanwhile (/proc/stat: the suite, its children, Ray's daemons that nobody waits for, the kernel);
* the cores that kept busy (CPU / wall);
* a reference workload's CPU (`reference_cpu_s`: a fixed computation in plain Python that no change to preland
  alters, in this process), timed before and after: the same machine runs the same code 20 % faster or slower
  from one hour to the next, and the suite's CPU in units of that workload compares runs made at different
  times, and commits;
* the CPU of each test module and of the longest tests (each test's process, its threads and the children
  it waited for, from a pytest plugin this script loads), and what no test accounts for (xdist's start-up
  and collection, Ray's daemons).

Runs `make test` in the checkout (the venv it makes, `.venv`); `--runs N` repeats it.

Usage: python benchmarks/suite_time.py [--runs 1] [--top 15]
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REFERENCE_LOOPS = 6_000_000  # about 2 CPU s on the 2-core machine CI runs on
# A pytest plugin that appends one line per test: node id, CPU of the test's process (all its threads) and of
# the children it waited for, wall time. Written to a temporary folder put on PYTHONPATH for the run.
PLUGIN = '''
import os, resource, time
import pytest

def _cpu():
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime

@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    before, started = _cpu(), time.monotonic()
    yield
    after = _cpu()
    with open(os.environ["PRELAND_SUITE_CPU_TSV"], "a") as out:
        out.write(f"{item.nodeid}\\t{after[0] - before[0]:.3f}\\t{after[1] - before[1]:.3f}\\t"
                  f"{time.monotonic() - started:.3f}\\n")
'''


def busy_cpu_s() -> float:
    """CPU seconds all cores have spent busy since boot (user, nice, system, irq, softirq; not steal)."""
    fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    user, nice, system, _idle, _iowait, irq, softirq = (int(value) for value in fields[:7])
    return (user + nice + system + irq + softirq) / os.sysconf("SC_CLK_TCK")


def reference_cpu_s() -> float:
    """CPU seconds of a fixed computation in plain Python, of the kinds the simulator does (float arithmetic,
    calls, a dict): it gauges the machine's speed of the moment, and no change to preland's code alters it."""
    started = time.process_time()
    total, table = 0.0, {}
    for index in range(REFERENCE_LOOPS):
        x = (index % 97) * 0.5
        total += math.sin(x) * math.sqrt(x + 1.0) - abs(total) * 1e-9
        table[index & 1023] = total
    return time.process_time() - started


def run_suite(folder: Path, index: int) -> dict:
    tsv = folder / f"tests_{index}.tsv"
    env = {**os.environ, "PRELAND_SUITE_CPU_TSV": str(tsv),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(folder), os.environ.get("PYTHONPATH")])),
           "PYTEST_ADDOPTS": " ".join(filter(None, ["-p suite_cpu_plugin", os.environ.get("PYTEST_ADDOPTS")]))}
    busy_before, started = busy_cpu_s(), time.monotonic()
    result = subprocess.run(["make", "test"], cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    wall_s, busy_s = time.monotonic() - started, busy_cpu_s() - busy_before
    summary = next((line for line in reversed(result.stdout.splitlines()) if " in " in line and
                    ("passed" in line or "failed" in line or "error" in line)), "no pytest summary")
    tests = []
    if tsv.is_file():
        for line in tsv.read_text().splitlines():
            node, own, children, wall = line.split("\t")
            tests.append((node, float(own) + float(children), float(wall)))
    return {"returncode": result.returncode, "wall_s": wall_s, "busy_s": busy_s, "summary": summary,
            "tests": tests, "tail": result.stdout[-3000:] + result.stderr[-2000:]}


def report(run: dict, *, reference_s: float, top: int) -> None:
    tests = run["tests"]
    measured_s = sum(cpu for _, cpu, _ in tests)
    cores = os.cpu_count() or 1
    print(f"make test: exit {run['returncode']}, {run['summary']}")
    print(f"  wall {run['wall_s']:.1f} s; CPU of the whole machine {run['busy_s']:.1f} s "
          f"({run['busy_s'] / run['wall_s']:.2f} of {cores} cores busy); "
          f"{run['busy_s'] / reference_s:.1f} x the reference workload")
    print(f"  CPU in tests {measured_s:.1f} s; outside any test {run['busy_s'] - measured_s:.1f} s "
          "(workers' start-up and collection, Ray's daemons, the kernel)")
    modules: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0])
    for node, cpu, wall in tests:
        module = modules[node.split("::", 1)[0]]
        module[0] += cpu
        module[1] += wall
    print(f"  test modules by CPU (the first {top}): CPU s, wall s on its worker, module")
    for name, (cpu, wall) in sorted(modules.items(), key=lambda item: -item[1][0])[:top]:
        print(f"    {cpu:7.1f} {wall:7.1f}  {name}")
    print(f"  tests by CPU (the first {top}): CPU s, wall s, test")
    for node, cpu, wall in sorted(tests, key=lambda test: -test[1])[:top]:
        print(f"    {cpu:7.2f} {wall:7.1f}  {node}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=1, help="how many times to run `make test`")
    parser.add_argument("--top", type=int, default=15, help="how many modules and tests to list")
    args = parser.parse_args()
    if args.runs < 1 or args.top < 1:
        print("suite_time.py: --runs and --top must be >= 1", file=sys.stderr)
        return 2
    worst = 0
    with tempfile.TemporaryDirectory(prefix="preland-suite-time-") as name:
        folder = Path(name)
        (folder / "suite_cpu_plugin.py").write_text(PLUGIN)
        for index in range(1, args.runs + 1):
            before_s = reference_cpu_s()
            run = run_suite(folder, index)
            after_s = reference_cpu_s()
            reference_s = (before_s + after_s) / 2
            print(f"run {index} of {args.runs}: reference workload ({REFERENCE_LOOPS:,} loops in plain Python) "
                  f"{before_s:.2f} s CPU before, {after_s:.2f} s after")
            report(run, reference_s=reference_s, top=args.top)
            if run["returncode"] != 0:
                print(run["tail"])
                worst = run["returncode"]
    return worst


if __name__ == "__main__":
    sys.exit(main())
