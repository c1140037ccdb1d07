"""Report sections: domain code registers how to recognise its result files and draw their pages.

A section is ``(name, recognise, pages)``: ``recognise(path) -> bool`` says whether a result file
(or directory) is this section's, ``pages(path, pdf, context)`` appends pages to an open
:class:`matplotlib.backends.backend_pdf.PdfPages`. The report walks the results in the order the
user gave them and uses the first section that recognises each.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class ReportContext:
    """What every section may want to know: the robot directory, if the user named one."""

    robot: Path | None = None


@dataclass(frozen=True)
class Section:
    name: str
    recognise: Callable[[Path], bool]
    pages: Callable  # (path, pdf, context) -> None
    describe: Callable[[Path], dict] = lambda path: {}  # title-page facts: {log, robot, command, created}


SECTIONS: list[Section] = []


def register_section(section: Section, before: str | None = None) -> Section:
    """Add a section; later registrations of the same name replace earlier ones. ``before``: the
    name of a section this one must be tried before (a more specific kind of the same file)."""
    rest = [s for s in SECTIONS if s.name != section.name]
    at = next((i for i, s in enumerate(rest) if s.name == before), len(rest))
    SECTIONS[:] = rest[:at] + [section] + rest[at:]
    return section


def is_bundle(path, kind: str) -> bool:
    """Whether ``path`` is a fitted-output YAML file of bundle ``kind`` (the one loader,
    :func:`diegocal.io.bundle.load_bundle`, decides; a file it cannot read is no bundle)."""
    from diegocal.errors import DiegocalError
    from diegocal.io.bundle import load_bundle

    path = Path(path)
    if not path.is_file() or path.suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        return load_bundle(path).kind == kind
    except DiegocalError:
        return False


def section_for(path: Path) -> Section | None:
    for s in SECTIONS:
        try:
            if s.recognise(path):
                return s
        except (OSError, ValueError):
            continue
    return None
