"""preland modes and preland schema: what this version can fly and the files it reads."""

from __future__ import annotations

import typer

from .app import app, choices
from .app import columns


SchemaKind = choices("preland_app.config.schema:SCHEMA_KINDS")


@app.command("modes")
def modes() -> None:
    """List the land modes this version can fly: built-in ones and installed plugins (entry point group
    preland.land_modes). Any import path package.module:ClassName flies too."""
    from ..landing.registry import catalog

    rows = [(row.name, row.origin, row.scored_from or "-", row.sensor or "-", row.description) for row in catalog()]
    typer.echo(columns(("mode", "from", "scored from", "sensor", "description"), rows))


@app.command("schema")
def schema(kind: SchemaKind = typer.Argument(..., metavar="KIND", help="Which kind of file.")) -> None:
    """Print the JSON Schema of one kind of preland file (for editors: yaml-language-server)."""
    from ..config.schema import schema_text

    typer.echo(schema_text(kind), nl=False)

