"""Which SRC file is which map source, and the reader for each (CSV, C3D, TRC, Vicon/Motive CSV, bag)."""

from __future__ import annotations

import fnmatch
from pathlib import Path

from diegocal.errors import InputFileError
from diegocal.io.importers.mapping import ImportMap, MapError, SourceSpec
from diegocal.io.importers.tables import Source, kind_of
from diegocal.io.importers.units import close_match


def open_sources(paths, mapping: ImportMap) -> list[Source]:
    """One :class:`Source` per SRC path, each matched to the map's ``sources`` by file name.

    Without ``sources`` in the map each file is a source named after its file stem.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise MapError("no source files given")
    for p in paths:
        if not p.exists():
            raise InputFileError(f"{p}: no such file")
    if len({p.resolve() for p in paths}) != len(paths):
        raise MapError("the same source file is given twice")
    specs = _assign(paths, mapping)
    return [_open(path, spec) for path, spec in zip(paths, specs, strict=True)]


def _assign(paths: list[Path], mapping: ImportMap) -> list[SourceSpec]:
    if not mapping.sources:
        names, out = set(), []
        for p in paths:
            name = p.stem if p.suffix else p.name
            base, k = name, 2
            while name in names:
                name, k = f"{base}_{k}", k + 1
            names.add(name)
            out.append(SourceSpec(name=name))
        return out
    where = f"{mapping.path}: " if mapping.path else ""
    unmatched = [s for s in mapping.sources]
    out = []
    for p in paths:
        hits = [s for s in unmatched if s.file is not None and fnmatch.fnmatch(p.name, s.file)]
        if not hits:
            named = [s for s in unmatched if s.file is None]
            if len(named) == 1 and len(paths) == 1:
                hits = named  # one file, one source without a pattern
            else:
                files = [s.file for s in mapping.sources if s.file]
                raise MapError(f"{where}{p.name} matches no source in the map (files: {', '.join(files) or 'none'})"
                               + close_match(p.name, files))
        if len(hits) > 1:
            raise MapError(f"{where}{p.name} matches several sources ({', '.join(s.name for s in hits)})")
        unmatched.remove(hits[0])
        out.append(hits[0])
    if unmatched:
        s = unmatched[0]
        raise MapError(f"{where}source {s.name!r} ({s.file or 'no file pattern'}) matches none of the files "
                       f"given ({', '.join(p.name for p in paths)})"
                       + close_match(s.file or s.name, [p.name for p in paths]))
    return out


def _open(path: Path, spec: SourceSpec) -> Source:
    kind = kind_of(path, spec)
    if path.is_dir() and kind != "bag":
        raise InputFileError(f"{path}: is a directory (a ROS 2 bag folder needs its metadata.yaml)")
    if kind == "csv":
        from diegocal.io.importers.mocap_csv import sniff

        kind = sniff(path) or "csv"
    if kind in ("vicon", "motive"):
        from diegocal.io.importers.mocap_csv import open_mocap_csv

        return open_mocap_csv(path, spec, kind)
    if kind == "trc":
        from diegocal.io.importers.trc_source import open_trc

        return open_trc(path, spec)
    if kind == "csv":
        from diegocal.io.importers.csv_source import open_csv

        return open_csv(path, spec)
    if kind == "c3d":
        from diegocal.io.importers.c3d_source import open_c3d

        return open_c3d(path, spec)
    from diegocal.io.importers.bag_source import open_bag

    return open_bag(path, spec)
