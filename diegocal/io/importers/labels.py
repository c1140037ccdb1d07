"""Marker labels with a subject prefix: Vicon names each marker ``Subject:Marker`` (``PR2:ua1``) in
its C3D and CSV exports, Motive ``Asset:Marker``. A robot's sensors.yaml names the markers alone.

With one subject in the file the prefix is stripped; with several, the map's ``subject:`` on the
markers stream picks one (its markers, prefix stripped), else the full names are kept.
"""

from __future__ import annotations

from diegocal.io.importers.mapping import MapError
from diegocal.io.importers.units import close_match


def subject_of(label: str) -> str | None:
    return label.split(":", 1)[0] if ":" in label else None


def strip_subject(pairs, subject: str | None, where: str) -> tuple[tuple[tuple[str, str], ...], str]:
    """(file column, channel) pairs with the subject prefix taken off the channels, and words for the
    summary ('' when nothing changed)."""
    subjects = list(dict.fromkeys(s for c, _ in pairs if (s := subject_of(c)) is not None))
    if subject is not None:
        if subject not in subjects:
            raise MapError(f"{where}: no markers of subject {subject!r} (subjects: {', '.join(subjects) or 'none'})"
                           + close_match(subject, subjects))
        kept = tuple((c, ch.split(":", 1)[1] if subject_of(ch) == subject else ch)
                     for c, ch in pairs if subject_of(c) == subject)
        return kept, f"subject {subject}"
    if len(subjects) == 1 and all(subject_of(c) is not None for c, _ in pairs):
        return tuple((c, ch.split(":", 1)[1]) for c, ch in pairs), f"'{subjects[0]}:' prefix stripped"
    if len(subjects) > 1:
        return tuple(pairs), f"subjects {', '.join(subjects)} kept in the names (pick one with `subject:`)"
    return tuple(pairs), ""


def unprefixed(name: str, columns) -> str | None:
    """The one column ``Subject:<name>`` when ``name`` is a marker named without its subject."""
    hits = [c for c in columns if ":" in c and c.split(":", 1)[1] == name]
    return hits[0] if len(hits) == 1 else None
