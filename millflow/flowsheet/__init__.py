"""Flowsheets of grinding circuits: read, solve, report.

A flowsheet file (TOML, docs/flowsheets.md) names a size grid, materials with their
breakage functions, units (feed, mill, hydrocyclone, screen, air separator, mixer or
tank, splitter, product) and the streams between them. :func:`load` reads it (units of
measure converted to SI at the edge), :func:`solve` finds the steady state (one sparse
linear system when every unit is linear, tear iterations only for nonlinear units) and
:func:`to_dataset` / :func:`save` turn the solution into an xarray Dataset (dimensions
``stream`` and ``size``), tables, ``summary.json`` and plots.

Examples
--------
A file is read with ``load("flowsheets/closed_circuit_ball_mill.toml")``; the same text
can be given as a string (an open circuit: a feed, a mill of three tanks in series, a
product).

Examples
--------
>>> from millflow.flowsheet import loads, solve, summary
>>> sol = solve(loads('''
... grid = {top_um = 8000, bottom_um = 10, ratio = 1.4142135623730951}
... [materials.ore]
... rate = {form = "power", A_per_min = 0.7, alpha = 1.1, x0_um = 1000}
... breakage = {form = "normalized", phi = 0.5, gamma = 0.9, beta = 4.0}
... [units]
... fresh = {type = "feed", solids_tph = 100, psd = {form = "rosin_rammler", x63_um = 700, n = 1.1}}
... mill = {type = "mill", material = "ore", tau_min = 5, transport = {model = "tanks_in_series", n = 3}}
... product = {type = "product"}
... [streams]
... feed = {from = "fresh", to = "mill"}
... discharge = {from = "mill", to = "product"}
... '''))
>>> report = summary(sol)
>>> round(report["streams"]["discharge"]["solids_tph"], 9), report["mass_balance_error"] < 1e-12
(100.0, True)
>>> report["streams"]["discharge"]["p80_um"] < report["streams"]["feed"]["p80_um"]  # ground finer
True
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
