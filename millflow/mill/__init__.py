"""Continuous mills: breakage (eq. 4 kinetics) coupled to transport and classification.

``Mill`` composes rates S [1/s], fractional breakage b, an ``rtd`` transport model and
the normalised discharge d_i* (eq. 1-3); :func:`steady_mill` and
:func:`transfer_matrix` solve the steady state by the cheapest exact method for the
scene, :func:`transient_mill` the dynamics. Modules, one job each:

- :mod:`~millflow.mill.steady`: the scene (validation, method choice) and the steady
  solve, ``Mill``;
- :mod:`~millflow.mill.well_mixed`: the perfectly mixed mill, eq. 3 (one mill or a population);
- :mod:`~millflow.mill.segregated`: segregated flow and plug flow (eq. 4 in contact
  time) through the spectral decomposition of the breakage matrix;
- :mod:`~millflow.mill.cells`: compartment networks (tanks, recirculating cells),
  one class at a time;
- :mod:`~millflow.mill.axial`: the axial-dispersion PDE by finite volumes;
- :mod:`~millflow.mill.axial_open`: the open vessel's PDE on the whole line (sampled or
  flux discharge);
- :mod:`~millflow.mill.transport`: the one transport dispatch (names, kinds, cells, what
  a fit can estimate, builders) that code outside the mill layer asks;
- :mod:`~millflow.mill.transient`: the dynamic response;
- :mod:`~millflow.mill.population`: the products of many mills (rate vectors) at once;
- :mod:`~millflow.mill.nonlinear`: mills with non-linear kinetics (aggregation,
  population-dependent rates): perfect mixing by Newton, tanks in series,
  plug flow, axial dispersion, and the two micromixing limits of any RTD.
"""
from millflow._lazy import attach

# Served on first use: a flowsheet that needs only the steady solve does not load the
# transient solver (scipy.integrate) or the composed Mill (xarray).
__getattr__, __dir__ = attach(__name__, {
    "millflow.mill.composed": ("Mill",),
    "millflow.mill.steady": ("steady_mill", "transfer_matrix"),
    "millflow.mill.transient": ("transient_mill",),
    "millflow.mill.population": ("steady_population",),
})

__all__ = ["Mill", "steady_mill", "steady_population", "transfer_matrix", "transient_mill"]
