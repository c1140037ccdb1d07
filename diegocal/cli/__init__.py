"""Command line: a thin shell over the library (parse → load → one library call → save → summary)."""

import os
import sys

# Importing a command module registers its commands on the app.
from diegocal.cli import (  # noqa: F401
    batch_cmd,
    diagnose_cmd,
    import_cmd,
    inspect_cmd,
    pneumatic_cmd,
    predict_cmd,
    report_cmd,
    sgp_cmd,
    simulate_cmd,
    simulate_dynamics_cmd,
    split_cmd,
    stac_cmd,
)
from diegocal.cli.app import app

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point; a last guard so no traceback ever reaches the user."""
    try:
        app()
    except Exception as exc:  # noqa: BLE001
        if os.environ.get("DIEGOCAL_DEBUG"):
            raise
        print(f"error: internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
