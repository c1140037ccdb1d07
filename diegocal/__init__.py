"""diegocal: calibration and identification of compliant, sensor-rich robots.

Chapters of Tingfan Wu's thesis (UCSD 2013) as a toolchain: STAC (ch. 2), semi-parametric
Gaussian processes (ch. 3) and pneumatic valve-chamber models (ch. 4).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("diegocal")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+source"

from diegocal.errors import DiegocalError  # noqa: E402

__all__ = ["DiegocalError", "__version__"]
