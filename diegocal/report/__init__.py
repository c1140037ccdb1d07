"""PDF reports assembled from result files; each section module registers itself on import.

The batch section comes first: a batch table is a .csv, which the log section would otherwise take.
The SGP section gets its opening page (plain words, key numbers) from :mod:`.sgp_text`.
"""

from dataclasses import replace

from diegocal.report import batch, diagnose, logs, pneumatic, sgp, sgp_text, stac  # noqa: F401 - they register
from diegocal.report.pdf import write_report
from diegocal.report.registry import SECTIONS, ReportContext, Section, register_section, section_named

register_section(
    replace(
        section_named("sgp"),
        heading="Torque model (SGP)",
        abstract=sgp_text.abstract,
        opens_itself=False,
        key_table=sgp_text.key_table,
        headline=sgp_text.headline,
    )
)

__all__ = ["SECTIONS", "ReportContext", "Section", "register_section", "write_report"]
