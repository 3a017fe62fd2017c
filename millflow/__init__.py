"""millflow: population-balance simulation of continuous grinding mills.

Class 1 is the coarsest size class, class N the finest (the sink, S_N = 0); sizes are
upper class edges in metres (Austin's convention), times in seconds, rates in 1/s.
Equations are numbered as in docs/equations.md.
"""
import millflow._interrupt  # noqa: F401  (first: Ctrl-C while the command line imports is quiet)

__version__ = "0.1.0"

from millflow._lazy import attach

# Public names and their modules, imported on first use: ``import millflow`` (and
# ``millflow --version``) loads no scipy.integrate, scipy.stats, pandas, xarray or
# matplotlib until a call needs them.
__getattr__, __dir__ = attach(__name__, {
    "millflow.batch": ("batch_grind", "batch_solve", "grind", "plug_flow_profile"),
    "millflow.breakage": ("AustinRate", "NonNormalizedBreakage", "NormalizedBreakage", "PowerLawRate",
                          "TabulatedBreakage", "TabulatedRate", "b_from_B", "non_normalized_B", "normalized_B",
                          "power_law_rates"),
    "millflow.errors": ("AccuracyWarning", "BreakageError", "GridError", "InputError", "MillflowError",
                        "OutputError", "SolverError"),
    "millflow.grid": ("SizeGrid",),
    "millflow.linalg": ("SpectralBlocks", "breakage_matrix"),
    "millflow.mill": ("Mill", "steady_mill", "steady_population", "transfer_matrix"),
    "millflow.mill.well_mixed": ("solve_well_mixed",),
    "millflow.flowsheet": ("Flowsheet",),
})

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
    "steady_population",
    "transfer_matrix",
]
