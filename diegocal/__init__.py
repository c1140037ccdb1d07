"""diegocal: calibration and identification of compliant, sensor-rich robots.

Chapters of Tingfan Wu's thesis (UCSD 2013) as a toolchain: STAC (ch. 2), semi-parametric
Gaussian processes (ch. 3) and pneumatic valve-chamber models (ch. 4).
"""

from diegocal.errors import DiegocalError

__all__ = ["DiegocalError", "__version__"]


def __getattr__(name: str):
    """``__version__``, read from the installed package's metadata when first asked for (reading
    it costs the command line's help a tenth of a second)."""
    if name != "__version__":
        raise AttributeError(f"module 'diegocal' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version  # lazy: see the docstring

    try:
        value = version("diegocal")
    except PackageNotFoundError:  # running from a source tree that is not installed
        value = "0.0.0+source"
    globals()["__version__"] = value
    return value
