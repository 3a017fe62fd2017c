"""Exception types of millflow.

Every error names the bad value, where it came from (argument, file, key or column)
and what was expected, so that a user can fix the input without reading the source.
"""


class MillflowError(Exception):
    """Base class of all millflow errors."""


class InputError(MillflowError, ValueError):
    """An argument, file, key or column holds a value millflow cannot use."""


class GridError(InputError):
    """A size grid or PSD is inconsistent (ordering, coverage, sums)."""


class BreakageError(InputError):
    """A breakage rate vector or breakage distribution is not physically valid."""


class SolverError(MillflowError, RuntimeError):
    """A numerical method failed or could not reach the requested accuracy."""
