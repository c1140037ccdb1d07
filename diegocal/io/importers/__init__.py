"""`diegocal import`: lab files (C3D motion capture, ROS bags, CSV exports) -> one diegocal log.

:func:`import_log` reads the files, :func:`load_map` the small YAML map that names columns,
units, transmissions, the clock, filtering and the window (its keys: :mod:`.mapping`).
"""

from diegocal.io.importers.assemble import ImportResult, import_log
from diegocal.io.importers.mapping import ImportMap, MapError, load_map, parse_map
from diegocal.io.importers.signals import derivatives, excitation_window, lowpass, resample
from diegocal.io.importers.units import UnitError

__all__ = [
    "ImportMap",
    "ImportResult",
    "MapError",
    "UnitError",
    "derivatives",
    "excitation_window",
    "import_log",
    "load_map",
    "lowpass",
    "parse_map",
    "resample",
]
