"""Report section for sgp results (registers itself on import)."""
