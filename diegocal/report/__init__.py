"""PDF reports assembled from result files; each section module registers itself on import."""

from diegocal.report import diagnose, logs, pneumatic, sgp, stac  # noqa: F401 - imported to register their sections
from diegocal.report.pdf import write_report
from diegocal.report.registry import SECTIONS, ReportContext, Section, register_section

__all__ = ["SECTIONS", "ReportContext", "Section", "register_section", "write_report"]
