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

from diegocal.errors import DiegocalError
from diegocal.io.bundle import load_bundle
from diegocal.io.files import log_robot, log_streams


def robot_matches(robot: dict | str | None, log_robot_name: str | None) -> bool:
    """Whether a log whose robot attribute is ``log_robot_name`` is of ``robot`` (a bundle's robot
    record, :attr:`diegocal.io.bundle.Bundle.robot`, or a name): its name (the URDF's), its
    directory or that directory's name (a bundled robot: the log says ``tx40``, the URDF
    ``staubli_tx40``); any log when either is unknown."""
    rec = robot if isinstance(robot, dict) else {"name": robot, "dir": None}
    known = {str(v) for v in (rec.get("name"), rec.get("dir")) if v}
    if not known or log_robot_name is None:
        return True
    folder = {Path(rec["dir"]).name, Path(rec["dir"]).stem} if rec.get("dir") else set()
    return log_robot_name in known or Path(log_robot_name).name in {rec.get("name"), *folder}


def robot_words(robot: dict | str | None) -> str:
    """A robot record or name in words (its name)."""
    rec = robot if isinstance(robot, dict) else {"name": robot}
    return str(rec.get("name") or rec.get("dir") or "(not named)")


@dataclass(frozen=True)
class ReportContext:
    """What every section may want to know: the robot directory, if the user named one, and
    held-out logs (``--heldout``) on which a section may score its model."""

    robot: Path | None = None
    heldout: tuple[Path, ...] = ()

    def heldout_for(self, robot: dict | str | None, needs: tuple[str, ...]) -> list[Path]:
        """The held-out logs of ``robot`` (:func:`robot_matches`) that have every stream in ``needs``."""
        out = []
        for path in self.heldout:
            try:
                name, streams = log_robot(path), log_streams(path)
            except DiegocalError:
                continue
            if robot_matches(robot, name) and all(s in streams for s in needs):
                out.append(Path(path))
        return out


@dataclass(frozen=True)
class Section:
    """How the report shows one kind of result.

    ``abstract(path, context)`` gives the section's opening in plain words (paragraphs): what was fitted on
    what, how good it is on held-out data, what is still wrong. The report's summary page repeats
    the first paragraph; a section whose pages do not open with it themselves (``opens_itself``
    False) gets an opening page from the report with the paragraphs and ``key_table(path, context)`` ->
    (columns, rows), when given. Abstracts are asked for twice (summary page and section); sections
    cache what is costly.

    ``heldout_needs(path)``: for a fitted model that is scored on ``--heldout`` logs, each model's
    robot (record or name) and the streams a held-out log needs, [(robot, needs), ...]; the report
    refuses a held-out log that no result can be scored on.
    """

    name: str
    recognise: Callable[[Path], bool]
    pages: Callable  # (path, pdf, context) -> None
    describe: Callable[[Path], dict] = lambda path: {}  # title-page facts: {log, robot, command, created}
    heading: str = ""  # the contents' name for the section, e.g. "Kinematic calibration (STAC)"
    abstract: Callable[[Path, ReportContext], list[str]] | None = None
    opens_itself: bool = True
    key_table: Callable | None = None
    headline: Callable[[Path, ReportContext], str] | None = None  # one line for the terminal's summary
    heldout_needs: Callable[[Path], list[tuple[dict | str | None, tuple[str, ...]]]] | None = None

    def title(self, path: Path) -> str:
        return f"{self.heading or self.name}: {Path(path).name}"


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
    path = Path(path)
    if not path.is_file() or path.suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        return load_bundle(path).kind == kind
    except DiegocalError:
        return False


def section_named(name: str) -> Section | None:
    return next((s for s in SECTIONS if s.name == name), None)


def section_for(path: Path) -> Section | None:
    for s in SECTIONS:
        try:
            if s.recognise(path):
                return s
        except (OSError, ValueError):
            continue
    return None
