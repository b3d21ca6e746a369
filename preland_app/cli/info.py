"""preland modes and preland schema: what this version can fly and the files it reads."""

from __future__ import annotations

import typer

from .app import app, fail
from .app import columns


@app.command("modes")
def modes() -> None:
    """List the land modes this version can fly: built-in ones and installed plugins (entry point group
    preland.land_modes). Any import path package.module:ClassName flies too."""
    from ..landing.registry import catalog

    rows = [(row.name, row.origin, row.scored_from or "-", row.sensor or "-", row.description) for row in catalog()]
    typer.echo(columns(("mode", "from", "scored from", "sensor", "description"), rows))


@app.command("schema")
def schema(kind: str = typer.Argument(..., metavar="mission|campaign|pad", help="Which file's schema.")) -> None:
    """Print the JSON Schema of mission, campaign or pad files (for editors: yaml-language-server)."""
    from ..config.schema import SCHEMA_KINDS, schema_text

    if kind not in SCHEMA_KINDS:
        raise fail(f"schema: unknown kind {kind!r} (expected one of: {', '.join(SCHEMA_KINDS)})")
    typer.echo(schema_text(kind), nl=False)

