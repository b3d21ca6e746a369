"""ArduPilot parameter (defaults) files as SITL reads them; a module of its own, light to import (the SITL
stand-in reads them at its start)."""

from __future__ import annotations

from pathlib import Path


def read_parm_file(path: Path) -> dict[str, float]:
    """The parameters a defaults file sets, by name: `NAME VALUE` (or `NAME,VALUE`) lines, `#` comments, as
    AP_Param::load_defaults_file reads them; a later line for a name wins."""
    values: dict[str, float] = {}
    for line in Path(path).read_text().splitlines():
        fields = line.split("#", 1)[0].replace(",", " ").split()
        if len(fields) >= 2:  # as AP_Param::parse_param_line: a name and a value, the rest ignored
            values[fields[0]] = float(fields[1])
    return values
