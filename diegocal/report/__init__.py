"""PDF reports assembled from result files; each section module registers itself on import.

A section (:mod:`.registry`) says how to recognise a result and draws its pages from plot functions
``(result, ax=None) -> Axes`` (``*_plots`` modules, shared styling in :mod:`.style`) placed on typeset
sheets (:mod:`.layout`); :mod:`.pdf` assembles the document. Imports inside the package go one way:
``__init__`` → sections → their words, tables and plots → layout, registry, style.

The batch section comes first: a batch table is a .csv, which the log section would otherwise take.
"""

from diegocal.report import batch, diagnose, logs, pneumatic, sgp, stac  # noqa: F401 - they register
from diegocal.report.pdf import write_report
from diegocal.report.registry import SECTIONS, ReportContext, Section, register_section

__all__ = ["SECTIONS", "ReportContext", "Section", "register_section", "write_report"]
