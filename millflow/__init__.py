"""millflow: population-balance simulation of continuous grinding mills.

Class 1 is the coarsest size class, class N the finest (the sink, S_N = 0); sizes are
upper class edges in metres (Austin's convention), times in seconds, rates in 1/s.
Equations are numbered as in docs/equations.md.
"""
import millflow._interrupt  # noqa: F401  (first: Ctrl-C while the command line imports is quiet)
from millflow.batch import batch_grind, batch_solve, grind, plug_flow_profile
from millflow.breakage import (
    AustinRate,
    NonNormalizedBreakage,
    NormalizedBreakage,
    PowerLawRate,
    TabulatedBreakage,
    TabulatedRate,
    b_from_B,
    non_normalized_B,
    normalized_B,
    power_law_rates,
)
from millflow.errors import (AccuracyWarning, BreakageError, GridError, InputError, MillflowError, OutputError,
                             SolverError)
from millflow.grid import SizeGrid
from millflow.linalg import SpectralBlocks, breakage_matrix
from millflow.mill import Mill, steady_mill, transfer_matrix
from millflow.mill.well_mixed import solve_well_mixed

__version__ = "0.1.0"

#: Names served from higher layers on first use (the package root imports only the core).
_LAZY = {"Flowsheet": "millflow.flowsheet"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'millflow' has no attribute {name!r}")


__all__ = [
    "Flowsheet",
    "AustinRate",
    "BreakageError",
    "GridError",
    "InputError",
    "Mill",
    "MillflowError",
    "NonNormalizedBreakage",
    "NormalizedBreakage",
    "PowerLawRate",
    "SizeGrid",
    "SolverError",
    "AccuracyWarning",
    "OutputError",
    "SpectralBlocks",
    "TabulatedBreakage",
    "TabulatedRate",
    "b_from_B",
    "batch_grind",
    "batch_solve",
    "breakage_matrix",
    "grind",
    "non_normalized_B",
    "normalized_B",
    "plug_flow_profile",
    "power_law_rates",
    "solve_well_mixed",
    "steady_mill",
    "transfer_matrix",
]
