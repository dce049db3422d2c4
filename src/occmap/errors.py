"""Exception types raised on purpose by occmap.

Everything here derives from :class:`OccmapError`, so ``except OccmapError`` catches every
deliberate failure. Exceptions about bad values also derive from :class:`ValueError` (and
lookup failures from :class:`LookupError`) so code written against NumPy or scipy habits
keeps working.
"""

from __future__ import annotations


class OccmapError(Exception):
    """Base class of every exception occmap raises on purpose."""


class ShapeError(OccmapError, ValueError):
    """An array argument has the wrong shape (the message names the argument and both shapes)."""


class NonFiniteError(OccmapError, ValueError):
    """An argument holds NaN or infinity where a finite number is required."""


class InvalidArgumentError(OccmapError, ValueError):
    """A value is outside what the function accepts (a zero axis, a negative time step, ...)."""


class NotARotationError(OccmapError, ValueError):
    """A matrix is not a proper rotation (R Rᵀ ≠ I or det R ≠ +1 beyond the tolerance)."""


class NotUnitQuaternionError(OccmapError, ValueError):
    """A quaternion is zero, or not of unit norm where a rotation quaternion is required."""


class TransformError(OccmapError):
    """Base class of the frame-tree errors (tf2's ``TransformException``)."""


class UnknownFrameError(TransformError, LookupError):
    """A frame name was never set in the tree (tf2's ``LookupException``)."""


class ConnectivityError(TransformError, LookupError):
    """Both frames exist but no chain of transforms joins them (tf2's ``ConnectivityException``)."""


class ExtrapolationError(TransformError, LookupError):
    """The requested time lies before the first or after the last stored stamp of a link."""


class FrameLoopError(TransformError, ValueError):
    """Setting a transform would close a loop in the frame tree."""


class FormatError(OccmapError, ValueError):
    """A file does not follow its format; the message names the file and the line or byte offset."""

    def __init__(self, path, message: str, *, line: int | None = None, offset: int | None = None):
        where = str(path)
        if line is not None:
            where += f", line {line}"
        if offset is not None:
            where += f", byte {offset}"
        super().__init__(f"{where}: {message}")
        self.path = path
        self.line = line
        self.offset = offset


class MissingFileError(FormatError, FileNotFoundError):
    """A file to read is not there (also a :class:`FileNotFoundError`, as ``open`` would raise)."""
