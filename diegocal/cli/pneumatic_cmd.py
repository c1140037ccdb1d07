"""CLI commands of this domain (attach to diegocal.cli.app.app / simulate_app)."""
