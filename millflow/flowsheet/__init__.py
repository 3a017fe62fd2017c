"""Flowsheets of grinding circuits: read, solve, report.

A flowsheet file (TOML, docs/flowsheets.md) names a size grid, materials with their
breakage functions, units (feed, mill, hydrocyclone, screen, air separator, mixer or
tank, splitter, product) and the streams between them. :func:`load` reads it (units of
measure converted to SI at the edge), :func:`solve` finds the steady state (one sparse
linear system when every unit is linear, tear iterations only for nonlinear units) and
:func:`to_dataset` / :func:`save` turn the solution into an xarray Dataset (dimensions
``stream`` and ``size``), tables, ``summary.json`` and plots.

>>> from millflow.flowsheet import load, solve, summary   # doctest: +SKIP
>>> sol = solve(load("flowsheets/closed_circuit_ball_mill.toml"))  # doctest: +SKIP
>>> summary(sol)["circulating_load"]  # doctest: +SKIP
"""
from millflow.flowsheet.graph import Stream
from millflow.flowsheet.io import Flowsheet, from_dict, load, loads
from millflow.flowsheet.results import circulating_loads, save, stream_table, summary, to_dataset, unit_table
from millflow.flowsheet.solve import TEAR_METHODS, FlowsheetSolution, solve
from millflow.flowsheet.units import (CLASSIFIER_PORTS, TRANSPORTS, UNIT_TYPES, Classifier, Feed, Mill, MillUnit, Mixer,
                                      Product, Splitter)

__all__ = [
    "Flowsheet", "Stream", "load", "loads", "from_dict", "solve", "FlowsheetSolution", "TEAR_METHODS",
    "to_dataset", "summary", "stream_table", "unit_table", "circulating_loads", "save",
    "Feed", "MillUnit", "Mill", "Classifier", "Mixer", "Splitter", "Product", "UNIT_TYPES", "TRANSPORTS",
    "CLASSIFIER_PORTS",
]
