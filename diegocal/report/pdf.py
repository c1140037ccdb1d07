"""`diegocal report`: one PDF document from result files.

The document opens with a front page (what was run, the contents with page numbers, and a summary
in plain words: each section's first paragraph), then one section per result in the order given;
a report of one result opens the same way. Every page carries a footer with its section and page
number. Sections are drawn first into a :class:`Document` (which collects the pages), so that the
contents know where each section starts. Held-out logs (``--heldout``) are checked before anything
is drawn: each must be one that some fitted model given can be scored on.
"""

from __future__ import annotations

import datetime as _dt
import platform
from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.backends.backend_pdf import PdfPages

from diegocal import __version__
from diegocal.errors import DiegocalError, InputFileError
from diegocal.io import atomic_path
from diegocal.io.files import log_robot, log_streams
from diegocal.report.layout import Column, Sheet, table_sheets
from diegocal.report.registry import ReportContext, Section, robot_matches, robot_words, section_for
from diegocal.report.style import save_page

#: What a section may fail with while it summarises a result: the summary says so and goes on.
SUMMARY_ERRORS = (DiegocalError, OSError, KeyError, TypeError, ValueError)


class Document:
    """Pages collected in order (``savefig`` as PdfPages has it), with where each section starts."""

    def __init__(self):
        self.pages: list = []
        self.sections: list[tuple[str, int]] = []  # (title, index of its first page)

    def savefig(self, fig, **kw) -> None:
        self.pages.append(fig)

    def start(self, title: str) -> None:
        self.sections.append((title, len(self.pages)))

    def section_of(self, index: int) -> str:
        title = ""
        for t, first in self.sections:
            if first <= index:
                title = t
        return title


def plan_report(results) -> list[tuple[Path, Section]]:
    """Every result with the section that shows it; one clear error for a file no section knows."""
    plan = []
    for r in map(Path, results):
        if not r.exists():
            raise InputFileError(f"{r}: no such file or directory")
        section = section_for(r)
        if section is None:
            raise InputFileError(
                f"{r}: not a result diegocal can report (a log, calib.yaml, pneumatic.yaml, sgp/ model, "
                "diagnosis.yaml or batch table)"
            )
        plan.append((r, section))
    return plan


def check_heldout(plan, context: ReportContext) -> None:
    """Every held-out log must be one that some fitted model of ``plan`` is scored on: of the same
    robot, with the streams the model needs. Raises :class:`InputFileError` with the reason (not a
    log, no fitted model given, another robot's log, a stream missing) for the first that is not."""
    uses = [
        (r, robot, needs)
        for r, section in plan
        if section.heldout_needs is not None
        for robot, needs in section.heldout_needs(r)
    ]
    for h in context.heldout:
        try:
            name, streams = log_robot(h), set(log_streams(h))
        except DiegocalError as exc:
            raise InputFileError(f"held-out log {exc}") from None
        if not uses:
            raise InputFileError(
                f"{h}: no result given is scored on a held-out log (calib.yaml, pneumatic.yaml and sgp/ models are)"
            )
        mine = [(r, robot, needs) for r, robot, needs in uses if robot_matches(robot, name)]
        if not mine:
            robots = ", ".join(dict.fromkeys(f"{robot_words(robot)} ({Path(r).name})" for r, robot, _ in uses))
            raise InputFileError(f"{h}: a log of robot {name}, but the models given are of robot {robots}")
        if not any(set(needs) <= streams for _, _, needs in mine):
            r, _, needs = mine[0]
            missing = ", ".join(s for s in needs if s not in streams)
            raise InputFileError(
                f"{h}: no {missing} stream, which {Path(r).name} needs to be scored on it (it has "
                f"{', '.join(sorted(streams)) or 'no stream'})"
            )


def _each(plan, context: ReportContext, attr: str, failed):
    """(section title, ``section.<attr>(result, context)``) of every result whose section has one;
    ``failed(exc)`` stands in for what a section could not say."""
    out = []
    for r, section in plan:
        say = getattr(section, attr)
        if say is None:
            continue
        try:
            out.append((section.title(r), say(r, context)))
        except SUMMARY_ERRORS as exc:
            out.append((section.title(r), failed(exc)))
    return out


def abstracts(plan, context: ReportContext) -> list[tuple[str, list[str]]]:
    """(section title, plain-words paragraphs) of every result that has an abstract."""
    return _each(plan, context, "abstract", lambda exc: [f"(no summary: {exc})"])


def headlines(plan, context: ReportContext) -> list[tuple[str, str]]:
    """(section title, one line) of every result whose section has a headline: the terminal's summary."""
    return _each(plan, context, "headline", lambda exc: f"(no summary: {exc})")


def write_report(results, out, context: ReportContext | None = None, command: str = "diegocal report") -> list[str]:
    """Write the report; returns the section name used for each result, in order.

    Every result is recognised and every held-out log checked before anything is written, so an
    unknown file or a held-out log no model can be scored on fails cleanly and no half-written PDF
    is left behind (the write is atomic too).
    """
    context = context or ReportContext()
    plan = plan_report(results)
    check_heldout(plan, context)
    doc = Document()
    for r, section in plan:
        doc.start(section.title(r))
        if not section.opens_itself and section.abstract is not None:
            for sheet in opening_sheets(section, r, context):
                save_page(doc, sheet.fig)
        section.pages(r, doc, context)
    summary = abstracts(plan, context)
    counting = front_sheets(plan, doc, context, command, summary, offset=0)
    for sheet in counting:  # the first pass only counts the front pages
        plt.close(sheet.fig)
    front = front_sheets(plan, doc, context, command, summary, offset=len(counting))
    n_front = len(front)
    pages = [s.fig for s in front] + doc.pages
    stamp = f"diegocal {__version__}, {_dt.datetime.now(_dt.UTC):%Y-%m-%d}"
    with atomic_path(out) as tmp, PdfPages(tmp) as pdf:
        for i, fig in enumerate(pages):
            where = "contents and summary" if i < n_front else doc.section_of(i - n_front)
            footer = f"{where}  ·  page {i + 1} of {len(pages)}  ·  {stamp}"
            fig.text(0.5, 0.018, footer, ha="center", fontsize=7, color="0.45")
            pdf.savefig(fig)
            plt.close(fig)
        info = pdf.infodict()
        info["Title"] = "diegocal report"
        info["Creator"] = f"diegocal {__version__}"
    return [s.name for _, s in plan]


def opening_sheets(section: Section, path: Path, context: ReportContext) -> list[Sheet]:
    """The report-made opening page of a section: its title, its paragraphs and its key table."""
    title = section.title(path)
    paragraphs = section.abstract(path, context)
    if section.key_table is not None:
        columns, rows = section.key_table(path, context)
        return table_sheets(title, columns, rows, intro=paragraphs)
    sheet = Sheet(title)
    for p in paragraphs:
        sheet.paragraph(p)
    return [sheet]


def front_sheets(plan, doc: Document, context: ReportContext, command: str, summary, offset: int) -> list[Sheet]:
    """Title, what was run, the contents (page numbers counted after ``offset`` front pages) and the
    summary: every section's opening paragraphs."""
    now = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    sheets = [Sheet("diegocal report")]
    facts = f"Written {now} by diegocal {__version__} (Python {platform.python_version()}) with: {command}"
    if context.robot is not None:
        facts += f" Robot directory: {context.robot}."
    sheets[-1].paragraph(facts, size=8, color="0.3")
    columns = [
        Column("section", align="left"),
        Column("result file", align="left"),
        Column("from log", align="left"),
        Column("page"),
    ]
    rows = []
    for (title, first), (r, section) in zip(doc.sections, plan, strict=True):
        rows.append([title.split(": ", 1)[0], _short(r), _source(section, r), str(offset + first + 1)])
    sheets += table_sheets("Contents", columns, rows, sheet=sheets[-1])[1:]
    if summary:
        _put(sheets, "Summary", 11, heading=True, room=0.15)
        for title, paragraphs in summary:
            _put(sheets, title, 9.5, heading=True)
            for p in paragraphs:
                _put(sheets, p, 9)
    return sheets


def _source(section: Section, path: Path) -> str:
    """The log a result was made from (its provenance), by name; "–" when it does not say."""
    try:
        log = (section.describe(path) or {}).get("log")
    except SUMMARY_ERRORS:
        log = None
    return Path(str(log)).name if log else "–"


def _short(path: Path, width: int = 60) -> str:
    text = str(path)
    return text if len(text) <= width else "…" + text[-(width - 1) :]


def _put(sheets: list[Sheet], text: str, size: float, heading: bool = False, room: float = 0.08) -> None:
    """A heading or paragraph on the last sheet, or on a new one when it does not fit."""
    if heading and sheets[-1].room() < room:
        sheets.append(Sheet("Summary (continued)"))
    if heading:
        sheets[-1].heading(text, size=size)
    elif not sheets[-1].paragraph(text, size=size):
        sheets.append(Sheet("Summary (continued)"))
        sheets[-1].paragraph(text, size=size)
