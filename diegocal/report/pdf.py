"""`diegocal report`: one multi-page PDF from result files, with a title page saying what was run."""

from __future__ import annotations

import datetime as _dt
import platform
from pathlib import Path

from matplotlib.backends.backend_pdf import PdfPages

from diegocal import __version__
from diegocal.errors import InputFileError
from diegocal.io import atomic_path
from diegocal.report.registry import ReportContext, section_for
from diegocal.report.style import save_page, text_page


def write_report(results, out, context: ReportContext | None = None, command: str = "diegocal report") -> list[str]:
    """Write the report; returns the section name used for each result, in order.

    Every result is recognised before anything is written, so an unknown file fails cleanly
    and no half-written PDF is left behind (the write is atomic too).
    """
    context = context or ReportContext()
    results = [Path(r) for r in results]
    plan = []
    for r in results:
        if not r.exists():
            raise InputFileError(f"{r}: no such file or directory")
        section = section_for(r)
        if section is None:
            raise InputFileError(
                f"{r}: not a result diegocal can report (a log, calib.yaml, pneumatic.yaml or sgp/ model)"
            )
        plan.append((r, section))
    with atomic_path(out) as tmp, PdfPages(tmp) as pdf:
        save_page(pdf, text_page("diegocal report", _title_lines(plan, context, command)))
        for r, section in plan:
            section.pages(r, pdf, context)
        info = pdf.infodict()
        info["Title"] = "diegocal report"
        info["Creator"] = f"diegocal {__version__}"
    return [s.name for _, s in plan]


def _title_lines(plan, context: ReportContext, command: str) -> list[str]:
    now = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    lines = [
        f"command:  {command}",
        f"created:  {now}",
        f"diegocal: {__version__}  (Python {platform.python_version()})",
    ]
    if context.robot is not None:
        lines.append(f"robot:    {context.robot}")
    lines += ["", "results:"]
    for r, section in plan:
        facts = section.describe(r)
        extra = "  ".join(f"{k}={v}" for k, v in facts.items() if v)
        lines.append(f"  [{section.name}] {r}" + (f"\n      {extra}" if extra else ""))
    return lines
