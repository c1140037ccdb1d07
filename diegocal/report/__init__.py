"""PDF reports assembled from result files; each section module registers itself on import.

The batch section comes first: a batch table is a .csv, which the log section would otherwise take.
"""

from diegocal.report import batch, diagnose, logs, pneumatic, sgp, stac  # noqa: F401 - they register
from diegocal.report.pdf import write_report
from diegocal.report.registry import SECTIONS, ReportContext, Section, register_section

__all__ = ["SECTIONS", "ReportContext", "Section", "register_section", "write_report"]
