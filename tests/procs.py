"""Processes as /proc shows them, for the tests that check that what a run started has ended.

A process is known by its pid and the clock tick it started at (`started_ticks`): on a machine that starts
thousands of processes and threads a minute, Linux gives a gone process's pid to another within seconds
(pid_max is 32768 on 2 cores), and a pid alone would then read as the process that had it, still running."""

from pathlib import Path


def stat_field(pid: int | str, number: int) -> int | None:
    """Field `number` (1-based, as proc(5) counts them; 4 or above) of /proc/PID/stat; None when it is gone.
    Split after the command's closing parenthesis, which may itself hold spaces."""
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[number - 3])
    except (OSError, IndexError, ValueError):
        return None


def started_ticks(pid: int | str = "self") -> int | None:
    """When process `pid` started (clock ticks since boot; /proc/PID/stat field 22), None when it is gone."""
    return stat_field(pid, 22)


def alive(pid: int, started: int | None = None) -> bool:
    """Whether `pid` runs (a zombie does not), and, given `started`, is still the process that started at
    that tick."""
    try:
        if "State:\tZ" in Path(f"/proc/{pid}/status").read_text():
            return False
    except OSError:
        return False
    return started is None or started_ticks(pid) == started


def cmdline(pid: int) -> str:
    """The command line of `pid`, its arguments joined by spaces; '' when it is gone."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _children_by_parent() -> dict[int, list[int]]:
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            parent = stat_field(entry.name, 4)
            if parent is not None:
                children.setdefault(parent, []).append(int(entry.name))
    return children


def children(pid: int) -> list[int]:
    """The processes whose parent is `pid`."""
    return sorted(_children_by_parent().get(pid, []))


def descendants(pid: int) -> set[int]:
    """The processes under `pid`, at any depth."""
    tree = _children_by_parent()
    found, stack = set(), [pid]
    while stack:
        for child in tree.get(stack.pop(), []):
            found.add(child)
            stack.append(child)
    return found


def identified(pids) -> dict[int, int]:
    """Each of `pids` that still runs, with the tick it started at (for `alive`)."""
    found = {}
    for pid in pids:
        ticks = started_ticks(pid)
        if ticks is not None:
            found[pid] = ticks
    return found
