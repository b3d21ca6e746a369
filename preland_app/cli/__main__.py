"""`python -m preland_app.cli`."""

from .app import main

main()
