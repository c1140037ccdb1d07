"""Report section for pneumatic results (registers itself on import)."""
