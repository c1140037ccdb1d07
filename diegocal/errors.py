"""One error family for the whole library.

The library raises these and never prints or exits; the CLI alone turns them into one line
and a non-zero exit. Each subclasses a built-in so callers may catch the usual type too.
"""


class DiegocalError(Exception):
    """Base of every error diegocal raises on purpose."""


class InputFileError(DiegocalError, FileNotFoundError):
    """A file the user named is missing or cannot be read."""


class LogFormatError(DiegocalError, ValueError):
    """A log file does not follow the diegocal log format (DESIGN.md, version 1)."""


class DamagedFileError(LogFormatError):
    """A log file of the right kind whose bytes cannot be read (overwritten, a failed copy)."""


class MissingStreamError(DiegocalError, KeyError):
    """A command needs a stream the log does not have."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class RobotConfigError(DiegocalError, ValueError):
    """A robot directory (URDF + sensors.yaml) is invalid."""


class UnknownNameError(DiegocalError, KeyError):
    """A sensor, joint, marker or chamber name is not known to the robot."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class NumericalError(DiegocalError, ArithmeticError):
    """A numerical step failed (singular matrix, failed Cholesky); the message says what to change."""


class OptionError(DiegocalError, ValueError):
    """An option's value is malformed, not a word the option takes, or out of its range, found by
    the library rather than the parser; the CLI exits 2, as for the parser's own usage errors. (A
    name the robot or the log does not know is bad input, exit 1: UnknownNameError.)"""


class FitError(DiegocalError, RuntimeError):
    """A fit cannot proceed with the given data (too few samples, unobservable parameters)."""


class ScratchSpaceError(DiegocalError, OSError):
    """A temporary file a long run writes (the kinematics diagnosis's candidate columns) does not fit
    where ``TMPDIR`` puts it."""


class NotFittedError(DiegocalError, AttributeError):
    """An estimator asked to save or predict before it was fitted (scikit-learn's NotFittedError
    is an AttributeError and a ValueError too: this one is the former)."""
