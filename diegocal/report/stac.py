"""Report section for stac results (registers itself on import)."""
