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


class OutputError(MillflowError, OSError):
    """Results could not be written.

    Results could not be written (read-only or full disk, a file where a folder is
    expected, a missing parent folder). Nothing partial is left in the target.
    """


class AccuracyWarning(UserWarning):
    """A result missed its requested tolerance.

    A result missed its requested tolerance (mass balance or error estimate) and the
    caller asked for a warning (``on_inaccuracy="warn"``) instead of a SolverError.
    """


class ModelRangeWarning(UserWarning):
    """A model was used outside its stated range of validity (or with illustrative constants).

    The warning names the unit and the quantity.
    """
