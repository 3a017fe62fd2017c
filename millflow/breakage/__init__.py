"""Breakage functions: specific rates S_i and distributions B_ij, b_ij (eqs. 5-8, 10).

The public face of :mod:`millflow.breakage.rates` (eq. 5 power law, eq. 7 Austin's
rate with a maximum and ball-size dependence, eq. 10 process-parameter prefactor,
form-free vectors) and :mod:`millflow.breakage.distributions` (eq. 6 normalized and
eq. 8 non-normalized cumulative distributions, form-free B or b, conversions and
validation) and :mod:`millflow.breakage.t10` (B from an ore's tn-t10 family). Sizes are upper
class edges [m], rates [1/s]; class N is the sink:
S_N = 0 and column N of B and b is zero. A rate model is any callable ``x -> S``,
a distribution model any callable ``x -> b``; the dataclasses here are such
callables with validated parameters, and a user's own function plugs in the same way.
:mod:`millflow.breakage.averaged` puts continuous forms on a grid by class averages
(``breakage_on_grid``, ``averaged_breakage``, ``curve_on_grid``): second order in the class
width, where calling a form with the upper edges is Austin's first-order discrete model.
"""
from millflow.breakage.distributions import (
    COLUMN_TOL,
    B_from_b,
    NonNormalizedBreakage,
    NormalizedBreakage,
    TabulatedBreakage,
    b_from_B,
    breakage_population,
    evaluate_b,
    non_normalized_B,
    normalized_B,
    validate_B,
    validate_b,
)
from millflow.breakage.averaged import averaged_breakage, breakage_on_grid, class_average, curve_on_grid
from millflow.breakage.energy import EnergySpecificRate
from millflow.breakage.t10 import T10Breakage, T10Table, read_t10_table, t10_B
from millflow.breakage.rates import (
    AustinRate,
    PowerLawRate,
    TabulatedRate,
    X0_DEFAULT,
    austin_rates,
    austin_rates_population,
    evaluate_rates,
    power_law_rates,
    power_law_rates_population,
    ln_process_power_law,
    process_power_law,
    validate_rates,
)

__all__ = [
    "averaged_breakage",
    "breakage_on_grid",
    "class_average",
    "curve_on_grid",
    "power_law_rates",
    "austin_rates",
    "power_law_rates_population",
    "austin_rates_population",
    "X0_DEFAULT",
    "process_power_law",
    "ln_process_power_law",
    "validate_rates",
    "evaluate_rates",
    "PowerLawRate",
    "AustinRate",
    "TabulatedRate",
    "normalized_B",
    "non_normalized_B",
    "breakage_population",
    "b_from_B",
    "B_from_b",
    "validate_B",
    "validate_b",
    "evaluate_b",
    "NormalizedBreakage",
    "NonNormalizedBreakage",
    "TabulatedBreakage",
    "COLUMN_TOL",
    "T10Breakage",
    "T10Table",
    "read_t10_table",
    "t10_B",
    "EnergySpecificRate",
]
