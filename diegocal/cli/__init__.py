"""Command line: a thin shell over the library (parse → load → one library call → save → summary).

Each command's module is imported when that command runs (:data:`diegocal.cli.app.COMMANDS`), so
``from diegocal.cli import app`` and ``diegocal --help`` load none of them.
"""

import os
import sys

from diegocal.cli.app import COMMANDS, app

__all__ = ["COMMANDS", "app", "main"]


def main() -> None:
    """Console-script entry point; a last guard so no traceback ever reaches the user."""
    try:
        app()
    except Exception as exc:  # noqa: BLE001
        if os.environ.get("DIEGOCAL_DEBUG"):
            raise
        print(f"error: internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
