"""How many columns the command line draws in: the floor of ``--width`` and of ``COLUMNS``. Imports nothing
of quadctl: the console script's guard (:mod:`quadctl.cli.entry`) sets ``COLUMNS`` by it before any console
reads it, and the app (:mod:`quadctl.cli.app`) bounds ``--width`` by it."""

from __future__ import annotations

import os

NARROWEST = 40
"""The fewest columns a table or help page is drawn in: ``--width``'s floor."""


def usable_columns() -> None:
    """``COLUMNS`` as rich can draw in, before any console reads it: ``0`` (what a container or CI runner
    that knows no width may set) is taken as unset, where rich would draw every table and help page
    ``0`` columns wide, that is print nothing; ``1`` to ``39`` as :data:`NARROWEST`, where each cell would be
    cut to a character or less. Anything else, a terminal's own width included, is left as it is."""
    columns = os.environ.get("COLUMNS", "")
    if columns.isdigit() and int(columns) == 0:
        del os.environ["COLUMNS"]
    elif columns.isdigit() and int(columns) < NARROWEST:
        os.environ["COLUMNS"] = str(NARROWEST)
