"""The exceptions and the warning category of voxlab.

Every error the library reports is a :class:`VoxlabError` carrying the library's own
message (the same text the command line prints). The subclasses also derive from the
built-in exception that fits, so ``except ValueError`` or ``except OSError`` catch them
too:

=====================  ===============================  =====================================
class                  also a                           raised for
=====================  ===============================  =====================================
``FileError``          ``OSError``                      a file that cannot be read or written
``FormatError``        ``ValueError``, ``OSError``      a file whose contents break its format
``InvalidError``       ``ValueError``                   an invalid option or value
``TooLargeError``      ``ValueError``                   a size refused before allocating
``NonFiniteError``     ``ValueError``                   NaN/inf where finite values are needed
``UnsupportedError``   ``NotImplementedError``          a backend or option not implemented
``GpuError``           ``RuntimeError``                 a GPU failure (device lost, memory)
``NoGpuError``         ``GpuError``                     no GPU adapter
``CancelledError``     --                               a job stopped by its progress callback
``InternalError``      ``RuntimeError``                 a panic in the Rust code (a bug)
``DtypeError``         ``TypeError``                    an array of a dtype voxlab cannot take
``ShapeError``         ``ValueError``                   an array of the wrong shape
``LayoutError``        ``ValueError``                   an array of the wrong memory layout
=====================  ===============================  =====================================

Ctrl-C during a long job stops the job (between rows, views or iterations) and raises
``KeyboardInterrupt`` as usual.
"""


class VoxlabError(Exception):
    """An error reported by voxlab (the message is the library's)."""


class FileError(VoxlabError, OSError):
    """A file could not be read or written (the message names the file)."""


class FormatError(VoxlabError, ValueError, OSError):
    """A file was read but breaks its format (the message names the file and field)."""


class InvalidError(VoxlabError, ValueError):
    """An option or value is invalid (the message names it)."""


class TooLargeError(VoxlabError, ValueError):
    """A size was refused before allocating."""


class NonFiniteError(VoxlabError, ValueError):
    """NaN or infinite values where finite ones are required."""


class UnsupportedError(VoxlabError, NotImplementedError):
    """A backend, option or combination that voxlab does not implement (yet)."""


class GpuError(VoxlabError, RuntimeError):
    """The GPU failed: shader compilation, out of memory, device lost."""


class NoGpuError(GpuError):
    """No GPU adapter was found."""


class CancelledError(VoxlabError):
    """A job was stopped by its caller."""


class InternalError(VoxlabError, RuntimeError):
    """The Rust code panicked: a bug in voxlab, reported instead of crashing."""


class DtypeError(VoxlabError, TypeError):
    """An array's dtype is not one voxlab takes."""


class ShapeError(VoxlabError, ValueError):
    """An array's shape is wrong for the call."""


class LayoutError(VoxlabError, ValueError):
    """An array's memory layout is wrong for the call."""


class VoxlabWarning(UserWarning):
    """Something the library warns about (values replaced, a request adjusted)."""


__all__ = [
    "VoxlabError", "FileError", "FormatError", "InvalidError", "TooLargeError",
    "NonFiniteError", "UnsupportedError", "GpuError", "NoGpuError", "CancelledError",
    "InternalError", "DtypeError", "ShapeError", "LayoutError", "VoxlabWarning",
]
