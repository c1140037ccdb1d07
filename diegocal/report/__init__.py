"""PDF reports assembled from result files; domain sections register themselves on import."""

from diegocal.report import logs  # noqa: F401 - registers the log section
from diegocal.report.pdf import write_report
from diegocal.report.registry import SECTIONS, ReportContext, Section, register_section

# Domain sections (each module registers itself when imported).
from diegocal.report import stac as _stac  # noqa: E402,F401
from diegocal.report import pneumatic as _pneumatic  # noqa: E402,F401
from diegocal.report import sgp as _sgp  # noqa: E402,F401

__all__ = ["SECTIONS", "ReportContext", "Section", "register_section", "write_report"]
