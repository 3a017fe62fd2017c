"""millflow: population-balance simulation of continuous grinding mills.

Class 1 is the coarsest size class, class N the finest (the sink, S_N = 0).
Equations are numbered as in EQUATIONS.md of the project.
"""
from millflow.errors import BreakageError, GridError, InputError, MillflowError, SolverError
from millflow.batch import batch_grind

__version__ = "0.1.0"
__all__ = [
    "batch_grind",
    "BreakageError",
    "GridError",
    "InputError",
    "MillflowError",
    "SolverError",
]
