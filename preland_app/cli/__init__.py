"""The `preland` command line: a thin layer over the Python API.

Every user mistake ends in one line on stderr naming what is wrong and a
non-zero exit (2 for bad input, 1 for a failed run); never a traceback.
One module per command group; importing them registers their commands on `app`.
"""

from __future__ import annotations

from . import calibrate, campaign, campaign_results, field, fly, info, sim, trial  # noqa: F401  (registers the commands)
from .app import EXIT_BAD_INPUT, EXIT_FAILED, app, fail, main

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "app", "fail", "main"]
